"""Lifting image points to 3D on the fitted surfaces (camera frame, metres).

- `lift_pixels`: pixels -> points on one sheet of a surface along their rays.
- `project_to_intersection`: points -> the nearest points on the intersection curve of two surfaces (Gauss-Newton,
  minimal-norm steps on the two signed distances), vectorised.
- `solve_vertex`: one vertex from three equations (corner: three surfaces; intersection-visibility: two surfaces and
  the curved one's normal orthogonal to the view ray), Gauss-Newton with a numeric Jacobian.
- `intersection_curve`: the analytic curve dict of an intersection edge (line, circle, or general).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from v2c.primitives.base import Primitive
from v2c.vbrep.raycast import intersect, pixel_rays, project, sheet_depth


def lift_pixels(prim: Primitive, sheet: int, uv: np.ndarray, K: np.ndarray, window: tuple[float, float],
                prior: np.ndarray | None = None) -> np.ndarray:
    """(N, 2) pixels -> (N, 3) camera-frame points on sheet ``sheet`` of ``prim`` (closest approach where the
    ray misses the surface)."""
    rays = pixel_rays(uv, K)
    if len(rays) == 0:
        return np.zeros((0, 3))
    z = sheet_depth(intersect(prim, rays, window), sheet, prior)
    return rays * z[:, None]


def project_to_intersection(pa: Primitive, pb: Primitive, x0: np.ndarray, iters: int = 8,
                            K: np.ndarray | None = None, max_px: float | None = None) -> np.ndarray:
    """(N, 3) start points -> (N, 3) points on both surfaces (camera frame, metres), by minimal-norm Gauss-Newton
    steps on (sd_a, sd_b). Where the surfaces are tangent the step is damped and the point stays near both.
    With K and max_px: a point whose projection moved more than max_px pixels (an ill-conditioned, nearly
    tangent pair) keeps its start position."""
    x = np.asarray(x0, float).reshape(-1, 3).copy()
    if len(x) == 0:
        return x
    start = x.copy()
    for _ in range(iters):
        f = np.stack([pa.signed_distance(x), pb.signed_distance(x)], 1)  # (N, 2)
        J = np.stack([pa.normal(x), pb.normal(x)], 1)  # (N, 2, 3)
        JJ = J @ J.transpose(0, 2, 1) + 1e-6 * np.eye(2)
        lam = np.linalg.solve(JJ, f[:, :, None])  # (N, 2, 1)
        x -= (J.transpose(0, 2, 1) @ lam)[:, :, 0]
    bad = ~np.all(np.isfinite(x), axis=1)
    if K is not None and max_px is not None:
        bad |= np.linalg.norm(project(x, K) - project(start, K), axis=1) > max_px
    x[bad] = start[bad]
    return x


def surfaces_meet(pa: Primitive, pb: Primitive, x0: np.ndarray, tol: float, iters: int = 20,
                  eps: float = 1e-7) -> tuple[np.ndarray, np.ndarray]:
    """Whether the two surfaces meet near each start point (N, 3) (camera frame, metres): the Gauss-Newton
    projection onto both (`project_to_intersection`, unrestricted) ends within ``eps`` metres of both surfaces
    and within ``tol`` metres of its start. Returns (N,) bool and the projected points (N, 3)."""
    x0 = np.asarray(x0, float).reshape(-1, 3)
    x = project_to_intersection(pa, pb, x0, iters)
    res = np.maximum(np.abs(pa.signed_distance(x)), np.abs(pb.signed_distance(x))) if len(x) else np.zeros(0)
    ok = np.all(np.isfinite(x), axis=1) & (res <= eps) & (np.linalg.norm(x - x0, axis=1) <= tol)
    return ok, x


def visibility_residual(prim: Primitive) -> Callable[[np.ndarray], np.ndarray]:
    """g(x) = n(x) . x / |x|: zero where the surface normal is orthogonal to the view ray (camera at origin)."""

    def g(x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, float).reshape(-1, 3)
        return np.einsum("ij,ij->i", prim.normal(x), x) / np.linalg.norm(x, axis=1)

    return g


def solve_vertex(funcs: list[Callable[[np.ndarray], np.ndarray]], x0: np.ndarray, iters: int = 12,
                 h: float = 1e-6) -> tuple[np.ndarray, float]:
    """Solve f_k(x) = 0 (k = 1..3) for one point x (3,) from x0 by damped Gauss-Newton with a central-difference
    Jacobian (step ``h`` metres). Returns the point and the final max |f_k| (units of the f_k)."""
    x = np.asarray(x0, float).copy()
    eye = np.eye(3) * h

    def F(p: np.ndarray) -> np.ndarray:
        return np.array([float(f(p[None])[0]) for f in funcs])

    for _ in range(iters):
        f = F(x)
        pts = np.concatenate([x + eye, x - eye])
        J = np.stack([(fn(pts[:3]) - fn(pts[3:])) / (2 * h) for fn in funcs])  # (m, 3)
        step = np.linalg.lstsq(J.T @ J + 1e-9 * np.eye(3), J.T @ f, rcond=None)[0]
        x = x - step
        if np.linalg.norm(step) < 1e-9:
            break
    return x, float(np.max(np.abs(F(x))))


def sd_func(prim: Primitive) -> Callable[[np.ndarray], np.ndarray]:
    return lambda x: prim.signed_distance(np.asarray(x, float).reshape(-1, 3))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def intersection_curve(pa: Primitive, pb: Primitive, polyline: np.ndarray, perpendicular_deg: float = 1.0,
                       parallel_deg: float = 1.0) -> dict:
    """Analytic curve of the intersection edge of two surfaces, oriented along ``polyline`` (K, 3) (camera frame,
    metres): plane-plane -> line; plane with a cylinder/cone/torus whose axis is perpendicular to the plane, or a
    plane and a sphere -> circle; anything else -> {"kind": "intersection"} (the polyline samples it)."""
    ta, tb = pa.type, pb.type
    if ta != "plane" and tb == "plane":
        pa, pb, ta, tb = pb, pa, tb, ta
    cos_perp = np.cos(np.deg2rad(perpendicular_deg))
    if ta == "plane" and tb == "plane":
        na, nb = pa.axis_vector, pb.axis_vector
        cross = np.cross(na, nb)
        if np.linalg.norm(cross) > np.sin(np.deg2rad(parallel_deg)):
            d = _unit(cross)
            if len(polyline) >= 2 and d @ (polyline[-1] - polyline[0]) < 0:
                d = -d
            # the point of the line nearest the polyline's first point
            A = np.stack([na, nb, d])
            rhs = np.array([na @ pa.origin, nb @ pb.origin, d @ polyline[0]])
            o = np.linalg.solve(A, rhs)
            return {"kind": "line", "origin": o, "direction": d}
    elif ta == "plane" and tb in ("cylinder", "cone", "torus", "sphere"):
        n, o_p = pa.axis_vector, pa.origin
        c = np.asarray(pb.origin, float)
        if tb == "sphere":
            dist = float(n @ (c - o_p))
            r2 = pb.radius**2 - dist**2
            if r2 > 0:
                return {"kind": "circle", "center": c - dist * n, "axis": n.copy(), "radius": float(np.sqrt(r2))}
        else:
            a = pb.axis_vector
            if abs(a @ n) >= cos_perp:
                t = float(n @ (o_p - c)) / float(n @ a)
                center = c + t * a
                if tb == "cylinder":
                    radius = pb.radius
                elif tb == "cone":
                    radius = abs(t) * np.tan(pb.half_angle)
                else:  # torus: the circle nearest the polyline
                    rho = np.linalg.norm((polyline - center) - np.outer((polyline - center) @ a, a), axis=1)
                    radius = float(np.median(rho))
                return {"kind": "circle", "center": center, "axis": a.copy(), "radius": float(radius)}
    return {"kind": "intersection"}
