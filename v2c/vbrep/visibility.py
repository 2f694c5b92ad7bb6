"""Visibility optimisation: where a curved surface turns away from the camera (normal orthogonal to the view ray).

The contour generator of a surface seen from the camera is where its normal is orthogonal to the view ray; in the
image it is where the rays stop crossing the surface (the face's sheet appears or vanishes). For each edge sample
we search the image normal through it within +-``vis_px`` pixels for that change (grid search, then bisection);
the contour point is the grazing crossing there, a point on the surface whose normal is orthogonal to its ray.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from v2c.camera import pixel_rays
from v2c.primitives.base import Primitive
from v2c.vbrep.lift import FD_STEP_M
from v2c.vbrep.raycast import intersect


@dataclass
class ContourSearch:
    """found: (N,) bool, a contour within the band; offset: (N,) pixels along the given direction (NaN where not
    found); points: (N, 3) camera-frame metres on the contour (NaN where not found)."""

    found: np.ndarray
    offset: np.ndarray
    points: np.ndarray


def _exists(
    prim: Primitive, sheet: int, uv: np.ndarray, K: np.ndarray, window: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    rays = pixel_rays(uv, K)
    hits = intersect(prim, rays, window)
    z = hits.depths[:, sheet]
    return np.isfinite(z), rays * np.where(np.isfinite(z), z, hits.closest)[:, None]


def find_contour(
    prim: Primitive,
    sheet: int,
    uv: np.ndarray,
    direction: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    vis_px: float,
    step_px: float,
    bisect: int,
) -> ContourSearch:
    """Search for the contour generator of ``prim`` (sheet ``sheet``) along ``uv + o * direction``,
    o in [-vis_px, vis_px] pixels, every ``step_px`` pixels, then ``bisect`` bisection steps. uv, direction: (N, 2)
    pixels / unit image vectors."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    n = len(uv)
    out = ContourSearch(np.zeros(n, bool), np.full(n, np.nan), np.full((n, 3), np.nan))
    if n == 0 or prim.type == "plane":
        return out
    offs = np.arange(-vis_px, vis_px + 1e-9, step_px)
    m = len(offs)
    q = uv[:, None, :] + offs[None, :, None] * direction[:, None, :]
    ex, _ = _exists(prim, sheet, q.reshape(-1, 2), K, window)
    ex = ex.reshape(n, m)
    change = ex[:, :-1] != ex[:, 1:]
    found = change.any(1)
    if not found.any():
        return out
    # the change nearest offset 0
    mid = 0.5 * (offs[:-1] + offs[1:])
    dist = np.where(change, np.abs(mid)[None, :], np.inf)
    k = np.argmin(dist, 1)[found]
    idx = np.nonzero(found)[0]
    lo, hi = offs[k].copy(), offs[k + 1].copy()
    ex_lo = ex[idx, k]
    u0, dr = uv[idx], direction[idx]
    for _ in range(bisect):
        mm = 0.5 * (lo + hi)
        e, _ = _exists(prim, sheet, u0 + mm[:, None] * dr, K, window)
        same = e == ex_lo
        lo, hi = np.where(same, mm, lo), np.where(same, hi, mm)
    # the grazing point: the side where the sheet exists
    o_in = np.where(ex_lo, lo, hi)
    _, pts = _exists(prim, sheet, u0 + o_in[:, None] * dr, K, window)
    out.found[idx] = True
    out.offset[idx] = o_in
    out.points[idx] = pts
    return out


def contour_tangent(prim: Primitive, x: np.ndarray) -> np.ndarray:
    """(N, 3) unit tangents of the contour generator at its points x (camera frame): orthogonal to both the
    surface normal and the gradient of g = n . x / |x| (central differences, `FD_STEP_M` metres)."""
    h = FD_STEP_M
    x = np.asarray(x, float).reshape(-1, 3)

    def g(p: np.ndarray) -> np.ndarray:
        return np.einsum("ij,ij->i", prim.normal(p), p) / np.linalg.norm(p, axis=1)

    eye = np.eye(3) * h
    grad_g = np.stack([(g(x + eye[k]) - g(x - eye[k])) / (2 * h) for k in range(3)], 1)
    t = np.cross(prim.normal(x), grad_g)
    return t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-15)
