"""Intersection refinement: parallel planes are never forced to meet; intersections pull neighbours together."""

from __future__ import annotations

import numpy as np
import pytest
from test_fit_helpers import Box, make_scan, render_boxes

from v2c.fit import FitConfig, fit_scan
from v2c.fit.intersect import Lifted, memberships
from v2c.primitives import Plane
from v2c.primitives.directions import angle_between_axes, unit

STEP = 0.003  # metres between the two parallel top faces


def _step_scene(seed: int = 0):
    """Two boxes one behind the other, the front one STEP taller: their top faces meet in the image along an
    occlusion edge (the step's face is turned away from the camera)."""
    z = unit(np.array([0.0, -0.8, -0.6]))
    x = np.array([1.0, 0.0, 0.0])
    y = np.cross(z, x)
    r = np.stack([x, y, z], axis=1)
    c = np.array([0.0, 0.0, 0.42])
    front = Box(c, r, np.array([0.05, 0.03, 0.02]))
    back = Box(c + 0.06 * y - 0.5 * STEP * z, r, np.array([0.05, 0.03, 0.02 - 0.5 * STEP]))
    depth, inst, labels, planes = render_boxes([front, back], r, noise_m=0.0005, seed=seed)
    return depth, inst, labels, planes, r


def test_step_scene_has_the_two_tops_adjacent() -> None:
    _, inst, _, _, _ = _step_scene()
    top_front, top_back = 6, 12  # box 0/1, +Z face
    a, b = inst == top_front, inst == top_back
    assert a.sum() > 1000 and b.sum() > 1000
    # some pixel of the back top is directly below (in the image: behind) a pixel of the front top
    assert np.any(a[:-1] & b[1:]) or np.any(a[1:] & b[:-1])


@pytest.mark.parametrize("w_r", [FitConfig().w_r, 0.1])
def test_parallel_planes_are_never_made_to_intersect(w_r: float) -> None:
    depth, inst, labels, _, _ = _step_scene()
    scan, seg = make_scan(depth, inst, labels)
    for ablation in ("full", "no-axis"):
        res = fit_scan(scan, seg, FitConfig(w_r=w_r), ablation)
        assert res.n_intersections > 0
        pf, pb = res.primitives[6], res.primitives[12]
        assert np.rad2deg(angle_between_axes(pf.axis_vector, pb.axis_vector)) < 0.3
        gap = abs(pb.signed_distance(pf.origin[None])[0])
        assert abs(gap - STEP) < 0.0003  # the 3 mm step survives (metres)


def test_step_scene_collapses_without_the_rejection() -> None:
    """The scene is a real test: with the rejection off and a weak E_recon (w_r = 0.1), free planes are pulled
    together across the step."""
    depth, inst, labels, _, _ = _step_scene()
    scan, seg = make_scan(depth, inst, labels)
    off = fit_scan(scan, seg, FitConfig(parallel_deg=0.0, w_r=0.1), "no-axis")
    gap_off = abs(off.primitives[12].signed_distance(off.primitives[6].origin[None])[0])
    assert gap_off < 0.002


def test_membership_rejects_the_farther_parallel_plane() -> None:
    near = Plane([0, 0, 0.5], [0, 0, -1.0])
    far = Plane([0, 0, 0.502], [0, 0, -1.0])
    side = Plane([0, 0, 0.5], [1.0, 0, 0])
    lifted = Lifted(
        uv=np.zeros((1, 2)),
        rays=np.array([[0.0, 0.0, 1.0]]),
        candidates=[(0, 1, 2)],
        vertex=np.array([0]),
        s=np.array([0.5005]),
    )
    pi, tj = memberships(lifted, [near, far, side], scale=0.1, d_thresh=0.05, parallel_deg=10.0)
    assert sorted(tj.tolist()) == [0, 2]  # the farther of the two parallel planes is dropped
    pi, tj = memberships(lifted, [near, far, side], scale=0.1, d_thresh=0.05, parallel_deg=0.0)
    assert sorted(tj.tolist()) == [0, 1, 2]  # without the rejection all three would be pulled together
    lifted.candidates = [(0, 1)]
    pi, tj = memberships(lifted, [near, far, side], scale=0.1, d_thresh=0.05, parallel_deg=10.0)
    assert len(pi) == 0  # a point between two parallel planes only is no intersection at all
