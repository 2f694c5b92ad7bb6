"""exporters.figure: drawing a VB-Rep whose geometry reaches the viewer's plane."""

from __future__ import annotations

import warnings

import numpy as np

from exporters.figure import render_vbrep

from scenes.vbrep import box_corner


def test_points_on_the_viewer_plane_are_skipped_not_drawn_as_garbage() -> None:
    vb = box_corner()
    clean = render_vbrep(vb, size=(160, 120), supersample=1)
    # One edge gets a point on the camera's own plane (z = 0, off-centre): it has no image position and must be
    # left out of the drawing and of the fitted crop, not projected to a huge coordinate.
    e = vb.edges[0]
    e.polyline = np.vstack([e.polyline, [[0.05, 0.02, 0.0]]])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with np.errstate(divide="ignore", invalid="ignore"):
            img = render_vbrep(vb, size=(160, 120), crop=None, supersample=1)
    assert img.shape == clean.shape == (120, 160, 3)
    # The rest of the drawing is the same picture: at most the pixels of the one edge differ.
    assert np.mean(np.any(img != clean, axis=2)) < 0.02
