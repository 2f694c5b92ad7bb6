"""RANSAC per instance mask (Schnabel et al. 2007 style): hypotheses from minimal sets of points with normals,
scored by inliers (distance and normal angle; tori by MSAC, below), the best one refined by robust least squares.

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

Tori are scored by MSAC (the sum of squared distances truncated at d_inlier) instead of the inlier count: on a
fillet a few millimetres wide d_inlier exceeds the tube itself and the normals are 20-30 degrees off, so a
loose, tilted, fat torus counts as many inliers as the right one; the truncated squared distance prefers the
tight fit. Normal-free "ring" hypotheses (`_hyp_torus_rings`: the axis line from the circle through three
points, the cross-section from the points' (rho, h) cloud) join the minimal-set ones for the same reason.

Torus bounds (`torus_limits`): a small fillet's tube is a few pixels wide and its cross-section is an arc barely
above the noise, so an unconstrained fit can trade a tilted axis or a giant tube for the same distances (a
1.9 mm fillet came back as r = 11.6 mm, a 2.9 mm one as r = 1116 mm on R = 910 mm). The data do fix the patch's
cross-section *span* (its extent in the torus' own (rho, h) half-plane) and its radial range: the minor radius is
held within `torus_minor_span` times the span and the tube centre circle within the points' radial range widened
by the largest allowed r. Hypotheses outside are dropped, the refinement is bounded, and `torus_ok` lets the joint
solves reject a torus that ran away. Within those bounds a thin tube's cross-section is still a flat valley (a
90-degree arc of a 2 mm tube with 0.3 mm noise is matched as well by a 3.7 mm tube centred further in), so the
local refinement adds a weak prior residual pulling r towards `torus_minor_prior` times the span (a fillet's
quarter arc: r = 0.80 span on every torus of the benchmark sets), weighted `torus_prior_weight` per point, which
decides only where the points cannot; and only for thin tubes (span below `torus_prior_max_span` d_inlier): a
larger cross-section fixes r by itself, and the prior would only bias it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from v2c.geometry.config import RansacConfig
from v2c.geometry.quantiles import median_exact, percentile_values
from v2c.geometry.residuals import Layout, Term, recon_jacobian_blocks, recon_residuals
from v2c.primitives import Cone, Cylinder, Plane, Primitive, Sphere, Torus
from v2c.primitives.base import radial_coords, radial_frame
from v2c.primitives.directions import unit


@dataclass
class RansacFit:
    """Best primitive of one instance; inliers: (n,) bool over the instance's points; score = inlier fraction."""

    primitive: Primitive
    inliers: np.ndarray
    score: float


def inlier_mask(prim: Primitive, x: np.ndarray, n: np.ndarray, eps: float, cos_min: float) -> np.ndarray:
    """Points within ``eps`` metres of ``prim`` whose normal is within acos(cos_min) of the surface's (either
    orientation: concave faces seen from inside have normals facing the axis)."""
    dist, nrm = prim.distance_and_normal(x)
    d = np.abs(dist)
    c = np.abs(np.sum(nrm * n, axis=1))
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


def _hyp_cylinders(x: np.ndarray, n: np.ndarray, idx: np.ndarray, rmax: float, min_sin: float) -> list[Primitive]:
    p1, p2, n1, n2 = x[idx[:, 0]], x[idx[:, 1]], n[idx[:, 0]], n[idx[:, 1]]
    ax = np.cross(n1, n2)
    ok = np.linalg.norm(ax, axis=1) > min_sin  # near-parallel normals give no axis
    a = unit(ax)

    def proj(v: np.ndarray) -> np.ndarray:
        return v - np.sum(v * a, 1)[:, None] * a

    q1, q2 = _line_closest(proj(p1), proj(n1), proj(p2), proj(n2))
    c = 0.5 * (q1 + q2)
    r = 0.5 * (np.linalg.norm(proj(p1) - c, axis=1) + np.linalg.norm(proj(p2) - c, axis=1))
    ok &= np.isfinite(r) & (r < rmax)
    return [Cylinder(c[k], a[k], r[k]) for k in np.flatnonzero(ok)]


