"""The ground-truth edge-type rule (v2c.vbrep.gt_types) and the edge confidence on analytic scenes."""

from __future__ import annotations

import numpy as np
import pytest

from v2c.vbrep.extract import extract_vbrep
from v2c.vbrep.gt_types import gt_edge_samples
from v2c.vbrep.model import EdgeType

from scenes.raycast import box_scene, cylinder_scene, plate_feature_scene, scene_inputs


def _types_by_pair(gt):
    out = {}
    for f, o, t in zip(gt.face, gt.other, gt.type):
        out.setdefault((int(f), int(o)), set()).add(str(t))
    return out


def test_box_ground_truth_is_intersections_and_silhouettes():
    inp = scene_inputs(box_scene())
    gt = gt_edge_samples(inp.scan)
    pairs = _types_by_pair(gt)
    for (_f, o), types in pairs.items():
        if o == 0:
            assert types == {"silhouette"}
        else:
            assert types == {"intersection"}
    assert gt.share(EdgeType.INTERSECTION) > 0.3 and gt.share(EdgeType.SILHOUETTE) > 0.3


def test_cylinder_ground_truth_has_visibility_on_its_contour():
    inp = scene_inputs(cylinder_scene())
    gt = gt_edge_samples(inp.scan)
    side = 1  # faces.png value of the cylinder face
    vis = (gt.face == side) & (gt.type == "visibility")
    assert vis.sum() > 100
    # the visibility records are the left and right outline, not the base arc: they span most of the height
    v_rows = gt.uv[vis, 1]
    assert np.ptp(v_rows) > 80
    # the top disc's boundary with the cylinder is an intersection, with the background a silhouette
    assert set(gt.type[(gt.face == 2) & (gt.other == side)]) == {"intersection"}
    assert set(gt.type[(gt.face == 2) & (gt.other == 0)]) == {"silhouette"}


def test_hole_ground_truth_has_occluded_far_wall():
    inp = scene_inputs(plate_feature_scene("hole"))
    gt = gt_edge_samples(inp.scan)
    wall = 4  # faces.png value of the hole's cylinder wall
    types = set(gt.type[gt.face == wall])
    assert {"intersection", "occluded"} <= types and "visibility" not in types
    # where the wall is occluded, the plate top in front is the silhouette
    occ = (gt.face == wall) & (gt.type == "occluded")
    assert set(gt.type[(gt.face == 1) & (gt.other == wall)]) >= {"silhouette"}
    assert occ.sum() > 20


@pytest.mark.parametrize("noise_m", [0.0004])
def test_confidence_drops_with_fit_residual(noise_m):
    inp = scene_inputs(box_scene(), noise_m=noise_m, seed=4)
    good = extract_vbrep(inp.scan, inp.seg, inp.fit)
    inp.fit.residuals = {k: 0.003 for k in inp.fit.residuals}  # 3 mm RMS: a poor fit
    bad = extract_vbrep(inp.scan, inp.seg, inp.fit)
    c_good = np.array([e.confidence for e in good.edges])
    c_bad = np.array([e.confidence for e in bad.edges])
    assert len(c_good) == len(c_bad)
    assert c_good.mean() > 0.6 and np.all(c_bad < c_good)
    # intersection edges of a clean box are the most certain kind here
    ints = [e.confidence for e in good.edges_of_type(EdgeType.INTERSECTION)]
    assert min(ints) > 0.7
