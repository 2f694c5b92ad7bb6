"""The plane-outlier split of learned instances (v2c.segment.refine) on exact synthetic depth maps."""

from __future__ import annotations

import numpy as np

from v2c.labels import label_of
from v2c.segment.refine import RefineConfig, split_plane_outliers
from v2c.segment.types import Segmentation

H, W = 120, 160
K = np.array([[200.0, 0.0, 80.0], [0.0, 200.0, 60.0], [0.0, 0.0, 1.0]])
PLANE_Z, CYL_Z = label_of("plane", "Z"), label_of("cylinder", "Z")


def _tilted_plane(rng: np.random.Generator, noise_m: float = 0.0) -> np.ndarray:
    """Depth (metres) of the plane z = 0.5 + 0.1 y (a floor seen obliquely), with Gaussian depth noise."""
    v = np.arange(H, dtype=float)[:, None].repeat(W, 1)
    y_over_z = (v - K[1, 2]) / K[1, 1]
    z = 0.5 / (1.0 - 0.1 * y_over_z)
    return z + rng.normal(0.0, noise_m, z.shape) if noise_m else z


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def _probs(label_map: np.ndarray) -> np.ndarray:
    p = np.full((18, H, W), 0.01, np.float32)
    p[label_map, np.arange(H)[:, None], np.arange(W)[None, :]] = 0.83
    return p


def test_off_plane_pocket_is_split_and_labelled_by_the_network() -> None:
    rng = np.random.default_rng(0)
    depth = _tilted_plane(rng, 2e-4)
    pocket = np.zeros((H, W), bool)
    pocket[50:70, 60:100] = True
    depth[pocket] += 0.02  # 20 mm deeper: a hole's wall the network painted as the plane around it
    inst = np.ones((H, W), np.int32)
    net = np.where(pocket, CYL_Z, PLANE_Z)  # ... although its own class map says cylinder there
    seg = Segmentation(inst, np.array([0, PLANE_Z], np.uint8), np.array([0, 0.9], np.float32), "learned")
    out = split_plane_outliers(seg, depth, K, _probs(net), RefineConfig())
    assert out.num_instances == 2
    assert _iou(out.instances == 2, pocket) > 0.99  # the 1-px opening may keep the corners in the plane
    assert out.labels[2] == CYL_Z and out.labels[1] == PLANE_Z
    assert 0.0 < out.scores[2] <= 1.0


def test_split_piece_joins_the_rest_of_its_face() -> None:
    rng = np.random.default_rng(1)
    depth = _tilted_plane(rng)
    wall = np.zeros((H, W), bool)
    wall[40:80, 100:] = True
    depth[wall] += 0.03
    inst = np.ones((H, W), np.int32)
    inst[40:80, 130:] = 2  # the network cut the wall at column 130 and gave columns 100-129 to the plane
    seg = Segmentation(inst, np.array([0, PLANE_Z, CYL_Z], np.uint8), np.array([0, 0.9, 0.9], np.float32),
                       "learned")
    out = split_plane_outliers(seg, depth, K, _probs(np.where(wall, CYL_Z, PLANE_Z)), RefineConfig())
    assert out.num_instances == 2  # no new instance: the piece went to instance 2
    assert _iou(out.instances == 2, wall) > 0.99


def test_a_noisy_plane_is_left_alone() -> None:
    rng = np.random.default_rng(2)
    depth = _tilted_plane(rng, 1e-3)  # 1 mm noise on a part of about 0.15 m
    depth[rng.random((H, W)) < 0.05] = 0.0  # missing readings
    inst = np.ones((H, W), np.int32)
    seg = Segmentation(inst, np.array([0, PLANE_Z], np.uint8), np.array([0, 0.9], np.float32), "learned")
    out = split_plane_outliers(seg, depth, K, _probs(np.full((H, W), PLANE_Z)), RefineConfig())
    assert out is seg


def test_fragments_of_one_plane_are_merged_and_a_step_is_not() -> None:
    from v2c.segment.refine import merge_coplanar

    rng = np.random.default_rng(3)
    depth = _tilted_plane(rng, 2e-4)
    depth[:, 120:] += 0.02  # columns 120+: a parallel plane 20 mm lower (a step), same label
    inst = np.ones((H, W), np.int32)
    inst[:, 60:120] = 2  # the network cut the first plane at column 60 (a print edge)
    inst[:, 120:] = 3
    labels = np.array([0, PLANE_Z, PLANE_Z, PLANE_Z], np.uint8)
    seg = Segmentation(inst, labels, np.array([0, 0.9, 0.9, 0.9], np.float32), "learned")
    out = merge_coplanar(seg, depth, K, RefineConfig())
    assert np.array_equal(out.instances == 1, inst <= 2) and np.array_equal(out.instances == 2, inst == 3)
    assert list(out.labels) == [0, PLANE_Z, PLANE_Z]  # ids renumbered: labels[k] stays instance k's
    other = Segmentation(inst, np.array([0, PLANE_Z, label_of("plane", "X"), PLANE_Z], np.uint8), seg.scores,
                         "learned")
    assert merge_coplanar(other, depth, K, RefineConfig()) is other  # labels differ: never merged
