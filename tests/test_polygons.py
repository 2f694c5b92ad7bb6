"""The 2D polygon helpers of the STEP exporter (exporters/polygons.py; shapely for Douglas-Peucker and signed area)
and the rotation helpers on scipy's Rotation (synth rest pose, bench tilt), against hand-computed ground truth."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from exporters.polygons import polygon_crossings, signed_area, simplify_polyline
from v2c.bench.metrics import _rotate
from v2c.polyline import rdp_indices


def _sorted_rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


def test_simplify_polyline_keeps_corners_and_drops_flat_points() -> None:
    poly = np.array([[0.0, 0.0], [1.0, 0.01], [2.0, 0.0], [2.01, 1.0], [2.0, 2.0]])
    np.testing.assert_array_equal(simplify_polyline(poly, 0.1), poly[[0, 2, 4]])
    np.testing.assert_array_equal(simplify_polyline(poly, 0.001), poly)
    np.testing.assert_array_equal(simplify_polyline(poly[:2], 5.0), poly[:2])


def test_simplify_polyline_keeps_a_turning_point_beyond_the_chord() -> None:
    # distance to the chord as a segment: (3, 0) is 2 from the chord (0, 0)-(1, 0), though on its line
    poly = np.array([[0.0, 0.0], [3.0, 0.0], [1.0, 0.0]])
    np.testing.assert_array_equal(simplify_polyline(poly, 0.5), poly)


def test_simplify_polyline_matches_the_numpy_douglas_peucker() -> None:
    rng = np.random.default_rng(3)
    for _ in range(40):
        pts = np.cumsum(rng.normal(size=(int(rng.integers(3, 200)), 2)), axis=0)
        tol = float(rng.uniform(0.1, 3.0))
        np.testing.assert_array_equal(simplify_polyline(pts, tol), pts[rdp_indices(pts, tol, clamp=True)])


def test_polygon_crossings_of_a_bow_tie_and_of_two_overlapping_squares() -> None:
    bow_tie = np.array([[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]])
    np.testing.assert_allclose(polygon_crossings([bow_tie]), [[1.0, 1.0]], atol=1e-12)
    a = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    b = a + 1.0
    np.testing.assert_allclose(_sorted_rows(polygon_crossings([a, b])), [[1.0, 2.0], [2.0, 1.0]], atol=1e-12)


def test_polygon_crossings_ignore_touching_and_nesting() -> None:
    a = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    assert polygon_crossings([a]).shape == (0, 2)
    assert polygon_crossings([a, a + [2.0, 0.0]]).shape == (0, 2)  # shares an edge
    assert polygon_crossings([a, a + 2.0]).shape == (0, 2)  # shares a vertex
    assert polygon_crossings([a, np.array([[2.0, 1.0], [3.0, 0.0], [3.0, 2.0]])]).shape == (0, 2)  # vertex on edge
    assert polygon_crossings([a, 0.5 * a + 0.5]).shape == (0, 2)  # a hole inside


def test_signed_area_is_positive_counter_clockwise() -> None:
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 3.0], [0.0, 3.0]])
    assert signed_area(square) == pytest.approx(6.0, abs=1e-12)
    assert signed_area(square[::-1]) == pytest.approx(-6.0, abs=1e-12)
    assert signed_area(np.vstack([square, square[:1]])) == pytest.approx(6.0, abs=1e-12)  # closed explicitly
    n, r = 64, 1.5
    t = 2 * np.pi * np.arange(n) / n
    ngon = r * np.stack([np.cos(t), np.sin(t)], 1) + [10.0, -4.0]
    assert signed_area(ngon) == pytest.approx(0.5 * n * r * r * np.sin(2 * np.pi / n), rel=1e-12)
    assert signed_area(square[:2]) == 0.0


def test_rotate_about_an_unnormalised_axis() -> None:
    np.testing.assert_allclose(
        _rotate(np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 5.0]), np.pi / 2), [0, 1, 0], atol=1e-15
    )
    axis, v = np.array([1.0, 2.0, 2.0]), np.array([0.3, -1.0, 0.4])
    out = _rotate(v, axis, 0.7)
    assert np.linalg.norm(out) == pytest.approx(np.linalg.norm(v), rel=1e-14)
    assert out @ axis == pytest.approx(v @ axis, abs=1e-14)  # the component along the axis stays
    k = axis / 3.0
    vp, op = v - k * (k @ v), out - k * (k @ out)
    assert np.arccos(vp @ op / (np.linalg.norm(vp) * np.linalg.norm(op))) == pytest.approx(0.7, abs=1e-12)
    assert np.cross(vp, op) @ k > 0  # counter-clockwise about the axis


def test_hull_rest_rotation_puts_the_largest_face_down_and_a_side_on_x() -> None:
    build123d = pytest.importorskip("build123d")
    from v2c.synth import occ
    from v2c.synth.parts import _hull_rest_rotation

    tilt = Rotation.from_rotvec(0.5 * np.array([1.0, 1.0, 0.3]) / np.linalg.norm([1.0, 1.0, 0.3])).as_matrix()
    plate = occ.transform_shape(build123d.Box(40.0, 30.0, 5.0).wrapped, np.hstack([tilt, np.zeros((3, 1))]))
    rot = _hull_rest_rotation(plate)
    assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
    big, side, long_side = tilt[:, 2], tilt[:, 1], tilt[:, 0]  # normals of the 40x30, 40x5 and 30x5 faces
    np.testing.assert_allclose(np.abs(rot @ big), [0.0, 0.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(np.abs(rot @ side), [1.0, 0.0, 0.0], atol=1e-9)  # the larger upright face
    np.testing.assert_allclose(np.abs(rot @ long_side), [0.0, 1.0, 0.0], atol=1e-9)
