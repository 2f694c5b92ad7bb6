"""The pinhole camera: its intrinsics record and the maps between pixels and camera-frame points.

Frames and units everywhere in v2c: camera frame (OpenCV: x right, y down, z forward), metres; pixel coordinates
(u, v) = (column, row) with pixel centres at integers. ``K`` is the (3, 3) intrinsic matrix in pixels,
``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``; the skew ``s = K[0, 1]`` is honoured by every function here (it is 0
for every sensor we know of, and then each formula gives bit for bit what its skew-free form gives).

This module is the bottom of the scan layer: it imports nothing from v2c. Reading and checking camera.json is
`v2c.scan_checks.load_camera`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Metres per depth unit when camera.json does not say (RealSense default; SCAN_FORMAT.md).
DEFAULT_DEPTH_SCALE_M = 0.001


@dataclass
class Camera:
    """Intrinsics read from camera.json. K in pixels; depth_scale in metres per depth.png unit."""

    K: np.ndarray
    depth_scale: float
    width: int | None
    height: int | None
    format: str  # "v2c" | "open3d" | "bop": which camera.json form was read


def backproject(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Back-project a depth map to camera-frame points.

    depth: (H, W) z-depth in metres (0 = no reading gives the point (0, 0, 0)); K: (3, 3) intrinsics in pixels,
    pixel centres at integer (u, v). Returns (H, W, 3) float64 points (x right, y down, z forward), metres.
    """
    depth = np.asarray(depth, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be (H, W), got shape {depth.shape}")
    if K.shape != (3, 3):
        raise ValueError(f"K must be 3x3, got shape {K.shape}")
    h, w = depth.shape
    fx, s, cx = K[0]
    fy, cy = K[1, 1], K[1, 2]
    v = np.arange(h, dtype=np.float64)[:, None]
    u = np.arange(w, dtype=np.float64)[None, :]
    yn = (v - cy) / fy  # (H, 1)
    xn = (u - cx - s * yn) / fx  # (H, W); with s = 0 exactly (u - cx) / fx
    out = np.empty((h, w, 3), dtype=np.float64)
    out[..., 0] = xn * depth
    out[..., 1] = yn * depth
    out[..., 2] = depth
    return out


def pixel_rays(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Rays through pixels: (N, 2) pixel coordinates (u, v) -> (N, 3) directions ``K^-1 (u, v, 1)`` scaled to
    z = 1 (camera frame), so the point at z-depth s (metres) is ``s * ray``. Computed with the inverse matrix.

    `pixel_rays_closed_form` gives the same rays from the closed-form inverse; the two differ in the last bits
    of rounding, and each stage keeps the one its results were produced with (the VB-Rep stage and the
    benchmark this one, the geometry stage the other).
    """
    uv = np.asarray(uv, float).reshape(-1, 2)
    Kinv = np.linalg.inv(np.asarray(K, float))
    h = np.concatenate([uv, np.ones((len(uv), 1))], 1) @ Kinv.T
    return h / h[:, 2:3]


def pixel_rays_closed_form(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """`pixel_rays` by the closed-form inverse of the upper-triangular K: y = (v - cy) / fy,
    x = (u - cx - s y) / fx, z = 1 (camera frame; (N, 2) pixels -> (N, 3)). Used by the geometry stage
    (`v2c.fit.intersect`)."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    K = np.asarray(K, float)
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]  # with s = 0 exactly (u - cx) / fx
    return np.stack([x, y, np.ones(len(uv))], axis=1)


def project(points: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame points (metres) -> (N, 2) pixel coordinates (u, v); points at z ~ 0 are divided by
    1e-12 instead of 0."""
    p = np.asarray(points, float).reshape(-1, 3) @ np.asarray(K, float).T
    return p[:, :2] / np.where(np.abs(p[:, 2:3]) > 1e-12, p[:, 2:3], 1e-12)
