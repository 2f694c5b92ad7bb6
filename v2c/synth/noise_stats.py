"""Statistics of a depth map's noise, measured the same way on real frames and on synthetic scans.

Used by scripts/sensor_stats.py (the noise profiles against ../shared/data/real) and by the tests of the noise
profiles. Depth maps are (H, W) float metres, 0 = no reading.

- `patch_noise`: the local noise. The map is cut into non-overlapping square patches; a patch with every reading
  present gets a least-squares plane z = a + b u + c v, and its noise is the residual standard deviation (3
  degrees of freedom removed); a patch with a residual above half a depth edge (`NoiseStatsConfig.edge_jump_m`,
  ``edge_jump_rel``) holds an edge and is left out. A patch is small (7 px: 6 mm at 0.9 m with f = 1067 px), so
  the plane absorbs the low-frequency part (the fBm warp of the synthetic profiles, calibration errors of a real
  sensor) and a gently curved surface (a can of radius 33 mm bends by 0.14 mm across a patch) looks flat. What is
  left is the per-pixel noise plus the quantisation's q^2 / 12. Spatially correlated noise shows as a std that
  grows with the patch side (scripts/sensor_stats.py prints that profile).
- `quantum_near`: the depth step: the median spacing of the distinct depth values within +-``quantum_window_rel``
  of a depth.
- `hole_share`: the share of pixels without a reading inside a region.
- `flying_share`: of the readings within ``edge_band_px`` of a depth edge, the share lying between two layers
  (`v2c.depth_clean.flying_pixels`: a nearer and a farther layer inside a ``flying_window_px`` window).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from v2c.depth_clean import DepthCleanConfig, flying_pixels


@dataclass(frozen=True)
class NoiseStatsConfig:
    """How the statistics are measured (units in the comments)."""

    patch_px: int = 7  # side of the square patches of `patch_noise` (pixels)
    edge_jump_m: float = 0.01  # a depth range above this (metres)...
    edge_jump_rel: float = 0.02  # ...and above this fraction of the depth is a depth edge (patch and band tests)
    quantum_window_rel: float = 0.05  # `quantum_near` looks at depths within this fraction of the given depth
    edge_band_px: int = 2  # `flying_share`: readings this close to a depth edge (pixels) form the band
    flying_window_px: int = 5  # window of the flying-pixel test (pixels, odd)
    z_bin_m: float = 0.1  # width of the depth bins of `binned_std` (metres)
    min_patches: int = 20  # a bin with fewer patches is not reported


def patch_noise(
    depth: np.ndarray, region: np.ndarray | None = None, cfg: NoiseStatsConfig = NoiseStatsConfig()
) -> tuple[np.ndarray, np.ndarray]:
    """(z, std): mean depth (metres) and residual std (metres) of every complete, edge-free patch (module
    docstring); with ``region`` ((H, W) bool), only patches lying wholly inside it."""
    p = cfg.patch_px
    h, w = depth.shape
    hp, wp = h // p, w // p
    blocks = depth[: hp * p, : wp * p].reshape(hp, p, wp, p).transpose(0, 2, 1, 3).reshape(-1, p * p).astype(float)
    keep = (blocks > 0).all(axis=1)
    if region is not None:
        inside = region[: hp * p, : wp * p].reshape(hp, p, wp, p).transpose(0, 2, 1, 3).reshape(-1, p * p)
        keep &= inside.all(axis=1)
    blocks = blocks[keep]
    zmean = blocks.mean(axis=1)
    v, u = np.mgrid[0:p, 0:p]
    a = np.stack([np.ones(p * p), u.ravel() - (p - 1) / 2, v.ravel() - (p - 1) / 2], axis=1)
    coef = np.linalg.lstsq(a, blocks.T, rcond=None)[0]
    res = blocks - (a @ coef).T
    # a depth edge inside the patch leaves residuals of about half its step: such patches are not noise
    flat = np.abs(res).max(axis=1) < 0.5 * np.maximum(cfg.edge_jump_m, cfg.edge_jump_rel * zmean)
    std = np.sqrt((res[flat] ** 2).sum(axis=1) / (p * p - 3))
    return zmean[flat], std


def binned_std(z: np.ndarray, std: np.ndarray, cfg: NoiseStatsConfig = NoiseStatsConfig()) -> list[tuple]:
    """[(bin centre m, patches, median std m)] over depth bins of `z_bin_m` with at least `min_patches` patches."""
    if len(z) == 0:
        return []
    idx = np.floor(z / cfg.z_bin_m).astype(int)
    out = []
    for b in np.unique(idx):
        sel = idx == b
        if sel.sum() >= cfg.min_patches:
            out.append(((b + 0.5) * cfg.z_bin_m, int(sel.sum()), float(np.median(std[sel]))))
    return out


def quantum_near(depth: np.ndarray, z: float, cfg: NoiseStatsConfig = NoiseStatsConfig()) -> float:
    """Median spacing (metres) of the distinct depth values within +-`quantum_window_rel` of ``z``; nan if < 3."""
    vals = np.unique(depth[np.abs(depth - z) <= cfg.quantum_window_rel * z])
    return float(np.median(np.diff(vals))) if len(vals) >= 3 else float("nan")


def hole_share(depth: np.ndarray, region: np.ndarray) -> float:
    """Share of the pixels of ``region`` ((H, W) bool) without a reading."""
    return float(np.mean(depth[region] <= 0)) if region.any() else float("nan")


def edge_band(depth: np.ndarray, cfg: NoiseStatsConfig = NoiseStatsConfig()) -> np.ndarray:
    """(H, W) bool: pixels within `edge_band_px` of a depth edge (3x3 range of the readings above the jump)."""
    valid = depth > 0
    if not valid.any():
        return np.zeros(depth.shape, bool)
    k = np.ones((3, 3), np.uint8)
    big = np.float32(float(depth.max()) + 1.0)
    zmin = cv2.erode(np.where(valid, depth, big).astype(np.float32), k)
    zmax = cv2.dilate(np.where(valid, depth, 0).astype(np.float32), k)
    edge = valid & (zmax - zmin > np.maximum(cfg.edge_jump_m, cfg.edge_jump_rel * zmin))
    b = 2 * cfg.edge_band_px + 1
    return cv2.dilate(edge.astype(np.uint8), np.ones((b, b), np.uint8)) > 0


def flying_share(depth: np.ndarray, region: np.ndarray, cfg: NoiseStatsConfig = NoiseStatsConfig()) -> float:
    """Of the readings in ``region`` within `edge_band_px` of a depth edge, the share lying between two layers."""
    band = edge_band(depth, cfg) & region & (depth > 0)
    if not band.any():
        return float("nan")
    fly = flying_pixels(
        depth,
        DepthCleanConfig(
            flying_window_px=cfg.flying_window_px, flying_jump_m=cfg.edge_jump_m, flying_jump_rel=cfg.edge_jump_rel
        ),
    )
    return float(np.mean(fly[band]))
