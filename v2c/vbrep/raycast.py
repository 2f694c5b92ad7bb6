"""Rays from the camera through pixels, intersected with analytic primitives (camera frame, metres).

A pixel (u, v) defines the ray ``x(z) = z * d`` with ``d = K^-1 (u, v, 1)`` (so ``d[2] = 1`` and the ray
parameter z is the depth along the camera z axis, metres; `v2c.camera.pixel_rays`). Every primitive's
intersections are returned as up to four depths per ray, sorted, NaN where absent: the "sheets" of the surface
along the ray (for a cylinder, sheet 0 is the near wall seen from outside (a boss), sheet 1 the far wall seen from
inside (a hole)).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from v2c.primitives import from_dict
from v2c.primitives.base import Primitive

__all__ = ["MAX_SHEETS", "RayHits", "as_primitive", "intersect", "sheet_depth"]

MAX_SHEETS = 4


def as_primitive(p: Primitive | dict) -> Primitive:
    """A `v2c.primitives` object from a Primitive or its to_dict form."""
    return p if isinstance(p, Primitive) else from_dict(p)


@dataclass
class RayHits:
    """Intersections of N rays with one primitive.

    depths: (N, 4) sorted depths z (metres) of the surface crossings, NaN where absent.
    closest: (N,) depth of the ray's closest approach to the surface (metres), defined for every ray; equals a
      crossing when the ray grazes the surface (used to lift pixels just outside a curved surface's contour).
    """

    depths: np.ndarray
    closest: np.ndarray

    @property
    def count(self) -> np.ndarray:
        """(N,) number of surface crossings of each ray (0 .. MAX_SHEETS)."""
        return np.isfinite(self.depths).sum(1)


def _sort_roots(roots: np.ndarray) -> np.ndarray:
    roots = np.where(roots > 1e-6, roots, np.nan)
    roots = np.sort(roots, axis=1)  # NaN last
    out = np.full((len(roots), MAX_SHEETS), np.nan)
    k = min(MAX_SHEETS, roots.shape[1])
    out[:, :k] = roots[:, :k]
    return out


def _quadratic(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Real roots (N, 2) of A z^2 + B z + C (NaN where none) and the extremum -B / 2A."""
    A = np.where(np.abs(A) > 1e-18, A, 1e-18)
    disc = B * B - 4 * A * C
    s = np.sqrt(np.where(disc >= 0, disc, np.nan))
    r = np.stack([(-B - s) / (2 * A), (-B + s) / (2 * A)], 1)
    return r, -B / (2 * A)


def intersect(
    prim: Primitive | dict, rays: np.ndarray, window: tuple[float, float] = (0.05, 5.0), samples: int = 160
) -> RayHits:
    """Intersect rays (N, 3, z component 1) with a primitive. window: depth range (metres) searched for the
    torus, which is sampled (``samples`` steps, then refined by regula falsi); the quadrics are solved exactly."""
    p = as_primitive(prim)
    d = np.asarray(rays, float).reshape(-1, 3)
    o = np.asarray(p.origin, float)
    t = p.type
    if t == "plane":
        n = p.axis_vector
        dn = d @ n
        z = (o @ n) / np.where(np.abs(dn) > 1e-12, dn, 1e-12)
        roots = z[:, None]
        return RayHits(_sort_roots(roots), z)
    if t == "sphere":
        A = np.einsum("ij,ij->i", d, d)
        B = -2 * d @ o
        C = np.full(len(d), o @ o - p.radius**2)
        roots, zc = _quadratic(A, B, C)
        return RayHits(_sort_roots(roots), zc)
    if t == "cylinder":
        a = p.axis
        dp = d - np.outer(d @ a, a)
        m = -o
        mp = m - (m @ a) * a
        A = np.einsum("ij,ij->i", dp, dp)
        B = 2 * dp @ mp
        C = np.full(len(d), mp @ mp - p.radius**2)
        roots, zc = _quadratic(A, B, C)
        return RayHits(_sort_roots(roots), zc)
    if t == "cone":
        a = p.axis
        c2 = np.cos(p.half_angle) ** 2
        m = -o
        da, ma = d @ a, m @ a
        A = da * da - c2 * np.einsum("ij,ij->i", d, d)
        B = 2 * (da * ma - c2 * d @ m)
        C = np.full(len(d), ma * ma - c2 * (m @ m))
        roots, _ = _quadratic(A, B, C)
        ok = (roots * da[:, None] + ma) > 0  # the nappe on the axis side
        roots = np.where(ok, roots, np.nan)
        zc = _closest_by_sampling(p, d, window, samples)
        return RayHits(_sort_roots(roots), zc)
    return _intersect_sampled(p, d, window, samples)


def _closest_by_sampling(p: Primitive, d: np.ndarray, window: tuple[float, float], samples: int) -> np.ndarray:
    z = np.linspace(window[0], window[1], samples)
    pts = d[:, None, :] * z[None, :, None]
    sd = np.abs(p.signed_distance(pts.reshape(-1, 3))).reshape(len(d), samples)
    return z[np.argmin(sd, 1)]


def _intersect_sampled(p: Primitive, d: np.ndarray, window: tuple[float, float], samples: int) -> RayHits:
    """Generic crossings of the signed distance along each ray (any primitive; used for the torus)."""
    n = len(d)
    z = np.linspace(window[0], window[1], samples)
    pts = d[:, None, :] * z[None, :, None]
    sd = p.signed_distance(pts.reshape(-1, 3)).reshape(n, samples)
    zc = z[np.argmin(np.abs(sd), 1)]
    change = np.signbit(sd[:, :-1]) != np.signbit(sd[:, 1:])
    depths = np.full((n, MAX_SHEETS), np.nan)
    rank = np.cumsum(change, 1) - 1
    ri, ci = np.nonzero(change & (rank < MAX_SHEETS))
    if len(ri):
        lo, hi = z[ci].copy(), z[ci + 1].copy()
        flo, fhi = sd[ri, ci].copy(), sd[ri, ci + 1].copy()
        dr = d[ri]
        for _ in range(6):  # regula falsi
            zm = lo - flo * (hi - lo) / np.where(fhi != flo, fhi - flo, 1e-18)
            fm = p.signed_distance(dr * zm[:, None])
            left = np.signbit(fm) == np.signbit(flo)
            lo, flo = np.where(left, zm, lo), np.where(left, fm, flo)
            hi, fhi = np.where(left, hi, zm), np.where(left, fhi, fm)
        depths[ri, rank[ri, ci]] = lo - flo * (hi - lo) / np.where(fhi != flo, fhi - flo, 1e-18)
    return RayHits(depths, zc)


def sheet_depth(hits: RayHits, sheet: int, prior: np.ndarray | None = None) -> np.ndarray:
    """Depth (N,) of each ray on one sheet of the surface (metres). Where that sheet is absent: the crossing
    nearest ``prior`` (e.g. the observed depth) if any, else the closest approach."""
    z = hits.depths[:, sheet].copy()
    miss = ~np.isfinite(z)
    if miss.any():
        alt = hits.closest[miss].copy()
        if prior is not None:
            dd = np.abs(hits.depths[miss] - np.asarray(prior, float)[miss][:, None])
            has = np.isfinite(dd).any(1)
            k = np.nanargmin(np.where(np.isfinite(dd), dd, np.inf), 1)
            alt = np.where(has, hits.depths[miss][np.arange(miss.sum()), k], alt)
        z[miss] = alt
    return z
