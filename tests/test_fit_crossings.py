"""Unaligned planes laid along the line where two neighbouring planes meet (`v2c.fit.stage._planes_along_crossings`):
a chamfer's points, tilted by the sensor's correlated depth error, do not fix its normal to a degree; the crossing
of the faces it joins does."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from v2c.camera import backproject, pixel_rays
from v2c.fit.config import FitConfig
from v2c.fit.stage import _planes_along_crossings
from v2c.geometry.points import instance_points
from v2c.primitives import Plane

from scenes.raycast import planes_depth

K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])


def _scene(tilt_per_px: float, rng: np.random.Generator, cols: tuple[int, int] = (100, 220), noise_m: float = 2e-4):
    """A face-on plane A (rows 60-99), a 45-degree chamfer B (rows 100-107, columns ``cols``) and a steep wall C
    (rows 108-140), columns 100-219, meeting along the image rows (the crossing of A and C runs along the camera's
    x axis); B's other columns read nothing. B's depth carries a ramp along its length (``tilt_per_px`` metres per
    column: a correlated depth error) and ``noise_m`` of white noise."""
    ray = pixel_rays(np.array([[160.0, 99.5]]), K)[0]
    a = Plane([0.0, 0.0, 0.5], [0.0, 0.0, -1.0])
    nb = np.array([0.0, 1.0, -1.0]) / np.sqrt(2.0)
    b = Plane(ray * 0.5, nb)
    ray2 = pixel_rays(np.array([[160.0, 107.5]]), K)[0]
    p1 = ray2 * float(nb @ (ray * 0.5) / (nb @ ray2))
    c = Plane(p1, np.array([0.0, 1.0, -0.2]) / np.hypot(1.0, 0.2))
    inst = np.zeros((240, 320), np.int32)
    inst[60:100, 100:220], inst[100:108, cols[0] : cols[1]], inst[108:141, 100:220] = 1, 2, 3
    depth = planes_depth(inst, K, {1: a, 2: b, 3: c})
    on_b = inst == 2
    u = np.nonzero(on_b)[1].astype(float)
    depth[on_b] += tilt_per_px * (u - u.mean()) + rng.normal(0.0, noise_m, int(on_b.sum()))
    return depth, inst, (a, b, c)


def _fit_b(depth: np.ndarray, inst: np.ndarray, planes, cfg: FitConfig) -> tuple[Plane, Plane]:
    """The chamfer's free plane (total least squares through its points) and the same after the crossing step."""
    pts = backproject(depth, K)
    ipts = instance_points(pts, depth > 0, inst, np.array([1, 2, 3]), cfg)
    x = ipts[2].points
    c = x - x.mean(axis=0)
    n = np.linalg.svd(c, full_matrices=False)[2][-1]
    free = Plane(x.mean(axis=0), n if n @ planes[1].axis_vector > 0 else -n)
    prims = [planes[0], free, planes[2]]
    out = _planes_along_crossings(prims, [1, 2, 3], ipts, {1: 2, 2: -1, 3: None}, inst, 0.1, cfg)
    return free, out[1]


def _deg(p: Plane, q: Plane) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(p.axis_vector @ q.axis_vector))))))


def test_a_short_tilted_chamfer_is_laid_along_the_crossing_of_its_neighbours() -> None:
    # A chamfer 12 columns long (8 rows, 96 px) with 0.8 mm of noise and a ramp of 0.04 mm per column along it:
    # its free plane is 2.3-5.6 degrees off over ten noise draws. Where its points cannot tell the tilt along the
    # crossing of A and C from the noise (RMS ratio at most 1.05), it is laid along that crossing: its normal keeps
    # no x component and comes nearer the true chamfer's (what is left is its turn about the crossing, which only
    # its 8 rows measure); where they can, it is kept.
    errors = []
    for seed in range(10):  # loop over noise draws
        depth, inst, planes = _scene(4e-5, np.random.default_rng(seed), cols=(150, 162), noise_m=8e-4)
        free, got = _fit_b(depth, inst, planes, FitConfig())
        if got is not free:
            assert abs(float(got.axis_vector[0])) < 1e-9  # perpendicular to the crossing line
            assert _deg(got, planes[1]) <= _deg(free, planes[1])
        errors.append((_deg(free, planes[1]), _deg(got, planes[1])))
    assert sum(1 for e in errors if e[1] < e[0]) >= 7
    assert np.mean([e[1] for e in errors]) < np.mean([e[0] for e in errors]) - 0.5
    # off (a ratio no fit meets), every free plane is kept
    depth, inst, planes = _scene(4e-5, np.random.default_rng(1), cols=(150, 162), noise_m=8e-4)
    free, kept = _fit_b(depth, inst, planes, replace(FitConfig(), crossing_max_rms_ratio=0.0))
    assert kept is free


def test_a_plane_across_the_crossing_is_kept() -> None:
    # the chamfer turned 30 degrees about the image's vertical is no chamfer of A and C: laid along their crossing
    # it leaves its points far off (the RMS ratio is far above 1.05), so its own plane stays
    depth, inst, planes = _scene(0.0, np.random.default_rng(1))
    a, b, c = planes
    turn = np.radians(30.0)
    rot = np.array([[np.cos(turn), 0.0, np.sin(turn)], [0.0, 1.0, 0.0], [-np.sin(turn), 0.0, np.cos(turn)]])
    b2 = Plane(np.asarray(b.origin, float), rot @ np.asarray(b.axis_vector, float))
    depth = np.where(inst == 2, planes_depth(inst, K, {2: b2}), depth)
    free, got = _fit_b(depth, inst, (a, b2, c), FitConfig())
    assert _deg(free, b2) < 0.5
    assert _deg(got, free) < 1e-9
