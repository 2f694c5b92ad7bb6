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
