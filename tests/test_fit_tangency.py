"""Tangent (G1) constraints of the geometry stage (v2c.fit.tangency, issue 16 item 1), on exact surfaces with depth
noise: a fillet between two planes and a dome on a cylinder are refitted tangent to their neighbours with their
true radius and placement; a cylinder that crosses a plane at 30 degrees is not a tangent junction."""

from __future__ import annotations

import numpy as np

from v2c.fit.config import FitConfig
from v2c.fit.tangency import constrain_blends, tangent_junctions
from v2c.primitives import Cylinder, Plane, Sphere

Z = 0.5  # metres from the camera
RNG_SEED = 3


def _noisy(x: np.ndarray, n: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Points moved along their normals by Gaussian noise of ``sigma`` metres."""
    return x + rng.normal(0.0, sigma, (len(x), 1)) * n


def _fillet_arc(c: np.ndarray, r: float, n_pts: int, rng: np.random.Generator) -> np.ndarray:
    """Points on the quarter arc of the cylinder (axis +x through ``c``) between the plane z = Z (facing the camera
    at -z) and the plane y = c_y + r, over x in [-0.03, 0.03] m."""
    t = rng.uniform(0.0, np.pi / 2, n_pts)
    xs = rng.uniform(-0.03, 0.03, n_pts)
    # the arc from the top face (normal -z) round to the side face (normal +y)
    nrm = np.stack([np.zeros(n_pts), np.sin(t), -np.cos(t)], axis=1)
    return np.stack([xs, c[1] + r * np.sin(t), c[2] - r * np.cos(t)], axis=1), nrm


def _junction_samples(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rays with z = 1, z-depths) of camera-frame points ``p`` (N, 3)."""
    return p / p[:, 2:3], p[:, 2].copy()


def test_fillet_between_two_planes_gets_its_true_radius() -> None:
    """A 10 mm fillet whose free fit came out at 13 mm and 1.4 mm off: refitted tangent to both planes, radius within
    0.2 mm and the axis line within 0.2 mm of the truth (noise 0.3 mm)."""
    rng = np.random.default_rng(RNG_SEED)
    r_true = 0.010
    top = Plane(np.array([0.0, 0.0, Z]), np.array([0.0, 0.0, -1.0]))  # n . x = -Z
    side = Plane(np.array([0.0, 0.04, Z]), np.array([0.0, 1.0, 0.0]))  # y = 0.04
    c_true = np.array([0.0, 0.04 - r_true, Z + r_true])
    arc, nrm = _fillet_arc(c_true, r_true, 400, rng)
    x = _noisy(arc, nrm, 0.0003, rng)
    free = Cylinder(c_true + np.array([0.0, -0.001, 0.001]), np.array([1.0, 0.0, 0.0]), 0.013)
    prims = [top, free, side]
    # boundary samples where the arc meets each plane (candidates: term indices)
    meet_top = np.stack([np.linspace(-0.02, 0.02, 6), np.full(6, c_true[1]), np.full(6, Z)], axis=1)
    meet_side = np.stack([np.linspace(-0.02, 0.02, 6), np.full(6, 0.04), np.full(6, c_true[2])], axis=1)
    rays, s = _junction_samples(np.concatenate([meet_top, meet_side]))
    cands = [(0, 1)] * 6 + [(1, 2)] * 6
    cfg = FitConfig()
    # the free fit is not tangent to its neighbours by much: the test must still find the junctions at 10 degrees
    junctions = tangent_junctions(prims, rays, s, cands, np.full(12, -1), cfg)
    assert {(j.a, j.b) for j in junctions} == {(0, 1), (1, 2)}
    out, taken = constrain_blends(prims, junctions, lambda i: x, 0.1, cfg)
    assert taken == {1: "fillet"}
    cyl = out[1]
    assert abs(cyl.radius - r_true) < 0.0002
    off = (cyl.origin - c_true) - ((cyl.origin - c_true) @ cyl.axis) * cyl.axis
    assert np.linalg.norm(off) < 0.0002
    assert abs(abs(cyl.axis @ np.array([1.0, 0.0, 0.0])) - 1.0) < 1e-9
    # tangent to both planes: the axis line at the radius from each
    assert abs(abs(top.signed_distance(cyl.origin[None])[0]) - cyl.radius) < 1e-9
    assert abs(abs(side.signed_distance(cyl.origin[None])[0]) - cyl.radius) < 1e-9
    assert out[0] is top and out[2] is side  # neighbours held


def test_dome_on_a_cylinder_is_centred_on_its_axis() -> None:
    """A hemisphere of the shaft's radius whose free fit is 3 mm off the axis and 2 mm too large: refitted on the
    axis with the shaft's radius, its centre within 0.2 mm of the truth."""
    rng = np.random.default_rng(RNG_SEED)
    r = 0.02
    shaft = Cylinder(np.array([0.0, 0.0, Z]), np.array([0.0, 1.0, 0.0]), r)
    c_true = np.array([0.0, 0.03, Z])
    # visible half of the dome (facing the camera, -z), beyond the junction (y > 0.03)
    u = rng.normal(size=(600, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u = u[(u[:, 1] > 0.05) & (u[:, 2] < -0.1)]
    x = _noisy(c_true + r * u, u, 0.0003, rng)
    free = Sphere(c_true + np.array([0.003, 0.002, 0.0]), 0.022)
    ring = c_true + r * np.stack([np.sin(np.linspace(-1, 1, 8)), np.zeros(8), -np.cos(np.linspace(-1, 1, 8))], 1)
    rays, s = _junction_samples(ring)
    cfg = FitConfig()
    junctions = tangent_junctions([shaft, free], rays, s, [(0, 1)] * 8, np.full(8, -1), cfg)
    assert [(j.a, j.b) for j in junctions] == [(0, 1)]
    out, taken = constrain_blends([shaft, free], junctions, lambda i: x, 0.1, cfg)
    assert taken == {1: "dome"}
    assert out[1].radius == r
    assert np.linalg.norm(out[1].origin - c_true) < 0.0002


def test_a_crossing_is_not_a_tangent_junction() -> None:
    """A cylinder that meets a plane at 30 degrees: no junction, nothing refitted."""
    plane = Plane(np.array([0.0, 0.0, Z]), np.array([0.0, 0.0, -1.0]))
    r = 0.01
    # axis along x, axis line 8.66 mm behind the plane: the surfaces cross at 30 degrees
    cyl = Cylinder(np.array([0.0, 0.0, Z + r * np.cos(np.pi / 6)]), np.array([1.0, 0.0, 0.0]), r)
    meet = np.stack([np.linspace(-0.02, 0.02, 6), np.full(6, r * np.sin(np.pi / 6)), np.full(6, Z)], axis=1)
    rays, s = _junction_samples(meet)
    ang = np.degrees(np.arccos(np.abs(np.einsum("ij,ij->i", plane.normal(meet), cyl.normal(meet)))))
    assert np.allclose(ang, 30.0)
    assert tangent_junctions([plane, cyl], rays, s, [(0, 1)] * 6, np.full(6, -1), FitConfig()) == []


def _blend_strip(rc: float, r: float, n_pts: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Points on the concave fillet (a torus) between a plate facing the camera (z = Z, normal -z) and a boss of
    radius ``rc`` standing out of it towards the camera (axis -z, through x = y = 0), over 40 degrees of azimuth:
    tube centre circle at radius rc + r and z = Z - r; with the outward normals (towards the tube's centre line,
    away from the material)."""
    az = rng.uniform(-0.35, 0.35, n_pts)
    t = rng.uniform(0.0, np.pi / 2, n_pts)  # 0: on the plate, pi / 2: on the boss's wall
    radial = np.stack([np.cos(az), np.sin(az), np.zeros(n_pts)], axis=1)
    centre = (rc + r) * radial + np.array([0.0, 0.0, Z - r])
    nrm = -np.cos(t)[:, None] * np.array([0.0, 0.0, -1.0]) - np.sin(t)[:, None] * radial
    return centre - r * nrm, nrm


def test_a_small_torus_blend_is_refitted_onto_its_boss_and_plate() -> None:
    """A 2 mm fillet at the foot of a 12 mm boss, seen as 40 points: its free fit (the kind of a corpus blend of a
    few pixels) has its ring 4 mm too large and its centre 3.6 mm off. Refitted as a blend tangent to the boss and
    the plate (only the minor radius free): both radii within 0.2 mm and the centre within 0.2 mm."""
    from v2c.primitives import Torus

    rng = np.random.default_rng(RNG_SEED)
    rc, r = 0.012, 0.002
    x = _noisy(*_blend_strip(rc, r, 40, rng), 0.0001, rng)
    plate = Plane(np.array([0.0, 0.0, Z]), np.array([0.0, 0.0, -1.0]))
    boss = Cylinder(np.array([0.0, 0.0, Z - 0.02]), np.array([0.0, 0.0, -1.0]), rc)
    free = Torus(np.array([-0.003, 0.0, Z - r - 0.002]), np.array([0.0, 0.0, -1.0]), rc + r + 0.004, r)
    prims = [plate, boss, free]
    cfg = FitConfig()
    out, taken = constrain_blends(
        prims, [], lambda i: x, 0.1, cfg, adjacent={0: [2], 1: [2], 2: [0, 1]}, all_points=lambda i: x
    )
    assert taken == {2: "torus blend"}
    t = out[2]
    assert isinstance(t, Torus)
    assert abs(t.minor_radius - r) < 2e-4 and abs(t.radius - (rc + r)) < 2e-4
    assert np.linalg.norm(t.origin - np.array([0.0, 0.0, Z - r])) < 2e-4
    # without the neighbours' adjacency nothing changes
    same, none = constrain_blends(prims, [], lambda i: x, 0.1, cfg)
    assert none == {} and same[2] is free


def test_a_torus_the_blend_does_not_explain_keeps_its_fit() -> None:
    """A rounded ring (a 5 mm tube on a 30 mm ring, 170 degrees of its tube seen over 60 degrees of azimuth) beside
    a coaxial 12 mm cylinder and a plate it is not tangent to: no blend of them explains its points as well as its
    own fit (a tube of 5 mm on the cylinder would be a ring of 17 mm, a ring of 30 mm a tube of 18 mm), so the fit
    stays."""
    from v2c.primitives import Torus

    rng = np.random.default_rng(RNG_SEED)
    true = Torus(np.array([0.0, 0.0, Z - 0.01]), np.array([0.0, 0.0, -1.0]), 0.030, 0.005)
    az = rng.uniform(-0.5, 0.5, 200)
    t = rng.uniform(-1.5, 1.5, 200)
    radial = np.stack([np.cos(az), np.sin(az), np.zeros(200)], axis=1)
    nrm = np.cos(t)[:, None] * radial + np.sin(t)[:, None] * np.array([0.0, 0.0, -1.0])
    x = _noisy(true.origin + 0.030 * radial + 0.005 * nrm, nrm, 0.0001, rng)
    plate = Plane(np.array([0.0, 0.0, Z]), np.array([0.0, 0.0, -1.0]))
    boss = Cylinder(np.array([0.0, 0.0, Z - 0.02]), np.array([0.0, 0.0, -1.0]), 0.012)
    out, taken = constrain_blends(
        [plate, boss, true], [], lambda i: x, 0.1, FitConfig(), adjacent={2: [0, 1]}, all_points=lambda i: x
    )
    assert taken == {} and out[2] is true
