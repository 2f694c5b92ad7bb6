"""The whole reconstruction: scan -> segmentation -> geometry optimisation -> VB-Rep extraction.

`reconstruct(scan)` is the one entry point (the CLI, `v2c.api`, the bench and fixtures_design all call it). It runs
the stages in order with one `PipelineConfig` carrying each stage's settings down, and times each stage into
``vbrep.meta["timings"]`` (seconds): ``segment``, ``fit``, ``vbrep`` and ``total``; the fit's own sub-stage timings
are in ``vbrep.meta["fit_timings"]``; with the learned segmenter, ``vbrep.meta["network_precision"]`` ("bf16" or
"fp32") says in which arithmetic the network ran.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path
from time import perf_counter
from typing import Literal, overload

from v2c.choices import ABLATIONS, DEFAULT_ABLATION, DEFAULT_SEGMENTATION, SEGMENTATION_METHODS
from v2c.fit.config import FitConfig
from v2c.fit.result import FitResult
from v2c.scan import Scan
from v2c.segment.refine import RefineConfig
from v2c.segment.types import Segmentation
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.model import VBRep

log = logging.getLogger(__name__)

__all__ = ["ABLATIONS", "DEFAULT_SEGMENTATION", "SEGMENTATION_METHODS", "PipelineConfig", "reconstruct"]


@dataclass
class PipelineConfig:
    """Settings of every stage, passed down by `reconstruct`: ``refine`` (instance refinement after the learned
    segmenter: plane-outlier split, coaxial steps, coplanar merge), ``fit`` (RANSAC, the joint LM fit and the
    intersection refinement; its RANSAC settings also reach the refinement) and ``vbrep`` (VB-Rep extraction).
    Units are in each config's field comments; the defaults are the shipped, validated settings."""

    refine: RefineConfig = field(default_factory=RefineConfig)
    fit: FitConfig = field(default_factory=FitConfig)
    vbrep: VBRepConfig = field(default_factory=VBRepConfig)


@overload
def reconstruct(
    scan: Scan | str | Path,
    segmentation: str | Segmentation = ...,
    ablation: str = ...,
    config: PipelineConfig | None = ...,
    *,
    roi: str | tuple[int, int, int, int] | None = ...,
    return_stages: Literal[False] = ...,
) -> VBRep: ...


@overload
def reconstruct(
    scan: Scan | str | Path,
    segmentation: str | Segmentation = ...,
    ablation: str = ...,
    config: PipelineConfig | None = ...,
    *,
    roi: str | tuple[int, int, int, int] | None = ...,
    return_stages: Literal[True],
) -> tuple[VBRep, Segmentation, FitResult]: ...


def reconstruct(
    scan: Scan | str | Path,
    segmentation: str | Segmentation = DEFAULT_SEGMENTATION,
    ablation: str = DEFAULT_ABLATION,
    config: PipelineConfig | None = None,
    *,
    roi: str | tuple[int, int, int, int] | None = None,
    return_stages: bool = False,
) -> VBRep | tuple[VBRep, Segmentation, FitResult]:
    """Reconstruct the VB-Rep of one scan (camera frame, metres).

    scan: a loaded `Scan` or a scan folder (loaded with ``roi``: "x0,y0,x1,y1" pixels or a tuple; ignored for a
    loaded scan). segmentation: "learned" (default) | "geometric" | "oracle", or a ready `Segmentation`.
    ablation: the fit ablation ("full", "no-axis", "no-int", "fit-only"). config: every stage's settings
    (`PipelineConfig()` when None). return_stages: also return the Segmentation and the FitResult (for figures
    and benchmarks).
    """
    from v2c.fit import fit_scan
    from v2c.scan import load_scan
    from v2c.segment import segment
    from v2c.vbrep.extract import extract_vbrep

    config = config if config is not None else PipelineConfig()
    t0 = perf_counter()
    if isinstance(scan, (str, Path)):
        scan = load_scan(scan, roi=roi)
    timings: dict[str, float] = {}
    t = perf_counter()
    if isinstance(segmentation, str):
        seg = segment(scan, segmentation, refine=config.refine, ransac=config.fit)
    else:
        seg = segmentation
    timings["segment"] = perf_counter() - t
    log.info("segment (%s): %d instances, %.2f s", seg.method, len(seg.labels) - 1, timings["segment"])
    t = perf_counter()
    fit = fit_scan(scan, seg, config.fit, ablation=ablation)
    timings["fit"] = perf_counter() - t
    log.info("fit (%s): %d primitives, %.2f s", ablation, len(fit.primitives), timings["fit"])
    t = perf_counter()
    vbrep = extract_vbrep(scan, seg, fit, config.vbrep)
    timings["vbrep"] = perf_counter() - t
    log.info("VB-Rep: %d faces, %d edges, %.2f s", len(vbrep.faces), len(vbrep.edges), timings["vbrep"])
    timings["total"] = perf_counter() - t0
    vbrep.meta["timings"] = timings
    vbrep.meta["fit_timings"] = {k: float(v) for k, v in fit.timings.items()}
    vbrep.meta["ablation"] = ablation
    vbrep.meta["scan"] = str(scan.path or "")
    if seg.method == "learned":  # the network's arithmetic changes its output (`segment.learned.network_precision`)
        from v2c.segment.learned import network_precision

        vbrep.meta["network_precision"] = network_precision()
    if return_stages:
        return vbrep, seg, fit
    return vbrep
