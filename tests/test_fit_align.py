"""The shared frame R: recovered from a turned box within 0.5 degrees; robust to a wrong axis label."""

from __future__ import annotations

import numpy as np
import pytest
from test_fit_helpers import make_scan, turned_box_scene

from v2c.fit import FitConfig, fit_scan
from v2c.fit.align import init_frame
from v2c.primitives.directions import angle_between_axes, perturb_direction, rotation_exp


def _frame_errors_deg(frame: np.ndarray, cols: np.ndarray) -> list[float]:
    return [float(np.rad2deg(angle_between_axes(frame[k], cols[:, k]))) for k in range(3)]


def test_turned_box_axes_within_half_a_degree() -> None:
    depth, inst, labels, planes, r = turned_box_scene(noise_m=0.001, seed=3)
    scan, seg = make_scan(depth, inst, labels)
    res = fit_scan(scan, seg, FitConfig(), "full")
    assert max(_frame_errors_deg(res.frame, r)) < 0.5
    assert np.allclose(res.frame @ res.frame.T, np.eye(3), atol=1e-9) and np.linalg.det(res.frame) > 0
    for i, p in res.primitives.items():
        assert res.axis_labels[i] in ("X", "Y", "Z")
        # aligned primitives take their axis exactly from R
        assert np.rad2deg(angle_between_axes(p.axis_vector, res.frame["XYZ".index(res.axis_labels[i])])) < 1e-6
        # and sit where the faces are (metres)
        assert abs((p.origin - planes[i][0]) @ planes[i][1]) < 0.0005


def test_init_frame_ignores_a_wrong_label() -> None:
    rng = np.random.default_rng(0)
    true = rotation_exp(np.array([0.4, -0.3, 1.1])).T  # rows X, Y, Z
    axes, labels, weights = [], [], []
    for k in range(3):
        for _ in range(4):
            axes.append(perturb_direction(true[k], rng.normal(0, 0.003, 2)) * rng.choice([-1, 1]))
            labels.append(k)
            weights.append(1000.0)
    axes.append(true[1])  # a big face labelled X that is really Y
    labels.append(0)
    weights.append(3000.0)
    frame = init_frame(axes, labels, weights, view_dir=np.array([0.0, 0.0, 1.0]), outlier_deg=8.0)
    assert max(np.rad2deg(angle_between_axes(frame[k], true[k])) for k in range(3)) < 0.5


def test_init_frame_from_two_classes_and_signs() -> None:
    true = rotation_exp(np.array([1.9, 0.1, -0.2])).T
    frame = init_frame([true[0], -true[2]], [0, 2], [1.0, 1.0], view_dir=np.array([0.0, 0.0, 1.0]), outlier_deg=8.0)
    assert max(np.rad2deg(angle_between_axes(frame[k], true[k])) for k in range(3)) < 1e-6
    assert frame[2] @ [0, 0, 1.0] <= 0 and frame[0] @ [0, 0, 1.0] >= 0  # Z towards the camera, X away
    assert np.linalg.det(frame) > 0


@pytest.mark.parametrize("missing", [False, True])
def test_weak_labels_still_find_the_frame(missing: bool) -> None:
    """Scores 0: types from the type search; the frame from the weak labels' axis classes, or (labels missing)
    from the fitted axes themselves."""
    depth, inst, labels, planes, r = turned_box_scene(noise_m=0.001, seed=4)
    scan, seg = make_scan(depth, inst, labels)
    seg.scores[:] = 0.0
    if missing:
        seg.labels[1:] = 0
    res = fit_scan(scan, seg, FitConfig(), "full")
    assert sorted(res.types_searched) == sorted(res.primitives)
    assert all(p.type == "plane" for p in res.primitives.values())
    assert all(res.axis_labels[i] in ("X", "Y", "Z") for i in res.primitives)
    for k in range(3):  # every box axis is one of the frame's (naming is a heuristic without labels)
        assert min(np.rad2deg(angle_between_axes(res.frame[j], r[:, k])) for j in range(3)) < 0.5
    for i, p in res.primitives.items():
        assert np.rad2deg(angle_between_axes(p.axis_vector, planes[i][1])) < 0.5
