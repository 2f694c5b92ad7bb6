"""RANSAC per instance mask (Schnabel et al. 2007 style): hypotheses from minimal sets of points with normals,
scored by inliers (distance and normal angle), the best one refined by robust least squares.

Minimal sets (camera frame, metres; normals from the depth gradient):
- plane: 1 point + normal.
- cylinder: 2 points + normals: axis = n1 x n2; the axis point is where the two normal lines, projected along the
  axis, meet; radius = mean distance of the two points to it.
- sphere: 2 points + normals: centre = midpoint of the shortest segment between the two normal lines.
- cone: 3 points + normals: apex = the common point of the three tangent planes; axis = normal of the plane through
  the three unit directions apex -> point (oriented towards the points); half angle = their mean angle to the axis.
- torus: 3 points + normals and a minor-radius candidate r (a geometric grid, both sides): the tube centres
  p - r n lie on the major circle, which the three of them define (centre, axis, major radius).
Every hypothesis is scored on a random subset of the instance; the best is refined on its inliers by
`refine_primitive` and its inliers recounted on all points.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from v2c.fit.config import FitConfig
from v2c.primitives import Cone, Cylinder, Plane, Primitive, Sphere, Torus
from v2c.primitives.directions import unit

#: Degrees of freedom of each type (for the complexity penalty of the type search).
TYPE_DOF = {"plane": 3, "sphere": 4, "cylinder": 5, "cone": 6, "torus": 7}
TYPES = tuple(TYPE_DOF)


@dataclass
class RansacFit:
    """Best primitive of one instance; inliers: (n,) bool over the instance's points; score = inlier fraction."""

    primitive: Primitive
    inliers: np.ndarray
    score: float


def inlier_mask(prim: Primitive, x: np.ndarray, n: np.ndarray, eps: float, cos_min: float) -> np.ndarray:
    """Points within ``eps`` metres of ``prim`` whose normal is within acos(cos_min) of the surface's (either
    orientation: concave faces seen from inside have normals facing the axis)."""
    d = np.abs(prim.signed_distance(x))
    c = np.abs(np.sum(prim.normal(x) * n, axis=1))
    return (d < eps) & (c > cos_min)


