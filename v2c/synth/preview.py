"""A side-by-side picture of one generated scan: colour | depth (turbo, near = warm) | labels (18 colours)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

#: One colour per 18-class label (RGB); 255 (non-analytic) is white.
LABEL_COLORS = np.array(
    [
        [0, 0, 0],
        [230, 25, 75],
        [245, 130, 48],
        [255, 225, 25],
        [128, 0, 0],  # plane X Y Z U
        [60, 180, 75],
        [170, 255, 195],
        [0, 128, 128],
        [128, 128, 0],  # cylinder
        [0, 130, 200],
        [70, 240, 240],
        [0, 0, 128],
        [145, 30, 180],  # cone
        [240, 50, 230],
        [250, 190, 212],
        [220, 190, 255],
        [128, 128, 128],  # torus
        [255, 250, 200],  # sphere
    ],
    np.uint8,
)


def label_image(labels: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB rendering of an 18-class label map."""
    lut = np.full((256, 3), 255, np.uint8)
    lut[: len(LABEL_COLORS)] = LABEL_COLORS
    return lut[labels]


def depth_image(depth_units: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB turbo map of a depth image (any unit), robust range, no reading = black."""
    valid = depth_units > 0
    out = np.zeros((*depth_units.shape, 3), np.uint8)
    if valid.any():
        lo, hi = np.percentile(depth_units[valid], [1, 99])
        x = np.clip((depth_units.astype(float) - lo) / max(hi - lo, 1e-9), 0, 1)
        col = cv2.applyColorMap((255 * (1 - x)).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
        out[valid] = col[valid]
    return out


def preview(scan_dir: Path) -> np.ndarray:
    """(H, 3W, 3) uint8 RGB: color.png | depth.png | gt/labels.png of a generated scan."""
    scan_dir = Path(scan_dir)
    color = cv2.imread(str(scan_dir / "color.png"), cv2.IMREAD_COLOR)[..., ::-1]
    depth = cv2.imread(str(scan_dir / "depth.png"), cv2.IMREAD_UNCHANGED)
    labels = cv2.imread(str(scan_dir / "gt" / "labels.png"), cv2.IMREAD_UNCHANGED)
    return np.hstack([color, depth_image(depth), label_image(labels)])


def write_preview(scan_dirs: list[Path], path: Path) -> None:
    """Stack the previews of several scans (same size) vertically into one PNG."""
    rows = [preview(d) for d in scan_dirs]
    cv2.imwrite(str(path), np.vstack(rows)[..., ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
