"""Training of the segmentation U-Net on an accelerator from packed shards (`v2c.segment.shards`).

The CPU path (`v2c.segment.train.train`) reads a uint8 feature cache from disk, eight 160 px crops a step. On a
GPU the whole training set fits in device memory as uint8 tensors, so crops are cut there by one gather per
batch and many more steps fit in the same minutes. The steps, losses, class weights, schedule and checkpoint
format are the CPU path's (`train.losses`, `train.class_weights`, `train._lr_at`, `net.save_weights`): a
checkpoint loads with `net.load_weights` and ships like any other.

Data: every packed scan is realised ``realisations`` times (`shards.realise`: fresh depth noise of a profile per
realisation, features as inference computes them), in ``workers`` processes. Held-out scans (every
``len // val_scans``-th packed scan, first realisation) give the checkpoint metric, as in the CPU path.

Time budget: after ``probe_steps`` steps the step time is measured and the schedule's length set so that the run
ends within ``minutes`` (the cosine schedule then completes); the chosen length is recorded.

Run on the machine that trains: ``v2c train-device --shards DIR [DIR ...] --out DIR ...`` (`v2c.commands.train_device`).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
import torch

from v2c.labels import IGNORE, NUM_CLASSES
from v2c.segment.net import NetConfig, UNet, load_weights, save_weights
from v2c.segment.shards import PackedScan, read_shard, realise
from v2c.segment.train import _lr_at, class_weights_from_histogram, losses, pixel_metrics
from v2c.segment.train_config import TrainConfig

#: Noise profile of realisation r of packed scan i: realisation 0 is the generator's `sensor` profile (the bench's),
#: later ones cycle through these by scan index (structured light is what the real frames are, docs/synth.md).
LATER_PROFILES: tuple[str, ...] = ("structured_light", "structured_light", "sensor", "paper", "structured_light")


def profile_of(i: int, r: int) -> str:
    """Noise profile of realisation ``r`` of packed scan ``i``."""
    return "sensor" if r == 0 else LATER_PROFILES[(i + r) % len(LATER_PROFILES)]


@dataclass(frozen=True)
class DeviceTrainConfig:
    """What the accelerator run adds to `TrainConfig` (units in the comments)."""

    realisations: int = 2  # noise draws per packed scan held in memory
    workers: int = 16  # processes realising scans
    probe_steps: int = 60  # steps timed before the schedule length is fixed by ``TrainConfig.minutes``
    eval_minutes: float = 1.0  # wall-clock minutes between checkpoint evaluations
    seed: int = 0


def _realise_job(args: tuple[PackedScan, str, tuple[int, ...]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import cv2

    cv2.setNumThreads(1)
    p, profile, seed = args
    x, y, b, _ = realise(p, profile, seed)
    return x, y, b


class DeviceScans:
    """Realised scans of one image size as uint8 tensors on ``device``; random crops cut there.

    x: (N, 9, H, W), y: (N, H, W) labels, b: (N, H, W) boundaries. Part pixels (subsampled by 4) per scan bias the
    crop centres towards the part as `data.CachedScans.crop` does; mirrors negate the 'left' normal channel.
    """

    def __init__(self, x: np.ndarray, y: np.ndarray, b: np.ndarray, device: torch.device) -> None:
        self.n, _, self.h, self.w = x.shape
        self.x = torch.from_numpy(x).to(device)
        self.y = torch.from_numpy(y).to(device)
        self.b = torch.from_numpy(b).to(device)
        self.device = device
        self.part = []
        for lab in y:
            vv, uu = np.nonzero((lab[::4, ::4] > 0) & (lab[::4, ::4] != IGNORE))
            self.part.append(np.stack([vv * 4, uu * 4], 1) if len(vv) else np.zeros((0, 2), np.int64))

    def batch(
        self, ids: np.ndarray, size: int, rng: np.random.Generator, flip: bool = True, part_share: float = 0.75
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(features float32 (B, 9, S, S) channels_last, labels int64 (B, S, S), boundary float32 (B, S, S))."""
        n = len(ids)
        if size > self.h or size > self.w:
            raise ValueError(f"crop {size} px exceeds the scans' {self.w}x{self.h}")
        v0 = rng.integers(0, self.h - size + 1, n)
        u0 = rng.integers(0, self.w - size + 1, n)
        for k, i in enumerate(ids):
            pts = self.part[int(i)]
            if len(pts) and rng.random() < part_share:
                cv, cu = pts[rng.integers(len(pts))]
                v0[k] = np.clip(cv - size // 2, 0, self.h - size)
                u0[k] = np.clip(cu - size // 2, 0, self.w - size)
        mirror = rng.random(n) < 0.5 if flip else np.zeros(n, bool)
        ar = np.arange(size)
        rows = v0[:, None] + ar[None, :]
        cols = np.where(mirror[:, None], u0[:, None] + size - 1 - ar[None, :], u0[:, None] + ar[None, :])
        dev = self.device
        it = torch.as_tensor(np.asarray(ids), device=dev)[:, None, None]
        rt = torch.as_tensor(rows, device=dev)[:, :, None]
        ct = torch.as_tensor(cols, device=dev)[:, None, :]
        xq = self.x[it, :, rt, ct]  # (B, S, S, C): advanced indices first
        y = self.y[it, rt, ct].long()
        b = self.b[it, rt, ct].float()
        x = dequantise_torch(xq.permute(0, 3, 1, 2))
        m = torch.as_tensor(mirror, device=dev)
        x[:, 4] = torch.where(m[:, None, None], -x[:, 4], x[:, 4])  # MIRROR_SIGN_CHANNEL
        return x.contiguous(memory_format=torch.channels_last), y, b


def dequantise_torch(q: torch.Tensor) -> torch.Tensor:
    """`v2c.segment.data.dequantise` on a (B, 9, H, W) uint8 tensor (same formulas), float32."""
    from v2c.segment.data import RGB_MEAN, RGB_STD

    q = q.float()
    f = torch.empty_like(q)
    f[:, 0:3] = (q[:, 0:3] / 255.0 - RGB_MEAN) / RGB_STD
    f[:, 3:6] = (q[:, 3:6] - 128.0) / 127.0
    f[:, 6] = (q[:, 6] - 128.0) / 30.0
    f[:, 7:9] = q[:, 7:9] / 255.0
    return f


@torch.no_grad()
def evaluate_device(model: UNet, data: DeviceScans, ids: Sequence[int], amp: bool) -> dict:
    """`train.evaluate` on whole scans held on the device: mean IoU over classes present, accuracy, boundary F1."""
    model.eval()
    dev = data.device
    conf = torch.zeros(NUM_CLASSES * NUM_CLASSES, dtype=torch.int64, device=dev)
    tp = fp = fn = 0
    for i in ids:
        x = dequantise_torch(data.x[i : i + 1]).contiguous(memory_format=torch.channels_last)
        with torch.autocast(dev.type, dtype=torch.bfloat16, enabled=amp):
            lab, bnd = model(x)
        pred = lab[0].float().argmax(0)
        y = data.y[i].long()
        ok = y != IGNORE
        conf += torch.bincount(y[ok] * NUM_CLASSES + pred[ok], minlength=NUM_CLASSES**2)
        pb, gb = bnd[0, 0].float() > 0, data.b[i] > 0
        tp += int((pb & gb).sum())
        fp += int((pb & ~gb).sum())
        fn += int((~pb & gb).sum())
    model.train()
    return pixel_metrics(conf.reshape(NUM_CLASSES, NUM_CLASSES).cpu().numpy(), tp, fp, fn)


def realise_all(
    packed: list[PackedScan], dcfg: DeviceTrainConfig, log: Callable[[str], object] = print
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """Realise every packed scan ``dcfg.realisations`` times; returns stacked x, y, b and (scan, realisation)."""
    h, w = None, None
    jobs, keys = [], []
    for r in range(dcfg.realisations):
        for i, p in enumerate(packed):
            jobs.append((p, profile_of(i, r), (dcfg.seed, i, r)))
            keys.append((i, r))
    t0 = time.time()
    xs: list[np.ndarray] = []
    ys: list[np.ndarray] = []
    bs: list[np.ndarray] = []
    if dcfg.workers > 1:
        with ProcessPoolExecutor(dcfg.workers) as ex:
            results = ex.map(_realise_job, jobs, chunksize=8)
            for k, (x, y, b) in enumerate(results):
                xs.append(x)
                ys.append(y)
                bs.append(b)
                if (k + 1) % 500 == 0:
                    log(f"realised {k + 1}/{len(jobs)} in {time.time() - t0:.0f} s")
    else:
        for job in jobs:
            x, y, b = _realise_job(job)
            xs.append(x)
            ys.append(y)
            bs.append(b)
    shapes = {x.shape for x in xs}
    if len(shapes) != 1:
        raise ValueError(f"packed scans of several sizes {sorted(shapes)}: train one size at a time")
    (_, h, w) = next(iter(shapes))
    log(f"realised {len(jobs)} samples of {w}x{h} in {time.time() - t0:.0f} s")
    return np.stack(xs), np.stack(ys), np.stack(bs), keys


def train_on_device(
    packed: list[PackedScan],
    out_dir: str | Path,
    nets: dict[str, tuple[NetConfig | None, str | Path | None]],
    cfg: TrainConfig,
    dcfg: DeviceTrainConfig = DeviceTrainConfig(),
    device: str | None = None,
    lr_scale: dict[str, float] | None = None,
    log: Callable[[str], object] = print,
    boundary_weight: dict[str, float] | None = None,
) -> dict:
    """Train every net of ``nets`` (name -> (architecture, init weights or None)) on the same batches.

    lr_scale: per net, a factor on ``cfg.lr`` (e.g. a net trained from scratch takes a larger step than one
    fine-tuned from weights); 1 for nets not named.
    boundary_weight: per net, the weight of its boundary BCE against the label CE (``cfg.boundary_weight`` for
    nets not named).

    Writes ``out_dir``/<name>.pt (best held-out mIoU), <name>.last.pt and <name>.json (the record). The schedule
    length is ``cfg.steps`` unless ``cfg.minutes`` is set (then fitted to the minutes after the probe steps).
    """
    dev = torch.device(device or ("cuda" if torch.cuda.is_available() else "cpu"))
    if dev.type == "cuda":
        torch.backends.cudnn.benchmark = True  # fixed crop size: let cuDNN pick its kernels once
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    x, y, b, keys = realise_all(packed, dcfg, log)
    data = DeviceScans(x, y, b, dev)
    del x, b
    stride = max(1, len(packed) // max(cfg.val_scans, 1))
    val_scans = set(range(0, len(packed), stride)[: cfg.val_scans])
    val_ids = [k for k, (i, r) in enumerate(keys) if i in val_scans and r == 0]
    train_ids = np.array([k for k, (i, _) in enumerate(keys) if i not in val_scans])
    hist = np.zeros(256, np.int64)
    for k in train_ids[:: max(1, len(train_ids) // 300)]:
        hist += np.bincount(y[k].ravel(), minlength=256)
    del y
    cw = torch.from_numpy(class_weights_from_histogram(hist, cfg.class_weight_power)).to(dev)
    amp = dev.type == "cuda" or bool(cfg.bf16)
    bnd_weight = {name: (boundary_weight or {}).get(name, cfg.boundary_weight) for name in nets}
    models: dict[str, UNet] = {}  # trained in lock step on the same batches
    opts: dict[str, torch.optim.Optimizer] = {}
    records: dict[str, dict] = {}
    for name, (net_cfg, init) in nets.items():
        init_meta = None
        if init is not None:
            model, init_meta = load_weights(init)
        else:
            model = UNet(net_cfg or NetConfig())
        model = model.to(dev).to(memory_format=torch.channels_last)
        model.train()
        models[name] = model
        opts[name] = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        records[name] = {
            "config": asdict(cfg),
            "device_config": asdict(dcfg),
            "lr_scale": (lr_scale or {}).get(name, 1.0),
            "boundary_weight": bnd_weight[name],
            "net": asdict(model.cfg),
            "device": str(torch.cuda.get_device_name(dev) if dev.type == "cuda" else dev),
            "packed_scans": len(packed),
            "train_samples": int(len(train_ids)),
            "val_scans": len(val_ids),
            "history": [],
            "best": None,
            "init": None
            if init is None
            else {
                "path": str(init),
                "steps_done": (init_meta or {}).get("step"),
                "best": (init_meta or {}).get("best"),
            },
        }
    best = dict.fromkeys(models, -1.0)

    def checkpoint(step: int, steps: int, elapsed: float) -> None:
        for name, model in models.items():
            ev = evaluate_device(model, data, val_ids, amp)
            entry = {"step": step, "minutes": round(elapsed, 2), "miou": ev["miou"], "pixel_acc": ev["pixel_acc"]}
            entry["boundary_f1"] = ev["boundary_f1"]
            rec = records[name]
            rec["history"].append(entry)
            rec["steps"] = steps
            log(f"eval {name} {entry}")
            save_weights(model, out / f"{name}.last.pt", {**rec, "step": step})
            if ev["miou"] > best[name]:
                best[name] = ev["miou"]
                rec["best"] = {**entry, "iou": ev["iou"]}
                save_weights(model, out / f"{name}.pt", {**rec, "step": step})
            (out / f"{name}.json").write_text(json.dumps(rec, indent=1))

    steps = cfg.steps
    t_start = time.time()
    deadline = None if cfg.minutes is None else t_start + cfg.minutes * 60.0
    last_eval = t_start
    run = {name: [0.0, 0.0] for name in models}
    step = 0
    t_mark = t_start
    while step < steps:
        for name in models:
            for g in opts[name].param_groups:
                g["lr"] = _lr_at(step, replace(cfg, steps=steps)) * (lr_scale or {}).get(name, 1.0)
        ids = train_ids[rng.integers(0, len(train_ids), cfg.batch)]
        xb, yb, bb = data.batch(ids, cfg.crop_px, rng, flip=cfg.flip)
        for name, model in models.items():
            ce, bce = losses(model, xb, yb, bb, cw, cfg, amp, device_type=dev.type)
            loss = ce + bnd_weight[name] * bce
            opts[name].zero_grad(set_to_none=True)
            loss.backward()
            opts[name].step()
            run[name][0] += float(ce.detach())
            run[name][1] += float(bce.detach())
        step += 1
        if step == max(1, dcfg.probe_steps // 3):
            t_mark = time.time()  # the first steps carry the accelerator's warm-up: timed from here
        if step == dcfg.probe_steps and deadline is not None:
            # time the steps, then one checkpoint (its cost is counted for every later one), then fix the length
            if dev.type == "cuda":
                torch.cuda.synchronize()
            per_step = (time.time() - t_mark) / max(step - max(1, dcfg.probe_steps // 3), 1)
            t_eval = time.time()
            checkpoint(step, steps, (time.time() - t_start) / 60)
            eval_s = time.time() - t_eval
            last_eval = time.time()
            left = deadline - time.time()
            n_evals = left / (dcfg.eval_minutes * 60.0) + 1
            steps = step + max(1, int((left - n_evals * eval_s) / per_step))
            log(f"{per_step * 1000:.1f} ms per step, {eval_s:.1f} s per checkpoint: schedule set to {steps} steps")
        elapsed = (time.time() - t_start) / 60
        if step % 200 == 0:
            msg = " ".join(f"{n} ce {v[0] / 200:.3f} bce {v[1] / 200:.3f}" for n, v in run.items())
            log(f"step {step}/{steps} {msg} lr {_lr_at(step - 1, replace(cfg, steps=steps)):.2e} {elapsed:.2f} min")
            run = {name: [0.0, 0.0] for name in models}
        capped = deadline is not None and time.time() >= deadline
        if time.time() - last_eval >= dcfg.eval_minutes * 60 or step == steps or capped:
            checkpoint(step, steps, elapsed)
            last_eval = time.time()
        if capped:
            log(f"stopped at step {step} of {steps} by the {cfg.minutes} min cap")
            break
    for name, rec in records.items():
        rec["steps_done"] = step
        rec["minutes"] = round((time.time() - t_start) / 60, 2)
        (out / f"{name}.json").write_text(json.dumps(rec, indent=1))
    return records


def load_packed(shards: Sequence[str | Path], limit: int | None = None) -> tuple[list[PackedScan], int]:
    """The packed scans of the given shard folders (their shard_*.npz) or shard files, in order; the first ``limit``
    only if given. Returns the scans and the number of shard files read."""
    files: list[Path] = []
    for s in shards:
        p = Path(s)
        files += sorted(p.glob("shard_*.npz")) if p.is_dir() else [p]
    packed: list[PackedScan] = []
    for f in files:
        packed += read_shard(f)
    if limit:
        packed = packed[:limit]
    return packed, len(files)


def nets_to_train(
    init: str | None, wide: Sequence[int], init_copies: Sequence[str] = ()
) -> dict[str, tuple[NetConfig | None, str | None]]:
    """The nets of one run: 'init' fine-tuned from the weights file ``init`` (and one more copy of it per name of
    ``init_copies``, e.g. trained with another loss weight), 'wide' of widths ``wide`` from scratch, or, with
    neither, 'scratch' of the default widths."""
    nets: dict[str, tuple[NetConfig | None, str | None]] = {}
    if init:
        nets["init"] = (None, init)
        for name in init_copies:
            nets[name] = (None, init)
    if wide:
        nets["wide"] = (NetConfig(widths=tuple(int(v) for v in wide)), None)
    if not nets:
        nets["scratch"] = (NetConfig(), None)
    return nets
