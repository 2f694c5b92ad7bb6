"""Figure of the segmenters on the real frames: per frame of `v2c/bench/real_rois.json` one row of colour, learned
and geometric instances inside its ROI (no mask), instance boundaries dark, pixels off the part faded.

    PYTHONPATH=. python scripts/real_segmentation_figure.py ../shared/data/real docs/figures/segmentation_real.jpg

Prints the number of instances per frame and segmenter. Instance colours come from a fixed seed, so a figure drawn
twice is the same.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

from v2c.bench.real import load_frames
from v2c.scan import load_scan
from v2c.segment import segment

TILE_W_PX = 260  # width of one tile (pixels)
TILE_H_PX = 184  # height of one tile (pixels)
FADE = 0.7  # share of white mixed into the pixels off the part
BOUNDARY_GREY = 40  # grey level of the pixels where two instances meet
JPEG_QUALITY = 85
COLOUR_SEED = 3  # seed of the instance colours


def colours(n: int) -> np.ndarray:
    """(n + 1, 3) uint8 instance colours; 0 (no instance) white."""
    lut = np.random.default_rng(COLOUR_SEED).integers(40, 255, (n + 1, 3)).astype(np.uint8)
    lut[0] = 255
    return lut


def fit_tile(img: np.ndarray) -> np.ndarray:
    """``img`` scaled (nearest) into a white TILE_W_PX x TILE_H_PX tile, centred."""
    h, w = img.shape[:2]
    s = min(TILE_W_PX / w, TILE_H_PX / h)
    r = cv2.resize(img, (max(1, int(w * s)), max(1, int(h * s))), interpolation=cv2.INTER_NEAREST)
    out = np.full((TILE_H_PX, TILE_W_PX, 3), 255, np.uint8)
    y, x = (TILE_H_PX - r.shape[0]) // 2, (TILE_W_PX - r.shape[1]) // 2
    out[y : y + r.shape[0], x : x + r.shape[1]] = r
    return out


def instance_tile(colour: np.ndarray, inst: np.ndarray) -> np.ndarray:
    """The ROI's colour (BGR) with each instance painted, boundaries dark, the rest faded."""
    out = colour.copy()
    part = inst > 0
    out[~part] = ((1 - FADE) * out[~part] + FADE * 255).astype(np.uint8)
    out[part] = colours(int(inst.max()))[inst][part]
    edge = np.zeros_like(part)
    edge[:, 1:] |= inst[:, 1:] != inst[:, :-1]
    edge[1:] |= inst[1:] != inst[:-1]
    out[edge & part] = BOUNDARY_GREY
    return out


def main(argv: list[str]) -> int:
    """Draw the figure of the frames under argv[0] into argv[1]."""
    if len(argv) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    data, out = Path(argv[0]), Path(argv[1])
    rows = []
    for name, spec in load_frames().items():  # loop over frames
        folder = data / name
        if not folder.is_dir():
            print(f"{folder}: missing; skipped", file=sys.stderr)
            continue
        scan = load_scan(folder, roi=tuple(spec["roi"]))
        x0, y0, x1, y1 = spec["roi"]
        colour = np.ascontiguousarray(np.asarray(scan.color)[..., ::-1][y0:y1, x0:x1])
        tiles = [colour]
        for method in ("learned", "geometric"):  # loop over segmenters
            inst = np.asarray(segment(scan, method).instances)[y0:y1, x0:x1]
            tiles.append(instance_tile(colour, inst))
            print(f"{name} {method}: {len(np.unique(inst[inst > 0]))} instances")
        rows.append(np.concatenate([fit_tile(t) for t in tiles], 1))
    if not rows:
        print(f"{data}: no frame of v2c/bench/real_rois.json found", file=sys.stderr)
        return 1
    if not cv2.imwrite(str(out), np.concatenate(rows, 0), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]):
        print(f"{out}: could not write the figure", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
