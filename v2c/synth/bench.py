"""Generator speed: `python -m v2c.synth.bench --size 256x256 --n 40` prints scans/s of one process (one core).

Imports and one warm-up scan are excluded; every timed scan is a distinct random scene (seed, i). Both the CPU
time of the process (all its threads; what one core delivers, robust to other users of a shared machine) and the
wall-clock time are reported.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from v2c.synth.dataset import SynthConfig, generate_scan
from v2c.synth.occ import silence_occt


def main() -> None:
    """Time `generate_scan` on ``--n`` scans (after a warm-up) and print the seconds per scan."""
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--size", default="256x256", help="WxH pixels")
    ap.add_argument("--n", type=int, default=40, help="timed scans")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--noise", default="sensor")
    ap.add_argument(
        "--families",
        default=None,
        help="comma-separated families or groups as `v2c synth --families` (default: its default mix)",
    )
    args = ap.parse_args()
    w, h = (int(x) for x in args.size.split("x"))
    extra = {}
    if args.families:
        from v2c.synth.families import FAMILY_GROUPS

        names = [f.strip() for f in args.families.split(",") if f.strip()]
        extra["families"] = tuple(dict.fromkeys(f for v in names for f in FAMILY_GROUPS.get(v, (v,))))
    cfg = SynthConfig(width=w, height=h, noise=args.noise, **extra)
    silence_occt()
    with tempfile.TemporaryDirectory() as tmp:
        generate_scan(Path(tmp), args.seed, 10**6, cfg)  # warm-up: lazy imports, caches
        wall, cpu = [], []
        for i in range(args.n):
            t0, c0 = time.perf_counter(), time.process_time()
            generate_scan(Path(tmp), args.seed, i, cfg)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    c, t = np.asarray(cpu), np.asarray(wall)
    print(
        f"{args.size} noise={args.noise} n={len(t)}: {len(c) / c.sum():.2f} scans/s per core by CPU time "
        f"(mean {1e3 * c.mean():.0f} ms, max {1e3 * c.max():.0f} ms); wall clock {len(t) / t.sum():.2f} scans/s "
        f"(median {1e3 * np.median(t):.0f} ms)"
    )


if __name__ == "__main__":
    main()
