"""Sphere: ``origin`` = centre, ``radius`` (metres, camera frame)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from v2c.primitives.base import Primitive, _vec, as_points
from v2c.primitives.directions import unit


@dataclass(eq=False, repr=False)
class Sphere(Primitive):
    """Sphere; signed distance is positive outside.

    uv: (azimuth around the camera z axis, elevation from the camera x-y plane), radians.
    Local parameters: [p1, p2, p3] centre shift (metres, camera axes), [d_radius] (metres).
    """

    origin: np.ndarray
    radius: float

    type = "sphere"
    local_size = 4
    local_names = ("px", "py", "pz", "d_radius")

    def __post_init__(self) -> None:
        self.origin = _vec(self.origin)
        self.radius = float(self.radius)

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Distance from the centre minus the radius (metres) of points ``x`` (N, 3)."""
        return np.linalg.norm(as_points(x) - self.origin, axis=1) - self.radius

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit direction (N, 3) from the centre to each point (-z, towards the camera, at the centre itself)."""
        p = unit(as_points(x) - self.origin)
        p[np.linalg.norm(p, axis=1) == 0] = (0.0, 0.0, -1.0)
        return p

    def uv(self, x: np.ndarray) -> np.ndarray:
        """(N, 2): azimuth around the camera z axis and elevation from the camera x-y plane (radians)."""
        e = self.normal(x)
        return np.stack([np.arctan2(e[:, 1], e[:, 0]), np.arcsin(np.clip(e[:, 2], -1, 1))], axis=1)

    def from_local(self, x: np.ndarray, axis: np.ndarray | None) -> Sphere:
        """The sphere with its centre shifted by [px, py, pz] (metres, camera axes) and radius by [d_radius];
        ``axis`` is ignored."""
        return Sphere(self.origin + np.asarray(x[:3], float), self.radius + float(x[3]))

    def local_jacobian(self, x: np.ndarray, ref: Primitive) -> np.ndarray:
        """(N, 4) derivatives of the signed distance w.r.t. [px, py, pz, d_radius] of ``ref.from_local``."""
        n = self.normal(x)
        return np.concatenate([-n, np.full((len(n), 1), -1.0)], axis=1)

    def params(self) -> dict[str, Any]:
        """primitives.json ``params``: origin (centre), radius."""
        return {"origin": self.origin.tolist(), "radius": self.radius}

    @classmethod
    def from_params(cls, p: dict[str, Any]) -> Sphere:
        """A sphere from primitives.json ``params`` (origin = centre, radius)."""
        return cls(p["origin"], p["radius"])
