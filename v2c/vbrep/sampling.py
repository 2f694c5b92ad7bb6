"""Samples along one 2D graph edge (pixels): resampling, smoothing, reading images beside it, smoothing the
per-sample type codes into runs, and finding the image corners of an outline.

Every function works on whole (K, 2) arrays of image points (u, v).
"""

from __future__ import annotations

import numpy as np

from v2c.vbrep.config import VBRepConfig


def resample_polyline(poly: np.ndarray, step: float) -> np.ndarray:
    """(K, 2) polyline -> points every ``step`` (same unit) from its first to its last point (both kept)."""
    poly = np.asarray(poly, float)
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    if total <= 0:
        return poly[:1].copy()
    n = max(2, int(np.ceil(total / step)) + 1)
    t = np.linspace(0.0, total, n)
    return np.stack([np.interp(t, s, poly[:, 0]), np.interp(t, s, poly[:, 1])], 1)


def smooth_uv(uv: np.ndarray, window: int) -> np.ndarray:
    """Moving average of (K, 2) image points over ``window`` samples, shrinking near the ends (ends kept)."""
    n = len(uv)
    if window <= 1 or n < 3:
        return uv.copy()
    half = window // 2
    cs = np.concatenate([np.zeros((1, 2)), np.cumsum(uv, 0)])
    k = np.arange(n)
    r = np.minimum(half, np.minimum(k, n - 1 - k))  # symmetric window that fits
    return (cs[k + r + 1] - cs[k - r]) / (2 * r + 1)[:, None]


def image_normals(pts: np.ndarray) -> np.ndarray:
    """(K, 2) unit image normals of a polyline (its tangent turned by +90 degrees; (0, 1) for a single point)."""
    t = np.gradient(pts, axis=0) if len(pts) > 1 else np.array([[1.0, 0.0]])
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return np.stack([-t[:, 1], t[:, 0]], 1)


def read_at(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Values of ``img`` at the nearest pixels of the image points uv (K, 2), clipped to the image."""
    h, w = img.shape[:2]
    u = np.clip(np.rint(uv[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.rint(uv[:, 1]).astype(int), 0, h - 1)
    return img[v, u]


def smooth_codes(codes: np.ndarray, window: int, min_run: int, n_codes: int) -> np.ndarray:
    """Per-sample codes (K,) in [0, n_codes) smoothed: a mode filter over ``window`` samples, then runs shorter
    than ``min_run`` samples merged into the longer neighbouring run (repeatedly, shortest first)."""
    codes = np.asarray(codes, int).copy()
    n = len(codes)
    if n == 0:
        return codes
    if window > 1 and n > window:
        onehot = np.eye(n_codes)[codes]
        pad = window // 2
        padded = np.concatenate([np.repeat(onehot[:1], pad, 0), onehot, np.repeat(onehot[-1:], pad, 0)])
        cs = np.cumsum(np.concatenate([np.zeros((1, n_codes)), padded]), 0)
        counts = cs[window:] - cs[:-window]
        counts = counts[:n] + 1e-3 * onehot  # ties keep the sample's own code
        codes = np.argmax(counts, 1)
    while True:
        starts = np.flatnonzero(np.concatenate([[True], codes[1:] != codes[:-1]]))
        ends = np.concatenate([starts[1:], [n]])
        lens = ends - starts
        if len(starts) == 1 or lens.min() >= min_run:
            return codes
        r = int(np.argmin(lens))
        left = lens[r - 1] if r > 0 else -1
        right = lens[r + 1] if r + 1 < len(starts) else -1
        src = r - 1 if left >= right else r + 1
        codes[starts[r] : ends[r]] = codes[starts[src]]


def turn_deg(uv: np.ndarray, L: int) -> np.ndarray:
    """Turn angle (degrees) of a polyline at each sample, over arms of L samples (0 within L of the ends)."""
    n = len(uv)
    out = np.zeros(n)
    if n < 2 * L + 1:
        return out
    k = np.arange(L, n - L)
    t_in, t_out = uv[k] - uv[k - L], uv[k + L] - uv[k]
    c = np.einsum("ij,ij->i", t_in, t_out) / np.maximum(
        np.linalg.norm(t_in, axis=1) * np.linalg.norm(t_out, axis=1), 1e-12
    )
    out[k] = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    return out


def corner_samples(uv: np.ndarray, cfg: VBRepConfig) -> list[int]:
    """Indices (into uv) of the image corners of a polyline: the turn over arms of ``corner_scale_px`` exceeds
    ``corner_deg`` on both scales and is concentrated there (at least ``corner_concentration`` of the turn over
    arms twice as long; a circular arc turns in proportion to the arm length, a corner does not, and pixel
    staircase kinks vanish on the longer arms). Local maxima at least
    ``min_edge_px`` from the ends and from each other."""
    n = len(uv)
    L = max(1, round(cfg.corner_scale_px / cfg.sample_step_px))
    m = max(L, int(np.ceil(cfg.min_edge_px / cfg.sample_step_px)))
    if n < 2 * m + 1:
        return []
    turn, wide = turn_deg(uv, L), turn_deg(uv, 2 * L)
    # a corner turns at every scale (pixel staircase kinks fade on the wide scale); an arc turns more on the
    # wide scale than on the narrow one
    ok = (turn > cfg.corner_deg) & (wide > cfg.corner_deg) & (turn >= cfg.corner_concentration * wide)
    cuts: list[int] = []
    for c in np.argsort(-turn):
        if turn[c] <= cfg.corner_deg:
            break
        if not ok[c] or c < m or c > n - 1 - m or any(abs(c - x) < max(m, 2 * L) for x in cuts):
            continue
        cuts.append(int(c))
    return sorted(cuts)
