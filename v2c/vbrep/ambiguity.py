"""Ambiguity resolution: which bounded subset of its surface a face is (paper: "up to four" subsets).

A ray through a face's pixel crosses the face's surface up to four times (a torus; two for a cylinder, cone or
sphere; once for a plane). Each crossing index is a "sheet": for a cylinder, sheet 0 is the near wall, seen from
outside (a boss, convex), sheet 1 the far wall, seen from inside (a hole, concave). The same image outline can
come from either; the depth points decide: the sheet whose depths agree best (median absolute difference) with
the observed depth over the face's pixels wins.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from v2c.camera import pixel_rays
from v2c.primitives.base import Primitive
from v2c.vbrep.raycast import MAX_SHEETS, intersect


@dataclass
class SheetChoice:
    """sheet: the chosen crossing index; errors: (4,) median |z_obs - z_sheet| (metres, inf where absent)."""

    sheet: int
    errors: np.ndarray

    @property
    def concave(self) -> bool:
        """True when the face is seen from inside its surface (a hole, a concave fillet): odd sheets."""
        return self.sheet % 2 == 1


def choose_sheet(
    prim: Primitive,
    pixels: np.ndarray,
    depth: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    rng: np.random.Generator,
    max_pixels: int,
) -> SheetChoice:
    """Pick the sheet of ``prim`` that agrees best with observed depths.

    pixels: (N, 2) (u, v) of the face; depth: (N,) observed depth (metres, 0 = none); at most ``max_pixels`` of
    those with a reading are scored (a sample drawn with ``rng``). A sheet present on fewer than half the pixels
    counts as absent (its error is inf).
    """
    ok = depth > 0
    pixels, depth = pixels[ok], depth[ok]
    if len(pixels) == 0:
        return SheetChoice(0, np.full(MAX_SHEETS, np.inf))
    if len(pixels) > max_pixels:
        idx = rng.choice(len(pixels), max_pixels, replace=False)
        pixels, depth = pixels[idx], depth[idx]
    hits = intersect(prim, pixel_rays(pixels, K), window)
    err = np.full(MAX_SHEETS, np.inf)
    for k in range(MAX_SHEETS):
        z = hits.depths[:, k]
        have = np.isfinite(z)
        if have.mean() >= 0.5:
            # pixels where the sheet is absent (just outside a contour) count with their closest approach
            zz = np.where(have, z, hits.closest)
            err[k] = float(np.median(np.abs(zz - depth)))
    if not np.isfinite(err).any():
        return SheetChoice(0, err)
    return SheetChoice(int(np.argmin(err)), err)
