"""Training shards (`v2c.segment.shards`) and the accelerator trainer (`v2c.segment.train_device`), on the CPU.

A packed scan realised with fresh noise must give exactly the scan's own targets, and inputs whose noise has the
generator's statistics; crops cut on the device must be the arrays' own pixels; a few steps of training must
lower the loss and write checkpoints that `net.load_weights` reads.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from v2c.scan import load_scan
from v2c.segment.data import MIRROR_SIGN_CHANNEL, boundary_map, dequantise
from v2c.segment.net import NetConfig, load_weights
from v2c.segment.shards import ShardConfig, cos_incidence_from_depth, read_shard, realise, write_shards
from v2c.segment.train_config import TrainConfig
from v2c.segment.train_device import DeviceScans, DeviceTrainConfig, realise_all, train_on_device
from v2c.synth.dataset import SynthConfig, generate_dataset


@pytest.fixture(scope="module")
def scans(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Path]]:
    root = tmp_path_factory.mktemp("shard_scans")
    dirs = generate_dataset(root / "s", 4, 31, SynthConfig(width=320, height=240, noise="sensor"), progress=False)
    return root, dirs


def test_shards_round_trip_and_split(scans: tuple[Path, list[Path]], tmp_path: Path) -> None:
    """Every scan lands in exactly one shard under the size limit, in order, and reads back with its intrinsics."""
    root, dirs = scans
    one = write_shards(dirs, root, tmp_path / "one")
    assert len(one) == 1
    packed = read_shard(one[0])
    assert [p.name for p in packed] == [str(d.relative_to(root)) for d in dirs]
    for p, d in zip(packed, dirs, strict=True):
        np.testing.assert_array_equal(p.K, load_scan(d).K)
        assert p.profile == "sensor"
    limit_mb = 0.015
    small = write_shards(dirs, root, tmp_path / "small", ShardConfig(max_shard_mb=limit_mb))
    assert len(small) >= 2
    names = [p.name for s in small for p in read_shard(s)]
    assert names == [p.name for p in packed]
    for s in small:  # under the limit, or a single scan that alone exceeds it
        assert s.stat().st_size < limit_mb * 2**20 + 2_000 or len(read_shard(s)) == 1


def test_realise_targets_exact_and_noise_like_the_generator(scans: tuple[Path, list[Path]], tmp_path: Path) -> None:
    """Labels and boundaries are the scan's own; the redrawn depth noise on the part has the generator's size
    (median |noisy - clean| within 30 %) and hole share (within 3 points); no reading appears where the clean depth
    has none."""
    root, dirs = scans
    packed = read_shard(write_shards(dirs, root, tmp_path)[0])
    gen_err, re_err, gen_holes, re_holes = [], [], [], []
    for p, d in zip(packed, dirs, strict=True):
        scan = load_scan(d)
        x, y, b, depth = realise(p, "sensor", (5, 1))
        assert x.shape == (9, 240, 320) and x.dtype == np.uint8
        np.testing.assert_array_equal(y, scan.gt.labels)
        np.testing.assert_array_equal(b, boundary_map(scan.gt.faces).astype(np.uint8))
        clean = np.load(d / "gt" / "depth_clean.npy")
        assert not np.any((clean == 0) & (depth > 0))
        part = scan.gt.faces > 0
        both_g = part & (scan.depth > 0)
        both_r = part & (depth > 0)
        gen_err.append(np.median(np.abs(scan.depth[both_g] - clean[both_g])))
        re_err.append(np.median(np.abs(depth[both_r] - clean[both_r])))
        gen_holes.append(np.mean(scan.depth[part] == 0))
        re_holes.append(np.mean(depth[part] == 0))
        # a second draw is different noise on the same targets
        x2, y2, _, depth2 = realise(p, "sensor", (5, 2))
        np.testing.assert_array_equal(y2, y)
        assert np.mean(depth2[both_r] != depth[both_r]) > 0.5
    assert np.median(re_err) == pytest.approx(np.median(gen_err), rel=0.3)
    assert np.mean(re_holes) == pytest.approx(np.mean(gen_holes), abs=0.03)


def test_cos_incidence_of_a_tilted_plane_and_at_a_step() -> None:
    """|cos| of a plane tilted 60 degrees about the camera x axis, seen straight on at the principal point, is the
    exact cos(60 deg) there; across a depth step the slope of the pixel's own side is used."""
    h = w = 41
    K = np.array([[500.0, 0, 20], [0, 500.0, 20], [0, 0, 1]])
    v = np.arange(h)[:, None] - 20.0
    t = np.tan(np.deg2rad(60.0))
    # plane through (0, 0, 1) with normal (0, sin60, -cos60)... z(v) = 1 / (1 - t * v / f) solves y * t = z - 1
    z = np.repeat(1.0 / (1.0 - t * v / 500.0), w, axis=1)
    cos = cos_incidence_from_depth(z, K, 0.02)
    assert cos[20, 20] == pytest.approx(np.cos(np.deg2rad(60.0)), abs=2e-3)
    flat = np.full((h, w), 1.0)
    flat[:, 21:] = 1.5  # a step: both sides are fronto-parallel
    c2 = cos_incidence_from_depth(flat, K, 0.02)
    assert c2[20, 20] == pytest.approx(1.0, abs=1e-3) and c2[20, 21] == pytest.approx(1.0, abs=1e-3)