def _hyp_cones(
    x: np.ndarray, n: np.ndarray, idx: np.ndarray, rmax: float, amin: float, min_sin: float
) -> list[Primitive]:
    p, nn = x[idx], n[idx]  # (K, 3, 3)
    rhs = np.sum(p * nn, axis=2)
    det = np.linalg.det(nn)
    ok = np.abs(det) > min_sin**3  # three near-coplanar normals give no apex
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


def _hyp_tori(
    x: np.ndarray, n: np.ndarray, idx: np.ndarray, rmax: float, extent: float, config: RansacConfig
) -> list[Primitive]:
    radii = extent * np.geomspace(*config.torus_minor_range, config.torus_radius_steps)
    max_off = np.sin(np.deg2rad(config.torus_normal_axis_deg))
    out: list[Primitive] = []
    p, nn = x[idx], n[idx]  # (K, 3, 3)
    for sgn in (1.0, -1.0):  # tube centre behind (convex) or in front of (concave) the surface
        for r in radii:
            q = p - sgn * r * nn
            c, axis, ok = _circumcircles(q)
            big_r = np.linalg.norm(q[:, 0] - c, axis=1)
            ok &= (big_r < rmax) & (big_r > config.torus_min_ratio * r)
            # the normals must lie in the planes through the axis (a torus' normal lines cross its axis)
            rad = unit(q - c[:, None, :])
            off = np.abs(np.sum(nn * np.cross(axis[:, None, :], rad), axis=2)).max(axis=1)
            ok &= off < max_off
            out += [Torus(c[k], axis[k], big_r[k], r) for k in np.flatnonzero(ok)]
    return out


def _circumcircles(p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Circles through point triples (K, 3, 3): centres (K, 3), unit plane normals (K, 3), and a mask of the
    non-degenerate (not collinear) triples; centres of degenerate triples are not meaningful."""
    a, b = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    ab = np.cross(a, b)
    den = 2 * np.sum(ab * ab, axis=1)
    ok = den > 1e-18
    num = np.cross(np.sum(a * a, 1)[:, None] * b - np.sum(b * b, 1)[:, None] * a, ab)
    return p[:, 0] + num / np.where(ok, den, 1.0)[:, None], unit(ab), ok


def circle_2d(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Algebraic (Kasa) circle fit of 2D points (N, 2): centre (2,), radius."""
    a = np.column_stack([2 * p, np.ones(len(p))])
    sol = np.linalg.lstsq(a, np.sum(p * p, axis=1), rcond=None)[0]
    return sol[:2], float(np.sqrt(max(sol[2] + sol[:2] @ sol[:2], 0.0)))


def torus_from_axis_line(c: np.ndarray, a: np.ndarray, x: np.ndarray, config: RansacConfig) -> Torus | None:
    """Torus with axis line (point ``c``, unit direction ``a``) whose tube cross-section is the circle fitted to
    the points' (rho, h) cloud, its radius held within `torus_limits` (the circle then keeps its direction from
    the cloud's median point); None where degenerate."""
    h, rho, _ = radial_frame(x - c, a)
    m = np.stack([rho, h], axis=1)
    cc, r = circle_2d(m)
    if not np.isfinite(r) or r <= 0:
        return None
    r_lo, r_hi, _, _ = torus_limits(Torus(c, a, 1.0, 1.0), x, config)
    if not r_lo <= r <= r_hi:
        med = np.median(m, axis=0)
        r = float(np.clip(r, r_lo, r_hi))
        cc = med + r * unit(cc - med)
    if not cc[0] > 0:
        return None
    return Torus(c + cc[1] * a, a, float(cc[0]), r)


def _hyp_torus_rings(x: np.ndarray, idx: np.ndarray, m: int, config: RansacConfig) -> list[Primitive]:
    """Normal-free torus hypotheses for thin tubes (a small fillet's normals are tens of degrees off): the circle
    through three sample points gives the axis line (its centre and normal), the first ``m`` points' (rho, h)
    cloud the tube's cross-section; plus one from the whole patch (best-fit plane normal as the axis, circle
    fitted in that plane)."""
    c, axes, ok = _circumcircles(x[idx])
    y = x[:m]
    lines = [(c[k], axes[k]) for k in np.flatnonzero(ok)]
    if len(x) >= 6:
        mu = x.mean(axis=0)
        a = np.linalg.eigh((x - mu).T @ (x - mu))[1][:, 0]
        t1 = unit(np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0]))
        t2 = np.cross(a, t1)
        c2, _ = circle_2d(np.stack([(x - mu) @ t1, (x - mu) @ t2], axis=1))
        lines.append((mu + c2[0] * t1 + c2[1] * t2, a))
    out: list[Primitive] = []
    for cl, al in lines:
        t = torus_from_axis_line(cl, al, y, config)
        if t is not None:
            out.append(t)
    return out


