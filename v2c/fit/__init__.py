"""Geometry optimisation stage: RANSAC per instance, the shared-frame aligned fit and the iterative intersection
refinement (`fit_scan`), with every threshold in `FitConfig`."""

from v2c.fit.config import FitConfig
from v2c.fit.result import ABLATIONS, FitResult
from v2c.fit.stage import fit_scan

__all__ = ["ABLATIONS", "FitConfig", "FitResult", "fit_scan"]