def test_device_crops_are_the_arrays_pixels() -> None:
    """A crop cut by `DeviceScans.batch` holds the dequantised pixels of its scan at its place; a mirrored crop is
    the same region reversed with the 'left' normal negated."""
    rng = np.random.default_rng(0)
    x = rng.integers(0, 256, (3, 9, 48, 64), dtype=np.uint8)
    y = rng.integers(0, 18, (3, 48, 64), dtype=np.uint8)
    b = rng.integers(0, 2, (3, 48, 64), dtype=np.uint8)
    data = DeviceScans(x, y, b, torch.device("cpu"))
    for seed in range(20):
        r = np.random.default_rng(seed)
        ids = np.array([seed % 3])
        xb, yb, bb = data.batch(ids, 16, r, flip=True, part_share=0.0)
        lab = yb[0].numpy()
        i = int(ids[0])
        hits = [
            (v, u, m)
            for v in range(48 - 15)
            for u in range(64 - 15)
            for m in (False, True)
            if np.array_equal((y[i, v : v + 16, u : u + 16][:, ::-1] if m else y[i, v : v + 16, u : u + 16]), lab)
        ]
        assert len(hits) == 1
        v, u, m = hits[0]
        want = x[i, :, v : v + 16, u : u + 16]
        want = want[:, :, ::-1] if m else want
        f = dequantise(want.copy())
        if m:
            f[MIRROR_SIGN_CHANNEL] *= -1
        np.testing.assert_allclose(xb[0].numpy(), f, atol=1e-6)
        np.testing.assert_array_equal(
            bb[0].numpy(), (b[i, v : v + 16, u : u + 16][:, ::-1] if m else b[i, v : v + 16, u : u + 16])
        )


