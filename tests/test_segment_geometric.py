"""The geometric fallback segmenter (depth only) on generated scans, and its building blocks on exact data."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from v2c.bench.segmentation import evaluate_segmentation, summarise
from v2c.labels import AxisClass, PrimitiveType
from v2c.scan import load_scan
from v2c.segment import segment
from v2c.segment.data import estimate_ground, estimate_normals, gravity_frame
from v2c.segment.geometric import GeometricConfig, _Fit, classify_instance, part_frame
from v2c.synth.dataset import SynthConfig, generate_dataset

# Measured on these 6 scans (seed 4343, 320x240 `sensor`), 2026-11-21: face recall 0.514 (gt faces >= 50 px),
# type accuracy 0.556, precision 0.420. The segmenter is seeded; the margins cover platform differences in the
# RANSAC arithmetic and in the generator's rendering.
RECALL_MIN = 0.40
TYPE_ACC_MIN = 0.40


@pytest.fixture(scope="module")
def scans(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    out = tmp_path_factory.mktemp("geometric_scans")
    return generate_dataset(out, 6, 4343, SynthConfig(width=320, height=240, noise="sensor"), progress=False)


def test_geometric_face_recall(scans: list[Path]) -> None:
    rows = []
    for d in scans:
        scan = load_scan(d)
        seg = segment(scan, "geometric")
        assert seg.method == "geometric" and seg.instances.shape == scan.depth.shape
        assert not (seg.instances[~scan.mask] > 0).any()  # never outside the part mask
        rows.append(evaluate_segmentation(seg, scan))
    s = summarise(rows)
    assert s["recall"] >= RECALL_MIN, s
    assert s["type_acc"] >= TYPE_ACC_MIN, s


def test_ground_and_frame_match_ground_truth(scans: list[Path]) -> None:
    for d in scans[:3]:
        scan = load_scan(d)
        ground = estimate_ground(scan.depth, scan.K, scan.mask)
        assert ground is not None
        z_gt = np.asarray(scan.gt.meta["axes_cam"])[2]
        assert np.degrees(np.arccos(min(abs(float(ground.up @ z_gt)), 1.0))) < 2.0
        frame = gravity_frame(ground, scan.K, scan.mask, scan.depth.shape)
        assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-9)


def test_normals_of_a_plane_are_exact() -> None:
    K = np.array([[300.0, 0, 80], [0, 300.0, 60], [0, 0, 1]])
    n_true = np.array([0.0, -0.6, -0.8])  # facing the camera
    v, u = np.mgrid[0:120, 0:160]
    rays = np.stack([(u - 80) / 300.0, (v - 60) / 300.0, np.ones_like(u, float)], axis=-1)
    depth = (-0.5 / (rays @ n_true)).astype(np.float32)  # plane n . p = -0.5
    n = estimate_normals(depth, K)
    err = np.degrees(np.arccos(np.clip(n[5:-5, 5:-5] @ n_true, -1, 1)))
    assert err.max() < 0.1


def test_type_tests_and_part_frame_on_exact_points() -> None:
    rng = np.random.default_rng(0)
    cfg = GeometricConfig()
    # cylinder of radius 0.02 around the axis a through c, seen from one side
    a = np.array([1.0, 0.0, 0.0])
    c = np.array([0.0, 0.0, 0.5])
    t = rng.uniform(-0.05, 0.05, 500)
    phi = rng.uniform(np.pi * 0.6, np.pi * 1.4, 500)
    radial = np.stack([np.zeros_like(phi), np.sin(phi), np.cos(phi)], axis=1)
    p = c + t[:, None] * a + 0.02 * radial
    f = classify_instance(p, radial, "cylinder", cfg)
    assert f.kind is PrimitiveType.CYLINDER and abs(abs(f.axis @ a) - 1) < 1e-6
    # a cone: normals tilted 30 degrees from the axis
    cone_n = np.cos(np.radians(30)) * radial + np.sin(np.radians(30)) * a
    assert classify_instance(p, cone_n, "cylinder", cfg).kind is PrimitiveType.CONE
    # part frame: up = -y; horizontal plane normals at 20 degrees from the forward direction
    fwd, left, up = np.array([0, 0, 1.0]), np.array([-1.0, 0, 0]), np.array([0, -1.0, 0])
    th = np.radians(20)
    h1 = np.cos(th) * fwd + np.sin(th) * left
    h2 = np.cross(up, h1)
    fits = [_Fit(PrimitiveType.PLANE, h1, 500), _Fit(PrimitiveType.PLANE, -h2, 300), _Fit(PrimitiveType.PLANE, up, 800)]
    frame = part_frame(fits, np.stack([fwd, left, up]))
    assert abs(frame[0] @ h1 - 1) < 1e-9  # X: the horizontal axis nearer the viewing direction, pointing away
    assert abs(abs(frame[1] @ h2) - 1) < 1e-9 and abs(frame[2] @ up - 1) < 1e-9
    assert AxisClass.X.value == "X"