def torus_limits(prim: Torus, x: np.ndarray, config: RansacConfig) -> tuple[float, float, float, float]:
    """(r_lo, r_hi, R_lo, R_hi) (metres) for a torus with ``prim``'s centre and axis on points ``x`` (N, 3): the
    minor radius within config.torus_minor_span times the cross-section span (the robust extent of the points'
    (rho, h) cloud along its principal direction), the major radius within the points' radial range widened by
    r_hi (the tube centre circle lies within r of every surface point), and above torus_min_ratio * r_lo."""
    if len(x) < 3:  # nothing to measure: no bounds
        return 0.0, np.inf, 1e-6, np.inf
    h, rho = radial_coords(np.asarray(x, float) - prim.origin, prim.axis)
    m = np.stack([rho, h], axis=1)
    m = m - np.array([median_exact(rho), median_exact(h)])  # np.median(m, axis=0), without its overhead
    u = np.linalg.eigh(m.T @ m)[1][:, -1]
    q = config.torus_span_pct
    lo, hi = percentile_values(m @ u, [q, 100 - q])  # np.percentile's values (geometry.quantiles)
    span = max(float(hi - lo), 1e-5)
    r_lo, r_hi = config.torus_minor_span[0] * span, config.torus_minor_span[1] * span
    rho_lo, rho_hi = percentile_values(rho, [q, 100 - q])
    big_lo = max(float(rho_lo) - r_hi, config.torus_min_ratio * r_lo, 1e-6)
    return r_lo, r_hi, big_lo, max(float(rho_hi) + r_hi, big_lo * (1 + 1e-6))


def torus_ok(prim: Primitive, x: np.ndarray, config: RansacConfig, slack: float = 1.0) -> bool:
    """True unless ``prim`` is a torus outside `torus_limits` on its points ``x`` (``slack`` >= 1 widens them)."""
    if not isinstance(prim, Torus) or len(x) < 3:
        return True
    r_lo, r_hi, big_lo, big_hi = torus_limits(prim, x, config)
    return (
        r_lo / slack <= prim.minor_radius <= r_hi * slack
        and big_lo / slack <= prim.radius <= big_hi * slack
        and prim.radius > config.torus_min_ratio * prim.minor_radius / slack
        and prim.radius > 0
    )


def cone_ok(prim: Primitive, x: np.ndarray, scale: float, config: RansacConfig) -> bool:
    """True unless ``prim`` is a cone whose radius at its points ``x`` (median over them) is not within
    (0, max_radius * scale): a near-cylinder cone's apex is far away, and an unbounded solve can trade its half
    angle against the apex distance until the surface is a wide, almost flat funnel through the points."""
    if not isinstance(prim, Cone) or len(x) == 0:
        return True
    rho = float(np.median(((x - prim.origin) @ prim.axis) * np.tan(prim.half_angle)))
    return 0 < rho < config.max_radius * scale


def torus_msac(prim: Torus, x: np.ndarray, scale: float, config: RansacConfig) -> float:
    """Comparable score of torus candidates on the same points ``x`` (lower is better): the truncated squared
    distance (MSAC, in part-size units) plus the refinement's weak prior on the minor radius."""
    eps = config.d_inlier * scale
    dist = np.abs(prim.signed_distance(x))
    d = np.minimum(dist, eps) / scale
    near = x[dist < eps]
    r_lo = torus_limits(prim, near if len(near) >= 3 else x, config)[0]
    span = r_lo / config.torus_minor_span[0]
    cost = float(np.sum(d * d))
    if span < config.torus_prior_max_span * eps:  # a thin tube only (module docstring)
        prior = config.torus_prior_weight * (prim.minor_radius - config.torus_minor_prior * span) / scale
        cost += len(x) * prior**2
    return cost


