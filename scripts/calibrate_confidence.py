"""Fit the edge-confidence calibration (v2c/vbrep/confidence_calibration.json) on training scans.

    PYTHONPATH=. python scripts/calibrate_confidence.py            # label what is missing, fit, write the map
    PYTHONPATH=. python scripts/calibrate_confidence.py --label-only   # only label (records), no fit

Training scans (what the map is fitted on), each reconstructed with the learned AND the oracle segmentation:

- in-family: `v2c bench`'s generator cache of ``--train-seed`` (7100; scans 0..``--train-n``-1, 640x480, sensor
  noise, the six procedural families);
- feature families: ``--feat-n`` scans of the training feature families (`v2c.synth.families.FEATURE_FAMILIES`
  less `LEAVE_OUT_FAMILIES`: feat_prismatic, feat_plate, feat_turned) of seed ``--feat-seed`` (7200), rendered into
  ``<bench cache>/calib_features_sensor_640x480_s<seed>``;
- the CAD corpus's **training** split, ``--corpus-train-views`` views a part, rendered as `v2c bench --suite
  corpus-train` renders them.

Validation (what the method and its features were chosen on, never fitted on): the in-family cache of
``--val-seed`` (9000, ``--val-n`` scans) and the corpus **validation** split (``--corpus-val-views`` views a part,
as `v2c bench --suite corpus-val`). Never seed 0 (the reported in-family bench), never the corpus test split or the
leave-out families (`v2c bench --suite unseen`).

Each edge is labelled right/wrong by `v2c.bench.vbrep.edge_correctness` (the bench's own label) and recorded with
the quantities the extraction hands the calibration (`v2c.vbrep.calibration.EDGE_RECORD`); records are cached per
scan and segmentation in ``--records`` (JSON), so a re-fit is instant. The file carries the fingerprint of the code
and weights that labelled it (`code_fingerprint`: every ``v2c/**/*.py`` and the shipped weights); records of other
code are set aside and every scan labelled again, unless ``--reuse-stale-records`` says to keep them.
The fit (`v2c.vbrep.calibration.fit_calibration`) weighs the three training sources equally (each source's edges of
a type sum to the same weight) so that the 80 in-family scans do not outvote the new parts. Deterministic: same
scans, same map.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import sys
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from v2c.vbrep.calibration import DEFAULT_MAP, POST_MIN_BLOCK, expected_calibration_error

SEGMENTATIONS = ("learned", "oracle")
_FACTORS = (
    "logit_raw",
    "log_length_px",
    "agreement",
    "angle_deg",
    "gap_rel",
    "log_residual_noise",
    "log_depth_err_noise",
    "log_jump_rel",
    "vis_share",
)
#: The feature sets compared on the validation scans (--candidates); the shipped one is DEFAULT_FEATURES.
CANDIDATES: dict[str, tuple[str, ...]] = {
    "raw score only": ("logit_raw",),
    "factors": _FACTORS,
    "factors + part score": (*_FACTORS, "part_score_mean"),
    "factors + part score + sigma": (*_FACTORS, "part_score_mean", "log_sigma_mm"),
    "factors + segmentation (4) + sigma": (
        *_FACTORS,
        "seg_score_min",
        "part_score_mean",
        "log_face_px_min",
        "log_n_faces",
        "log_sigma_mm",
    ),
}


def label_scan(args: tuple[str, str]) -> list[dict]:
    """Labelled edges of one scan reconstructed with one segmentation: the quantities the extraction recorded for
    the calibration, plus ``ok`` (right: 1, wrong: 0). An empty list when the reconstruction fails."""
    from v2c.bench.run import limit_threads

    limit_threads()
    from v2c.bench.vbrep import edge_correctness
    from v2c.contexts import scoped
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan
    from v2c.vbrep.calibration import EDGE_RECORD

    path, seg = args
    scan = load_scan(path)
    try:
        with scoped(EDGE_RECORD, []) as rec:
            v = reconstruct(scan, seg)
    except Exception as exc:  # noqa: BLE001 - a failing scan is reported and skipped, as the bench does
        print(f"{path} ({seg}): {type(exc).__name__}: {exc}", file=sys.stderr)
        return []
    ok = edge_correctness(v, scan)
    q = rec[-1]
    if len(q) != len(v.edges):
        raise RuntimeError(f"{path}: {len(q)} recorded edges for {len(v.edges)} in the VB-Rep")
    return [dict(qi, ok=int(k)) for qi, k in zip(q, ok)]


def collect(dirs: Sequence[Path], records: dict, jobs: int, records_path: Path, fingerprint: str | None = None) -> None:
    """Label every (scan, segmentation) not yet in ``records``, saving the records (with ``fingerprint``) every 10
    scans."""
    todo = [(str(d), s) for d in dirs for s in SEGMENTATIONS if f"{d}|{s}" not in records]
    if not todo:
        return
    print(f"labelling {len(todo)} reconstructions", file=sys.stderr)
    import multiprocessing as mp

    with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn")) as pool:
        for i, (key, rows) in enumerate(zip(todo, pool.map(label_scan, todo))):
            records[f"{key[0]}|{key[1]}"] = rows
            if i % 10 == 9 or i == len(todo) - 1:
                save_records(records, records_path, fingerprint)
                print(f"  {i + 1}/{len(todo)}", file=sys.stderr)


#: The key of the records file that holds the fingerprint of the code that labelled them.
FINGERPRINT_KEY = "__code_fingerprint__"


def code_fingerprint(root: Path | None = None) -> str:
    """SHA-1 over the relative path and bytes of every ``.py`` file of the ``v2c`` package under ``root`` (default:
    the package imported) and of its shipped weights: what decides the reconstructions, their edges and labels.
    Any change to them changes it, so records labelled by other code are never mixed with new ones."""
    import v2c

    pkg = Path(v2c.__file__).parent if root is None else Path(root)
    h = hashlib.sha1()
    files = sorted(pkg.rglob("*.py")) + sorted((pkg / "segment" / "weights").glob("*.pt"))
    for f in files:
        h.update(f.relative_to(pkg).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def load_records(path: Path, fingerprint: str, reuse_stale: bool = False) -> dict:
    """The records at ``path`` when they were labelled by the code of ``fingerprint`` (or ``reuse_stale``), else
    an empty dict (a message says why); empty without a file."""
    if not path.is_file():
        return {}
    records = json.loads(path.read_text())
    theirs = records.get(FINGERPRINT_KEY)
    if theirs != fingerprint and not reuse_stale:
        print(
            f"{path}: records labelled by other code (fingerprint {theirs or 'none'}, this code {fingerprint}): "
            "labelling every scan again (--reuse-stale-records keeps them)",
            file=sys.stderr,
        )
        return {}
    return records


def save_records(records: dict, path: Path, fingerprint: str | None = None) -> None:
    """Write the records with ``fingerprint`` (a temporary file renamed into place: a killed run keeps the last
    complete file)."""
    if fingerprint is not None:
        records[FINGERPRINT_KEY] = fingerprint
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(records))
    tmp.replace(path)


def feature_scans(seed: int, n: int, jobs: int) -> list[Path]:
    """``n`` scans of the training feature families (640x480, sensor noise), rendering the missing ones."""
    if not n:
        return []
    from v2c.bench.cache import default_cache_dir, scan_complete
    from v2c.synth.dataset import SynthConfig, generate_dataset, scan_name
    from v2c.synth.families import FAMILY_GROUPS

    folder = default_cache_dir() / f"calib_features_sensor_640x480_s{seed}"
    dirs = [folder / scan_name(i) for i in range(n)]
    missing = [i for i, d in enumerate(dirs) if not scan_complete(d)]
    if missing:
        cfg = SynthConfig(width=640, height=480, noise="sensor", families=FAMILY_GROUPS["features"])
        generate_dataset(folder, n - missing[0], seed, cfg, jobs=jobs, progress=True, start=missing[0])
    return dirs


def corpus_scans(suite: str, views: int, jobs: int) -> list[Path]:
    """The rendered scans of a corpus split (`v2c bench --suite corpus-train / corpus-val`), rendering the missing
    ones; none when ``views`` is 0. Never the test split."""
    if not views:
        return []
    if suite not in ("corpus-train", "corpus-val"):
        raise ValueError(f"{suite}: the calibration may only see corpus-train and corpus-val")
    from v2c.bench.config import BenchConfig
    from v2c.bench.suite import SuiteConfig, plan_scans, render_missing

    scans, _ = plan_scans(SuiteConfig(suite=suite, views=views, bench=BenchConfig(ablations=("full",), jobs=jobs)))
    failed = render_missing(scans, jobs, progress=True)
    return [s.path for s in scans if s.label not in failed and (s.path / "gt" / "meta.json").is_file()]


def rows_of(dirs: Sequence[Path], records: dict, source: str) -> list[dict]:
    """The labelled edges of the scans, each tagged with its source."""
    return [dict(r, source=source) for d in dirs for s in SEGMENTATIONS for r in records.get(f"{d}|{s}", [])]


def report(cmap: object, sets: dict[str, list[dict]]) -> dict[str, dict[str, float]]:
    """Intersection and all-edge ECE (10 bins) of the raw and calibrated confidence per set and segmentation,
    printed and returned."""
    out = {}
    for name, rows in sets.items():
        for seg in SEGMENTATIONS:
            r = [x for x in rows if x["method"] == seg]
            if not r:
                continue
            t = np.array([x["type"] for x in r])
            ok = np.array([x["ok"] for x in r], float)
            raw = np.array([x["raw"] for x in r], float)
            cal = np.array([cmap.apply(x["type"], x["raw"], x) for x in r], float)
            s = t == "intersection"
            e = {
                "intersection_edges": int(s.sum()),
                "intersection_right": float(ok[s].mean()) if s.any() else float("nan"),
                "intersection_raw": expected_calibration_error(raw[s], ok[s]),
                "intersection_calibrated": expected_calibration_error(cal[s], ok[s]),
                "all_raw": expected_calibration_error(raw, ok),
                "all_calibrated": expected_calibration_error(cal, ok),
            }
            out[f"{name}/{seg}"] = e
            print(
                f"{name:>14s} {seg:8s} int {e['intersection_edges']:5d} right {e['intersection_right']:.3f} "
                f"ECE int raw {e['intersection_raw']:.3f} cal {e['intersection_calibrated']:.3f} | "
                f"all raw {e['all_raw']:.3f} cal {e['all_calibrated']:.3f}"
            )
    return out


def main(argv: list[str] | None = None) -> int:
    """Label the training and validation scans, fit the map on the training edges, report, write the map."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--train-seed", type=int, default=7100)
    ap.add_argument("--train-n", type=int, default=60)
    ap.add_argument("--feat-seed", type=int, default=7200)
    ap.add_argument("--feat-n", type=int, default=40)
    ap.add_argument("--corpus-train-views", type=int, default=1)
    ap.add_argument("--corpus-train-n", type=int, default=None, help="only the first N corpus-train scans")
    ap.add_argument("--val-seed", type=int, default=9000)
    ap.add_argument("--val-n", type=int, default=40)
    ap.add_argument("--corpus-val-views", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--l2", type=float, default=30.0, help="L2 penalty of the logistic fit (standardised features)")
    ap.add_argument(
        "--post-min-block",
        type=float,
        default=POST_MIN_BLOCK,
        help="edge weight each knot of the isotonic post-map rests on (0: no post-map)",
    )
    ap.add_argument("--candidates", action="store_true", help="print the validation ECE of each candidate feature set")
    ap.add_argument("--label-only", action="store_true", help="label the scans, fit nothing")
    ap.add_argument("--records", type=Path, default=Path.home() / ".cache" / "v2c" / "calibration_records_v2.json")
    ap.add_argument(
        "--reuse-stale-records",
        action="store_true",
        help="keep records labelled by other code (their fingerprint differs from this code's)",
    )
    ap.add_argument("--out", type=Path, default=DEFAULT_MAP)
    a = ap.parse_args(argv)
    if 0 in (a.train_seed, a.val_seed, a.feat_seed):
        print("seed 0 is the reported in-family bench: never fit or choose on it", file=sys.stderr)
        return 1
    from v2c.bench.run import BenchConfig, prepare_scans

    fingerprint = code_fingerprint()
    records = load_records(a.records, fingerprint, a.reuse_stale_records)
    sources = {
        "in-family": prepare_scans(BenchConfig(n=a.train_n, seed=a.train_seed, jobs=a.jobs), progress=False),
        "features": feature_scans(a.feat_seed, a.feat_n, a.jobs),
        "corpus-train": corpus_scans("corpus-train", a.corpus_train_views, a.jobs)[: a.corpus_train_n],
    }
    val = {
        "in-family-val": prepare_scans(BenchConfig(n=a.val_n, seed=a.val_seed, jobs=a.jobs), progress=False),
        "corpus-val": corpus_scans("corpus-val", a.corpus_val_views, a.jobs),
    }
    # round robin over the sources (new parts first), so that a partial run already holds some of every source
    lists = (
        sources["corpus-train"],
        val["corpus-val"],
        sources["in-family"],
        sources["features"],
        val["in-family-val"],
    )
    order = [d for group in itertools.zip_longest(*lists) for d in group if d is not None]
    collect(order, records, a.jobs, a.records, fingerprint)
    if a.label_only:
        return 0
    from v2c.vbrep.calibration import DEFAULT_FEATURES, fit_calibration

    train = {k: rows_of(v, records, k) for k, v in sources.items()}
    tr = [r for v in train.values() for r in v]
    valrows = {k: rows_of(v, records, k) for k, v in val.items()}
    post = a.post_min_block if a.post_min_block > 0 else None
    if a.candidates:
        for name, feats in CANDIDATES.items():
            print(f"candidate {name}: {', '.join(feats)}")
            report(fit_calibration(tr, feats, source_key="source", l2=a.l2), valrows)
            for mb in (20.0, 50.0, 100.0, 200.0, 400.0):
                print(f"candidate {name}, isotonic post-map, min_block {mb:g}")
                report(fit_calibration(tr, feats, source_key="source", l2=a.l2, post_min_block=mb), valrows)
    cmap = fit_calibration(tr, DEFAULT_FEATURES, source_key="source", l2=a.l2, post_min_block=post)
    cmap.meta = {
        "fitted_on": {
            "in-family": f"v2c bench cache seed {a.train_seed}, scans 0..{a.train_n - 1} (procedural families)",
            "features": f"{a.feat_n} scans of feat_prismatic / feat_plate / feat_turned, seed {a.feat_seed}",
            "corpus-train": f"the corpus training split, {a.corpus_train_views} view(s) a part "
            f"(v2c bench --suite corpus-train), {len(sources['corpus-train'])} scans",
            "segmentations": list(SEGMENTATIONS),
            "edges": {k: len(v) for k, v in train.items()},
            "weighting": "each source's edges of a type weigh the same in all",
        },
        "chosen_on": f"in-family seed {a.val_seed} (scans 0..{a.val_n - 1}) and the corpus validation split "
        f"({a.corpus_val_views} views a part), learned and oracle",
        "label": "v2c.bench.vbrep.edge_correctness",
        "tol_px": 3.0,
        "method": "logistic regression per edge type on features of the edge (v2c.vbrep.calibration"
        f".FEATURE_FUNCTIONS), L2 penalty {a.l2} on the standardised weights, fitted by Newton's method"
        + (
            f"; then an isotonic post-map of its probability (knots on at least {post:g} of edge weight; "
            "v2c.vbrep.calibration.post_isotonic, applied by post_map)"
            if post
            else ""
        ),
        "features": list(DEFAULT_FEATURES),
    }
    print("training:")
    cmap.meta["ece_train"] = report(cmap, train)
    print("validation:")
    cmap.meta["ece_val"] = report(cmap, valrows)
    cmap.save(a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
