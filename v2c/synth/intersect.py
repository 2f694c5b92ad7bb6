"""Exact ray / primitive intersection, used to move mesh hits onto the true analytic surface.

Rays start at the camera centre (origin of the camera frame) with unit directions; distances t are metres along
the ray. Each function takes the rough mesh-hit distance t0 and returns the analytic hit nearest to it, or NaN
where the ray misses the surface or the analytic hit is farther than `max_shift` from t0. Primitive parameters
follow ARCHITECTURE.md (camera frame, metres).
"""

from __future__ import annotations

import numpy as np


def rows_dot(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n,) dot products of the rows of `a` (n, 3) with `v` (3,). einsum, not matmul: BLAS spawns threads that
    busy-wait on a loaded machine and made these products 10x slower."""
    return np.einsum("ij,j->i", a, v)


#: Newton iterations for the torus (quadratic convergence from a hit within the tessellation tolerance).
TORUS_NEWTON_STEPS = 12


def _nearest_quadratic_root(a: np.ndarray, b: np.ndarray, c: np.ndarray, t0: np.ndarray) -> np.ndarray:
    """Root of a t^2 + b t + c = 0 nearest t0 (NaN where there is no real root or a ~ 0)."""
    disc = b * b - 4.0 * a * c
    ok = (disc >= 0.0) & (np.abs(a) > 1e-12)
    sq = np.sqrt(np.where(ok, disc, 0.0))
    # Numerically stable pair: q = -(b + sign(b) sqrt(disc)) / 2, roots q / a and c / q.
    q = -0.5 * (b + np.copysign(sq, b))
    with np.errstate(divide="ignore", invalid="ignore"):
        r1 = q / np.where(ok, a, 1.0)
        r2 = np.where(np.abs(q) > 0, c / np.where(q == 0, 1.0, q), r1)
    t = np.where(np.abs(r1 - t0) <= np.abs(r2 - t0), r1, r2)
    return np.where(ok, t, np.nan)


def _axis(params: dict, key: str = "axis") -> np.ndarray:
    v = np.asarray(params[key], float)
    return v / np.linalg.norm(v)


def intersect_primitive(
    kind: str, params: dict, dirs: np.ndarray, t0: np.ndarray, max_shift: float
) -> tuple[np.ndarray, np.ndarray]:
    """Analytic hit distances (n,) and unit normals (n, 3) facing the camera for rays `dirs` (n, 3) from the
    origin against one primitive; NaN distance where there is no hit within `max_shift` metres of t0."""
    o = np.asarray(params["origin"], float)
    if kind == "plane":
        n = _axis(params, "normal")
        dn = rows_dot(dirs, n)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.where(np.abs(dn) > 1e-12, (o @ n) / dn, np.nan)
        normals = np.broadcast_to(n, dirs.shape)
    elif kind == "sphere":
        r = float(params["radius"])
        q0 = -o
        t = _nearest_quadratic_root(
            np.ones(len(dirs)), 2.0 * rows_dot(dirs, q0), np.full(len(dirs), q0 @ q0 - r * r), t0
        )
        normals = dirs * t[:, None] - o
    elif kind == "cylinder":
        a, r = _axis(params), float(params["radius"])
        q0 = -o
        qp = q0 - (q0 @ a) * a
        dp = dirs - rows_dot(dirs, a)[:, None] * a
        t = _nearest_quadratic_root(
            np.einsum("ij,ij->i", dp, dp), 2.0 * rows_dot(dp, qp), np.full(len(dirs), qp @ qp - r * r), t0
        )
        p = dirs * t[:, None] - o
        normals = p - rows_dot(p, a)[:, None] * a
    elif kind == "cone":
        a, cos2 = _axis(params), np.cos(float(params["half_angle"])) ** 2
        q0 = -o  # ray origin relative to the apex
        da = rows_dot(dirs, a)
        qa = q0 @ a
        t = _nearest_quadratic_root(
            da * da - cos2,
            2.0 * (qa * da - cos2 * rows_dot(dirs, q0)),
            np.full(len(dirs), qa * qa - cos2 * (q0 @ q0)),
            t0,
        )
        p = dirs * t[:, None] - o
        t = np.where(rows_dot(p, a) > 0.0, t, np.nan)  # the material nappe only
        normals = rows_dot(p, a)[:, None] * a - cos2 * p
    elif kind == "torus":
        t, normals = _torus_newton(o, _axis(params), float(params["radius"]), float(params["minor_radius"]), dirs, t0)
    else:
        raise ValueError(f"no analytic intersection for {kind}")
    t = np.where(np.abs(t - t0) <= max_shift, t, np.nan)
    normals = np.array(normals, float)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    flip = np.einsum("ij,ij->i", normals, dirs) > 0
    normals[flip] *= -1.0
    return t, normals


def _torus_newton(
    c: np.ndarray, a: np.ndarray, big_r: float, small_r: float, dirs: np.ndarray, t0: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Newton on the torus signed distance along each ray, started at the mesh hit t0 (the quartic's root nearest
    t0). Returns NaN where it does not converge to the surface."""
    t = t0.astype(float).copy()
    for _ in range(TORUS_NEWTON_STEPS):
        q = dirs * t[:, None] - c
        w = rows_dot(q, a)
        radial = q - w[:, None] * a
        rho = np.maximum(np.linalg.norm(radial, axis=1), 1e-300)
        tube = q - radial * (big_r / rho)[:, None]  # from the tube's centre circle to the point
        dist = np.maximum(np.linalg.norm(tube, axis=1), 1e-300)
        grad = tube / dist[:, None]
        slope = np.einsum("ij,ij->i", grad, dirs)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = (dist - small_r) / slope
        t = t - np.where(np.abs(slope) > 1e-9, step, np.nan)
    q = dirs * t[:, None] - c
    w = rows_dot(q, a)
    radial = q - w[:, None] * a
    rho = np.maximum(np.linalg.norm(radial, axis=1), 1e-300)
    tube = q - radial * (big_r / rho)[:, None]
    resid = np.abs(np.linalg.norm(tube, axis=1) - small_r)
    t = np.where(resid <= 1e-9 * max(1.0, big_r), t, np.nan)
    return t, tube
