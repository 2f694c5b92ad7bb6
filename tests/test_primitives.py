"""Primitives: signed distance, closest point, normal and (u, v) on analytic cases; JSON round trip; local
parameters; axis classes."""

from __future__ import annotations

import numpy as np
import pytest

from v2c.labels import AxisClass
from v2c.primitives import Cone, Cylinder, Plane, Sphere, Torus, from_dict
from v2c.primitives.directions import cross_vec, perturb_direction, rotation_exp, tangent_basis, unit


def test_plane_distance_closest_normal_uv() -> None:
    p = Plane([0, 0, 1.0], [0, 0, -1.0])
    x = np.array([[0.1, 0.2, 0.5], [0.0, 0.0, 1.5]])
    assert np.allclose(p.signed_distance(x), [0.5, -0.5])
    assert np.allclose(p.closest_point(x), [[0.1, 0.2, 1.0], [0.0, 0.0, 1.0]])
    assert np.allclose(p.normal(x), [[0, 0, -1.0]] * 2)
    t1, t2 = tangent_basis(np.array([0, 0, -1.0]))
    assert np.allclose(p.uv(x)[0], [np.array([0.1, 0.2, 0.0]) @ t1, np.array([0.1, 0.2, 0.0]) @ t2])


def test_cylinder_distance_closest_normal_uv() -> None:
    c = Cylinder([0, 0, 0], [0, 0, 1.0], 0.5)
    x = np.array([[2.0, 0, 3.0], [0, 0.25, -1.0], [0, -1.0, 0.0]])
    assert np.allclose(c.signed_distance(x), [1.5, -0.25, 0.5])
    assert np.allclose(c.closest_point(x), [[0.5, 0, 3.0], [0, 0.5, -1.0], [0, -0.5, 0.0]])
    assert np.allclose(c.normal(x), [[1, 0, 0], [0, 1, 0], [0, -1, 0]])
    uv = c.uv(x)
    assert np.allclose(uv[:, 1], [3.0, -1.0, 0.0])
    assert np.isclose(abs(uv[0, 0] - uv[1, 0]), np.pi / 2)  # quarter turn between +x and +y


def test_sphere_distance_closest_normal_uv() -> None:
    s = Sphere([1.0, 0, 0], 2.0)
    x = np.array([[1.0, 0, 5.0], [1.0, 1.0, 0.0]])
    assert np.allclose(s.signed_distance(x), [3.0, -1.0])
    assert np.allclose(s.closest_point(x), [[1.0, 0, 2.0], [1.0, 2.0, 0.0]])
    assert np.allclose(s.normal(x), [[0, 0, 1.0], [0, 1.0, 0]])
    assert np.allclose(s.uv(x), [[0.0, np.pi / 2], [np.pi / 2, 0.0]])


def test_cone_distance_closest_normal_and_apex_region() -> None:
    a = np.deg2rad(30.0)
    c = Cone([0, 0, 0], [0, 0, 1.0], a)
    # a point on the surface at height 2, radius 2 tan(30)
    on = np.array([[2 * np.tan(a), 0, 2.0]])
    assert np.allclose(c.signed_distance(on), 0.0, atol=1e-12)
    # on the axis at height h: inside, distance h sin(a)
    x = np.array([[0, 0, 2.0]])
    assert np.allclose(c.signed_distance(x), -2.0 * np.sin(a))
    # outside along the surface normal
    m = np.array([np.cos(a), 0, -np.sin(a)])
    y = on + 0.3 * m
    assert np.allclose(c.signed_distance(y), 0.3)
    assert np.allclose(c.closest_point(y), on)
    assert np.allclose(c.normal(y), m)
    # behind the apex: the apex is the closest point
    z = np.array([[0.1, 0, -1.0]])
    assert np.allclose(c.signed_distance(z), np.hypot(0.1, 1.0))
    assert np.allclose(c.closest_point(z), [[0, 0, 0]])
    assert np.allclose(c.uv(on)[:, 1], 2.0)


