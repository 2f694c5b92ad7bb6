"""Fits with a known axis direction (the shared frame's), used to test and apply axis labels.

Closed-form starts, then the robust refinement of `v2c.geometry.ransac.refine_primitive` with the axis held fixed:
- plane: offset = median of n . x.
- cylinder: the axis line is the least-squares meeting point of the normal lines projected along the axis;
  radius = median distance to it.
- cone: half angle from the median normal-axis angle, or (by points) from the slope of the radius over the height
  around a circle-fitted axis line; axis line as for the cylinder; apex height from the median of h - rho / tan(a)
  (axis flipped if the radius shrinks along it). A refit wider than max_radius at its points
  (`geometry.ransac.cone_ok`, a funnel through a small patch) is taken only when no other start gives a plausible
  cone.
- torus: axis line as for the cylinder; the tube's cross-section is a circle in the (rho, h) half-plane
  (algebraic circle fit) giving major radius, height of the centre and minor radius; also the free fit's torus
  turned onto the axis. The refinement keeps the radii within `geometry.ransac.torus_limits`.
"""

from __future__ import annotations

import numpy as np

from v2c.fit.config import FitConfig
from v2c.geometry.ransac import circle_2d, cone_ok, refine_primitive, torus_msac
from v2c.primitives import Cone, Cylinder, Plane, Primitive, Sphere, Torus
from v2c.primitives.directions import tangent_basis

_FUNNEL_COST = 1e3  # metres added to an implausible cone's median residual: any plausible candidate wins


def _axis_line(x: np.ndarray, n: np.ndarray, a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(point on the axis line (3,), radial distances (N,), heights (N,)) for direction ``a``: the point
    closest (least squares) to all normal lines projected onto the plane orthogonal to ``a``."""
    t1, t2 = tangent_basis(a)
    p2 = np.stack([x @ t1, x @ t2], axis=1)
    e2 = np.stack([n @ t1, n @ t2], axis=1)
    e2 = e2 / np.maximum(np.linalg.norm(e2, axis=1, keepdims=True), 1e-12)
    proj = np.eye(2)[None] - e2[:, :, None] * e2[:, None, :]  # (N, 2, 2) projectors across each line
    m = proj.sum(axis=0)
    b = np.einsum("nij,nj->i", proj, p2)
    c2 = np.linalg.lstsq(m, b, rcond=None)[0]
    rho = np.linalg.norm(p2 - c2, axis=1)
    return c2[0] * t1 + c2[1] * t2, rho, x @ a


def _circle_axis(x: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Point on the axis line of direction ``a`` from a circle fit of the points projected along it."""
    t1, t2 = tangent_basis(a)
    c2, _ = circle_2d(np.stack([x @ t1, x @ t2], axis=1))
    return c2[0] * t1 + c2[1] * t2


def start_with_axis(
    ptype: str, x: np.ndarray, n: np.ndarray, a: np.ndarray, by_points: bool = False
) -> Primitive | None:
    """Closed-form primitive of ``ptype`` with axis direction ``a`` (unit, camera frame) for points/normals.

    by_points: place the axis line of a cylinder or torus by a circle fit of the projected points instead of the
    normal lines (better where normals are poor: small patches)."""
    if ptype == "plane":
        return Plane(np.median(x @ a) * a, a)
    if ptype == "sphere":
        return None
    c, rho, h = _axis_line(x, n, a)
    if by_points and ptype in ("cylinder", "torus", "cone"):
        c = _circle_axis(x, a)
        rho = np.linalg.norm((x - c) - np.outer((x - c) @ a, a), axis=1)
    if ptype == "cylinder":
        return Cylinder(c, a, float(np.median(rho)))
    if ptype == "cone":
        if len(h) > 2 and np.corrcoef(h, rho)[0, 1] < 0:
            a, h = -a, -h
        # the start half angle stays within (2, 88) degrees
        if by_points:  # from the radius' growth along the axis (least-squares slope of rho over h)
            slope = np.polyfit(h, rho, 1)[0] if len(h) > 2 and np.ptp(h) > 0 else 0.0
            half = float(np.clip(np.arctan(max(slope, 0.0)), 0.035, 1.535))
        else:  # from the normals' angle to the axis
            half = float(np.arcsin(np.clip(np.median(np.abs(n @ a)), 0.035, 0.999)))
        h0 = float(np.median(h - rho / np.tan(half)))
        return Cone(c + (h0 - c @ a) * a, a, half)
    if ptype == "torus":
        cc, r = circle_2d(np.stack([rho, h], axis=1))
        return Torus(c + (cc[1] - c @ a) * a, a, float(cc[0]), r)
    raise ValueError(ptype)


def fit_with_axis(
    prim: Primitive, x: np.ndarray, n: np.ndarray, a: np.ndarray, scale: float, config: FitConfig
) -> Primitive:
    """``prim``'s type refitted to points ``x`` / normals ``n`` with its axis fixed to ``a`` (sign kept from
    the start where the type defines it). Spheres are returned unchanged."""
    if isinstance(prim, Sphere):
        return prim
    best, cost = prim, np.inf
    starts = [
        start_with_axis(prim.type, x, n, a, by_points)
        for by_points in ((False, True) if prim.type in ("cylinder", "torus", "cone") else (False,))
    ]
    if isinstance(prim, (Torus, Cone)):  # the free fit turned onto the axis: the closed-form cross-section circle
        # of a noisy arc can be far off (a 11 mm tube started at 27 mm), and so can a cone's half angle from the
        # normals of a small patch (64 degrees for a 5-degree taper), while the free fit's are good
        starts.append(prim.from_local(np.zeros(prim.local_size), a))
    for start in starts:
        if start is None:
            continue
        if isinstance(prim, Torus):  # on the start's distance inliers (even soft-l1 tails let a few far points
            # fatten a thin tube), chosen by MSAC with the refinement's prior on the minor radius
            m = np.abs(start.signed_distance(x)) < config.d_inlier * scale
            if np.count_nonzero(m) < max(start.local_size + 2, len(x) // 4):
                continue
            q = refine_primitive(start, x[m], scale, config, axis=start.axis_vector)
            c = torus_msac(q, x, scale, config)
        else:
            q = refine_primitive(start, x, scale, config, axis=start.axis_vector)
            c = float(np.median(np.abs(q.signed_distance(x))))
            if not cone_ok(q, x, scale, config):  # a funnel wider than max_radius: only if nothing else fits
                c += _FUNNEL_COST
        if c < cost:
            best, cost = q, c
    return best
