"""Generator speed: `v2c bench --stage synth --size 256x256 --n 40` prints scans/s of one process (one core).

Imports and one warm-up scan are excluded; every timed scan is a distinct random scene (seed, i). Both the CPU
time of the process (all its threads; what one core delivers, robust to other users of a shared machine) and the
wall-clock time are reported.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from v2c.synth.dataset import SynthConfig, generate_scan
from v2c.synth.occ import silence_occt


def generator_speed(cfg: SynthConfig, n: int, seed: int = 0) -> dict[str, Any]:
    """Time `generate_scan` on ``n`` scans (seed, 0..n-1) after a warm-up scan, into a temporary folder.

    Returns the per-scan CPU and wall seconds (``cpu_s``, ``wall_s``) and their summaries: ``scans_per_cpu_s``,
    ``cpu_mean_ms``, ``cpu_max_ms``, ``scans_per_wall_s``, ``wall_median_ms``."""
    silence_occt()
    with tempfile.TemporaryDirectory() as tmp:
        generate_scan(Path(tmp), seed, 10**6, cfg)  # warm-up: lazy imports, caches
        wall, cpu = [], []
        for i in range(n):
            t0, c0 = time.perf_counter(), time.process_time()
            generate_scan(Path(tmp), seed, i, cfg)
            wall.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
    c, t = np.asarray(cpu), np.asarray(wall)
    return {
        "size": f"{cfg.width}x{cfg.height}",
        "noise": cfg.noise,
        "families": list(cfg.families),
        "seed": seed,
        "scans": n,
        "scans_per_cpu_s": float(n / c.sum()),
        "cpu_mean_ms": float(1e3 * c.mean()),
        "cpu_max_ms": float(1e3 * c.max()),
        "scans_per_wall_s": float(n / t.sum()),
        "wall_median_ms": float(1e3 * np.median(t)),
        "cpu_s": c.tolist(),
        "wall_s": t.tolist(),
    }


def format_speed(r: dict[str, Any]) -> str:
    """One line of a `generator_speed` result."""
    return (
        f"{r['size']} noise={r['noise']} n={r['scans']}: {r['scans_per_cpu_s']:.2f} scans/s per core by CPU time "
        f"(mean {r['cpu_mean_ms']:.0f} ms, max {r['cpu_max_ms']:.0f} ms); wall clock {r['scans_per_wall_s']:.2f} "
        f"scans/s (median {r['wall_median_ms']:.0f} ms)"
    )