def _line_closest(p1: np.ndarray, d1: np.ndarray, p2: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points (K, 3) on lines p1 + t d1 and p2 + s d2 (batched over K); NaN where parallel."""
    w = p1 - p2
    a, b, c = np.sum(d1 * d1, 1), np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    d, e = np.sum(d1 * w, 1), np.sum(d2 * w, 1)
    den = a * c - b * b
    ok = den > 1e-12 * a * c
    den = np.where(ok, den, np.nan)
    t, s = (b * e - c * d) / den, (a * e - b * d) / den
    return p1 + t[:, None] * d1, p2 + s[:, None] * d2


def _hyp_planes(x: np.ndarray, n: np.ndarray, idx: np.ndarray) -> list[Primitive]:
    return [Plane(x[i], n[i]) for i in idx[:, 0]]


def _hyp_spheres(x: np.ndarray, n: np.ndarray, idx: np.ndarray, rmax: float) -> list[Primitive]:
    p1, p2, n1, n2 = x[idx[:, 0]], x[idx[:, 1]], n[idx[:, 0]], n[idx[:, 1]]
    q1, q2 = _line_closest(p1, n1, p2, n2)
    c = 0.5 * (q1 + q2)
    r = 0.5 * (np.linalg.norm(p1 - c, axis=1) + np.linalg.norm(p2 - c, axis=1))
    ok = np.isfinite(r) & (r < rmax)
    return [Sphere(c[k], r[k]) for k in np.flatnonzero(ok)]


def _hyp_cylinders(x: np.ndarray, n: np.ndarray, idx: np.ndarray, rmax: float) -> list[Primitive]:
    p1, p2, n1, n2 = x[idx[:, 0]], x[idx[:, 1]], n[idx[:, 0]], n[idx[:, 1]]
    ax = np.cross(n1, n2)
    ok = np.linalg.norm(ax, axis=1) > np.sin(np.deg2rad(3.0))
    a = unit(ax)

    def proj(v: np.ndarray) -> np.ndarray:
        return v - np.sum(v * a, 1)[:, None] * a

    q1, q2 = _line_closest(proj(p1), proj(n1), proj(p2), proj(n2))
    c = 0.5 * (q1 + q2)
    r = 0.5 * (np.linalg.norm(proj(p1) - c, axis=1) + np.linalg.norm(proj(p2) - c, axis=1))
    ok &= np.isfinite(r) & (r < rmax)
    return [Cylinder(c[k], a[k], r[k]) for k in np.flatnonzero(ok)]


def _hyp_cones(x: np.ndarray, n: np.ndarray, idx: np.ndarray, rmax: float, amin: float) -> list[Primitive]:
    p, nn = x[idx], n[idx]  # (K, 3, 3)
    rhs = np.sum(p * nn, axis=2)
    det = np.linalg.det(nn)
    ok = np.abs(det) > 1e-6
    apex = np.full((len(idx), 3), np.nan)
    apex[ok] = np.linalg.solve(nn[ok], rhs[ok][..., None])[..., 0]
    u = unit(p - apex[:, None, :])
    ax = unit(np.cross(u[:, 1] - u[:, 0], u[:, 2] - u[:, 0]))
    sgn = np.sign(np.sum(u @ ax[:, :, None], axis=(1, 2)))
    ax = ax * np.where(sgn == 0, 1.0, sgn)[:, None]
    ang = np.mean(np.arccos(np.clip(np.sum(u * ax[:, None, :], axis=2), -1, 1)), axis=1)
    far = np.linalg.norm(p[:, 0] - apex, axis=1)
    ok &= np.isfinite(ang) & (ang > amin) & (ang < np.pi / 2 - amin) & (far < rmax)
    return [Cone(apex[k], ax[k], ang[k]) for k in np.flatnonzero(ok)]


def _hyp_tori(x: np.ndarray, n: np.ndarray, idx: np.ndarray, rmax: float, extent: float,
              steps: int) -> list[Primitive]:
    radii = extent * np.geomspace(0.02, 0.6, steps)
    out: list[Primitive] = []
    p, nn = x[idx], n[idx]  # (K, 3, 3)
    for sgn in (1.0, -1.0):  # tube centre behind (convex) or in front of (concave) the surface
        for r in radii:
            q = p - sgn * r * nn
            a, b = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
            ab = np.cross(a, b)
            den = 2 * np.sum(ab * ab, axis=1)
            ok = den > 1e-18
            num = np.cross(np.sum(a * a, 1)[:, None] * b - np.sum(b * b, 1)[:, None] * a, ab)
            c = q[:, 0] + num / np.where(ok, den, 1.0)[:, None]
            big_r = np.linalg.norm(q[:, 0] - c, axis=1)
            ok &= (big_r < rmax) & (big_r > 0.2 * r)
            axis = unit(ab)
            # the normals must lie in the planes through the axis (a torus' normal lines cross its axis)
            rad = unit(q - c[:, None, :])
            off = np.abs(np.sum(nn * np.cross(axis[:, None, :], rad), axis=2)).max(axis=1)
            ok &= off < np.sin(np.deg2rad(20.0))
            out += [Torus(c[k], axis[k], big_r[k], r) for k in np.flatnonzero(ok)]
    return out


def hypotheses(ptype: str, x: np.ndarray, n: np.ndarray, scale: float, config: FitConfig,
               rng: np.random.Generator) -> list[Primitive]:
    """Candidate primitives of type ``ptype`` from minimal samples of points ``x`` / normals ``n`` (N, 3)."""
    k = config.ransac_hypotheses
    size = {"plane": 1, "sphere": 2, "cylinder": 2, "cone": 3, "torus": 3}[ptype]
    if len(x) < size:
        return []
    idx = np.stack([rng.choice(len(x), size=size, replace=False) for _ in range(k)])
    rmax = config.max_radius * scale
    if ptype == "plane":
        return _hyp_planes(x, n, idx)
    if ptype == "sphere":
        return _hyp_spheres(x, n, idx, rmax)
    if ptype == "cylinder":
        return _hyp_cylinders(x, n, idx, rmax)
    if ptype == "cone":
        return _hyp_cones(x, n, idx, rmax, np.deg2rad(config.min_half_angle_deg))
    extent = float(np.max(np.ptp(x, axis=0)))
    return _hyp_tori(x, n, idx, rmax, extent, config.torus_radius_steps)


def refine_primitive(prim: Primitive, x: np.ndarray, scale: float, config: FitConfig,
                     axis: np.ndarray | None = None) -> Primitive:
    """Robust least-squares refinement of ``prim`` on points ``x`` (N, 3): point-to-surface distances in part-size
    units, 'trf' with the soft-l1 loss (robust to the few outliers left after the inlier test) and the analytic
    Jacobian of `align.Layout`. The axis moves by two tangent coefficients (supplement's reparameterisation)
    unless fixed by ``axis`` (unit, camera frame)."""
    from v2c.fit.align import Layout, Term, recon_jacobian_blocks, recon_residuals

    if len(x) < prim.local_size + 2:
        return prim
    if axis is not None and prim.axis_vector is not None:
        prim = prim.from_local(np.zeros(prim.local_size), axis)
    mode = None if prim.axis_vector is None else (-2 if axis is not None else -1)
    terms = [Term(prim, x, mode)]
    layout = Layout(terms, np.eye(3))

    def fun(v: np.ndarray) -> np.ndarray:
        return recon_residuals(layout.primitives(v)[1], terms, scale)

    def jac(v: np.ndarray) -> np.ndarray:
        return recon_jacobian_blocks(layout, v, layout.primitives(v)[1], scale)[0][2]

    res = least_squares(fun, np.zeros(layout.size), jac=jac, method="trf", loss=config.loss,
                        f_scale=config.loss_scale, x_scale="jac", max_nfev=config.max_nfev, ftol=config.ftol,
                        xtol=config.ftol)
    out = layout.primitives(res.x)[1][0]
    return out if _plausible(out, scale, config) else prim


def _plausible(prim: Primitive, scale: float, config: FitConfig) -> bool:
    rmax = config.max_radius * scale
    p = prim.params()
    if not np.all(np.isfinite(np.concatenate([np.ravel(v) for v in p.values()]))):
        return False
    if prim.type == "cone":
        amin = np.deg2rad(config.min_half_angle_deg)
        return amin < prim.half_angle < np.pi / 2 - amin  # type: ignore[attr-defined]
    if prim.type == "torus":
        return 0 < prim.minor_radius < rmax and 0 < prim.radius < rmax  # type: ignore[attr-defined]
    if prim.type in ("cylinder", "sphere"):
        return 0 < prim.radius < rmax  # type: ignore[attr-defined]
    return True


def ransac_fit(ptype: str, x: np.ndarray, n: np.ndarray, scale: float, config: FitConfig,
               rng: np.random.Generator) -> RansacFit | None:
    """Best primitive of type ``ptype`` for points ``x`` and normals ``n`` (N, 3, camera frame, metres).

    Inliers lie within d_inlier * scale and normal_angle_deg; the best hypothesis (most inliers on a random subset
    of ransac_points) is refined twice on its inliers (recounted on all points in between). None when no
    hypothesis is valid.
    """
    eps = config.d_inlier * scale
    cos_min = float(np.cos(np.deg2rad(config.normal_angle_deg)))
    sub = rng.choice(len(x), size=min(len(x), config.ransac_points), replace=False)
    xs, ns = x[sub], n[sub]
    hyps = hypotheses(ptype, xs, ns, scale, config, rng)
    if not hyps:
        return None
    # two-stage scoring: every hypothesis on a small subset, the most promising on the whole subset
    pre = slice(0, config.ransac_prescore_points)  # `sub` is a random permutation: its head is a random subset
    counts = np.array([np.count_nonzero(inlier_mask(h, xs[pre], ns[pre], eps, cos_min)) for h in hyps])
    top = np.argsort(-counts, kind="stable")[: config.ransac_keep]
    counts = np.array([np.count_nonzero(inlier_mask(hyps[k], xs, ns, eps, cos_min)) for k in top])
    best = hyps[int(top[int(np.argmax(counts))])]
    for _ in range(2):
        inl = inlier_mask(best, x, n, eps, cos_min)
        if np.count_nonzero(inl) < best.local_size + 2:
            break
        pts = x[inl]
        if len(pts) > config.refine_points:
            pts = pts[rng.choice(len(pts), size=config.refine_points, replace=False)]
        best = refine_primitive(best, pts, scale, config)
    inl = inlier_mask(best, x, n, eps, cos_min)
    return RansacFit(best, inl, float(np.count_nonzero(inl)) / max(len(x), 1))


def fit_instance(x: np.ndarray, n: np.ndarray, ptype: str | None, scale: float, config: FitConfig,
                 rng: np.random.Generator) -> tuple[str, RansacFit | None]:
    """RANSAC with a known type, or (ptype None: missing/weak label) every type, choosing the best inlier fraction
    minus complexity_penalty per parameter beyond a plane's. Returns (type, fit)."""
    if ptype is not None:
        return ptype, ransac_fit(ptype, x, n, scale, config, rng)
    best: tuple[float, str, RansacFit | None] = (-np.inf, "plane", None)
    for t in TYPES:
        f = ransac_fit(t, x, n, scale, config, rng)
        if f is None:
            continue
        s = f.score - config.complexity_penalty * (TYPE_DOF[t] - TYPE_DOF["plane"])
        if s > best[0]:
            best = (s, t, f)
    return best[1], best[2]
