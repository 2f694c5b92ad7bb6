"""Per-instance point sets of a scan: camera-frame points, normals from the depth gradient, part size.

The point map they are taken from is `v2c.camera.backproject` of the scan's depth (camera frame, metres).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from v2c.geometry.config import RansacConfig
from v2c.primitives.directions import unit

#: Median absolute deviation to standard deviation, for normally distributed residuals.
MAD_TO_SIGMA = 1.4826


def mad_sigma(r: np.ndarray) -> float:
    """Robust standard deviation of residuals ``r`` about 0: MAD_TO_SIGMA x median |r| (the units of ``r``)."""
    return MAD_TO_SIGMA * float(np.median(np.abs(r)))


def median_depth_sigma(x: np.ndarray, coeff: float) -> float:
    """The sensor's depth sigma (metres) at the median depth of camera-frame points ``x`` (N, 3): coeff z^2 (a
    config's noise_sigma_coeff; `geometry.selection.noise_sigma` gives it per point)."""
    return coeff * float(np.median(x[:, 2])) ** 2


@dataclass
class InstancePoints:
    """Valid pixels of one instance: flat pixel indices (n,), points (n, 3) and unit normals (n, 3), camera frame,
    metres. Normals face the camera (n . x < 0)."""

    pixels: np.ndarray
    points: np.ndarray
    normals: np.ndarray


def estimate_part_size(points: np.ndarray, trim: float = 0.01) -> float:
    """Part size (metres) from the part's visible points (N, 3): the largest side of their trimmed extent along
    their principal axes. It approximates the largest side of the part's bounding box (what BENCHMARK.md divides
    by) from the scan alone; the ground truth's part_size_m is only for metrics."""
    p = np.asarray(points, float)
    if len(p) < 3:
        return 1.0
    c = p - p.mean(axis=0)
    _, _, vt = np.linalg.svd(c[:: max(1, len(c) // 20000)], full_matrices=False)
    q = c @ vt.T
    lo, hi = np.quantile(q, [trim, 1 - trim], axis=0)
    return float(max(np.max(hi - lo), 1e-6))


def instance_points(
    points: np.ndarray, valid: np.ndarray, instances: np.ndarray, ids: np.ndarray, config: RansacConfig
) -> dict[int, InstancePoints]:
    """Points and depth-gradient normals of each instance in ``ids``.

    points: (H, W, 3) camera-frame point map (metres); valid: (H, W) bool pixels to use; instances: (H, W) ids.
    The point map is smoothed inside the instance only (normalised box filter of ``config.normal_window_px``
    pixels over the instance's valid pixels, on its bounding box), so normals near a boundary are one-sided
    rather than mixed with a neighbour; the normal is the cross product of the Sobel (``config.normal_sobel_px``)
    derivatives along u and v.
    """
    window_px, sobel_px = config.normal_window_px, config.normal_sobel_px
    h, w = instances.shape
    pad = window_px + sobel_px
    out: dict[int, InstancePoints] = {}
    flat_all = np.arange(h * w).reshape(h, w)
    for i in ids:  # loop over instances; everything inside is whole-array
        m = (instances == i) & valid
        rows, cols = np.nonzero(m.any(axis=1))[0], np.nonzero(m.any(axis=0))[0]
        if len(rows) == 0:
            continue
        r0, r1 = max(rows[0] - pad, 0), min(rows[-1] + pad + 1, h)
        c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, w)
        mc = m[r0:r1, c0:c1].astype(np.float32)
        pc = points[r0:r1, c0:c1].astype(np.float32) * mc[..., None]
        k = (window_px, window_px)
        wsum = cv2.boxFilter(mc, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
        psum = cv2.boxFilter(pc, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
        ps = psum / np.maximum(wsum, 1e-6)[..., None]
        du = cv2.Sobel(ps, cv2.CV_32F, 1, 0, ksize=sobel_px, borderType=cv2.BORDER_REPLICATE)
        dv = cv2.Sobel(ps, cv2.CV_32F, 0, 1, ksize=sobel_px, borderType=cv2.BORDER_REPLICATE)
        sel = mc > 0
        n = unit(np.cross(du[sel].astype(float), dv[sel].astype(float)))
        x = points[r0:r1, c0:c1][sel].astype(float)
        n = np.where((np.sum(n * x, axis=1) > 0)[:, None], -n, n)
        out[int(i)] = InstancePoints(pixels=flat_all[r0:r1, c0:c1][sel], points=x, normals=n)
    return out
