"""Depth clean-up for real sensor frames: flying pixels, speckle, small holes, edge-preserving smoothing.

Real structured-light and active-stereo depth (the Asus Xtion and Kinect v1 frames of ../shared/data/real) carries
artefacts our synthetic scans draw only in part: pixels floating between the two layers of a depth edge, small
islands of wrong depth, pin holes, and per-pixel noise. Each step below is a named parameter of
`DepthCleanConfig` (units in the field comments) and can be switched off on its own:

1. flying pixels: a reading with a neighbour nearer AND a neighbour farther by more than a layer jump (inside a
   ``flying_window_px`` window) lies between two surfaces: it becomes no reading;
2. speckle: a connected piece of readings (neighbours joined when their depths differ by less than
   ``speckle_jump_m``) smaller than ``speckle_max_px`` pixels becomes no reading;
3. holes: a piece of missing readings not touching the image border, at most ``hole_max_px`` pixels, whose rim
   spans less than ``hole_rim_range_m`` in depth, is filled by inpainting from its rim (0 = holes left);
4. smoothing: a bilateral filter on depth (``bilateral_diameter_px`` 0 = off), depth steps well above
   ``bilateral_sigma_depth_m`` are not blurred; missing readings stay missing.

Where it runs: `v2c.scan.load_scan` calls `clean_loaded_depth`, which follows the mode in force (the
`depth_clean` context; `DEFAULT_MODE` outside one): ``auto`` cleans scans without ``gt/`` (real frames) and leaves
synthetic scans as written; ``on`` cleans every scan; ``off`` none. ``auto`` and ``on`` apply `DEFAULT_CONFIG`
unless given another config.

Measured on the real-frame bench (`v2c bench --real`, docs/synth.md "Depth clean-up of real frames"): no step
improved the figures without hurting one (speckle removal raised the 3 mm coverage and lowered the depth RMS but
broke a box angle and worsened the soup can's radius; flying-pixel removal, hole filling and the bilateral filter
hurt coverage or depth RMS), and a 1 ppm depth scale alone moves the figures as much. So `DEFAULT_MODE` is
``off``: loading is unchanged, and the steps are there to be switched on (``depth_clean("auto")``).
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np

from v2c.contexts import scoped

#: The modes of `depth_clean`: ``auto`` = frames without ground truth only.
MODES = ("auto", "on", "off")


@dataclass(frozen=True)
class DepthCleanConfig:
    """The steps of the clean-up; a step whose size parameter is 0 is off. Units in the comments."""

    flying_window_px: int = 5  # side of the window searched for a nearer and a farther layer (pixels, odd; 0 = off)
    flying_jump_m: float = 0.01  # a neighbour this much nearer / farther (metres)...
    flying_jump_rel: float = 0.02  # ...or this fraction of the depth, whichever is larger, is another layer
    speckle_max_px: int = 0  # pieces of readings smaller than this are removed (pixels; 0 = off)
    speckle_jump_m: float = 0.01  # neighbours closer than this in depth join one piece (metres)
    hole_max_px: int = 0  # holes up to this size are filled (pixels; 0 = holes left)
    hole_rim_range_m: float = 0.005  # ...only when the depths around the hole span less than this (metres)
    bilateral_diameter_px: int = 0  # bilateral filter diameter (pixels; 0 = off)
    bilateral_sigma_space_px: float = 1.5  # spatial sigma (pixels)
    bilateral_sigma_depth_m: float = 0.004  # range sigma (metres): steps well above it are kept sharp


#: What ``auto`` and ``on`` apply: speckle removal, the one step that raised the real frames' 3 mm coverage in
#: every draw (module docstring; off by default all the same).
DEFAULT_CONFIG = DepthCleanConfig(flying_window_px=0, speckle_max_px=30)
#: The mode outside a `depth_clean` block: off (measured, module docstring).
DEFAULT_MODE = "off"

_MODE: contextvars.ContextVar[tuple[str, DepthCleanConfig] | None] = contextvars.ContextVar(
    "v2c_depth_clean", default=None
)


def current_mode() -> tuple[str, DepthCleanConfig]:
    """The (mode, config) in force: (`DEFAULT_MODE`, `DEFAULT_CONFIG`) unless inside `depth_clean`."""
    return _MODE.get() or (DEFAULT_MODE, DEFAULT_CONFIG)


@contextlib.contextmanager
def depth_clean(mode: str = "auto", cfg: DepthCleanConfig | None = None, **changes: Any) -> Iterator[DepthCleanConfig]:
    """Use ``mode`` (one of `MODES`) and ``cfg`` (or `DEFAULT_CONFIG` with ``changes``) for scans loaded inside."""
    if mode not in MODES:
        raise ValueError(f"depth clean-up mode {mode!r}: expected one of {', '.join(MODES)}")
    new = replace(cfg or DEFAULT_CONFIG, **changes)
    with scoped(_MODE, (mode, new)):
        yield new


def flying_pixels(depth: np.ndarray, cfg: DepthCleanConfig) -> np.ndarray:
    """(H, W) bool: readings with a nearer and a farther layer inside the `flying_window_px` window."""
    valid = depth > 0
    if cfg.flying_window_px <= 0 or not valid.any():
        return np.zeros(depth.shape, bool)
    k = np.ones((cfg.flying_window_px, cfg.flying_window_px), np.uint8)
    big = np.float32(float(depth.max()) + 1.0)
    zmin = cv2.erode(np.where(valid, depth, big).astype(np.float32), k)
    zmax = cv2.dilate(np.where(valid, depth, 0).astype(np.float32), k)
    jump = np.maximum(cfg.flying_jump_m, cfg.flying_jump_rel * depth)
    return valid & (depth - zmin > jump) & (zmax - depth > jump)


def speckle(depth: np.ndarray, cfg: DepthCleanConfig) -> np.ndarray:
    """(H, W) bool: readings in pieces smaller than `speckle_max_px` (neighbours joined below `speckle_jump_m`)."""
    valid = depth > 0
    if cfg.speckle_max_px <= 0 or not valid.any():
        return np.zeros(depth.shape, bool)
    unit = max(float(depth.max()) / 30000.0, 1e-6)  # metres per int16 step, so the whole range fits
    img = np.round(np.where(valid, depth, 0) / unit).astype(np.int16)
    marked = img.copy()
    cv2.filterSpeckles(marked, -1, cfg.speckle_max_px, max(1, int(round(cfg.speckle_jump_m / unit))))
    return valid & (marked == -1)


def fill_holes(depth: np.ndarray, cfg: DepthCleanConfig) -> np.ndarray:
    """Depth with the small, flat-rimmed holes filled by the least-squares plane through their rim readings."""
    if cfg.hole_max_px <= 0:
        return depth
    holes = (depth <= 0).astype(np.uint8)
    _, lab, stats, _ = cv2.connectedComponentsWithStats(holes, connectivity=4)
    h, w = depth.shape
    x, y, bw, bh, area = (stats[:, i] for i in range(5))
    inner = (area <= cfg.hole_max_px) & (x > 0) & (y > 0) & (x + bw < w) & (y + bh < h)
    inner[0] = False  # label 0 is the readings
    if not inner[1:].any():
        return depth
    out = depth.astype(np.float32).copy()
    valid = depth > 0
    k = np.ones((3, 3), np.uint8)
    for i in np.flatnonzero(inner):  # a loop over holes, never over pixels
        y0, x0 = max(int(y[i]) - 1, 0), max(int(x[i]) - 1, 0)
        win = np.s_[y0 : int(y[i] + bh[i]) + 1, x0 : int(x[i] + bw[i]) + 1]
        hole = lab[win] == i
        rim = (cv2.dilate(hole.astype(np.uint8), k) > 0) & valid[win]
        zr = depth[win][rim]
        if len(zr) < 3 or float(zr.max() - zr.min()) >= cfg.hole_rim_range_m:
            continue
        # the plane z = a + b u + c v through the rim, evaluated inside the hole
        vv, uu = np.nonzero(rim)
        coef = np.linalg.lstsq(np.stack([np.ones(len(zr)), uu, vv], axis=1), zr.astype(float), rcond=None)[0]
        hv, hu = np.nonzero(hole)
        out[win][hv, hu] = coef[0] + coef[1] * hu + coef[2] * hv
    return out


def clean_depth(depth: np.ndarray, cfg: DepthCleanConfig = DEFAULT_CONFIG) -> tuple[np.ndarray, dict[str, int]]:
    """(H, W) float metres (0 = no reading) -> (cleaned float32 depth, pixel counts of each step)."""
    out = np.asarray(depth, np.float32).copy()
    fly = flying_pixels(out, cfg)
    out[fly] = 0
    spk = speckle(out, cfg)
    out[spk] = 0
    missing = out <= 0
    out = fill_holes(out, cfg)
    filled = int((missing & (out > 0)).sum())
    if cfg.bilateral_diameter_px > 0:
        smooth = cv2.bilateralFilter(
            out, cfg.bilateral_diameter_px, cfg.bilateral_sigma_depth_m, cfg.bilateral_sigma_space_px
        )
        out = np.where(out > 0, smooth, 0).astype(np.float32)
    return out, {"flying": int(fly.sum()), "speckle": int(spk.sum()), "filled": filled}


def clean_loaded_depth(depth: np.ndarray, has_ground_truth: bool, notes: list[str]) -> np.ndarray:
    """The hook of `v2c.scan.load_scan`: clean ``depth`` when the mode in force asks for it (``auto``: only
    without ground truth), appending what changed to ``notes``; otherwise ``depth`` itself."""
    mode, cfg = current_mode()
    if mode == "off" or (mode == "auto" and has_ground_truth):
        return depth
    out, counts = clean_depth(depth, cfg)
    changed = {k: v for k, v in counts.items() if v}
    if changed:
        notes.append("depth clean-up: " + ", ".join(f"{v} {k}" for k, v in changed.items()) + " pixels")
    return out
