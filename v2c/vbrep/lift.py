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

from v2c.camera import pixel_rays, project
from v2c.primitives.base import Primitive
from v2c.vbrep.raycast import intersect, sheet_depth

#: metres: the central-difference step of numeric Jacobians (far below any tolerance, far above rounding at 1 m)
FD_STEP_M = 1e-6


def lift_pixels(
    prim: Primitive,
    sheet: int,
    uv: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    prior: np.ndarray | None = None,
) -> np.ndarray:
    """(N, 2) pixels -> (N, 3) camera-frame points on sheet ``sheet`` of ``prim`` (closest approach where the
    ray misses the surface)."""
    rays = pixel_rays(uv, K)
    if len(rays) == 0:
        return np.zeros((0, 3))
    z = sheet_depth(intersect(prim, rays, window), sheet, prior)
    return rays * z[:, None]


def project_to_intersection(
    pa: Primitive, pb: Primitive, x0: np.ndarray, iters: int, K: np.ndarray | None = None, max_px: float | None = None
) -> np.ndarray:
    """(N, 3) start points -> (N, 3) points on both surfaces (camera frame, metres), by minimal-norm Gauss-Newton
    steps on (sd_a, sd_b). Where the surfaces are tangent the step is damped and the point stays near both.
    With K and max_px: a point whose projection moved more than max_px pixels (an ill-conditioned, nearly
    tangent pair) keeps its start position."""
    x = np.asarray(x0, float).reshape(-1, 3).copy()
    if len(x) == 0:
        return x
    start = x.copy()
    for _ in range(iters):
        (da, na), (db, nb) = pa.distance_and_normal(x), pb.distance_and_normal(x)
        f = np.stack([da, db], 1)  # (N, 2)
        J = np.stack([na, nb], 1)  # (N, 2, 3)
        JJ = J @ J.transpose(0, 2, 1) + 1e-6 * np.eye(2)
        lam = np.linalg.solve(JJ, f[:, :, None])  # (N, 2, 1)
        x -= (J.transpose(0, 2, 1) @ lam)[:, :, 0]
    bad = ~np.all(np.isfinite(x), axis=1)
    if K is not None and max_px is not None:
        bad |= np.linalg.norm(project(x, K) - project(start, K), axis=1) > max_px
    x[bad] = start[bad]
    return x


def surfaces_meet(
    pa: Primitive, pb: Primitive, x0: np.ndarray, tol: float, iters: int, eps: float
) -> tuple[np.ndarray, np.ndarray]:
    """Whether the two surfaces meet near each start point (N, 3) (camera frame, metres): the Gauss-Newton
    projection onto both (`project_to_intersection`, unrestricted, ``iters`` steps) ends within ``eps`` metres of
    both surfaces and within ``tol`` metres of its start. Returns (N,) bool and the projected points (N, 3)."""
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


def solve_vertex(
    funcs: list[Callable[[np.ndarray], np.ndarray]], x0: np.ndarray, iters: int
) -> tuple[np.ndarray, float]:
    """Solve f_k(x) = 0 (k = 1..3) for one point x (3,) from x0 by damped Gauss-Newton with a central-difference
    Jacobian (step `FD_STEP_M`), at most ``iters`` steps. Returns the point and the final max |f_k| (units of the
    f_k)."""
    h = FD_STEP_M
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
    """f(x) = signed distance (metres) of points x (N, 3 or 3,) to ``prim``: a residual for `solve_vertex`."""
    return lambda x: prim.signed_distance(np.asarray(x, float).reshape(-1, 3))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def intersection_curve(
    pa: Primitive, pb: Primitive, polyline: np.ndarray, perpendicular_deg: float, parallel_deg: float
) -> dict:
    """Analytic curve of the intersection edge of two surfaces, oriented along ``polyline`` (K, 3) (camera frame,
    metres): plane-plane -> line; plane with a cylinder/cone/torus whose axis is perpendicular to the plane, or a
    plane and a sphere -> circle; anything else -> {"kind": "intersection"} (the polyline samples it). Axes within
    ``perpendicular_deg`` of the plane's normal count as perpendicular; plane normals within ``parallel_deg`` as
    parallel (no line)."""
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


def normals_angle_deg(pa: Primitive, pb: Primitive, x: np.ndarray) -> np.ndarray:
    """(N,) angle in degrees between the two surfaces' normal lines at the points nearest ``x`` (N, 3) on each
    (0: the surfaces are tangent there; sign-free, so a concave blend counts as a convex one)."""
    x = np.asarray(x, float).reshape(-1, 3)
    c = np.abs(np.einsum("ij,ij->i", pa.normal(x), pb.normal(x)))
    return np.degrees(np.arccos(np.clip(c, 0.0, 1.0)))


def contact_points(pa: Primitive, pb: Primitive, x0: np.ndarray, iters: int) -> tuple[np.ndarray, np.ndarray]:
    """Points of contact of two (nearly) tangent surfaces near ``x0`` (N, 3), camera frame, metres: the midpoint of
    each point's closest points on both, iterated ``iters`` times (alternating projection, which converges to where
    the surfaces touch, or to the middle of their closest approach where a small gap or overlap is left).
    Intersection solves wander along the normal there: the surfaces barely cross. Returns the points and the gap
    between the two surfaces at each (metres)."""
    x = np.asarray(x0, float).reshape(-1, 3).copy()
    if len(x) == 0:
        return x, np.zeros(0)
    for _ in range(iters):
        qa, qb = pa.closest_point(x), pb.closest_point(x)
        x = 0.5 * (qa + qb)
    gap = np.linalg.norm(pa.closest_point(x) - pb.closest_point(x), axis=1)
    bad = ~np.all(np.isfinite(x), axis=1)
    x[bad] = np.asarray(x0, float).reshape(-1, 3)[bad]
    gap[bad] = np.inf
    return x, gap