def clamp_torus(prim: Torus, x: np.ndarray, config: RansacConfig) -> Torus:
    """``prim`` with its radii clamped into `torus_limits` on ``x`` (slightly inside the bounds)."""
    r_lo, r_hi, big_lo, big_hi = torus_limits(prim, x, config)
    if not np.isfinite(r_hi + big_hi):  # too few points to bound anything
        return prim
    r = float(np.clip(prim.minor_radius, r_lo * 1.001, r_hi * 0.999))
    big = float(np.clip(prim.radius, big_lo + 1e-3 * (big_hi - big_lo), big_hi - 1e-3 * (big_hi - big_lo)))
    return Torus(prim.origin, prim.axis, big, r)


def hypotheses(
    ptype: str, x: np.ndarray, n: np.ndarray, scale: float, config: RansacConfig, rng: np.random.Generator
) -> list[Primitive]:
    """Candidate primitives of type ``ptype`` from minimal samples of points ``x`` / normals ``n`` (N, 3)."""
    k = config.ransac_hypotheses
    size = {"plane": 1, "sphere": 2, "cylinder": 2, "cone": 3, "torus": 3}[ptype]
    if len(x) < size:
        return []
    idx = np.stack([rng.choice(len(x), size=size, replace=False) for _ in range(k)])
    rmax = config.max_radius * scale
    min_sin = float(np.sin(np.deg2rad(config.min_normal_angle_deg)))
    if ptype == "plane":
        return _hyp_planes(x, n, idx)
    if ptype == "sphere":
        return _hyp_spheres(x, n, idx, rmax)
    if ptype == "cylinder":
        return _hyp_cylinders(x, n, idx, rmax, min_sin)
    if ptype == "cone":
        return _hyp_cones(x, n, idx, rmax, np.deg2rad(config.min_half_angle_deg), min_sin)
    extent = float(np.max(np.ptp(x, axis=0)))
    rings = _hyp_torus_rings(x, idx, config.ransac_prescore_points, config)
    return _hyp_tori(x, n, idx, rmax, extent, config) + [t for t in rings if plausible(t, scale, config)]


def refine_primitive(
    prim: Primitive, x: np.ndarray, scale: float, config: RansacConfig, axis: np.ndarray | None = None
) -> Primitive:
    """Robust least-squares refinement of ``prim`` on points ``x`` (N, 3): point-to-surface distances in part-size
    units, 'trf' with the soft-l1 loss (robust to the few outliers left after the inlier test) and the analytic
    Jacobian of `residuals.Layout`. The axis moves by two tangent coefficients (supplement's reparameterisation)
    unless fixed by ``axis`` (unit, camera frame)."""
    if len(x) < prim.local_size + 2:
        return prim
    if axis is not None and prim.axis_vector is not None:
        prim = prim.from_local(np.zeros(prim.local_size), axis)
    mode = None if prim.axis_vector is None else (-2 if axis is not None else -1)
    lb = np.full(prim.local_size + (2 if mode == -1 else 0), -np.inf)
    ub = -lb
    prior = np.zeros((0, 2))  # rows (parameter index, target value) of weak priors (tori only)
    if isinstance(prim, Torus):  # radii bounded by the data, a weak prior on the minor radius (module docstring)
        prim = clamp_torus(prim, x, config)
        r_lo, r_hi, big_lo, big_hi = torus_limits(prim, x, config)
        lb[3], ub[3] = big_lo - prim.radius, big_hi - prim.radius
        lb[4], ub[4] = r_lo - prim.minor_radius, r_hi - prim.minor_radius
        span = r_lo / config.torus_minor_span[0]
        if config.torus_prior_weight > 0 and span < config.torus_prior_max_span * config.d_inlier * scale:
            prior = np.array([[4, config.torus_minor_prior * span - prim.minor_radius]])
    terms = [Term(prim, x, mode)]
    layout = Layout(terms, np.eye(3))
    w_prior = config.torus_prior_weight * np.sqrt(len(x)) / scale
    last: list = [None, None]  # (parameters, their primitives): the solver asks for jac at the fun's last point

    def prims_at(v: np.ndarray) -> list[Primitive]:
        key = v.tobytes()
        if last[0] != key:
            last[:] = [key, layout.primitives(v)[1]]
        return last[1]

    def fun(v: np.ndarray) -> np.ndarray:
        r = recon_residuals(prims_at(v), terms, scale)
        if len(prior):
            r = np.concatenate([r, w_prior * (v[prior[:, 0].astype(int)] - prior[:, 1])])
        return r

    def jac(v: np.ndarray) -> np.ndarray:
        j = recon_jacobian_blocks(layout, v, prims_at(v), scale)[0][2]
        if len(prior):
            jp = np.zeros((len(prior), layout.size))
            jp[np.arange(len(prior)), prior[:, 0].astype(int)] = w_prior
            j = np.vstack([j, jp])
        return j

    res = least_squares(
        fun,
        np.zeros(layout.size),
        jac=jac,
        method="trf",
        loss=config.loss,
        f_scale=config.loss_scale,
        x_scale="jac",
        max_nfev=config.max_nfev,
        ftol=config.ftol,
        xtol=config.ftol,
        bounds=(lb, ub),
    )
    out = layout.primitives(res.x)[1][0]
    # a free torus axis moves the (rho, h) half-plane its bounds were measured in: re-check with some slack
    return out if plausible(out, scale, config) and torus_ok(out, x, config, 1.2) else prim


