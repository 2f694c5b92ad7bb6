"""Confidence of each edge in [0, 1]: how sure we are of its type and geometry (its type says what it is).

The confidence is the product of factors, each in [0, 1] (units of the constants: VBRepConfig):

- fit: ``exp(-r / (conf_residual * scale))`` with r the larger RMS fit residual (metres) of the edge's faces: a
  poorly fitted surface makes every edge on it uncertain.
- depth: ``exp(-e / (conf_depth * scale))`` with e the median distance (metres, along the rays) between the lifted
  polyline and the observed depth just on the edge's face side: the 3D edge should sit on the measured surface.
- length: ``1 - exp(-L / conf_length_px)`` with L the edge's length in the image (pixels): short edges rest on
  few samples.
- margin, by type:
  intersection: ``min(1, angle / conf_angle_deg)`` for the angle between the two surfaces at the edge (nearly
  tangent surfaces meet in a poorly defined curve) times ``1 - gap / gap_thr`` for the median depth gap of the
  surfaces relative to the intersection threshold;
  silhouette / occluded: ``1 - exp(-jump / gap_thr)`` for the median depth jump between the two sides (1 for the
  background);
  visibility: the share of the edge's samples whose contour was found within vis_px.
- agreement: the share of the edge's samples whose own (unsmoothed) type equals the edge's type.
"""

from __future__ import annotations

import numpy as np

from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.model import EdgeType


def edge_confidence(
    etype: EdgeType,
    *,
    residual: float,
    depth_err: float,
    length_px: float,
    angle: float,
    gap: float,
    jump: float,
    vis_share: float,
    agreement: float,
    gap_thr: float,
    scale: float,
    cfg: VBRepConfig,
) -> float:
    """Confidence in [0, 1] of one edge; see the module docstring. Lengths in metres, angle in radians."""
    f_fit = np.exp(-residual / (cfg.conf_residual * scale))
    f_depth = np.exp(-depth_err / (cfg.conf_depth * scale)) if np.isfinite(depth_err) else 0.5
    f_len = 1.0 - np.exp(-length_px / cfg.conf_length_px)
    if etype is EdgeType.INTERSECTION:
        f_ang = min(1.0, angle / np.deg2rad(cfg.conf_angle_deg)) if np.isfinite(angle) else 0.5
        f_gap = max(0.0, 1.0 - gap / gap_thr) if np.isfinite(gap) else 0.5
        f_margin = f_ang * f_gap
    elif etype is EdgeType.VISIBILITY:
        f_margin = vis_share
    else:
        f_margin = 1.0 if not np.isfinite(jump) else 1.0 - np.exp(-jump / gap_thr)
    c = f_fit * f_depth * f_len * f_margin * agreement
    return float(np.clip(c, 0.0, 1.0))


def face_confidence(residual: float, sheet_errors: np.ndarray, sheet: int, scale: float, cfg: VBRepConfig) -> float:
    """Face confidence in [0, 1]: the fit factor times how clearly the chosen sheet beats the next best
    (1 when only one sheet exists)."""
    f_fit = np.exp(-residual / (cfg.conf_residual * scale))
    errs = np.sort(np.asarray(sheet_errors, float))
    best = float(sheet_errors[sheet]) if np.isfinite(sheet_errors[sheet]) else np.inf
    second = errs[1] if len(errs) > 1 else np.inf
    f_sheet = 1.0 if not np.isfinite(second) else float(np.clip(1.0 - best / max(second, 1e-12), 0.0, 1.0))
    return float(np.clip(f_fit * f_sheet, 0.0, 1.0))
