"""Appearance and framing randomization of the synthetic generator (v2c.synth.appearance, docs/synth.md).

Random appearance changes the colour only (plus the depth of clutter pixels, which are background): face ids,
labels, primitives and the part's depth are those of the plain scan with the same seed; printed art makes colour
edges inside single faces; extent framing puts the part's silhouette at 30-70 % of the smaller image side.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from v2c.synth import occ
from v2c.synth.appearance import Appearance, draw_art
from v2c.synth.dataset import SynthConfig, generate_scan

SEED = 11
N_PAIRS = 6  # seeds 0..5: plain and random appearance, both framed by extent, 320x240
SIZE = (320, 240)
EDGE_BAND_PX = 5  # sensor noise reads a 3x3 neighbourhood and drops a band of up to 3 px around depth edges
GRADIENT_EDGE = 200.0  # Sobel (3x3) magnitude of an 8-bit channel taken as a colour edge (a step of about 50)
INTERIOR_ERODE_PX = 5  # face interiors: the face mask eroded by a 5x5 square (boundary edges left out)


def _read(path: Path) -> np.ndarray:
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert img is not None, path
    return img


@pytest.fixture(scope="module")
def pairs(tmp_path_factory) -> list[tuple[Path, Path]]:
    occ.silence_occt()
    out = tmp_path_factory.mktemp("look")
    plain = SynthConfig(width=SIZE[0], height=SIZE[1], appearance="plain", framing="extent")
    rand = SynthConfig(width=SIZE[0], height=SIZE[1], appearance="random", framing="extent")
    return [
        (generate_scan(out / "plain", SEED, i, plain), generate_scan(out / "random", SEED, i, rand))
        for i in range(N_PAIRS)
    ]


def _meta(folder: Path) -> dict:
    return json.loads((folder / "gt" / "meta.json").read_text())


def test_random_appearance_keeps_labels_and_part_depth(pairs) -> None:
    clutter_px = 0
    for plain, rand in pairs:
        for name in ("gt/faces.png", "gt/labels.png", "mask.png"):
            assert np.array_equal(_read(plain / name), _read(rand / name)), (rand, name)
        assert (plain / "gt/primitives.json").read_text() == (rand / "gt/primitives.json").read_text()
        assert (plain / "camera.json").read_text() == (rand / "camera.json").read_text()
        faces = _read(rand / "gt/faces.png")
        d_plain = np.load(plain / "gt/depth_clean.npy")
        d_rand = np.load(rand / "gt/depth_clean.npy")
        changed = d_plain != d_rand
        # Only background pixels change depth (clutter stands on the ground), and they get a reading of their own
        # that is nearer than the ground (or the backdrop's no-reading) they hide.
        assert not (changed & (faces > 0)).any(), rand
        assert (d_rand[changed] > 0).all()
        assert ((d_plain[changed] == 0) | (d_rand[changed] < d_plain[changed])).all()
        n_clutter = len(_meta(rand)["appearance"]["clutter"])
        if changed.any():  # (an object may stand out of view: clutter without changed pixels is allowed)
            assert n_clutter > 0, rand
        clutter_px += int(changed.sum())
        # The sensor noise of the two scans is one draw: away from clutter edges the noisy depth is the same.
        near = cv2.dilate(changed.astype(np.uint8), np.ones((2 * EDGE_BAND_PX + 1,) * 2, np.uint8)) > 0
        assert np.array_equal(_read(plain / "depth.png")[~near], _read(rand / "depth.png")[~near]), rand
        assert not np.array_equal(_read(plain / "color.png"), _read(rand / "color.png"))
        assert _meta(rand)["framing"] == _meta(plain)["framing"]
    assert clutter_px > 0  # some of the seeds show clutter


def _interior_edge_share(folder: Path) -> float:
    faces = _read(folder / "gt/faces.png")
    col = _read(folder / "color.png").astype(np.float32)
    grad = np.zeros(faces.shape, np.float32)
    for c in range(3):
        gx = cv2.Sobel(col[..., c], cv2.CV_32F, 1, 0, ksize=3)
        gy = cv2.Sobel(col[..., c], cv2.CV_32F, 0, 1, ksize=3)
        grad = np.maximum(grad, np.hypot(gx, gy))
    kernel = np.ones((INTERIOR_ERODE_PX, INTERIOR_ERODE_PX), np.uint8)
    inner = np.zeros(faces.shape, bool)
    for f in np.unique(faces[faces > 0]):
        inner |= cv2.erode((faces == f).astype(np.uint8), kernel) > 0
    return float((grad[inner] > GRADIENT_EDGE).mean())


def test_printed_art_makes_colour_edges_inside_faces(pairs) -> None:
    plain = [_interior_edge_share(p) for p, _ in pairs]
    art = [_interior_edge_share(r) for _, r in pairs if _meta(r)["appearance"].get("art_px", 0) > 0]
    assert len(art) >= N_PAIRS // 2, "most parts carry art"
    # Plain parts: colour edges inside a face come only from shadows and highlights.
    assert np.mean(art) > 0.03 and np.mean(art) > 5 * np.mean(plain), (art, plain)


def test_draw_art_stays_inside_single_faces() -> None:
    faces = np.zeros((120, 160), np.uint16)
    faces[10:110, 10:80] = 1
    faces[10:110, 80:150] = 2
    faces[50:70, 100:130] = 3  # a small face inside face 2
    for seed in range(5):
        albedo, on, kinds = draw_art(Appearance(seed, True), faces)
        assert kinds and on.any()
        assert not (on & (faces == 0)).any()
        # colour changes between horizontal neighbours of one face: edges inside single surfaces
        same = (faces[:, 1:] == faces[:, :-1]) & (faces[:, 1:] > 0)
        step = np.abs(albedo[:, 1:] - albedo[:, :-1]).max(axis=2) > 0.05
        assert (same & step).sum() > 20
    _, none, kinds = draw_art(Appearance(0, False), faces)
    assert not none.any() and kinds == []


def test_extent_framing_over_20_seeds(tmp_path) -> None:
    occ.silence_occt()
    cfg = SynthConfig(width=200, height=150, noise="none", framing="extent")
    dists, extents = [], []
    for i in range(20):
        folder = generate_scan(tmp_path, 3, i, cfg)
        mask = _read(folder / "mask.png") > 0
        ys, xs = np.nonzero(mask)
        extent = max(np.ptp(xs) + 1, np.ptp(ys) + 1) / min(mask.shape)
        assert 0.30 <= extent <= 0.70, (i, extent)
        # whole part inside the image
        assert xs.min() > 0 and ys.min() > 0 and xs.max() < mask.shape[1] - 1 and ys.max() < mask.shape[0] - 1
        meta = _meta(folder)
        assert abs(meta["framing"]["extent"] - extent) < 0.03, (i, extent, meta["framing"])
        dists.append(meta["framing"]["distance_m"])
        extents.append(extent)
    assert max(dists) > 1.5 * min(dists)  # a spread of distances
    assert max(extents) - min(extents) > 0.15  # and of extents


def test_same_seed_same_files_other_seed_differs(tmp_path, pairs) -> None:
    occ.silence_occt()
    cfg = SynthConfig(width=SIZE[0], height=SIZE[1], appearance="random", framing="extent")
    _, first = pairs[1]
    again = generate_scan(tmp_path, SEED, 1, cfg)
    for name in ("color.png", "depth.png", "gt/faces.png", "gt/depth_clean.npy", "gt/meta.json"):
        assert (first / name).read_bytes() == (again / name).read_bytes(), name
    assert (pairs[2][1] / "color.png").read_bytes() != (first / "color.png").read_bytes()


def test_cli_appearance_and_framing(tmp_path) -> None:
    from v2c.commands.synth import command

    res = CliRunner().invoke(
        command,
        [str(tmp_path / "a"), "--n", "1", "--size", "96x72", "--appearance", "random", "--quiet"],
        catch_exceptions=False,
    )
    assert res.exit_code == 0, res.output
    meta = _meta(tmp_path / "a" / "scan_00000")
    assert meta["appearance"]["mode"] == "random" and meta["framing"]["mode"] == "extent"
    res = CliRunner().invoke(command, [str(tmp_path / "b"), "--n", "1", "--size", "96x72", "--quiet"])
    meta = _meta(tmp_path / "b" / "scan_00000")
    assert "appearance" not in meta and "framing" not in meta  # the default writes what it always wrote
    res = CliRunner().invoke(command, [str(tmp_path / "c"), "--appearance", "shiny"])
    assert res.exit_code != 0 and "shiny" in res.output and not (tmp_path / "c").exists()


def test_bench_and_recipe_take_appearance(tmp_path) -> None:
    from v2c.bench import run as R
    from v2c.bench import suite as S
    from v2c.commands.bench import command
    from v2c.segment.train import RECIPES, generate_training_data

    bench = R.BenchConfig(cache_dir=tmp_path)
    plain = S.suite_cache_dir(S.SuiteConfig(bench=bench))
    rand = S.suite_cache_dir(S.SuiteConfig(bench=bench, appearance="random"))
    assert plain != rand and "random" in rand.name and "random" not in plain.name
    scans, _ = S.plan_scans(
        S.SuiteConfig(bench=bench, appearance="random", parts=(), families=("feat_hex",), family_scans=1)
    )
    assert scans[0].synth.appearance == "random" and scans[0].synth.framing == "extent"
    res = CliRunner().invoke(command, ["--appearance", "random", "--n", "1"])
    assert res.exit_code != 0 and "--appearance belongs to --suite unseen" in res.output
    assert RECIPES["appearance"][-1][-1] == "random"
    done = generate_training_data(tmp_path / "data", recipe=((64, 48, "none", 1, 0, 0.0, ("block",), "random"),))
    assert done[0].parent.name == "64x48_none_block_look_s0"
    assert _meta(done[0])["appearance"]["mode"] == "random"