def plausible(prim: Primitive, scale: float, config: RansacConfig) -> bool:
    """Finite parameters, radii in (0, max_radius * scale), cone half angle within its limits."""
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


def ransac_fit(
    ptype: str, x: np.ndarray, n: np.ndarray, scale: float, config: RansacConfig, rng: np.random.Generator
) -> RansacFit | None:
    """Best primitive of type ``ptype`` for points ``x`` and normals ``n`` (N, 3, camera frame, metres).

    Inliers lie within d_inlier * scale and normal_angle_deg; the best hypothesis (most inliers on a random subset
    of ransac_points) is refined twice on its inliers (recounted on all points in between). None when no
    hypothesis is valid.
    """
    eps = config.d_inlier * scale
    cos_min = float(np.cos(np.deg2rad(config.normal_angle_deg)))
    sub = rng.choice(len(x), size=min(len(x), config.ransac_points), replace=False)
    xs, ns = x[sub], n[sub]
    # degenerate hypotheses (a zero normal where the normal estimate had no neighbours, NaN from a division) are
    # dropped where they arise, before they are scored or refined
    hyps = [h for h in hypotheses(ptype, xs, ns, scale, config, rng) if h.is_finite(axis_tol=0.5)]
    if not hyps:
        return None
    # two-stage scoring: every hypothesis on a small subset, the most promising on the whole subset
    pre = slice(0, config.ransac_prescore_points)  # `sub` is a random permutation: its head is a random subset
    if ptype == "torus":  # radii consistent with the patch (module docstring); else the nearest such radii
        ok = [h for h in hyps if torus_ok(h, xs[pre], config)]
        hyps = ok or [clamp_torus(h, xs[pre], config) for h in hyps]  # type: ignore[arg-type]
    if ptype == "torus":  # MSAC: the truncated squared distance, with the refinement's prior (module docstring)

        def score(h: Primitive, xq: np.ndarray, nq: np.ndarray) -> float:
            return -torus_msac(h, xq, scale, config)  # type: ignore[arg-type]
    else:

        def score(h: Primitive, xq: np.ndarray, nq: np.ndarray) -> float:
            return float(np.count_nonzero(inlier_mask(h, xq, nq, eps, cos_min)))

    counts = np.array([score(h, xs[pre], ns[pre]) for h in hyps])
    top = np.argsort(-counts, kind="stable")[: config.ransac_keep]
    counts = np.array([score(hyps[k], xs, ns) for k in top])
    best = hyps[int(top[int(np.argmax(counts))])]
    cos_refine = -1.0 if ptype == "torus" else cos_min  # a thin tube's normals are too poor to select points
    for _ in range(2):
        inl = inlier_mask(best, x, n, eps, cos_refine)
        if np.count_nonzero(inl) < best.local_size + 2:
            break
        pts = x[inl]
        if len(pts) > config.refine_points:
            pts = pts[rng.choice(len(pts), size=config.refine_points, replace=False)]
        refined = refine_primitive(best, pts, scale, config)
        if not refined.is_finite(axis_tol=0.5):
            break  # a refinement that degenerates keeps the hypothesis it started from
        best = refined
    inl = inlier_mask(best, x, n, eps, cos_min)
    return RansacFit(best, inl, float(np.count_nonzero(inl)) / max(len(x), 1))