def _circle_about(o: np.ndarray, d: np.ndarray, h: float, radius: float) -> dict:
    return {"kind": "circle", "center": o + h * d, "axis": d.copy(), "radius": float(radius)}


def tangent_curve(pa: Primitive, pb: Primitive, pts: np.ndarray, parallel_deg: float) -> dict:
    """Analytic line of contact of a tangent (G1) junction, from the two surfaces' parameters (camera frame,
    metres); ``pts`` (K, 3), samples along the junction, only orient it and pick the branch. Where the two fitted
    surfaces do not touch exactly, the curve lies between them. Axes and normals within ``parallel_deg`` count as
    parallel.

    - plane and cylinder with its axis parallel to the plane (a fillet): the line under the axis, on the plane;
    - plane normal to the axis of a torus (a rounded edge of a disc): the torus' major circle, on the plane;
    - plane and cone whose normal makes the cone's half angle's complement with its axis (a flat face run
      tangentially into a conical corner): the ruling from the apex along the axis' projection on the plane,
      halfway between the apex and the plane;
    - sphere on the axis of a cylinder (a dome): the circle about the axis at the sphere's centre, radius the
      mean of both radii; torus and cylinder on one axis (a shoulder fillet): the circle at the torus' centre;
    - anything else: ``{"kind": "intersection"}`` (the polyline samples the contact, `contact_points`).

    Every curve dict carries ``"tangent": True``."""
    pts = np.asarray(pts, float).reshape(-1, 3)
    sin_par = np.sin(np.deg2rad(parallel_deg))
    order = {"plane": 0, "cylinder": 1, "cone": 2, "sphere": 3, "torus": 4}
    if order.get(pa.type, 9) > order.get(pb.type, 9):
        pa, pb = pb, pa
    ta, tb = pa.type, pb.type
    out: dict = {"kind": "intersection"}

    def on_axis(c: np.ndarray, o: np.ndarray, d: np.ndarray) -> bool:
        off = (c - o) - ((c - o) @ d) * d
        return float(np.linalg.norm(off)) <= sin_par * max(float(np.linalg.norm(c - o)), 1e-9) + 1e-6

    if ta == "plane" and tb == "cylinder" and len(pts):
        n, a = pa.axis_vector, pb.axis_vector
        if abs(n @ a) <= sin_par:
            o = np.asarray(pb.origin, float)
            dist = float(n @ (o - pa.origin))
            side = np.sign(dist) or 1.0
            # halfway between the plane and the cylinder's nearest line (they touch when |dist| = radius)
            foot = o - side * 0.5 * (abs(dist) + pb.radius) * n
            d = a if len(pts) < 2 or a @ (pts[-1] - pts[0]) >= 0 else -a
            foot = foot + ((pts[0] - foot) @ d) * d
            out = {"kind": "line", "origin": foot, "direction": d.copy()}
    elif ta == "plane" and tb == "cone" and len(pts):
        n, a, apex = pa.axis_vector, pb.axis_vector, np.asarray(pb.origin, float)
        if abs(abs(n @ a) - np.sin(pb.half_angle)) <= sin_par:
            r = a - (a @ n) * n
            if np.linalg.norm(r) > 1e-9:
                r = r / np.linalg.norm(r)
                d = r if len(pts) < 2 or r @ (pts[-1] - pts[0]) >= 0 else -r
                out = {"kind": "line", "origin": apex - 0.5 * float(n @ (apex - pa.origin)) * n, "direction": d}
    elif ta == "plane" and tb == "torus":
        n, a, c = pa.axis_vector, pb.axis_vector, np.asarray(pb.origin, float)
        if np.linalg.norm(np.cross(n, a)) <= sin_par:
            h = float(a @ (pa.origin - c))
            out = _circle_about(c, a, h, pb.radius)
    elif ta == "cylinder" and tb == "sphere":
        o, a, c = np.asarray(pa.origin, float), pa.axis_vector, np.asarray(pb.origin, float)
        if on_axis(c, o, a):
            out = _circle_about(o, a, float((c - o) @ a), 0.5 * (pa.radius + pb.radius))
    elif ta == "cylinder" and tb == "torus":
        o, a, c = np.asarray(pa.origin, float), pa.axis_vector, np.asarray(pb.origin, float)
        if np.linalg.norm(np.cross(a, pb.axis_vector)) <= sin_par and on_axis(c, o, a):
            out = _circle_about(o, a, float((c - o) @ a), pa.radius)
    out["tangent"] = True
    return out


def points_on_curve(curve: dict, x: np.ndarray) -> np.ndarray | None:
    """(N, 3) points projected onto an analytic line or circle dict (camera frame, metres); None for another
    kind."""
    x = np.asarray(x, float).reshape(-1, 3)
    if curve.get("kind") == "line":
        o, d = np.asarray(curve["origin"], float), np.asarray(curve["direction"], float)
        return o + np.outer((x - o) @ d, d)
    if curve.get("kind") == "circle":
        c, a, r = np.asarray(curve["center"], float), np.asarray(curve["axis"], float), float(curve["radius"])
        v = (x - c) - np.outer((x - c) @ a, a)
        nv = np.linalg.norm(v, axis=1, keepdims=True)
        return c + r * v / np.where(nv > 0, nv, 1.0)
    return None
