"""Torus: ``origin`` = centre, unit ``axis``, ``radius`` (major), ``minor_radius`` (metres, camera frame)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from v2c.primitives.base import Primitive, _vec, as_points, radial_frame
from v2c.primitives.directions import tangent_basis, unit


@dataclass(eq=False, repr=False)
class Torus(Primitive):
    """Torus: the points at ``minor_radius`` from the circle of ``radius`` around ``axis`` through ``origin``.

    Signed distance is positive outside the tube. uv: (angle around the axis from the axis' first tangent
    vector, angle around the tube measured from the outward radial direction towards the axis), radians.
    Local parameters: [p1, p2, p3] centre shift (metres, reference tangent basis and axis), [d_radius,
    d_minor_radius] (metres).
    """

    origin: np.ndarray
    axis: np.ndarray
    radius: float
    minor_radius: float

    type = "torus"
    local_size = 5
    local_names = ("p1", "p2", "p3", "d_radius", "d_minor_radius")

    def __post_init__(self) -> None:
        self.origin = _vec(self.origin)
        self.axis = unit(_vec(self.axis))
        self.radius = float(self.radius)
        self.minor_radius = float(self.minor_radius)

    @property
    def axis_vector(self) -> np.ndarray:
        """The unit axis (camera frame)."""
        return self.axis

    def _tube_offset(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        h, rho, e = radial_frame(as_points(x) - self.origin, self.axis)
        w = (rho - self.radius)[:, None] * e + h[:, None] * self.axis  # from the tube's centre circle
        return w, h, rho, e

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Distance from the tube's centre circle minus the minor radius (metres) of points ``x`` (N, 3)."""
        return np.linalg.norm(self._tube_offset(x)[0], axis=1) - self.minor_radius

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit direction (N, 3) from the tube's centre circle to each point (radial where they coincide)."""
        return self.distance_and_normal(x)[1]

    def distance_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(`signed_distance`, `normal`) of points ``x`` (N, 3) from one tube offset."""
        w, _, _, e = self._tube_offset(x)
        n = np.linalg.norm(w, axis=1, keepdims=True)
        return n[:, 0] - self.minor_radius, np.where(n > 1e-15, w / np.where(n > 1e-15, n, 1.0), e)

    def uv(self, x: np.ndarray) -> np.ndarray:
        """(N, 2): angle around the axis (from its first tangent vector) and around the tube (radians)."""
        _, h, rho, e = self._tube_offset(x)
        t1, t2 = tangent_basis(self.axis)
        return np.stack([np.arctan2(e @ t2, e @ t1), np.arctan2(h, rho - self.radius)], axis=1)

    def from_local(self, x: np.ndarray, axis: np.ndarray | None) -> Torus:
        """The torus with its centre shifted by [p1, p2, p3] (metres, reference tangent basis and axis), radii
        by [d_radius, d_minor_radius] (metres), and unit ``axis`` (None keeps it)."""
        t1, t2 = self.local_basis()
        a = self.axis if axis is None else axis
        c = self.origin + x[0] * t1 + x[1] * t2 + x[2] * self.axis
        return Torus(c, a, self.radius + float(x[3]), self.minor_radius + float(x[4]))

    def local_jacobian(self, x: np.ndarray, ref: Primitive) -> np.ndarray:
        """(N, 5) derivatives of the signed distance w.r.t. [p1, p2, p3, d_radius, d_minor_radius] of
        ``ref.from_local``."""
        t1, t2 = ref.local_basis()
        w, _, _, e = self._tube_offset(x)
        nw = np.linalg.norm(w, axis=1, keepdims=True)
        n = np.where(nw > 1e-15, w / np.where(nw > 1e-15, nw, 1.0), e)
        return np.stack(
            [-(n @ t1), -(n @ t2), -(n @ ref.axis_vector), -np.sum(n * e, axis=1), np.full(len(n), -1.0)], axis=1
        )

    def params(self) -> dict[str, Any]:
        """primitives.json ``params``: origin (centre), axis, radius, minor_radius."""
        return {
            "origin": self.origin.tolist(),
            "axis": self.axis.tolist(),
            "radius": self.radius,
            "minor_radius": self.minor_radius,
        }

    @classmethod
    def from_params(cls, p: dict[str, Any]) -> Torus:
        """A torus from primitives.json ``params`` (origin = centre, axis, radius, minor_radius)."""
        return cls(p["origin"], p["axis"], p["radius"], p["minor_radius"])
