"""Plane: ``origin`` (a point on the plane, metres), unit ``normal`` (camera frame)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from v2c.primitives.base import Primitive, _vec, as_points
from v2c.primitives.directions import tangent_basis, unit


@dataclass(eq=False, repr=False)
class Plane(Primitive):
    """Plane through ``origin`` with unit ``normal``; signed distance is positive on the normal's side.

    uv: metres along the tangent basis (t1, t2) of the normal (`directions.tangent_basis`), from ``origin``.
    Local parameters: [offset] (metres) along the new normal; the axis is the normal.
    """

    origin: np.ndarray
    normal_vec: np.ndarray

    type = "plane"
    local_size = 1
    local_names = ("offset",)

    def __post_init__(self) -> None:
        self.origin = _vec(self.origin)
        self.normal_vec = unit(_vec(self.normal_vec))

    @property
    def axis_vector(self) -> np.ndarray:
        """The unit normal (camera frame)."""
        return self.normal_vec

    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """(x - origin) . normal (metres) of points ``x`` (N, 3)."""
        return (as_points(x) - self.origin) @ self.normal_vec

    def normal(self, x: np.ndarray) -> np.ndarray:
        """The plane's unit normal, repeated (N, 3)."""
        return np.broadcast_to(self.normal_vec, as_points(x).shape).copy()

    def uv(self, x: np.ndarray) -> np.ndarray:
        """(N, 2) metres along the tangent basis (t1, t2) of the normal, from ``origin``."""
        t1, t2 = tangent_basis(self.normal_vec)
        p = as_points(x) - self.origin
        return np.stack([p @ t1, p @ t2], axis=1)

    def from_local(self, x: np.ndarray, axis: np.ndarray | None) -> Plane:
        """The plane moved by [offset] (metres) along ``axis`` (the new unit normal; None keeps it)."""
        n = self.normal_vec if axis is None else axis
        return Plane(self.origin + float(x[0]) * n, n)

    def local_jacobian(self, x: np.ndarray, ref: Primitive) -> np.ndarray:
        """d(signed distance) / d(offset) = -1 for every point: (N, 1)."""
        return np.full((len(as_points(x)), 1), -1.0)

    def params(self) -> dict[str, Any]:
        """primitives.json ``params``: origin, normal."""
        return {"origin": self.origin.tolist(), "normal": self.normal_vec.tolist()}

    @classmethod
    def from_params(cls, p: dict[str, Any]) -> Plane:
        """A plane from primitives.json ``params`` (origin, normal)."""
        return cls(p["origin"], p["normal"])