def test_train_on_device_learns_and_writes_loadable_checkpoints(scans: tuple[Path, list[Path]], tmp_path: Path) -> None:
    """A small net trained 40 steps on the CPU path of the accelerator trainer: on the held-out scans its pixel
    accuracy rises by more than 20 points over the same net untrained, and its checkpoints load with
    `load_weights` and carry the schedule."""
    from v2c.segment.net import UNet
    from v2c.segment.train_device import evaluate_device

    root, dirs = scans
    packed = read_shard(write_shards(dirs, root, tmp_path / "sh")[0])
    dcfg = DeviceTrainConfig(realisations=2, workers=1, eval_minutes=100.0)
    x, y, b, keys = realise_all(packed, dcfg)
    assert x.shape[0] == 8 and keys[4] == (0, 1)
    data = DeviceScans(x, y, b, torch.device("cpu"))
    held_out = [0, 2]  # val_scans=2 of 4 packed scans: every 2nd, first realisation
    torch.manual_seed(3)
    before = evaluate_device(UNet(NetConfig(widths=(8, 16, 32))), data, held_out, amp=False)["pixel_acc"]
    cfg = TrainConfig(steps=40, batch=4, crop_px=64, lr=3e-3, warmup_steps=5, val_scans=2, seed=3, bf16=False)
    rec = train_on_device(
        packed, tmp_path / "out", {"small": (NetConfig(widths=(8, 16, 32)), None)}, cfg, dcfg, device="cpu"
    )["small"]
    model, meta = load_weights(tmp_path / "out" / "small.last.pt")
    assert model.cfg.widths == (8, 16, 32)
    assert meta["step"] == 40 and meta["steps"] == 40
    assert (tmp_path / "out" / "small.pt").is_file()
    assert rec["steps_done"] == 40 and rec["train_samples"] == 4  # 2 of 4 scans held out, 2 realisations each
    after = evaluate_device(model, data, held_out, amp=False)["pixel_acc"]
    assert after == pytest.approx(rec["history"][-1]["pixel_acc"], abs=2e-3)  # the file holds fp16 weights
    assert after > before + 0.2


def test_boundary_weight_per_net_trains_the_boundary_head_of_that_net(
    scans: tuple[Path, list[Path]], tmp_path: Path
) -> None:
    """Two copies of one init net trained in lock step on the same batches, one with the boundary loss at weight 1
    and one at 0 (`nets_to_train`'s init copy, `train_on_device`'s per-net ``boundary_weight``): the records carry
    their weights, and on the held-out scans the boundary loss of the first falls below that of the second (whose
    boundary head learned nothing)."""
    from v2c.segment.net import UNet, save_weights
    from v2c.segment.train import class_weights_from_histogram, losses
    from v2c.segment.train_device import nets_to_train

    root, dirs = scans
    packed = read_shard(write_shards(dirs, root, tmp_path / "sh")[0])
    torch.manual_seed(5)
    save_weights(UNet(NetConfig(widths=(8, 16, 32))), tmp_path / "start.pt", {"step": 0})
    nets = nets_to_train(str(tmp_path / "start.pt"), (), ("init_bw",))
    assert list(nets) == ["init", "init_bw"]
    cfg = TrainConfig(steps=40, batch=4, crop_px=64, lr=3e-3, warmup_steps=5, val_scans=2, seed=3, bf16=False)
    dcfg = DeviceTrainConfig(realisations=1, workers=1, eval_minutes=100.0)
    recs = train_on_device(packed, tmp_path / "out", nets, cfg, dcfg, device="cpu", boundary_weight={"init_bw": 0.0})
    assert recs["init"]["boundary_weight"] == 1.0 and recs["init_bw"]["boundary_weight"] == 0.0
    x, y, b, _ = realise_all(packed, dcfg)
    xs = torch.from_numpy(np.stack([dequantise(x[i]) for i in (0, 2)]))  # the held-out scans
    ys, bs = torch.from_numpy(y[[0, 2]].astype(np.int64)), torch.from_numpy(b[[0, 2]].astype(np.float32))
    cw = torch.from_numpy(class_weights_from_histogram(np.bincount(y.ravel(), minlength=256), cfg.class_weight_power))
    bce = {}
    for name in nets:
        model, _ = load_weights(tmp_path / "out" / f"{name}.last.pt")
        model.eval()
        with torch.no_grad():
            bce[name] = float(losses(model, xs, ys, bs, cw, cfg, False)[1])
    assert bce["init"] < 0.8 * bce["init_bw"], bce


