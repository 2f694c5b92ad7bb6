"""What every step of VB-Rep extraction reads: the faces' surfaces, the camera, the observed depth, the config.

Built once by `v2c.vbrep.extract.extract_vbrep` after the face step; the edge, vertex and assembly steps take it.
Camera frame, metres; pixels (u, v).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from v2c.vbrep.ambiguity import SheetChoice
from v2c.vbrep.classify import FaceGeom, SurfaceView
from v2c.vbrep.config import VBRepConfig


def depth_window(depth: np.ndarray, cfg: VBRepConfig) -> tuple[float, float]:
    """Depth range (near, far) in metres searched by sampled ray casts: around the observed depths (the
    ``window_*`` fields of the config)."""
    z = depth[depth > 0]
    if len(z) == 0:
        return cfg.window_empty_m
    near = cfg.window_near * np.percentile(z, cfg.window_percentile)
    far = cfg.window_far * np.percentile(z, 100.0 - cfg.window_percentile)
    return float(max(cfg.window_min_m, near)), float(far)


@dataclass
class ExtractContext:
    """The inputs of the edge, vertex and assembly steps of one scan.

    faces / sheets: instance id -> surface and its chosen sheet (faces without either are background); K: (3, 3)
    intrinsics (pixels); window: depth range of the ray casts (metres); scale: part size estimate (metres);
    gap_thr: depth-gap threshold of intersections (metres); depth: (H, W) observed depth (metres, 0 = none);
    instances: (H, W) instance map the edges are found in (specks merged, `v2c.vbrep.faces.absorb_specks`);
    regions: the segmentation's own instance map, which faces are meshed and measured on (None: ``instances``);
    stats: counts reported in ``VBRep.meta["extract"]``.
    """

    faces: dict[int, FaceGeom]
    sheets: dict[int, SheetChoice]
    K: np.ndarray
    window: tuple[float, float]
    scale: float
    gap_thr: float
    depth: np.ndarray
    instances: np.ndarray
    cfg: VBRepConfig
    stats: dict[str, Any] = field(default_factory=dict)
    regions: np.ndarray | None = None

    @property
    def face_map(self) -> np.ndarray:
        """The instance map faces are meshed and measured on (``regions``, else ``instances``)."""
        return self.instances if self.regions is None else self.regions

    @property
    def view(self) -> SurfaceView:
        """The surfaces, camera and instance map as the edge-type rule sees them."""
        return SurfaceView(self.faces, self.K, self.window, self.instances)
