"""Common interface of the analytic primitives (camera frame, metres, radians).

Every primitive offers, vectorised over (N, 3) point arrays: ``signed_distance`` (positive on the outer side, the
side its ``normal`` points to), ``closest_point``, ``normal`` (unit surface normal at the closest point) and ``uv``
(a 2D surface parameterisation). ``to_dict``/``from_dict`` use the primitives.json form
``{"type": ..., "params": {...}}`` of ARCHITECTURE.md.

For optimisation a primitive is moved by a *local* parameter vector around itself (the reference):
``p.from_local(x, axis)`` returns a new primitive, and ``p.from_local(zeros(p.local_size), p.axis)`` equals ``p``.
Positions are moved in metres, radii in metres, angles in radians. The axis is passed separately because it either
comes from the shared frame R (aligned primitives) or from two tangent coefficients (`directions.perturb_direction`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from v2c.labels import AxisClass, axis_class
from v2c.primitives.directions import cross3, tangent_basis, unit


def _vec(v: Any) -> np.ndarray:
    a = np.asarray(v, float).reshape(3)
    return a


def _radial_split(p: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Height h (N,), radial offset q (N, 3) and radius rho (N,) of offsets ``p`` (N, 3) from a point on ``axis``."""
    h = p @ axis
    q = p - h[:, None] * axis
    return h, q, np.sqrt(np.einsum("ij,ij->i", q, q))


def radial_coords(p: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Height h (N,) and radius rho (N,) of `radial_frame` (the same values), without the radial directions."""
    h, _, rho = _radial_split(p, axis)
    return h, rho


def radial_frame(p: np.ndarray, axis: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split offsets ``p`` (N, 3) from a point on an axis into height h (N,), radius rho (N,) and unit radial e (N, 3).

    Points on the axis get an arbitrary but fixed radial direction (the axis' first tangent vector).
    """
    h, q, rho = _radial_split(p, axis)
    on_axis = rho <= 1e-15
    if on_axis.any():
        e = q / np.where(on_axis, 1.0, rho)[:, None]
        e[on_axis] = tangent_basis(axis)[0]
        return h, rho, e
    return h, rho, q / rho[:, None]


class Primitive(ABC):
    """An analytic surface. Subclasses are small dataclasses holding the primitives.json parameters."""

    type: ClassVar[str]
    #: Number of local (non-axis) parameters used by `from_local`.
    local_size: ClassVar[int]
    #: Names of the local parameters (for reports and Jacobian layouts).
    local_names: ClassVar[tuple[str, ...]]

    origin: np.ndarray

    # -- geometry ---------------------------------------------------------------------------------------------
    @abstractmethod
    def signed_distance(self, x: np.ndarray) -> np.ndarray:
        """Signed distance (metres) of points ``x`` (N, 3, camera frame); positive on the normal's side."""

    @abstractmethod
    def normal(self, x: np.ndarray) -> np.ndarray:
        """Unit outward normal (N, 3) of the surface at the point closest to each ``x`` (N, 3)."""

    def distance_and_normal(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(``signed_distance(x)``, ``normal(x)``): the same values; curved types share the work of the two."""
        return self.signed_distance(x), self.normal(x)

    def closest_point(self, x: np.ndarray) -> np.ndarray:
        """Closest surface point (N, 3) to each ``x`` (N, 3), metres."""
        x = np.asarray(x, float).reshape(-1, 3)
        d, nrm = self.distance_and_normal(x)
        return x - d[:, None] * nrm

    @abstractmethod
    def uv(self, x: np.ndarray) -> np.ndarray:
        """Surface coordinates (N, 2) of the closest points (see each subclass for units)."""

    # -- axis ---------------------------------------------------------------------------------------------------
    @property
    def axis_vector(self) -> np.ndarray | None:
        """The primitive's axis (plane normal; cylinder, cone, torus axis), unit (3,), or None (sphere)."""
        return None

    def axis_class(self, frame: np.ndarray) -> AxisClass | None:
        """Axis class (X, Y, Z or U) of the axis against ``frame`` (3, 3) rows X, Y, Z; None for a sphere."""
        a = self.axis_vector
        return None if a is None else axis_class(a, frame)

    # -- optimisation --------------------------------------------------------------------------------------------
    @abstractmethod
    def from_local(self, x: np.ndarray, axis: np.ndarray | None) -> Primitive:
        """A new primitive moved by the local parameters ``x`` (local_size,) with unit ``axis`` (ignored if none)."""

    def local_jacobian(self, x: np.ndarray, ref: Primitive) -> np.ndarray:
        """(N, local_size) derivatives of ``signed_distance(x)`` with respect to the local parameters of
        ``ref.from_local`` (of which this primitive is the current value), axis held fixed."""
        raise NotImplementedError

    def rotation_gradient(self, x: np.ndarray) -> np.ndarray:
        """(N, 3) derivative of ``signed_distance(x)`` with respect to a small rotation vector (radians, camera
        frame) turning the surface about its origin: n(x) x (x - origin)."""
        x = as_points(x)
        return cross3(self.normal(x), x - self.origin)

    def local_basis(self) -> tuple[np.ndarray, np.ndarray]:
        """Tangent basis of the reference axis (or of the camera z axis for axis-free primitives); cached, since
        an optimiser calls `from_local` on the same reference many times (parameters are not mutated)."""
        b = self.__dict__.get("_local_basis")
        if b is None:
            a = self.axis_vector
            b = tangent_basis(np.array([0.0, 0.0, 1.0]) if a is None else a)
            self.__dict__["_local_basis"] = b
        return b

    def is_finite(self, axis_tol: float = 1e-6) -> bool:
        """True when every parameter is finite and the axis (if any) is a unit vector within ``axis_tol``: a
        degenerate fit (a plane normal of zero length from collinear points, NaN from a division) is not."""
        if not all(np.all(np.isfinite(np.asarray(v, float))) for v in self.params().values()):
            return False
        a = self.axis_vector
        return a is None or abs(float(np.linalg.norm(a)) - 1.0) <= axis_tol

    # -- serialisation -----------------------------------------------------------------------------------------
    @abstractmethod
    def params(self) -> dict[str, Any]:
        """primitives.json ``params`` (lists of floats, metres/radians)."""

    def to_dict(self) -> dict[str, Any]:
        """``{"type": ..., "params": {...}}`` as in primitives.json."""
        return {"type": self.type, "params": self.params()}

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        a, b = self.params(), other.params()  # type: ignore[attr-defined]
        return a.keys() == b.keys() and all(np.allclose(a[k], b[k], rtol=0, atol=1e-12) for k in a)

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        body = ", ".join(f"{k}={np.round(v, 5).tolist()}" for k, v in self.params().items())
        return f"{type(self).__name__}({body})"


def as_points(x: np.ndarray) -> np.ndarray:
    """View ``x`` as a float (N, 3) array."""
    return np.asarray(x, float).reshape(-1, 3)


__all__ = ["Primitive", "_vec", "as_points", "radial_coords", "radial_frame", "unit"]
