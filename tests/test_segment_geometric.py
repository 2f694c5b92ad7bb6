"""The geometric segmenter (depth only) on generated scans and on exact synthetic depth, and its building blocks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from v2c.bench.segmentation import evaluate_segmentation, match_faces
from v2c.labels import TYPE_OF_LABEL, AxisClass, PrimitiveType
from v2c.primitives import Cone, Cylinder
from v2c.scan import Scan, load_scan
from v2c.segment import segment
from v2c.segment.data import estimate_ground, estimate_normals, gravity_frame
from v2c.segment.geometric import (
    GeometricConfig,
    _Fit,
    _polish,
    cone_about,
    fit_cylinder,
    part_frame,
    ranked_primitives,
    segment_geometric,
)
from v2c.synth.dataset import SynthConfig, generate_dataset

SIGMA_COEFF = 0.0015  # the `sensor` profile's depth noise, sigma = coeff * z^2 (metres)


@pytest.fixture(scope="module")
def scan_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("geometric_scans")
    cfg = SynthConfig(width=640, height=480, noise="sensor", families=("bracket",))  # seed 4345: 4 faces of >= 200 px
    return generate_dataset(out, 1, 4345, cfg, progress=False)[0]


def test_every_face_of_200_px_recovered_with_its_type(scan_dir: Path) -> None:
    """Every analytic gt face of at least 200 pixels is matched (IoU >= 0.5) by an instance of its type."""
    scan = load_scan(scan_dir)
    seg = segment(scan, "geometric")
    assert seg.method == "geometric" and seg.instances.shape == scan.depth.shape
    assert not (seg.instances[~scan.mask] > 0).any()  # never outside the part mask
    faces, labels = scan.gt.faces.astype(np.int64), scan.gt.labels.astype(np.int64)
    faces = np.where(labels == 255, 0, faces)
    matched = {g: p for p, g, _ in match_faces(seg.instances, faces, 0.5)}
    big = [g for g in np.unique(faces[faces > 0]) if np.count_nonzero(faces == g) >= 200]
    assert len(big) >= 4
    for g in big:
        assert g in matched, f"face {g} ({np.count_nonzero(faces == g)} px) not recovered"
        gt_type = TYPE_OF_LABEL[np.bincount(labels[faces == g]).argmax()]
        assert TYPE_OF_LABEL[seg.labels[matched[g]]] == gt_type, f"face {g}: wrong type"
    r = evaluate_segmentation(seg, scan)
    assert r["precision"] >= 0.6, r


def test_deterministic(scan_dir: Path) -> None:
    scan = load_scan(scan_dir)
    a, b = segment_geometric(scan), segment_geometric(scan)
    assert np.array_equal(a.instances, b.instances) and np.array_equal(a.labels, b.labels)


def _plane_scan(offsets: np.ndarray, gap_cols: slice | None = None, seed: int = 0) -> Scan:
    """A 320x240 scan of planes with one normal, tilted 35 degrees from the view, about 0.5 m away: pixel columns
    take the plane offset ``offsets`` (per column, metres along the normal); ``gap_cols`` have no depth.
    `sensor`-model Gaussian noise; the mask is the whole image."""
    h, w = 240, 320
    K = np.array([[300.0, 0, w / 2], [0, 300.0, h / 2], [0, 0, 1]])
    v, u = np.mgrid[0:h, 0:w]
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((h, w))], axis=-1)
    t = np.radians(35)
    n = np.array([0.0, -np.sin(t), -np.cos(t)])  # faces the camera
    d0 = -0.5 * np.cos(t)  # n . p = d: the plane through (0, 0, 0.5)
    depth = (d0 - offsets[None, :]) / (rays @ n)  # rays have z = 1, so this is the depth
    rng = np.random.default_rng(seed)
    depth = depth + SIGMA_COEFF * depth**2 * rng.standard_normal(depth.shape)
    if gap_cols is not None:
        depth[:, gap_cols] = 0.0
    return Scan(
        path=Path("synthetic"),
        color=np.zeros((h, w, 3), np.uint8),
        depth=depth.astype(np.float32),
        K=K,
        mask=np.ones((h, w), bool),
        roi=None,
        gt=None,
    )


def test_coplanar_pieces_become_one_instance() -> None:
    """One plane cut in two by a band of pixels without depth (a highlight, a dropout line): one instance."""
    scan = _plane_scan(np.zeros(320), gap_cols=slice(150, 154))
    seg = segment_geometric(scan)
    valid = scan.depth > 0
    ids, counts = np.unique(seg.instances[valid], return_counts=True)
    assert ids[0] != 0 and len(ids) == 1, dict(zip(ids.tolist(), counts.tolist(), strict=True))
    assert TYPE_OF_LABEL[seg.labels[ids[0]]] == 0  # a plane


def test_parallel_planes_3mm_apart_stay_two() -> None:
    """Two parallel planes 3 mm apart (a step seen square on, its wall hidden): two instances, cut at the step."""
    offsets = np.where(np.arange(320) < 160, 0.0, 0.003)
    scan = _plane_scan(offsets)
    seg = segment_geometric(scan)
    left, right = seg.instances[:, :156], seg.instances[:, 164:]
    a = np.bincount(left[left > 0]).argmax()
    b = np.bincount(right[right > 0]).argmax()
    assert a != b
    assert np.mean(left == a) > 0.97 and np.mean(right == b) > 0.97
    assert len(np.unique(seg.instances[seg.instances > 0])) == 2


def test_ground_and_frame_match_ground_truth(scan_dir: Path) -> None:
    scan = load_scan(scan_dir)
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


def _cylinder_patch(rng: np.random.Generator, noise: float) -> tuple[np.ndarray, np.ndarray, Cylinder]:
    """A hole's wall seen from one side: radius 6 mm around the axis a through c, a 150-degree arc, 15 mm tall."""
    a = np.array([0.0, -0.6, -0.8])
    c = np.array([0.01, 0.0, 0.5])
    e1 = np.array([1.0, 0.0, 0.0])
    e2 = np.cross(a, e1)
    t = rng.uniform(0.0, 0.015, 600)
    phi = rng.uniform(0.0, np.radians(150), 600)
    radial = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    x = c + t[:, None] * a + 0.006 * radial + noise * rng.standard_normal((600, 3))
    return x, radial, Cylinder(c, a, 0.006)


