"""Fit the edge-confidence calibration map (v2c/vbrep/confidence_calibration.json) from training scans.

    PYTHONPATH=. python scripts/calibrate_confidence.py --train-seed 7100 --train-n 80 --val-seed 9600 --val-n 20

Training scans: `v2c bench`'s generator cache of seed ``--train-seed`` (scans 0..n-1, generated when missing:
640x480, sensor noise, the procedural families); validation: the cache of ``--val-seed`` (9600, the tuning seed).
Never seed 0 (the reported in-family bench) nor the corpus test split. Each scan is reconstructed with
``--segmentation`` (learned, as in the bench) and every edge labelled right/wrong by
`v2c.bench.vbrep.edge_correctness`; the per-type isotonic map is fitted on the training edges only and its ECE
reported on both sets. Labelled edges are cached per scan in ``--records`` (a JSON file), so a re-fit is instant;
delete it after changing the extraction. Deterministic: same scans, same map.
"""

from __future__ import annotations

import argparse
import json
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from v2c.vbrep.calibration import DEFAULT_MAP, expected_calibration_error, fit_map


def label_scan(args: tuple[str, str]) -> list[dict]:
    """Labelled edges of one scan: type, raw confidence, right (0/1), length (px), the edge's faces' residual."""
    from v2c.bench.run import limit_threads

    limit_threads()
    from v2c.bench.vbrep import edge_correctness
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan

    path, seg = args
    scan = load_scan(path)
    v = reconstruct(scan, seg)
    ok = edge_correctness(v, scan)
    return [
        {
            "type": e.type.value,
            "raw": float(e.confidence_raw if e.confidence_raw is not None else e.confidence),
            "ok": int(k),
            "tangent": bool(e.tangent),
        }
        for e, k in zip(v.edges, ok)
    ]


def collect(dirs: list[Path], seg: str, records: dict, jobs: int) -> list[dict]:
    todo = [d for d in dirs if f"{d}|{seg}" not in records]
    if todo:
        print(f"labelling {len(todo)} scans ({seg})", file=sys.stderr)
        import multiprocessing as mp

        with ProcessPoolExecutor(max_workers=jobs, mp_context=mp.get_context("spawn")) as pool:
            for d, rows in zip(todo, pool.map(label_scan, [(str(d), seg) for d in todo])):
                records[f"{d}|{seg}"] = rows
    return [r for d in dirs for r in records[f"{d}|{seg}"]]


def corpus_scans(suite: str, views: int, jobs: int) -> list[Path]:
    """The rendered scans of a corpus split (`v2c bench --suite corpus-train / corpus-val`), rendering the missing
    ones; none when ``views`` is 0. Never the test split."""
    if not views:
        return []
    from v2c.bench.config import BenchConfig
    from v2c.bench.suite import SuiteConfig, plan_scans, render_missing

    scans, _ = plan_scans(SuiteConfig(suite=suite, views=views, bench=BenchConfig(ablations=("full",), jobs=jobs)))
    failed = render_missing(scans, jobs, progress=True)
    return [s.path for s in scans if s.label not in failed and (s.path / "gt" / "meta.json").is_file()]


def arrays(rows: list[dict]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (
        np.array([r["type"] for r in rows], object),
        np.array([r["raw"] for r in rows], float),
        np.array([r["ok"] for r in rows], float),
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--train-seed", type=int, default=7100)
    ap.add_argument("--train-n", type=int, default=80)
    ap.add_argument("--val-seed", type=int, default=9600)
    ap.add_argument("--val-n", type=int, default=20)
    ap.add_argument("--corpus-train-views", type=int, default=0, help="also fit on the corpus training split")
    ap.add_argument("--corpus-val-views", type=int, default=0, help="also report the corpus validation split")
    ap.add_argument("--segmentation", default="learned")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--records", type=Path, default=Path.home() / ".cache" / "v2c" / "calibration_records.json")
    ap.add_argument("--out", type=Path, default=DEFAULT_MAP)
    a = ap.parse_args(argv)
    if a.train_seed == 0 or a.val_seed == 0:
        print("seed 0 is the reported in-family bench: never fit on it", file=sys.stderr)
        return 1
    from v2c.bench.run import BenchConfig, prepare_scans

    train = prepare_scans(BenchConfig(n=a.train_n, seed=a.train_seed, jobs=a.jobs), progress=False)
    val = prepare_scans(BenchConfig(n=a.val_n, seed=a.val_seed, jobs=a.jobs), progress=False) if a.val_n else []
    records = json.loads(a.records.read_text()) if a.records.is_file() else {}
    train += corpus_scans("corpus-train", a.corpus_train_views, a.jobs)
    val += corpus_scans("corpus-val", a.corpus_val_views, a.jobs)
    tr = collect(train, a.segmentation, records, a.jobs)
    va = collect(val, a.segmentation, records, a.jobs) if val else []
    a.records.parent.mkdir(parents=True, exist_ok=True)
    a.records.write_text(json.dumps(records))
    t, raw, ok = arrays(tr)
    cmap = fit_map(
        t,
        raw,
        ok,
        meta={
            "fitted_on": f"v2c bench cache seed {a.train_seed}, scans 0..{a.train_n - 1} (640x480, sensor noise)"
            + (
                f" + the corpus training split, {a.corpus_train_views} view(s) a part (v2c bench --suite corpus-train)"
                if a.corpus_train_views
                else ""
            ),
            "segmentation": a.segmentation,
            "edges": len(tr),
            "label": "v2c.bench.vbrep.edge_correctness",
            "tol_px": 3.0,
            "method": "isotonic (pool-adjacent-violators) per edge type on the raw confidence",
        },
    )
    for name, rows in (("train", tr), ("val", va)):
        if not rows:
            continue
        t, raw, ok = arrays(rows)
        cal = np.array([cmap.apply(ti, ri) for ti, ri in zip(t, raw)])
        for sel_name, sel in (("intersection", t == "intersection"), ("all", np.ones(len(t), bool))):
            print(
                f"{name} {sel_name}: {int(sel.sum())} edges, right {ok[sel].mean():.3f}, "
                f"ECE raw {expected_calibration_error(raw[sel], ok[sel]):.4f} "
                f"calibrated {expected_calibration_error(cal[sel], ok[sel]):.4f}"
            )
        cmap.meta[f"ece_{name}"] = {
            "intersection_raw": expected_calibration_error(raw[t == "intersection"], ok[t == "intersection"]),
            "intersection_calibrated": expected_calibration_error(cal[t == "intersection"], ok[t == "intersection"]),
            "all_raw": expected_calibration_error(raw, ok),
            "all_calibrated": expected_calibration_error(cal, ok),
        }
    cmap.save(a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
