"""An unaligned instance whose own points hardly fix its axis takes a direction its neighbours give
(`v2c.fit.stage._related_axes`, issue 16: on the CAD corpus's training split the largest axis errors of the oracle
path were small unaligned faces whose free axes their few pixels did not fix)."""

from __future__ import annotations

import numpy as np

from v2c.fit.config import FitConfig
from v2c.fit.stage import _Fits, _related_axes
from v2c.geometry.points import InstancePoints
from v2c.primitives import Plane
from v2c.primitives.directions import tangent_basis, unit

SCALE = 0.1  # part size (m)
NOISE = 5e-5  # m along the normal


def _plane_points(
    origin: np.ndarray, normal: np.ndarray, extent: tuple[float, float], n: int, seed: int
) -> InstancePoints:
    """``n`` points of a plane patch (``extent`` metres along its two tangents), noisy along the normal, with
    normals facing the camera at the origin."""
    rng = np.random.default_rng(seed)
    t1, t2 = tangent_basis(normal)
    u = rng.uniform(-extent[0] / 2, extent[0] / 2, n)
    v = rng.uniform(-extent[1] / 2, extent[1] / 2, n)
    x = origin + u[:, None] * t1 + v[:, None] * t2 + rng.normal(0.0, NOISE, n)[:, None] * normal
    nrm = np.repeat((normal if normal @ origin < 0 else -normal)[None], n, axis=0)
    return InstancePoints(pixels=np.arange(n), points=x, normals=nrm)


def _scene(small_normal: np.ndarray, small_fit: np.ndarray, extent: tuple[float, float], n_small: int):
    """A 5 x 5 cm anchor plane tilted off every camera axis (2,000 points) and a small plane patch 1 cm in front
    of it; the small patch's points lie on a plane of normal ``small_normal``, its free fit has ``small_fit``."""
    anchor_n = unit(np.array([0.3, -0.4, -0.866]))
    o1 = np.array([0.0, 0.0, 0.5])
    o2 = o1 + np.array([0.03, 0.0, -0.01])
    fits = _Fits()
    ipts = {
        1: _plane_points(o1, anchor_n, (0.05, 0.05), 2000, 1),
        2: _plane_points(o2, small_normal, extent, n_small, 2),
    }
    fits.prims = {1: Plane(o1, anchor_n), 2: Plane(ipts[2].points.mean(0), unit(small_fit))}
    fits.inliers = {i: np.ones(len(ipts[i].points), bool) for i in ipts}
    return fits, ipts, anchor_n


def test_a_thin_strip_takes_its_neighbours_normal() -> None:
    """A strip 40 x 0.3 mm parallel to its neighbour (a step's edge face seen one pixel wide): its points fit any
    plane through their line, and its free fit is turned 20 degrees about that line. It takes the neighbour's
    normal (within 0.5 degrees) and is held; not touching the neighbour in the instance map, it keeps its own."""
    anchor_n = unit(np.array([0.3, -0.4, -0.866]))
    t1, _ = tangent_basis(anchor_n)  # the strip's long side lies along t1
    turn = np.deg2rad(20.0)
    turned = np.cos(turn) * anchor_n + np.sin(turn) * np.cross(t1, anchor_n)
    cfg = FitConfig()
    fits, ipts, _ = _scene(anchor_n, turned, (0.04, 0.0003), 80)
    held = _related_axes(fits, ipts, {1: -1, 2: -1}, np.array([[1, 2]]), SCALE, cfg)
    assert held == {2}
    assert abs(fits.prims[2].axis_vector @ anchor_n) > np.cos(np.deg2rad(0.5))

    fits, ipts, _ = _scene(anchor_n, turned, (0.04, 0.0003), 80)
    held = _related_axes(fits, ipts, {1: -1, 2: -1}, np.array([[1, 0, 2]]), SCALE, cfg)
    assert held == set()
    assert abs(fits.prims[2].axis_vector @ unit(turned)) > 1 - 1e-12


def test_a_patch_whose_points_fix_another_normal_keeps_it() -> None:
    """A 1 x 1 cm patch (150 points) truly 30 degrees off its neighbour (within related_max_deg): held on the
    neighbour's normal its points would lie up to 2.9 mm off, so it keeps its own normal."""
    anchor_n = unit(np.array([0.3, -0.4, -0.866]))
    t1, _ = tangent_basis(anchor_n)
    turn = np.deg2rad(30.0)
    own = np.cos(turn) * anchor_n + np.sin(turn) * np.cross(t1, anchor_n)
    cfg = FitConfig()
    assert cfg.related_max_deg > 30.0
    fits, ipts, _ = _scene(own, own, (0.01, 0.01), 150)
    held = _related_axes(fits, ipts, {1: -1, 2: -1}, np.array([[1, 2]]), SCALE, cfg)
    assert held == set()
    assert abs(fits.prims[2].axis_vector @ unit(own)) > 1 - 1e-12