def test_fits_recover_exact_primitives() -> None:
    rng = np.random.default_rng(0)
    x, n, cyl = _cylinder_patch(rng, 0.0)
    f = fit_cylinder(x, n)
    assert f is not None and abs(abs(f.axis @ cyl.axis) - 1) < 1e-6 and abs(f.radius - 0.006) < 1e-6
    # polish from a start 20 degrees and 2 mm off, on the points alone
    off = Cylinder(cyl.origin + 0.002, cyl.axis + np.array([0.35, 0, 0]), 0.008)
    p = _polish(off, x, 1e-4, 8)
    assert abs(abs(p.axis @ cyl.axis) - 1) < 1e-6 and abs(p.radius - 0.006) < 1e-6  # type: ignore[attr-defined]
    # a cone of half angle 30 degrees about a known axis direction
    a = np.array([0.0, 0.0, 1.0])
    h = rng.uniform(0.01, 0.03, 500)
    phi = rng.uniform(0, np.pi, 500)
    pts = np.stack([h * np.tan(np.radians(30)) * np.cos(phi), h * np.tan(np.radians(30)) * np.sin(phi), 0.5 + h], 1)
    start = cone_about(pts, a)  # an approximate start (the circle centre of a half arc of varying radius)
    assert isinstance(start, Cone) and abs(np.degrees(start.half_angle) - 30) < 5
    cone = _polish(start, pts, 1e-4, 10)
    assert isinstance(cone, Cone) and abs(np.degrees(cone.half_angle) - 30) < 1e-4
    assert np.allclose(cone.origin, [0, 0, 0.5], atol=1e-6)


def test_ranked_primitives_pick_the_true_type_under_sensor_noise() -> None:
    rng = np.random.default_rng(1)
    cfg = GeometricConfig()
    noise = SIGMA_COEFF * 0.5**2  # 0.375 mm at 0.5 m
    x, n, cyl = _cylinder_patch(rng, noise)
    nn = n + 0.05 * rng.standard_normal(n.shape)  # smoothed depth normals are a few degrees off
    ranked = ranked_primitives(x, nn, ("plane", "cylinder", "cone", "sphere"), cfg, (cyl.axis,))
    assert ranked[0].type == "cylinder" and abs(ranked[0].radius - 0.006) < 0.0005  # type: ignore[attr-defined]
    # a plane patch of the same size stays a plane
    p = np.column_stack([rng.uniform(0, 0.02, 600), rng.uniform(0, 0.015, 600), np.full(600, 0.5)])
    p += noise * rng.standard_normal(p.shape)
    pn = np.tile([0.0, 0.0, -1.0], (600, 1)) + 0.05 * rng.standard_normal((600, 3))
    assert ranked_primitives(p, pn, ("plane", "cylinder", "cone", "sphere"), cfg)[0].type == "plane"


def test_part_frame_on_exact_axes() -> None:
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
