"""RANSAC per instance recovers known primitives from noisy, partial (camera-facing) samples.

Noise: 0.5 mm Gaussian on the points, about 3 degrees on the normals, 10 % gross outliers; part size 0.2 m,
so d_inlier = 6 mm. Tolerances are stated per assertion.
"""

from __future__ import annotations

import numpy as np
import pytest

from v2c.fit.config import FitConfig
from v2c.fit.constrained import fit_with_axis
from v2c.geometry.ransac import ransac_fit
from v2c.geometry.selection import fit_instance
from v2c.primitives import Cone, Cylinder, Plane, Primitive, Sphere, Torus
from v2c.primitives.directions import angle_between_axes, tangent_basis, unit

SCALE = 0.2
AXIS = unit(np.array([0.3, -0.8, 0.5]))


def visible_samples(prim: Primitive, n: int = 1500, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Points of ``prim`` within 6 cm of its origin that face the camera, with noisy points and normals."""
    rng = np.random.default_rng(seed)
    x = prim.closest_point(prim.origin + rng.normal(0, 0.04, (20 * n, 3)))
    x = x[np.linalg.norm(x - prim.origin, axis=1) < 0.06]
    nn = prim.normal(x)
    x = x[np.sum(nn * x, axis=1) < 0][:n]  # camera-facing side only, as a scan sees it
    nn = prim.normal(x)
    x = x + rng.normal(0, 0.0005, x.shape)
    nn = unit(nn + rng.normal(0, 0.03, nn.shape))
    k = len(x) // 10  # gross outliers
    x[:k] = prim.origin + rng.uniform(-0.06, 0.06, (k, 3))
    return x, nn


def _fit(prim: Primitive) -> Primitive:
    x, n = visible_samples(prim)
    f = ransac_fit(prim.type, x, n, SCALE, FitConfig(), np.random.default_rng(1))
    assert f is not None
    assert 0.8 < f.score < 0.95  # the inliers, not the 10 % outliers
    return f.primitive


def test_plane() -> None:
    gt = Plane([0.01, 0.0, 0.5], AXIS if AXIS[2] < 0 else -AXIS)
    p = _fit(gt)
    assert np.rad2deg(angle_between_axes(p.axis_vector, gt.axis_vector)) < 0.5  # degrees
    assert abs(gt.signed_distance(p.origin[None])[0]) < 0.0003  # metres


def test_cylinder() -> None:
    gt = Cylinder([0.0, 0.0, 0.5], AXIS, 0.03)
    p = _fit(gt)
    assert np.rad2deg(angle_between_axes(p.axis, gt.axis)) < 1.0
    assert abs(p.radius - gt.radius) < 0.01 * gt.radius  # 1 %
    assert abs(Cylinder(gt.origin, gt.axis, 0).signed_distance(p.origin[None])[0]) < 0.001


def test_sphere() -> None:
    gt = Sphere([0.0, 0.02, 0.5], 0.04)
    p = _fit(gt)
    assert np.linalg.norm(p.origin - gt.origin) < 0.001
    assert abs(p.radius - gt.radius) < 0.01 * gt.radius


def test_cone() -> None:
    gt = Cone([0.0, 0.0, 0.46], -AXIS if AXIS[2] < 0 else AXIS, np.deg2rad(35.0))
    p = _fit(gt)
    assert np.rad2deg(angle_between_axes(p.axis, gt.axis)) < 1.5
    assert p.axis @ gt.axis > 0  # towards growing radius
    assert abs(np.rad2deg(p.half_angle - gt.half_angle)) < 1.0
    assert np.linalg.norm(p.origin - gt.origin) < 0.002


def test_torus() -> None:
    gt = Torus([0.0, 0.0, 0.5], AXIS, 0.04, 0.012)
    p = _fit(gt)
    assert np.rad2deg(angle_between_axes(p.axis, gt.axis)) < 1.5
    assert abs(p.radius - gt.radius) < 0.03 * gt.radius
    assert abs(p.minor_radius - gt.minor_radius) < 0.05 * gt.minor_radius
    assert np.linalg.norm(p.origin - gt.origin) < 0.002


@pytest.mark.parametrize(
    "gt", [Plane([0.0, 0.0, 0.5], [0.0, -0.6, -0.8]), Cylinder([0, 0, 0.5], AXIS, 0.02), Sphere([0, 0, 0.5], 0.03)]
)
def test_type_search_picks_the_true_type(gt: Primitive) -> None:
    x, n = visible_samples(gt)
    t, f = fit_instance(x, n, None, SCALE, FitConfig(), np.random.default_rng(2))
    assert t == gt.type and f is not None


def test_deterministic_per_seed() -> None:
    x, n = visible_samples(Cylinder([0, 0, 0.5], AXIS, 0.03))
    a = ransac_fit("cylinder", x, n, SCALE, FitConfig(), np.random.default_rng(5)).primitive
    b = ransac_fit("cylinder", x, n, SCALE, FitConfig(), np.random.default_rng(5)).primitive
    assert a == b
    assert tangent_basis(AXIS)[0] @ AXIS == pytest.approx(0.0, abs=1e-12)


def fillet_samples(gt: Torus, n: int = 600, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """A small fillet as a scan sees it: the camera-facing part of a 90-degree arc of the tube (from the outward
    radial direction towards the axis side, v in [0, 90] degrees) all around the axis; 0.3 mm point noise,
    normals about 20 degrees off (a tube a few pixels wide has poor depth-gradient normals), 5 % outliers."""
    rng = np.random.default_rng(seed)
    t1, t2 = tangent_basis(gt.axis)
    u, v = rng.uniform(0, 2 * np.pi, 20 * n), rng.uniform(0, np.pi / 2, 20 * n)
    e = np.cos(u)[:, None] * t1 + np.sin(u)[:, None] * t2
    nn = np.cos(v)[:, None] * e + np.sin(v)[:, None] * gt.axis
    x = gt.origin + gt.radius * e + gt.minor_radius * nn
    keep = np.flatnonzero(np.sum(nn * x, axis=1) < 0)[:n]
    x, nn = x[keep], nn[keep]
    x = x + rng.normal(0, 0.0003, x.shape)
    nn = unit(nn + rng.normal(0, 0.25, nn.shape))
    k = len(x) // 20
    x[:k] = gt.origin + rng.uniform(-0.025, 0.025, (k, 3))
    return x, nn


def test_small_fillet_torus() -> None:
    """Major 20 mm, minor 2 mm (d_inlier = 3 mm exceeds the tube): the radii stay near the truth instead of a
    fat or giant torus that passes loosely through the band (seen on scans: 1.9 mm came back as 11.6 mm)."""
    gt = Torus([0.0, 0.0, 0.5], AXIS if AXIS[2] < 0 else -AXIS, 0.020, 0.002)
    x, n = fillet_samples(gt)
    f = ransac_fit("torus", x, n, 0.1, FitConfig(), np.random.default_rng(1))
    assert f is not None
    p = f.primitive
    assert np.rad2deg(angle_between_axes(p.axis, gt.axis)) < 1.0  # degrees
    assert abs(p.radius - gt.radius) < 0.0006  # 0.6 mm = 3 % of the major radius
    assert abs(p.minor_radius - gt.minor_radius) < 0.0006  # 0.6 mm = 30 % of the minor radius (noise 0.3 mm)
    assert Cylinder(gt.origin, gt.axis, 0).signed_distance(p.origin[None])[0] < 0.0005  # centre on the axis
    # the refit with the axis held (how the shared frame applies a label) once ran away to r = 15 mm here
    q = fit_with_axis(p, x, n, gt.axis, 0.1, FitConfig())
    assert abs(q.radius - gt.radius) < 0.0006 and abs(q.minor_radius - gt.minor_radius) < 0.0006


def test_type_search_short_cylinder_is_no_sphere() -> None:
    """A short cylinder patch (16 mm along the axis, 100 degrees around it, radius 30 mm): a sphere passes the
    inlier test as well; the type search (GRIC) sees its systematic error and keeps the cylinder."""
    rng = np.random.default_rng(7)
    gt = Cylinder([0.0, 0.0, 0.5], [0.0, 1.0, 0.0], 0.03)
    t = rng.uniform(-0.008, 0.008, 1500)
    phi = rng.uniform(np.deg2rad(-140), np.deg2rad(-40), 1500)  # around -z: the camera-facing side
    radial = np.stack([np.cos(phi), np.zeros_like(phi), np.sin(phi)], axis=1)
    x = gt.origin + 0.03 * radial + t[:, None] * gt.axis + rng.normal(0, 0.0005, (1500, 3))
    n = unit(radial + rng.normal(0, 0.03, radial.shape))
    kind, f = fit_instance(x, n, None, SCALE, FitConfig(), np.random.default_rng(2))
    assert kind == "cylinder" and f is not None


def taper_samples(gt: Cone, n: int = 200, seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """A short patch of a slightly tapered shaft as a small instance shows it: 12 mm along the axis, 100 degrees
    around it; 0.3 mm point noise, and depth-gradient normals smoothed across the shoulder beside it (turned 60
    degrees towards the axis, noise 0.1), so that their angle to the axis says nothing about the taper."""
    rng = np.random.default_rng(seed)
    t1, t2 = tangent_basis(gt.axis)
    h = rng.uniform(0.19, 0.202, n)  # heights from the apex (metres): radius about 17 mm at 5 degrees
    phi = rng.uniform(np.deg2rad(-140), np.deg2rad(-40), n)
    e = np.cos(phi)[:, None] * t1 + np.sin(phi)[:, None] * t2
    x = gt.origin + h[:, None] * gt.axis + (h * np.tan(gt.half_angle))[:, None] * e
    x = x + rng.normal(0, 0.0003, x.shape)
    return x, unit(gt.normal(x) + np.sqrt(3.0) * gt.axis + rng.normal(0, 0.1, x.shape))


def test_axis_refit_keeps_a_slight_taper() -> None:
    """Held on its axis, a 5-degree cone patch with misleading normals keeps its taper. On a benchmark scan the
    start from the normals alone once ran to a 68-degree funnel with its apex 2 m behind the camera; the refit
    now also starts from the free fit, and a joint solve that drives a cone that wide (wider than max_radius at
    its points) goes back (`cone_ok`)."""
    from v2c.geometry.ransac import cone_ok

    axis = unit(np.array([0.05, 0.92, 0.4]))
    gt = Cone(np.array([0.0, 0.0, 0.5]) - 0.196 * axis, axis, np.deg2rad(5.0))
    x, n = taper_samples(gt)
    free = Cone(
        gt.origin + 0.001 * tangent_basis(axis)[0],
        unit(axis + 0.01 * tangent_basis(axis)[1]),
        gt.half_angle + np.deg2rad(0.5),
    )  # a free fit a little off
    q = fit_with_axis(free, x, n, axis, 0.2, FitConfig())
    assert isinstance(q, Cone) and cone_ok(q, x, 0.2, FitConfig())
    assert abs(np.rad2deg(q.half_angle) - 5.0) < 1.5  # degrees
    assert np.median(np.abs(q.signed_distance(x))) < 0.0005  # metres (noise 0.3 mm)
    funnel = Cone(gt.origin - 2.0 * axis, axis, np.deg2rad(68.0))  # the runaway solution's shape
    assert not cone_ok(funnel, x, 0.2, FitConfig())