def test_clutter_beside_the_part_is_ignored_and_a_plain_scan_untouched(tmp_path: Path) -> None:
    """Random appearance stands boxes, cylinders and spheres beside the part, labelled background by the
    generator. Training targets ignore them (255): every ignored pixel is off the part and its clean depth stands
    above the ground, and pixels are ignored on at least 2 of 6 scans whose meta lists clutter; a plain scan (no
    clutter) keeps its labels exactly."""
    from v2c.camera import backproject
    from v2c.segment.data import estimate_ground, ignore_clutter

    look = generate_dataset(
        tmp_path / "look",
        6,
        204,
        SynthConfig(width=320, height=240, noise="sensor", appearance="random", framing="extent"),
        progress=False,
    )
    with_clutter = 0
    for d in look:
        scan = load_scan(d)
        gt = scan.gt
        out = ignore_clutter(gt.labels, gt.faces, gt.depth_clean, scan.K)
        ignored = (out == 255) & (gt.labels != 255)
        assert not np.any(ignored & (gt.faces > 0))
        n_clutter = len(gt.meta.get("appearance", {}).get("clutter", []))
        if n_clutter and ignored.any():
            with_clutter += 1
            ground = estimate_ground(gt.depth_clean, scan.K, gt.faces > 0)
            h = backproject(gt.depth_clean, scan.K) @ ground.up + ground.offset
            assert np.all(h[ignored] > 0.002)
    assert with_clutter >= 2
    plain = generate_dataset(tmp_path / "plain", 2, 4, SynthConfig(width=320, height=240), progress=False)
    for d in plain:
        scan = load_scan(d)
        np.testing.assert_array_equal(
            ignore_clutter(scan.gt.labels, scan.gt.faces, scan.gt.depth_clean, scan.K), scan.gt.labels
        )


def test_shards_and_train_device_commands(scans: tuple[Path, list[Path]], tmp_path: Path) -> None:
    """`v2c shards` packs every scan once and refuses a folder that holds shards without --force; `v2c
    train-device` trains from them, writes a checkpoint `load_weights` reads, and refuses to train over it."""
    from click.testing import CliRunner

    from v2c.cli import main

    root, dirs = scans
    out = tmp_path / "sh"
    res = CliRunner().invoke(main, ["shards", str(root), "-o", str(out)])
    assert res.exit_code == 0, res.output
    names = sorted(p.name for f in sorted(out.glob("shard_*.npz")) for p in read_shard(f))
    assert names == sorted(str(d.relative_to(root)) for d in dirs)
    res = CliRunner().invoke(main, ["shards", str(root), "-o", str(out)])
    assert res.exit_code == 1 and f"{out}: holds shards; pass --force" in res.output, res.output
    assert CliRunner().invoke(main, ["shards", str(root), "-o", str(out), "--force"]).exit_code == 0
    ck = tmp_path / "ck"
    args = ["train-device", "--shards", str(out), "-o", str(ck), "--steps", "3", "--batch", "2", "--crop", "64"]
    args += ["--warmup", "1", "--realisations", "1", "--workers", "1", "--val-scans", "2", "--probe-steps", "1"]
    args += ["--wide", "8,16,32"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    assert "4 packed scans from 1 shards" in res.output
    model, _ = load_weights(ck / "wide.pt")
    assert model.cfg.widths == (8, 16, 32)
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1 and f"{ck}: holds checkpoints; pass --force" in res.output, res.output
    res = CliRunner().invoke(main, ["train-device", "--shards", str(out), "-o", str(tmp_path / "w"), "--wide", "8,x"])
    assert res.exit_code == 2 and "'8,x': expected comma-separated integers" in res.output, res.output
    res = CliRunner().invoke(
        main, ["train-device", "--shards", str(out), "-o", str(tmp_path / "w2"), "--init-boundary-weight", "3"]
    )
    assert res.exit_code == 2 and "needs --init" in res.output, res.output
    assert not (tmp_path / "w2").exists()
