"""Cylinder: ``origin`` (a point on the axis), unit ``axis``, ``radius`` (metres, camera frame)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from v2c.primitives.base import Primitive, _vec, as_points, radial_frame
from v2c.primitives.directions import tangent_basis, unit


@dataclass(eq=False, repr=False)
class Cylinder(Primitive):
    """Infinite circular cylinder; signed distance is positive outside (away from the axis).

    uv: (angle around the axis in radians, measured from the axis' first tangent vector; height along the axis
    from ``origin`` in metres). Local parameters: [p1, p2] axis-point shift in the reference axis' tangent basis
    (metres), [d_radius] (metres).
    """

    origin: np.ndarray
    axis: np.ndarray
    radius: float

    type = "cylinder"
    local_size = 3
    local_names = ("p1", "p2", "d_radius")

    def __post_init__(self) -> None:
        self.origin = _vec(self.origin)
        self.axis = unit(_vec(self.axis))
        self.radius = float(self.radius)

    @property
    def axis_vector(self) -> np.ndarray:
        """The unit axis (camera frame)."""
        return self.axis

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Distance from the axis line minus the radius (metres) of points ``x`` (N, 3)."""
        _, rho, _ = radial_frame(as_points(x) - self.origin, self.axis)
        return rho - self.radius

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit radial direction (N, 3) from the axis line towards each point."""
        return radial_frame(as_points(x) - self.origin, self.axis)[2]

    def distance_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(`signed_distance`, `normal`) of points ``x`` (N, 3) from one radial frame."""
        _, rho, e = radial_frame(as_points(x) - self.origin, self.axis)
        return rho - self.radius, e

    def uv(self, x: np.ndarray) -> np.ndarray:
        """(N, 2): angle around the axis (radians, from its first tangent vector), height from ``origin`` (metres)."""
        h, _, e = radial_frame(as_points(x) - self.origin, self.axis)
        t1, t2 = tangent_basis(self.axis)
        return np.stack([np.arctan2(e @ t2, e @ t1), h], axis=1)

    def from_local(self, x: np.ndarray, axis: np.ndarray | None) -> Cylinder:
        """The cylinder with its axis point shifted by [p1, p2] (metres, reference tangent basis), radius by
        [d_radius] (metres), and unit ``axis`` (None keeps it)."""
        t1, t2 = self.local_basis()
        a = self.axis if axis is None else axis
        return Cylinder(self.origin + x[0] * t1 + x[1] * t2, a, self.radius + float(x[2]))

    def local_jacobian(self, x: np.ndarray, ref: Primitive) -> np.ndarray:
        """(N, 3) derivatives of the signed distance w.r.t. [p1, p2, d_radius] of ``ref.from_local``."""
        t1, t2 = ref.local_basis()
        n = self.normal(x)
        return np.stack([-(n @ t1), -(n @ t2), np.full(len(n), -1.0)], axis=1)

    def params(self) -> dict[str, Any]:
        """primitives.json ``params``: origin, axis, radius."""
        return {"origin": self.origin.tolist(), "axis": self.axis.tolist(), "radius": self.radius}

    @classmethod
    def from_params(cls, p: dict[str, Any]) -> Cylinder:
        """A cylinder from primitives.json ``params`` (origin, axis, radius)."""
        return cls(p["origin"], p["axis"], p["radius"])
