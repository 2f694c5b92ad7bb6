"""Cone: ``origin`` = apex, unit ``axis`` (towards growing radius), ``half_angle`` (radians, 0 < a < pi/2)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from v2c.primitives.base import Primitive, _vec, as_points, radial_frame
from v2c.primitives.directions import tangent_basis, unit


@dataclass(eq=False, repr=False)
class Cone(Primitive):
    """One nappe of a circular cone; signed distance is positive outside (away from the axis).

    In the half-plane through the axis and a point (height h along the axis, radius rho), the surface is the ray
    from the apex with direction g = (cos a, sin a); points whose projection on that ray falls behind the apex are
    closest to the apex itself. uv: (angle around the axis in radians from the axis' first tangent vector, height h
    along the axis from the apex in metres). Local parameters: [p1, p2, p3] apex shift (metres, in the reference
    axis' tangent basis t1, t2 and the axis), [d_half_angle] (radians).
    """

    origin: np.ndarray
    axis: np.ndarray
    half_angle: float

    type = "cone"
    local_size = 4
    local_names = ("p1", "p2", "p3", "d_half_angle")

    def __post_init__(self) -> None:
        self.origin = _vec(self.origin)
        self.axis = unit(_vec(self.axis))
        self.half_angle = float(self.half_angle)

    @property
    def axis_vector(self) -> np.ndarray:
        """The unit axis (camera frame), pointing from the apex into the nappe."""
        return self.axis

    def _split(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        p = as_points(x) - self.origin
        h, rho, e = radial_frame(p, self.axis)
        s, c = np.sin(self.half_angle), np.cos(self.half_angle)
        t = h * c + rho * s  # position along the generator from the apex
        m = c * e - s * self.axis  # outward normal of the generator's half-plane
        return p, h, t, m, -h * s + rho * c

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Signed distance (metres) of points ``x`` (N, 3) to the nappe, or to the apex behind it."""
        p, _, t, _, d = self._split(x)
        return np.where(t >= 0, d, np.linalg.norm(p, axis=1))

    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit outward normal (N, 3) of the nappe (the direction from the apex for points behind it)."""
        p, _, t, m, _ = self._split(x)
        return np.where((t >= 0)[:, None], m, unit(p))

    def distance_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(`signed_distance`, `normal`) of points ``x`` (N, 3) from one split."""
        p, _, t, m, d = self._split(x)
        return np.where(t >= 0, d, np.linalg.norm(p, axis=1)), np.where((t >= 0)[:, None], m, unit(p))

    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest point (N, 3) on the nappe, or the apex for points behind it (metres)."""
        x = as_points(x)
        _, _, t, m, d = self._split(x)
        return np.where((t >= 0)[:, None], x - d[:, None] * m, self.origin)

    def uv(self, x: np.ndarray) -> np.ndarray:
        """(N, 2): angle around the axis (radians, from its first tangent vector), height from the apex (metres)."""
        p = as_points(x) - self.origin
        h, _, e = radial_frame(p, self.axis)
        t1, t2 = tangent_basis(self.axis)
        return np.stack([np.arctan2(e @ t2, e @ t1), h], axis=1)

    def from_local(self, x: np.ndarray, axis: np.ndarray | None) -> Cone:
        """The cone with its apex shifted by [p1, p2, p3] (metres, reference tangent basis and axis), half
        angle by [d_half_angle] (radians), and unit ``axis`` (None keeps it)."""
        t1, t2 = self.local_basis()
        a = self.axis if axis is None else axis
        apex = self.origin + x[0] * t1 + x[1] * t2 + x[2] * self.axis
        return Cone(apex, a, self.half_angle + float(x[3]))

    def local_jacobian(self, x: np.ndarray, ref: Primitive) -> np.ndarray:
        """(N, 4) derivatives of the signed distance w.r.t. [p1, p2, p3, d_half_angle] of ``ref.from_local``."""
        t1, t2 = ref.local_basis()
        p, _, t, m, _ = self._split(x)
        n = np.where((t >= 0)[:, None], m, unit(p))
        da = np.where(t >= 0, -t, 0.0)  # d(signed distance)/d(half angle): -(h cos a + rho sin a) on the nappe
        return np.stack([-(n @ t1), -(n @ t2), -(n @ ref.axis_vector), da], axis=1)

    def params(self) -> dict[str, Any]:
        """primitives.json ``params``: origin (apex), axis, half_angle."""
        return {"origin": self.origin.tolist(), "axis": self.axis.tolist(), "half_angle": self.half_angle}

    @classmethod
    def from_params(cls, p: dict[str, Any]) -> Cone:
        """A cone from primitives.json ``params`` (origin = apex, axis, half_angle)."""
        return cls(p["origin"], p["axis"], p["half_angle"])
