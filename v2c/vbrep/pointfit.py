"""Least-squares surfaces through 3D evidence, for faces the geometry stage left without a usable primitive.

`measured_points` back-projects a mask's depth readings; the fits take (N, 3) camera-frame points (metres) and
return the surface with its RMS distance (metres), or None when the points are too few or the fit degenerate:
free plane and sphere (trimmed refits), the plane or cylinder whose axis direction is given (the part frame's, or
a neighbour's), and the cone or torus whose axis line is given (a neighbour's: a chamfer or a rounded rim coaxial
with the hole or shaft it edges).
"""

from __future__ import annotations

import numpy as np

from v2c.camera import pixel_rays
from v2c.geometry import circle_2d
from v2c.primitives import Cone, Cylinder, Plane, Sphere, Torus
from v2c.primitives.base import radial_frame
from v2c.primitives.directions import tangent_basis


def measured_points(mask: np.ndarray, depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame points (metres) of the pixels of ``mask`` that have a depth reading."""
    vs, us = np.nonzero(mask & (depth > 0))
    return pixel_rays(np.stack([us, vs], 1).astype(float), K) * depth[vs, us, None]


def fit_plane_points(X: np.ndarray, trim: float) -> tuple[Plane, float, float] | None:
    """Total-least-squares plane through (N, 3) points, refitted on the ``trim`` share closest to the first fit.
    Returns the plane (normal towards the camera), its RMS distance (metres) and its flatness (second singular
    value over the first: near 0 when the points lie on one line, so the plane is undetermined); None with fewer
    than 3 points."""
    if len(X) < 3:
        return None
    for _ in range(2):
        c = X.mean(0)
        sv, vt = np.linalg.svd(X - c, full_matrices=False)[1:]
        n = vt[-1]
        d = np.abs((X - c) @ n)
        if len(X) > 10:
            X = X[d <= np.quantile(d, trim)]
    c = X.mean(0)
    if n @ c > 0:  # outward normal towards the camera
        n = -n
    rms = float(np.sqrt(np.mean(((X - c) @ n) ** 2)))
    return Plane(c, n), rms, float(sv[1] / max(sv[0], 1e-15))


def fit_sphere_points(X: np.ndarray, trim: float) -> tuple[Sphere, float] | None:
    """Algebraic least-squares sphere through (N, 3) points (camera frame, metres), refitted on the ``trim``
    share closest to the first fit. Returns the sphere and its RMS distance (metres); None with fewer than 10
    points or a degenerate fit."""
    if len(X) < 10:
        return None
    for _ in range(2):
        A = np.concatenate([2 * X, np.ones((len(X), 1))], 1)
        sol = np.linalg.lstsq(A, np.sum(X**2, 1), rcond=None)[0]
        c = sol[:3]
        r2 = float(sol[3] + c @ c)
        if not (np.all(np.isfinite(sol)) and r2 > 0):
            return None
        d = np.abs(np.linalg.norm(X - c, axis=1) - np.sqrt(r2))
        X = X[d <= np.quantile(d, trim)]
    d = np.linalg.norm(X - c, axis=1) - np.sqrt(r2)
    return Sphere(c, float(np.sqrt(r2))), float(np.sqrt(np.mean(d**2)))


def _geometric_circle(q: np.ndarray, iters: int) -> tuple[np.ndarray, float] | None:
    """Circle through 2D points q (N, 2): the algebraic fit (`v2c.geometry.circle_2d`) refined by ``iters``
    Gauss-Newton steps on the geometric distance (the algebraic fit shrinks short noisy arcs). Returns (centre (2,),
    radius) or None where degenerate."""
    c, r = circle_2d(q)
    if not (np.all(np.isfinite(c)) and r > 0):
        return None
    for _ in range(iters):  # geometric (Gauss-Newton) refinement
        v = q - c
        dist = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
        J = np.concatenate([-v / dist[:, None], -np.ones((len(q), 1))], 1)
        step = np.linalg.lstsq(J, -(dist - r), rcond=None)[0]
        c, r = c + step[:2], r + float(step[2])
        if not np.isfinite(r) or r <= 0:
            return None
    return c, r


def fit_axis_cylinder_points(X: np.ndarray, axis: np.ndarray, iters: int) -> tuple[Cylinder, float] | None:
    """Least-squares cylinder with a given unit axis through (N, 3) points: an algebraic circle fit of the points
    projected on the plane normal to the axis (`v2c.geometry.circle_2d`), refined by ``iters`` Gauss-Newton steps on
    the geometric distance. Returns the cylinder and its RMS distance (metres); None with fewer than 5 points or a
    degenerate fit."""
    if len(X) < 5:
        return None
    a = axis / np.linalg.norm(axis)
    t1, t2 = tangent_basis(a)
    q = np.stack([X @ t1, X @ t2], 1)
    got = _geometric_circle(q, iters)
    if got is None:
        return None
    c, r = got
    d = np.linalg.norm(q - c, axis=1) - r
    origin = c[0] * t1 + c[1] * t2 + float(np.mean(X @ a)) * a
    return Cylinder(origin, a, r), float(np.sqrt(np.mean(d**2)))


def fit_axis_plane_points(X: np.ndarray, normal: np.ndarray) -> tuple[Plane, float] | None:
    """Least-squares plane with a given unit normal through (N, 3) points: the mean offset along the normal.
    Returns the plane and its RMS distance (metres); None with fewer than 3 points."""
    if len(X) < 3:
        return None
    n = normal / np.linalg.norm(normal)
    return Plane(X.mean(axis=0), n), float(np.std(X @ n))


def fit_plane_normal_across(X: np.ndarray, axis: np.ndarray) -> tuple[Plane, float] | None:
    """Least-squares plane whose normal is perpendicular to the unit ``axis`` (a face parallel to that axis)
    through (N, 3) points: a line fitted to the points projected along the axis. Returns the plane and its RMS
    distance (metres); None with fewer than 3 points."""
    if len(X) < 3:
        return None
    t1, t2 = tangent_basis(axis / np.linalg.norm(axis))
    q = np.stack([X @ t1, X @ t2], 1)
    c = q.mean(axis=0)
    _, _, vt = np.linalg.svd(q - c, full_matrices=False)
    n = vt[1, 0] * t1 + vt[1, 1] * t2
    return Plane(X.mean(axis=0), n), float(np.std(X @ n))


def fit_axis_line_cone_points(X: np.ndarray, point: np.ndarray, axis: np.ndarray) -> tuple[Cone, float] | None:
    """Least-squares cone on a given axis line (``point``, unit ``axis``) through (N, 3) points: the radius
    rho as a linear function of the height h along the axis (a line in the (h, rho) half-plane). Returns the cone
    (apex where that line meets the axis, axis towards growing radius) and its RMS distance (metres); None with
    fewer than 5 points, a degenerate fit or a half-angle within 1 degree of 0 or 90 (a cylinder or a plane)."""
    if len(X) < 5:
        return None
    a = axis / np.linalg.norm(axis)
    h, rho, _ = radial_frame(X - point, a)
    A = np.stack([h, np.ones_like(h)], 1)
    if np.linalg.matrix_rank(A) < 2:
        return None
    k, r0 = np.linalg.lstsq(A, rho, rcond=None)[0]
    half = float(np.arctan(abs(k)))
    if not (np.isfinite(half) and np.deg2rad(1.0) < half < np.deg2rad(89.0)):
        return None
    apex = point + (-r0 / k) * a
    cone = Cone(apex, a if k > 0 else -a, half)
    return cone, float(np.sqrt(np.mean(cone.signed_distance(X) ** 2)))


def fit_axis_line_torus_points(
    X: np.ndarray, point: np.ndarray, axis: np.ndarray, iters: int
) -> tuple[Torus, float] | None:
    """Least-squares torus on a given axis line (``point``, unit ``axis``) through (N, 3) points: its tube's
    cross-section the circle through the points' (rho, h) cloud (`_geometric_circle`, ``iters`` Gauss-Newton
    steps). Returns the torus and its RMS distance (metres); None with fewer than 5 points or a degenerate fit (a
    tube centre on or across the axis)."""
    if len(X) < 5:
        return None
    a = axis / np.linalg.norm(axis)
    h, rho, _ = radial_frame(X - point, a)
    got = _geometric_circle(np.stack([rho, h], 1), iters)
    if got is None or not 0 < got[1] < got[0][0]:
        return None
    c, r = got
    torus = Torus(point + c[1] * a, a, float(c[0]), float(r))
    return torus, float(np.sqrt(np.mean(torus.signed_distance(X) ** 2)))
