"""Geometry toolkit below the stages: what both the segmentation stage (`v2c.segment.refine`) and the geometry
optimisation stage (`v2c.fit`) need to fit primitives to a scan's points.

- `points`: per-instance camera-frame points with depth-gradient normals, and the part size they are scaled by.
- `ransac`: RANSAC per instance (minimal-set hypotheses of each primitive type, scoring, robust refinement).
- `selection`: which type a patch supports (curvature support, GRIC), RANSAC over all types.
- `residuals`: point-to-surface residuals of primitives and their analytic Jacobians (the least squares above
  and the stage's joint fits).
- `config`: `RansacConfig`, every threshold of the above with its unit (`v2c.fit.FitConfig` extends it).

Camera frame, metres; back-projection is `v2c.camera.backproject`.
"""

from v2c.geometry.config import RansacConfig
from v2c.geometry.points import InstancePoints, estimate_part_size, instance_points
from v2c.geometry.ransac import RansacFit, circle_2d, inlier_mask, ransac_fit, refine_primitive
from v2c.geometry.selection import fit_instance, select_type, supported

__all__ = [
    "InstancePoints",
    "RansacConfig",
    "RansacFit",
    "circle_2d",
    "estimate_part_size",
    "fit_instance",
    "inlier_mask",
    "instance_points",
    "ransac_fit",
    "refine_primitive",
    "select_type",
    "supported",
]
