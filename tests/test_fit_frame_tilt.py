"""Aligned planes turned toward their own depth by a bounded angle (`v2c.fit.stage._planes_toward_their_depth`): a
real sensor's box is not square in its depth, and a side held exactly on the shared frame leaves readings
millimetres off; a side within a fraction of a degree of its axis (the generated scans' correlated depth warp)
stays on the frame."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from v2c.camera import backproject
from v2c.fit.config import FitConfig
from v2c.fit.stage import _planes_toward_their_depth
from v2c.geometry.points import instance_points
from v2c.primitives import Plane

from scenes.raycast import planes_depth

K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])
AXIS = np.array([0.0, 0.0, -1.0])  # the frame axis the side is labelled with (facing the camera)
ORIGIN = np.array([0.0, 0.0, 0.6])
SCALE = 0.2  # part size (metres)


def _side(tilt_deg: float, rng: np.random.Generator, noise_m: float = 1e-3, outliers: int = 0, cols: tuple = (80, 240)):
    """A face-on side 0.6 m away, 120 px high, across image columns ``cols`` (160 px: 0.16 m), whose true normal
    lies ``tilt_deg`` off AXIS (turned about the camera's y axis), with ``noise_m`` white depth noise and
    ``outliers`` readings 30-60 mm off (flying pixels). Returns the instance points and the true plane."""
    n_true = Rotation.from_rotvec([0.0, np.deg2rad(tilt_deg), 0.0]).apply(AXIS)
    true = Plane(ORIGIN, n_true)
    inst = np.zeros((240, 320), np.int32)
    inst[60:180, cols[0] : cols[1]] = 1
    depth = planes_depth(inst, K, {1: true})
    on = inst == 1
    depth[on] += rng.normal(0.0, noise_m, int(on.sum()))
    if outliers:
        r, c = np.nonzero(on)
        pick = rng.choice(len(r), outliers, replace=False)
        depth[r[pick], c[pick]] += rng.uniform(0.03, 0.06, outliers)
    pts = backproject(depth, K)
    ipts = instance_points(pts, depth > 0, inst, np.array([1]), FitConfig())
    return ipts, true


def _deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(min(1.0, abs(float(a @ b))))))


def _turn(tilt_deg: float, axis_index: int | None = 2, config: FitConfig | None = None, seed: int = 0, **kw):
    ipts, true = _side(tilt_deg, np.random.default_rng(seed), **kw)
    on_frame = Plane(ORIGIN, AXIS)
    out = _planes_toward_their_depth([on_frame], [1], ipts, {1: axis_index}, SCALE, config or FitConfig())
    return on_frame, out[0], true, ipts[1].points


def test_a_side_far_off_its_axis_turns_toward_its_depth_by_the_bound() -> None:
    cfg = FitConfig()
    for tilt in (2.0, 5.0):  # a side 2 and 5 degrees off the frame, with flying pixels
        on_frame, got, true, x = _turn(tilt, outliers=300)
        # turned by exactly the bound, toward the true normal (the turn's remainder is the angle left to it)
        assert abs(_deg(got.normal_vec, AXIS) - cfg.frame_tilt_max_deg) < 1e-6
        assert abs(_deg(got.normal_vec, true.normal_vec) - (tilt - cfg.frame_tilt_max_deg)) < 0.1
        # through the middle of its readings: the median distance of the points is zero
        assert abs(float(np.median(got.signed_distance(x)))) < 1e-9
    # more of a 2-degree side's readings lie within 3 mm of the turned plane than of the one on the frame
    on_frame, got, true, x = _turn(2.0)
    assert np.mean(np.abs(got.signed_distance(x)) < 3e-3) > np.mean(np.abs(on_frame.signed_distance(x)) < 3e-3)


def test_a_side_between_the_gate_and_the_bound_turns_onto_its_depth() -> None:
    # 0.7 degrees is the bound; a wider bound lets a 1.5-degree side turn the whole way onto its depth
    cfg = replace(FitConfig(), frame_tilt_max_deg=3.0)
    _, got, true, _ = _turn(1.5, config=cfg)
    assert _deg(got.normal_vec, true.normal_vec) < 0.05
    assert abs(_deg(got.normal_vec, AXIS) - 1.5) < 0.05


def test_sides_near_their_axis_unaligned_planes_and_small_patches_stay() -> None:
    for seed in range(3):  # loop over noise draws: a side 0.5 degrees off lifts its free plane by 1.3 mm over its
        on_frame, got, _, _ = _turn(0.5, seed=seed)  # points (under frame_tilt_min_lift, 2 mm), and stays
        assert got is on_frame
    # a strip 20 px (20 mm) across, 5 degrees off: a tilt of 1.6 mm over it, as a correlated depth error makes
    on_frame, got, _, _ = _turn(5.0, cols=(150, 170))
    assert got is on_frame
    # the same tilt over a side 160 mm across (14 mm) turns it
    on_frame, got, _, _ = _turn(5.0)
    assert got is not on_frame
    on_frame, got, _, _ = _turn(5.0, axis_index=-1)  # an unaligned plane is not the frame's to turn
    assert got is on_frame
    on_frame, got, _, _ = _turn(5.0, axis_index=None)
    assert got is on_frame
    # too few points (the side has 19,200), and the step off
    on_frame, got, _, _ = _turn(5.0, config=replace(FitConfig(), frame_tilt_min_points=20_000))
    assert got is on_frame
    on_frame, got, _, _ = _turn(5.0, config=replace(FitConfig(), frame_tilt_max_deg=0.0))
    assert got is on_frame
