"""How much the real-frame figures of `v2c bench --real` move with the seed of the learned segmenter's geometric
checks (`RefineConfig.seed`: the RANSAC draws of the plane-outlier split, the merges and the fragment absorption).

The checks decide some fragments of the real frames within a fraction of a noise sigma of their thresholds, so one
seed's figures are one draw; this runs the bench once per seed and prints each seed's summary and the mean.

    PYTHONPATH=$PWD .venv/bin/python scripts/real_seed_spread.py ../shared/data/real --masks --seeds 0 1 2 3
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from v2c.bench.real import real_bench
from v2c.pipeline import PipelineConfig
from v2c.segment.refine import RefineConfig

KEYS = ("faces_per_side", "faces_per_box_side", "box_angle_error_deg", "can_radius_error_pct", "coverage_3mm")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data_dir", type=Path)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--masks", action="store_true", help="the frames' mask polygons (bench --real-masks)")
    ap.add_argument("--json", type=Path, help="write every seed's summary and frame rows here")
    args = ap.parse_args()
    runs = {}
    for seed in args.seeds:  # loop over the seeds
        cfg = PipelineConfig(refine=RefineConfig(seed=seed))
        rep = real_bench(args.data_dir, progress=False, start=False, masks=args.masks, config=cfg)
        s = rep["summary"]["learned"]
        # a box with fewer than three planes has no three-plane error (None): it does not count here
        errs = [r.get("box", {}).get("max_error_deg") for r in rep["frames"] if r.get("ok")]
        worst = max((e for e in errs if e is not None), default=0.0)
        faces = {r["frame"]: r.get("faces") for r in rep["frames"]}
        cover = {r["frame"]: round(r["coverage_3mm_object"], 4) for r in rep["frames"] if r.get("ok")}
        runs[seed] = {"summary": s, "worst_box_deg": worst, "faces": faces, "coverage_3mm_object": cover}
        print(f"seed {seed}: " + ", ".join(f"{k} {s[k]:.3f}" for k in KEYS) + f", worst box face {worst:.1f} deg")
        print(f"  STEP faces: {faces}")
        print(f"  object pixels within 3 mm: {cover}")
    for k in KEYS:  # loop over the figures: their mean over the seeds
        vals = [r["summary"][k] for r in runs.values() if math.isfinite(r["summary"][k])]
        print(f"mean {k}: {sum(vals) / len(vals):.3f} (min {min(vals):.3f}, max {max(vals):.3f})")
    if args.json:
        args.json.write_text(json.dumps(runs, indent=1, default=float))


if __name__ == "__main__":
    main()
