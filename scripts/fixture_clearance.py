"""Measure how the default fixture clearance k x sigma (fixtures_design.design.CLEARANCE_K) keeps fixtures out of
the true part: corner, pin and cradle fixtures designed on learned reconstructions of generated scans, checked
against the scan's true part (gt/part.step) for each k.

    PYTHONPATH=. python scripts/fixture_clearance.py --seed 7100 --n 20 --k 0,1,2,3

k = 0 is the kinds' own clearances (0.1-0.2 mm). A design "cuts" when its common volume with the true part exceeds
``--cut-share`` (0.1 %) of the fixture's volume. Seed 7100 is a training seed (never 0, never the unseen suite).
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=7100)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--start", type=int, default=0)
    ap.add_argument("--k", default="0,1,2,3")
    ap.add_argument("--kinds", default="corner,pin,cradle")
    ap.add_argument("--cut-share", type=float, default=0.001)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    from fixtures_design.assembly import true_part
    from fixtures_design.design import DEFAULT_PARAMS, design_fixture, mating_sigma_mm
    from fixtures_design.model import FixtureKind
    from fixtures_design.references import NoReferenceError
    from fixtures_design.verify import interference
    from v2c.bench.run import BenchConfig, prepare_scans
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan

    ks = [float(k) for k in a.k.split(",")]
    dirs = prepare_scans(BenchConfig(n=a.start + a.n, seed=a.seed, jobs=1), progress=False)[a.start :]
    rows = []
    for d in dirs:
        scan = load_scan(d)
        v = reconstruct(scan, "learned")
        for kind in a.kinds.split(","):
            for k in ks:
                try:
                    fx = design_fixture(v, kind, None if k > 0 else DEFAULT_PARAMS[FixtureKind(kind)], clearance_k=k)
                except (NoReferenceError, ValueError):
                    break
                tp = true_part(d / "gt" / "part.step", fx.fmap)
                vol, share = interference(fx, tp)
                sig = mating_sigma_mm(v, fx.reference)
                rows.append(
                    {
                        "scan": d.name,
                        "family": scan.gt.meta.get("family"),
                        "kind": kind,
                        "k": k,
                        "sigma_mm": sig,
                        "clearance": fx.params.clearance,
                        "cut_mm3": vol,
                        "cut_share": share,
                    }
                )
                print(
                    f"{d.name} {kind:6s} k={k:.0f} sigma {sig if sig is None else round(sig, 3)} clearance "
                    f"{fx.params.clearance:.2f} mm cut {vol:.1f} mm^3 ({100 * share:.2f} %)",
                    flush=True,
                )
    for kind in a.kinds.split(","):
        for k in ks:
            r = [x for x in rows if x["kind"] == kind and x["k"] == k]
            if r:
                cut = np.mean([x["cut_share"] > a.cut_share for x in r])
                print(
                    f"{kind} k={k:g}: {len(r)} designs, {100 * cut:.0f} % cut > {100 * a.cut_share:.1f} % of the "
                    f"fixture, median clearance {np.median([x['clearance'] for x in r]):.2f} mm"
                )
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
