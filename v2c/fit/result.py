"""The geometry stage's output (ARCHITECTURE.md contract) and its JSON form."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from v2c.choices import ABLATIONS as CHOICE_ABLATIONS
from v2c.primitives import Primitive
from v2c.segment.graph import EdgeGraph

#: The ablations of BENCHMARK.md / the paper's Table 1 (named once, in `v2c.choices`).
ABLATIONS = CHOICE_ABLATIONS


@dataclass
class FitResult:
    """Fitted primitives of one scan (camera frame, metres).

    primitives: instance id -> fitted primitive.
    frame: (3, 3) rows = the shared axis frame R's X, Y, Z in the camera frame.
    axis_labels: instance id -> "X" | "Y" | "Z" | "U" | None (sphere).
    inliers: instance id -> flat pixel indices (row * W + col) of the instance's inlier points.
    residuals: instance id -> RMS point-to-surface distance over the inliers (metres).
    vertex_depths: (M,) z-depths (metres) of the edge-graph vertices: vertex k is at vertex_depths[k] * ray_k,
        ray_k = K^-1 (u, v, 1).
    graph: the 2D edge graph of the instance map.
    scale: part size estimate (metres) used to scale thresholds.
    timings: wall-clock seconds per sub-stage ("normals", "ransac", "align", "graph", "intersect", "total") and
        "total_cpu", the process' CPU seconds over the whole call (the fair measure on a shared machine).
    types_searched: ids of instances whose type was chosen by the type search (weak or missing label).
    n_intersections: (point, surface) pairs in the last intersection round (0 without the intersection term).
    ablation: the ablation that produced this result.
    """

    primitives: dict[int, Primitive]
    frame: np.ndarray
    axis_labels: dict[int, str | None]
    inliers: dict[int, np.ndarray]
    residuals: dict[int, float]
    vertex_depths: np.ndarray
    graph: EdgeGraph
    scale: float
    timings: dict[str, float]
    types_searched: list[int] = field(default_factory=list)
    n_intersections: int = 0
    ablation: str = "full"

    def to_json(self) -> dict[str, Any]:
        """JSON-ready summary: primitives in primitives.json form plus axis label, inlier count and RMS."""
        prims = []
        for i, p in sorted(self.primitives.items()):
            prims.append(
                {
                    "instance": int(i),
                    **p.to_dict(),
                    "axis_label": self.axis_labels.get(i),
                    "inliers": len(self.inliers.get(i, ())),
                    "rms_m": float(self.residuals.get(i, 0.0)),
                }
            )
        return {
            "ablation": self.ablation,
            "scale_m": float(self.scale),
            "frame": np.asarray(self.frame).tolist(),
            "primitives": prims,
            "vertex_depths": np.asarray(self.vertex_depths).tolist(),
            "timings_s": {k: float(v) for k, v in self.timings.items()},
        }
