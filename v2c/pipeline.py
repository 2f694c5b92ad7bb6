"""The whole reconstruction: scan -> segmentation -> geometry optimisation -> VB-Rep extraction.

`reconstruct(scan)` runs the stages in order and times each into ``vbrep.meta["timings"]`` (seconds):
``segment``, ``fit``, ``vbrep`` and ``total``; the fit's own sub-stage timings are in
``vbrep.meta["fit_timings"]``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from time import perf_counter
from typing import Any

from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.model import VBRep

log = logging.getLogger(__name__)


def reconstruct(scan: Any, segmentation: Any = "learned", ablation: str = "full",
                config: VBRepConfig | None = None, fit_config: Any = None,
                return_stages: bool = False) -> VBRep | tuple[VBRep, Any, Any]:
    """Reconstruct the VB-Rep of one scan (camera frame, metres).

    scan: a `v2c.scan.Scan` or a scan folder path. segmentation: "learned" (default) | "geometric" | "oracle", or a
    ready `Segmentation`. ablation: the fit ablation ("full", "no-axis", "no-int", "fit-only").
    config: VB-Rep extraction thresholds; fit_config: a `v2c.fit.FitConfig` (default when None).
    return_stages: also return the Segmentation and the FitResult (for figures and benchmarks).
    """
    from v2c.fit import fit_scan
    from v2c.scan import load_scan
    from v2c.segment import segment
    from v2c.vbrep.extract import extract_vbrep

    t0 = perf_counter()
    if isinstance(scan, (str, Path)):
        scan = load_scan(scan)
    timings: dict[str, float] = {}
    t = perf_counter()
    if isinstance(segmentation, str):
        seg = segment(scan, segmentation)
    else:
        seg = segmentation
    timings["segment"] = perf_counter() - t
    log.info("segment (%s): %d instances, %.2f s", seg.method, len(seg.labels) - 1, timings["segment"])
    t = perf_counter()
    fit = fit_scan(scan, seg, fit_config, ablation=ablation)
    timings["fit"] = perf_counter() - t
    log.info("fit (%s): %d primitives, %.2f s", ablation, len(fit.primitives), timings["fit"])
    t = perf_counter()
    vbrep = extract_vbrep(scan, seg, fit, config)
    timings["vbrep"] = perf_counter() - t
    log.info("VB-Rep: %d faces, %d edges, %.2f s", len(vbrep.faces), len(vbrep.edges), timings["vbrep"])
    timings["total"] = perf_counter() - t0
    vbrep.meta["timings"] = timings
    vbrep.meta["fit_timings"] = {k: float(v) for k, v in getattr(fit, "timings", {}).items()}
    vbrep.meta["ablation"] = ablation
    vbrep.meta["scan"] = str(getattr(scan, "path", "") or "")
    if return_stages:
        return vbrep, seg, fit
    return vbrep
