"""Polyline helpers shared by the stages (2D pixel edge graphs, 3D VB-Rep edges, STEP edge fitting)."""

from __future__ import annotations

import numpy as np


def rdp_indices(points: np.ndarray, tol: float, clamp: bool = False) -> np.ndarray:
    """Indices of an open polyline's points (N, D) kept by Ramer-Douglas-Peucker within ``tol`` (the points' unit:
    pixels for image polylines, metres or millimetres for 3D ones); the first and last are always kept.

    Distances are to the chord's line, or with ``clamp`` to the chord as a segment (so a polyline that doubles
    back beyond an end keeps its turning point: the STEP exporter's curve fitting needs that). The loop runs over
    kept segments; each step is vectorised over the points between them.
    """
    points = np.asarray(points, float)
    n = len(points)
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        seg = points[i + 1 : j]
        a, d = points[i], points[j] - points[i]
        ln2 = float(d @ d)
        if ln2 > 1e-24:
            t = (seg - a) @ d / ln2
            if clamp:
                t = np.clip(t, 0.0, 1.0)
            dist = np.linalg.norm(seg - (a + t[:, None] * d), axis=1)
        else:
            dist = np.linalg.norm(seg - a, axis=1)
        k = int(np.argmax(dist))
        if dist[k] > tol:
            m = i + 1 + k
            keep[m] = True
            stack += [(i, m), (m, j)]
    return np.flatnonzero(keep)


def segment_distances(q: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(M, K) distances of the points ``q`` (M, D) to each of the K segments of the polyline ``poly`` (K + 1, D)."""
    a, d = poly[:-1], np.diff(poly, axis=0)
    dd = np.maximum(np.einsum("kj,kj->k", d, d), 1e-300)
    t = np.clip(np.einsum("mkj,kj->mk", q[:, None] - a[None], d) / dd, 0.0, 1.0)
    return np.linalg.norm(q[:, None] - (a[None] + t[..., None] * d[None]), axis=2)
