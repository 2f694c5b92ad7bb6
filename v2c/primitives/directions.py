"""Unit vectors and rotations as small unconstrained parameter vectors (the supplement's reparameterisation).

A unit vector has two degrees of freedom. The optimiser never sees the three components: it moves a direction
by two coefficients in the tangent plane of a fixed reference direction, ``d = normalise(d0 + a t1 + b t2)``,
which is smooth and singularity free within 90 degrees of ``d0`` (the optimiser never goes that far). A rotation
has three: the axis-angle vector ``w`` of ``R = exp([w]_x) R0`` around a fixed reference rotation ``R0``.
"""

from __future__ import annotations

import numpy as np


def unit(v: np.ndarray) -> np.ndarray:
    """Normalise vectors along the last axis (zero vectors stay zero)."""
    v = np.asarray(v, float)
    n = np.sqrt(np.einsum("...i,...i->...", v, v))[..., None]
    return v / np.where(n > 0, n, 1.0)


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product of (N, 3) arrays (or a (3,) broadcast against (N, 3)); faster than np.cross."""
    a, b = np.broadcast_arrays(np.asarray(a, float), np.asarray(b, float))
    return np.stack(
        [
            a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
            a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
            a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0],
        ],
        axis=-1,
    )


def cross_vec(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product of two 3-vectors (np.cross is slow on single vectors); the same products and differences as
    np.cross, so the same values."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def tangent_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (t1, t2) spanning the plane orthogonal to the unit vector ``d`` (3,), right-handed.

    Deterministic: t1 is built from the coordinate axis least aligned with ``d``.
    """
    d = np.asarray(d, float)
    d = d / np.sqrt(d @ d)
    e = np.zeros(3)
    e[int(np.argmin(np.abs(d)))] = 1.0
    t1 = cross_vec(d, e)
    t1 /= np.sqrt(t1 @ t1)
    return t1, cross_vec(d, t1)


def perturb_direction(d0: np.ndarray, ab: np.ndarray, basis: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """Unit direction ``normalise(d0 + a t1 + b t2)`` for the two tangent coefficients ``ab`` = (a, b)."""
    t1, t2 = tangent_basis(d0) if basis is None else basis
    return unit(np.asarray(d0, float) + ab[0] * t1 + ab[1] * t2)


def rotation_exp(w: np.ndarray) -> np.ndarray:
    """Rotation matrix of the axis-angle vector ``w`` (3,) (radians), Rodrigues' formula."""
    # kept, not Rotation.from_rotvec: the LM's analytic Jacobian (geometry.residuals.left_jacobian) is this
    # formula's derivative, and fits stay bit for bit; scipy's quaternion round trip is slower per call
    w = np.asarray(w, float)
    th = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-12:
        return np.eye(3) + k
    return np.eye(3) + np.sin(th) / th * k + (1 - np.cos(th)) / th**2 * (k @ k)


def nearest_rotation(m: np.ndarray) -> np.ndarray:
    """The proper rotation closest to the 3x3 matrix ``m`` in the Frobenius norm (polar decomposition)."""
    # kept: the SVD polar factor is the standard numpy form; Rotation.from_matrix refuses det <= 0 (two axis
    # classes give a singular m) and Rotation.align_vectors does this same SVD through a quaternion round trip
    u, _, vt = np.linalg.svd(np.asarray(m, float))
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    return u @ np.diag([1.0, 1.0, d]) @ vt


def angle_between_axes(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (radians, in [0, pi/2]) between two undirected axes."""
    c = abs(float(np.dot(unit(a), unit(b))))
    return float(np.arccos(min(1.0, c)))