def test_torus_distance_closest_normal_uv() -> None:
    t = Torus([0, 0, 0], [0, 0, 1.0], 2.0, 0.5)
    x = np.array([[3.0, 0, 0], [2.0, 0, 1.0], [0, 2.0, 0.0]])
    assert np.allclose(t.signed_distance(x), [0.5, 0.5, -0.5])
    assert np.allclose(t.closest_point(x), [[2.5, 0, 0], [2.0, 0, 0.5], [0, 2.5, 0]])
    assert np.allclose(t.normal(x[:2]), [[1, 0, 0], [0, 0, 1.0]])
    assert np.allclose(t.uv(x[:2])[:, 1], [0.0, np.pi / 2])


@pytest.mark.parametrize(
    "prim",
    [
        Plane([0.1, 0.2, 0.5], unit(np.array([0.3, -0.2, -1.0]))),
        Cylinder([0.0, 0.1, 0.6], unit(np.array([1.0, 0.2, 0.1])), 0.03),
        Cone([0.0, 0.0, 0.4], unit(np.array([0.1, -1.0, 0.3])), 0.4),
        Sphere([0.02, 0.0, 0.5], 0.04),
        Torus([0.0, 0.0, 0.5], unit(np.array([0.2, 0.3, 1.0])), 0.05, 0.01),
    ],
)
def test_closest_point_lies_on_surface_and_roundtrips(prim) -> None:
    rng = np.random.default_rng(0)
    x = prim.origin + rng.normal(0, 0.05, (500, 3))
    cp = prim.closest_point(x)
    assert np.abs(prim.signed_distance(cp)).max() < 1e-9
    # |signed distance| equals the distance to the closest point
    assert np.allclose(np.abs(prim.signed_distance(x)), np.linalg.norm(x - cp, axis=1), atol=1e-9)
    assert np.allclose(np.linalg.norm(prim.normal(x), axis=1), 1.0)
    back = from_dict(prim.to_dict())
    assert back == prim and type(back) is type(prim)
    same = prim.from_local(np.zeros(prim.local_size), prim.axis_vector)
    assert np.allclose(same.signed_distance(x), prim.signed_distance(x))
    assert prim.uv(x).shape == (500, 2)


def test_direction_reparameterisation_and_axis_class() -> None:
    d0 = unit(np.array([0.2, 0.3, 0.9]))
    t1, t2 = tangent_basis(d0)
    assert np.allclose([d0 @ t1, d0 @ t2, t1 @ t2], 0) and np.allclose(np.cross(t1, t2), d0)
    d = perturb_direction(d0, np.array([0.01, -0.02]))
    assert np.isclose(np.linalg.norm(d), 1) and np.isclose(np.arccos(d @ d0), np.arctan(np.hypot(0.01, 0.02)))
    frame = rotation_exp(np.array([0.3, -0.2, 0.5])).T  # rows X, Y, Z
    cyl = Cylinder([0, 0, 0.5], frame[1], 0.02)
    assert cyl.axis_class(frame) is AxisClass.Y
    tilted = Plane([0, 0, 0.5], perturb_direction(frame[2], np.array([np.tan(np.deg2rad(2.0)), 0])))
    assert tilted.axis_class(frame) is AxisClass.U
    assert Sphere([0, 0, 0], 1.0).axis_class(frame) is None


def test_cross_vec_equals_np_cross_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    for _ in range(2000):
        a, b = rng.normal(size=3) * 10.0 ** rng.uniform(-5, 5), rng.normal(size=3)
        assert np.array_equal(cross_vec(a, b).view(np.int64), np.cross(a, b).view(np.int64))


@pytest.mark.parametrize(
    "prim",
    [
        Plane([0.0, 0.0, 0.5], [0.2, 0.1, -1.0]),
        Sphere([0.0, 0.0, 0.5], 0.05),
        Cylinder([0.0, 0.0, 0.5], [0.1, 1.0, 0.2], 0.04),
        Cone([0.0, 0.0, 0.4], [0.0, 0.3, 1.0], 0.4),
        Torus([0.0, 0.0, 0.5], [0.2, 0.1, 1.0], 0.06, 0.01),
    ],
)
def test_distance_and_normal_equals_the_two_calls(prim: Plane | Sphere | Cylinder | Cone | Torus) -> None:
    x = np.random.default_rng(5).normal(size=(300, 3)) * 0.05 + np.array([0.0, 0.0, 0.5])
    x[0] = prim.origin  # on the axis / at the centre or apex
    d, n = prim.distance_and_normal(x)
    assert np.array_equal(d, prim.signed_distance(x)) and np.array_equal(n, prim.normal(x))
