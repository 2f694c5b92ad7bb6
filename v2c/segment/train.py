"""Training of the segmentation U-Net on `v2c synth` scans (CPU; bf16 autocast + channels_last where supported).

Deterministic given the seed and the step count (one process, fixed thread count): the crop sequence comes
from one ``np.random.Generator`` and the weights from ``torch.manual_seed``. ``minutes`` only caps the run; the
learning-rate schedule depends on ``steps`` alone, so a capped run is a prefix of the full one.

Losses: cross-entropy over the 18 labels (255 ignored, classes weighted by frequency^-``class_weight_power``) plus
``boundary_weight`` x binary cross-entropy of the face-boundary map.
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from v2c.executors import ExecutorConfig
from v2c.labels import IGNORE, NUM_CLASSES
from v2c.segment.data import CachedScans, build_cache, dequantise, find_scans
from v2c.segment.net import NetConfig, UNet, bf16_supported, load_weights, save_weights
from v2c.segment.train_config import TrainConfig
from v2c.synth.families import FAMILY_GROUPS, LEAVE_OUT_FAMILIES

logger = logging.getLogger(__name__)

#: The shipped training set: (width, height, noise profile, scans, `v2c synth` seed), generated into
#: DATA/<width>x<height>_<noise>_s<seed>/. Validation uses seed 9000 and later, never these.
TRAINING_RECIPE: tuple[tuple[int, int, str, int, int], ...] = (
    (256, 256, "sensor", 700, 101),
    (256, 256, "paper", 500, 102),
    (320, 240, "sensor", 400, 103),
    (320, 240, "paper", 300, 104),
    (640, 480, "sensor", 150, 105),
    (640, 480, "paper", 60, 106),
)
#: The fine-tuning sets (stages 4-7, MODEL_CARD.md): (width, height, noise, scans, seed, print share), generated
#: into DATA/<width>x<height>_<noise>[_print]_s<seed>/ like TRAINING_RECIPE. Stage 4 trains on STAGE4_RECIPE (the
#: validation size, 640x480, weighted up; half of seed 108's parts printed); stages 5 to 8 on STAGE5_RECIPE.
STAGE4_RECIPE: tuple[tuple, ...] = (
    *(row for row in TRAINING_RECIPE if row[4] in (101, 103, 105, 106)),
    (640, 480, "sensor", 1000, 107, 0.0),
    (640, 480, "sensor", 500, 108, 0.5),
)
STAGE5_RECIPE: tuple[tuple, ...] = (*STAGE4_RECIPE, (640, 480, "sensor", 1000, 111, 0.3))
#: STAGE5_RECIPE plus the feature-based training families (synth/features.py): a row's optional 7th element names
#: the part families it draws from (default: the six procedural ones); never a leave-out family.
FEATURES_RECIPE: tuple[tuple, ...] = (*STAGE5_RECIPE, (640, 480, "sensor", 1500, 121, 0.3, FAMILY_GROUPS["features"]))
#: FEATURES_RECIPE plus 1500 scans with appearance and framing randomization (synth/appearance.py: random, dark
#: and shiny materials, printed art inside faces, clutter, backgrounds, lights; part extent 30-70 % of the image):
#: a row's optional 8th element is the appearance ("plain" | "random"; random also frames by extent).
APPEARANCE_RECIPE: tuple[tuple, ...] = (
    *FEATURES_RECIPE,
    (640, 480, "sensor", 1500, 131, 0.0, FAMILY_GROUPS["train"], "random"),
)
#: The generator family name of a recipe row that renders the CAD corpus's **train** split (`v2c.synth.corpus`;
#: one random training file per scan, OCCT units in mm). Validation and test files are never rendered for training.
CORPUS_TRAIN = "corpus-train"
#: Stage 9 (MODEL_CARD.md): what a part a user scans looks like. The validation-size procedural rows kept (half
#: printed) so in-family parts are not forgotten, the feature-based training families, appearance and framing
#: randomization (random/dark/shiny materials, printed art, clutter; extent 30-70 %) over all training families,
#: and renders of the corpus's training files (plain and with random appearance).
STAGE9_RECIPE: tuple[tuple, ...] = (
    (640, 480, "sensor", 300, 107, 0.0),
    (640, 480, "sensor", 300, 111, 0.3),
    (640, 480, "sensor", 1500, 121, 0.3, FAMILY_GROUPS["features"]),
    (640, 480, "sensor", 1500, 131, 0.0, FAMILY_GROUPS["train"], "random"),
    (640, 480, "sensor", 300, 141, 0.0, (CORPUS_TRAIN,)),
    (640, 480, "sensor", 100, 142, 0.0, (CORPUS_TRAIN,), "random"),
)
#: Stage 10 (MODEL_CARD.md): stage 9's kinds of scan with the procedural families weighted up (41 % of the scans:
#: stage 9's in-family recall loss) and clutter ignored in the targets (`data.ignore_clutter`). The counts are what
#: was generated when the set was frozen (a 3,400-scan plan cut at 2,200 for time; scans are pure functions of
#: (seed, index), so these rows give exactly that set).
STAGE10_RECIPE: tuple[tuple, ...] = (
    (640, 480, "sensor", 525, 201, 0.0),
    (640, 480, "sensor", 375, 202, 0.3),
    (640, 480, "sensor", 600, 203, 0.3, FAMILY_GROUPS["features"]),
    (640, 480, "sensor", 450, 204, 0.0, FAMILY_GROUPS["train"], "random"),
    (640, 480, "sensor", 175, 205, 0.0, (CORPUS_TRAIN,)),
    (640, 480, "sensor", 75, 206, 0.0, (CORPUS_TRAIN,), "random"),
)
#: Stage 13 (MODEL_CARD.md): a set for one accelerator call (about 1,000 scans, one 45 MiB shard) weighted to
#: what the unseen suite lacks: renders of the corpus's training files (45 %, plain and with random appearance),
#: the feature-based training families (25 %, a third printed), random appearance over all training families,
#: and the procedural families (15 %) so that in-family parts are not forgotten.
STAGE13_RECIPE: tuple[tuple, ...] = (
    (640, 480, "sensor", 300, 301, 0.0, (CORPUS_TRAIN,)),
    (640, 480, "sensor", 150, 302, 0.0, (CORPUS_TRAIN,), "random"),
    (640, 480, "sensor", 250, 303, 0.3, FAMILY_GROUPS["features"]),
    (640, 480, "sensor", 150, 304, 0.0, FAMILY_GROUPS["train"], "random"),
    (640, 480, "sensor", 100, 305, 0.0),
    (640, 480, "sensor", 50, 306, 0.5),
)
#: The largest share of a recipe's scans that may fail to generate (parts OCCT's check refuses; the feature
#: generator's validity target is 95 %) before `generate_training_data` gives up instead of training without them.
MAX_FAILED_SHARE = 0.05
RECIPES = {
    "base": TRAINING_RECIPE,
    "stage4": STAGE4_RECIPE,
    "stage5": STAGE5_RECIPE,
    "features": FEATURES_RECIPE,
    "appearance": APPEARANCE_RECIPE,
    "stage9": STAGE9_RECIPE,
    "stage10": STAGE10_RECIPE,
    "stage13": STAGE13_RECIPE,
}


def generate_training_data(
    out_dir: str | Path,
    scale: float = 1.0,
    jobs: int = 1,
    recipe: tuple = TRAINING_RECIPE,
    executor: str | ExecutorConfig = "local",
    corpus_dir: Path | None = None,
    max_failed_share: float = MAX_FAILED_SHARE,
) -> list[Path]:
    """Generate the training scans of ``recipe`` (counts times ``scale``) under ``out_dir`` with the synth generator.

    Equivalent to one `v2c synth` run per recipe row; ``jobs`` local processes, or ``executor`` (e.g. a Ray
    cluster, `v2c.executors.ExecutorConfig`). A row is (width, height, noise, scans, seed[, print share
    [, families[, appearance]]]); rows naming families go to DATA/<width>x<height>_<noise>[_print]_<tag>[_look]_s<seed>/
    (tag: the family group's name, or the families joined by '+'; _look: appearance "random", which also frames
    the part by its extent, like `v2c synth --appearance random`). A leave-out family
    (families.LEAVE_OUT_FAMILIES) is refused. The family `CORPUS_TRAIN` renders the CAD corpus's training files
    (``corpus_dir``, default `v2c.synth.corpus.default_corpus_dir`), never its validation or test files.

    A scan the generator cannot make (its part fails OCCT's check; scans are pure functions of (seed, index), so it
    fails again on every try) does not stop the recipe: the rows after it are generated, and the scans made are
    returned with a warning naming the failures, unless more than ``max_failed_share`` of the scans asked for
    failed (then `SynthError`). Resuming regenerates only the missing scans of a row.
    """
    from v2c.synth.dataset import SynthConfig, SynthError, generate_dataset, scan_name
    from v2c.synth.scene import SceneConfig

    done: list[Path] = []
    failures: list[str] = []
    asked = 0
    for w, h, noise, n, seed, *extra in recipe:
        share = float(extra[0]) if extra else 0.0
        families = tuple(extra[1]) if len(extra) > 1 and extra[1] is not None else None
        look = str(extra[2]) if len(extra) > 2 else "plain"
        tag = ""
        if families is not None:
            left_out = [f for f in families if f in LEAVE_OUT_FAMILIES]
            if left_out:
                raise ValueError(
                    f"recipe row {w}x{h} seed {seed}: {', '.join(left_out)} is a leave-out family "
                    "(families.LEAVE_OUT_FAMILIES), never used for training"
                )
            named = [k for k, v in FAMILY_GROUPS.items() if v == families]
            tag = "_" + (named[0] if named else "+".join(families))
        cad_files: tuple[str, ...] = ()
        if families == (CORPUS_TRAIN,):
            from v2c.synth.corpus import split_files

            cad_files = tuple(str(f.resolve()) for f in split_files("train", corpus_dir))
            families = ("cad",)
        elif families is not None and CORPUS_TRAIN in families:
            raise ValueError(f"recipe row {w}x{h} seed {seed}: {CORPUS_TRAIN} must be a row's only family")
        look_tag = "_look" if look != "plain" else ""
        sub = Path(out_dir) / f"{w}x{h}_{noise}{'_print' if share > 0 else ''}{tag}{look_tag}_s{seed}"
        n = max(1, round(n * scale))
        asked += n

        missing = [i for i in range(n) if not _made(sub / scan_name(i))]
        if missing:
            cfg = SynthConfig(
                width=w,
                height=h,
                noise=noise,
                scene=SceneConfig(print_share=share),
                **({"families": families} if families is not None else {}),
                **({"cad_files": cad_files} if cad_files else {}),
                **({"appearance": look, "framing": "extent"} if look != "plain" else {}),
            )
            for start, stop in _runs(missing):
                try:
                    generate_dataset(
                        sub, stop - start, seed, cfg, jobs=jobs, progress=False, start=start, executor=executor
                    )
                except SynthError as exc:
                    failures.append(str(exc))
        done += [sub / scan_name(i) for i in range(n) if _made(sub / scan_name(i))]
    if failures:
        lost = asked - len(done)
        msg = f"{lost} of {asked} training scans could not be generated: " + " | ".join(failures)
        if lost > max_failed_share * asked:
            raise SynthError(f"{msg} (more than {max_failed_share:.0%} of the recipe)")
        logger.warning("%s; training goes on without them", msg)
    return done


def _made(scan_dir: Path) -> bool:
    """Whether a scan was written whole (resume: scans are pure functions of (seed, index); meta.json is last)."""
    return (scan_dir / "gt" / "meta.json").is_file()


def _runs(indices: list[int]) -> list[tuple[int, int]]:
    """Sorted indices as half-open runs of consecutive values: [1, 2, 3, 7] -> [(1, 4), (7, 8)]."""
    runs: list[tuple[int, int]] = []
    for i in indices:
        if runs and runs[-1][1] == i:
            runs[-1] = (runs[-1][0], i + 1)
        else:
            runs.append((i, i + 1))
    return runs


def _lr_at(step: int, cfg: TrainConfig) -> float:
    if step < cfg.warmup_steps:
        return cfg.lr * (step + 1) / cfg.warmup_steps
    t = (step - cfg.warmup_steps) / max(cfg.steps - cfg.warmup_steps, 1)
    return cfg.lr * (cfg.final_lr_frac + (1 - cfg.final_lr_frac) * 0.5 * (1 + math.cos(math.pi * min(t, 1.0))))


def class_weights(data: CachedScans, ids: list[int], power: float) -> np.ndarray:
    """(18,) float32 weights = frequency^-power over the training scans (mean 1 over present classes)."""
    hist = np.zeros(256, np.int64)
    for i in ids[:: max(1, len(ids) // 300)]:
        hist += np.bincount(np.asarray(data.full(i)[1]).ravel(), minlength=256)
    return class_weights_from_histogram(hist, power)


def class_weights_from_histogram(hist: np.ndarray, power: float) -> np.ndarray:
    """(18,) float32 weights = frequency^-power of a (256,) label histogram (mean 1 over present classes)."""
    f = hist[:NUM_CLASSES].astype(np.float64)
    with np.errstate(divide="ignore"):
        w = np.where(f > 0, (f / max(f.sum(), 1)) ** -power, 0.0)
    present = f > 0
    w[present] /= w[present].mean()
    w[~present] = 1.0
    return w.astype(np.float32)


def _batch(
    data: CachedScans, ids: list[int], cfg: TrainConfig, rng: np.random.Generator
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    xs, ys, bs = [], [], []
    for _ in range(cfg.batch):
        i = ids[int(rng.integers(len(ids)))]
        x, y, b = data.crop(i, cfg.crop_px, rng, flip=cfg.flip and bool(rng.random() < 0.5))
        xs.append(x)
        ys.append(y)
        bs.append(b)
    x = torch.from_numpy(dequantise(np.stack(xs))).contiguous(memory_format=torch.channels_last)
    return x, torch.from_numpy(np.stack(ys).astype(np.int64)), torch.from_numpy(np.stack(bs).astype(np.float32))


def losses(
    model: UNet,
    x: torch.Tensor,
    y: torch.Tensor,
    b: torch.Tensor,
    cw: torch.Tensor,
    cfg: TrainConfig,
    bf16: bool,
    device_type: str = "cpu",
) -> tuple[torch.Tensor, torch.Tensor]:
    """(label CE, boundary BCE) of one batch (bf16 autocast on ``device_type`` when ``bf16``)."""
    with torch.autocast(device_type, dtype=torch.bfloat16, enabled=bf16):
        lab, bnd = model(x)
    ce = F.cross_entropy(lab.float(), y, weight=cw, ignore_index=IGNORE)
    pos = torch.tensor(cfg.boundary_pos_weight, device=b.device)
    bce = F.binary_cross_entropy_with_logits(bnd.float()[:, 0], b, pos_weight=pos)
    return ce, bce


@torch.no_grad()
def evaluate(model: UNet, data: CachedScans, ids: list[int], bf16: bool) -> dict:
    """Pixel metrics on whole cached scans: mean IoU over the 18 classes present, pixel accuracy, boundary F1."""
    model.eval()
    conf = np.zeros((NUM_CLASSES, NUM_CLASSES), np.int64)
    tp = fp = fn = 0
    for i in ids:
        xq, y, b = data.full(i)
        x = torch.from_numpy(dequantise(np.asarray(xq))[None]).contiguous(memory_format=torch.channels_last)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            lab, bnd = model(x)
        pred = lab[0].float().argmax(0).numpy()
        y = np.asarray(y)
        ok = y != IGNORE
        conf += np.bincount(y[ok].astype(np.int64) * NUM_CLASSES + pred[ok], minlength=NUM_CLASSES**2).reshape(
            NUM_CLASSES, NUM_CLASSES
        )
        pb, gb = bnd[0, 0].float().numpy() > 0, np.asarray(b) > 0
        tp += int((pb & gb).sum())
        fp += int((pb & ~gb).sum())
        fn += int((~pb & gb).sum())
    model.train()
    return pixel_metrics(conf, tp, fp, fn)


def pixel_metrics(conf: np.ndarray, tp: int, fp: int, fn: int) -> dict:
    """Checkpoint metrics from an (18, 18) label confusion matrix (rows true) and boundary pixel counts: mean IoU
    over the classes present, pixel accuracy, boundary F1 and the IoU per present class."""
    inter = np.diag(conf)
    union = conf.sum(0) + conf.sum(1) - inter
    present = conf.sum(1) > 0
    iou = np.where(union > 0, inter / np.maximum(union, 1), 0.0)
    return {
        "miou": float(iou[present].mean()),
        "pixel_acc": float(inter.sum() / max(conf.sum(), 1)),
        "boundary_f1": 2 * tp / max(2 * tp + fp + fn, 1),
        "iou": {int(k): round(float(iou[k]), 4) for k in np.nonzero(present)[0]},
    }


def train(
    data_dir: str | Path,
    out: str | Path,
    cfg: TrainConfig | None = None,
    cache_dir: str | Path | None = None,
    net_cfg: NetConfig | None = None,
    init: str | Path | None = None,
    log: Callable[[str], object] = print,
) -> dict:
    """Train on the scans under ``data_dir``; write the best checkpoint (by validation mIoU) to ``out``.

    init: optional weights file to start from (a second stage: a fresh schedule over trained weights; its network
    config is used). Returns the training record (also written next to ``out`` as ``<out>.json``).
    """
    cfg = cfg if cfg is not None else TrainConfig()
    net_cfg = net_cfg or NetConfig()
    torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    scans = find_scans(data_dir)
    if len(scans) <= cfg.val_scans:
        raise ValueError(f"{data_dir}: {len(scans)} scans with gt/ found; need more than {cfg.val_scans}")
    cache = Path(cache_dir) if cache_dir else Path(data_dir) / ".cache"
    t0 = time.time()
    build_cache(scans, cache)
    data = CachedScans(cache)
    log(f"cache ready: {len(data)} scans in {time.time() - t0:.0f} s")
    val_ids = list(range(0, len(data), len(data) // cfg.val_scans))[: cfg.val_scans]  # spread over the groups
    train_ids = sorted(set(range(len(data))) - set(val_ids))
    cw = torch.from_numpy(class_weights(data, train_ids, cfg.class_weight_power))
    bf16 = bf16_supported() if cfg.bf16 is None else cfg.bf16
    if init is not None:
        model, init_meta = load_weights(init)
        net_cfg = model.cfg
        model = model.to(memory_format=torch.channels_last)
    else:
        init_meta = None
        model = UNet(net_cfg).to(memory_format=torch.channels_last)
    model.train()
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sizes = sorted({(e["w"], e["h"]) for e in data.entries})
    record = {
        "config": asdict(cfg),
        "net": asdict(net_cfg),
        "train_scans": len(train_ids),
        "val_scans": len(val_ids),
        "sizes": [list(s) for s in sizes],
        "bf16": bf16,
        "history": [],
        "best": None,
        "data_dir": str(data_dir),
        "init": None
        if init is None
        else {
            "path": str(init),
            "config": (init_meta or {}).get("config"),
            "steps_done": (init_meta or {}).get("step"),
            "best": (init_meta or {}).get("best"),
        },
    }
    best = -1.0
    t_start = time.time()
    run_ce = run_bce = 0.0
    step = 0
    for step in range(cfg.steps):
        for g in opt.param_groups:
            g["lr"] = _lr_at(step, cfg)
        x, y, b = _batch(data, train_ids, cfg, rng)
        ce, bce = losses(model, x, y, b, cw, cfg, bf16)
        loss = ce + cfg.boundary_weight * bce
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        run_ce += ce.item()
        run_bce += bce.item()
        elapsed = (time.time() - t_start) / 60
        capped = (cfg.minutes is not None and elapsed >= cfg.minutes) or step + 1 == cfg.stop_step
        if (step + 1) % 50 == 0:
            log(
                f"step {step + 1}/{cfg.steps} ce {run_ce / 50:.3f} bce {run_bce / 50:.3f} "
                f"lr {_lr_at(step, cfg):.2e} {elapsed:.1f} min"
            )
            run_ce = run_bce = 0.0
        if (step + 1) % cfg.eval_every == 0 or step + 1 == cfg.steps or capped:
            ev = evaluate(model, data, val_ids, bf16)
            entry = {
                "step": step + 1,
                "minutes": round(elapsed, 2),
                "miou": ev["miou"],
                "pixel_acc": ev["pixel_acc"],
                "boundary_f1": ev["boundary_f1"],
            }
            record["history"].append(entry)
            log(f"eval {entry}")
            save_weights(model, out.with_suffix(".last.pt"), {**record, "step": step + 1})
            if ev["miou"] > best:
                best = ev["miou"]
                record["best"] = {**entry, "iou": ev["iou"]}
                save_weights(model, out, {**record, "step": step + 1})
            Path(str(out) + ".json").write_text(json.dumps(record, indent=1))
        if capped:
            log(f"stopped at step {step + 1} ({elapsed:.1f} min)")
            break
    record["steps_done"] = step + 1
    record["minutes"] = round((time.time() - t_start) / 60, 2)
    Path(str(out) + ".json").write_text(json.dumps(record, indent=1))
    return record
