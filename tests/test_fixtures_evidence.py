"""Causes of fixtures cutting the true part, injected and checked against it (docs/fixtures.md, "What the scan
vouches for").

The corner of a generated bracket (320 x 240, ground-truth VB-Rep) is moved 3 mm into the part, as a wrong fit
would put it: designed on that reference the locator cuts into the true part (gt/part.step); given the scan's own
points of the part, `design_fixture` refuses it, and still designs the corner on the true reference, which does
not cut. A block's nest on a ground height read 2 mm too high cuts with a floor at the ground, not with the default
floor gap. A flange's bolt hole fitted too wide gives a pin that cuts and cannot be seated: the plane round the rim
or the wall's own points lie inside it, and it is refused; the true hole's pin is kept and seats.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fixtures_design import design_fixture, interference
from fixtures_design.frames import camera_mm_matrix
from fixtures_design.model import transformed
from fixtures_design.verify import observed_inside
from v2c.scan import load_scan

from scenes.truth import synthetic_scan, vbrep_from_scan

#: The injected error (metres): the edge moved this far into the part along both faces' inward normals.
OFFSET_M = 0.003


def _truth_and_points(folder: Path, family: str, seed: int) -> tuple:
    """(ground-truth VB-Rep, true part in the camera frame, the scan's observed points) of a generated scan."""
    path = synthetic_scan(folder, family, seed)
    vb, truth_cam = vbrep_from_scan(path)
    scan = load_scan(path)
    return vb, truth_cam, scan.points()[scan.valid]


@pytest.fixture(scope="module")
def bracket(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    return _truth_and_points(tmp_path_factory.mktemp("evidence_scans"), "bracket", 1)


def test_a_reference_moved_into_the_part_cuts_and_is_refused(bracket: tuple) -> None:
    vb, truth_cam, points = bracket
    fx = design_fixture(vb, "corner", clearance_k=0.0)
    ref = fx.reference
    inward = -(ref.normals[0] + ref.normals[1]) / np.sqrt(2.0)  # both faces' inward normals, 45 deg between
    wrong = replace(ref, start=ref.start + OFFSET_M * inward, end=ref.end + OFFSET_M * inward)
    bad = design_fixture(vb, "corner", clearance_k=0.0, reference=wrong)
    truth = transformed(truth_cam, camera_mm_matrix(bad.fmap))
    assert interference(bad, truth)[1] > 0.01  # the injected error cuts more than 1 % of the fixture into the part
    n_in, deepest = observed_inside(bad, points)
    assert n_in > 100 and deepest > 1.0  # the depth shows material inside it
    with pytest.raises(ValueError, match="scan's points of the part"):
        design_fixture(vb, "corner", clearance_k=0.0, reference=wrong, points=points)


def test_the_true_reference_is_kept_and_does_not_cut(bracket: tuple) -> None:
    vb, truth_cam, points = bracket
    fx = design_fixture(vb, "corner", points=points)
    truth = transformed(truth_cam, camera_mm_matrix(fx.fmap))
    assert observed_inside(fx, points)[0] == 0
    assert interference(fx, truth)[1] < 1e-3


#: The ground estimate's injected error (mm): the scan's ground read this much above the true part's bottom.
GROUND_ERROR_MM = 2.0


def test_a_nest_on_a_ground_read_too_high_does_not_cut(tmp_path_factory: pytest.TempPathFactory) -> None:
    """A generated block's nest (ground-truth VB-Rep) with the ground height read 2 mm too high, as the scan's
    depth offset can put it: a floor at the ground less the clearance cuts the block's bottom; the default floor
    (``floor_gap`` further down, under a relief) does not, and the pocket walls still mate."""
    from fixtures_design import NestParams, check_mating
    from fixtures_design.nest import footprint

    path = synthetic_scan(tmp_path_factory.mktemp("nest_ground"), "block", 0)
    vb, truth_cam = vbrep_from_scan(path)
    ground = (footprint(vb).ground_z + GROUND_ERROR_MM) / 1000.0  # metres along the part's up axis
    flat = design_fixture(vb, "nest", NestParams(floor_gap=0.0), ground_height=ground)
    truth = transformed(truth_cam, camera_mm_matrix(flat.fmap))
    assert interference(flat, truth)[1] > 1e-3
    fx = design_fixture(vb, "nest", NestParams(), ground_height=ground)
    assert interference(fx, truth)[1] < 1e-3
    assert check_mating(fx, truth, max_points_per_face=8).median < 1.0


@pytest.fixture(scope="module")
def flange(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    return _truth_and_points(tmp_path_factory.mktemp("evidence_pins"), "flange", 0)


@pytest.mark.parametrize(
    ("radius_error_mm", "refusal"),
    [(2.0, "wider than the opening the hole's plane shows"), (1.5, "wall points lie inside the pin")],
)
def test_a_hole_fitted_too_wide_gives_a_pin_that_is_refused(
    flange: tuple, radius_error_mm: float, refusal: str
) -> None:
    """A generated flange's bolt hole (ground-truth VB-Rep) fitted 2 mm / 1.5 mm too wide, as a short arc of its
    wall can fit it: a plain cylindrical pin (no taper) cuts into the true part and no move seats the part on it.
    Given the scan's points, the plane round the rim lies inside the pin (2 mm), or the wall's own points do (1.5
    mm), and the default pin is refused (its top at the flange is as wide as the plain pin; its taper takes some of
    such an error, not all)."""
    from fixtures_design import PinParams
    from fixtures_design.design import pin_clearance
    from fixtures_design.seat import seat_part

    vb, truth_cam, points = flange
    ref = design_fixture(vb, "pin", points=points).reference
    wrong = replace(ref, radius=ref.radius + radius_error_mm / 1000.0)
    plain = pin_clearance(PinParams(taper=0.0))  # the default pin's clearance, without its taper
    bad = design_fixture(vb, "pin", plain, reference=wrong)
    truth = transformed(truth_cam, camera_mm_matrix(bad.fmap))
    assert interference(bad, truth)[1] > 0.05
    assert not seat_part(bad, truth).ok
    with pytest.raises(ValueError, match=refusal):
        design_fixture(vb, "pin", reference=wrong, points=points)


def test_the_true_hole_keeps_its_pin_which_seats(flange: tuple) -> None:
    from fixtures_design.seat import seat_part
    from fixtures_design.verify import EvidenceConfig, hole_opening, wall_inside, wall_narrowing

    vb, truth_cam, points = flange
    fx = design_fixture(vb, "pin", points=points)
    ref = fx.reference
    opening = hole_opening(ref.center, ref.axis, ref.radius, points)
    assert opening is not None and abs(opening - ref.radius) < 0.001  # the plane's opening is the hole, within 1 mm
    n_in, n_wall = wall_inside(
        ref.center, ref.axis, ref.radius, fx.notes["pin_radius_mm"] / 1000.0, fx.notes["depth_mm"] / 1000.0, points
    )
    assert n_wall > 0 and n_in == 0
    # ... and its wall, a cylinder, does not narrow going in (within the refusal's margin)
    slope, se, n = wall_narrowing(ref.center, ref.axis, ref.radius, fx.notes["depth_mm"] / 1000.0, points)
    cfg = EvidenceConfig()
    assert n > 0
    assert not (n >= cfg.wall_narrowing_min_points and slope - cfg.wall_narrowing_z * se > cfg.wall_max_narrowing)
    truth = transformed(truth_cam, camera_mm_matrix(fx.fmap))
    assert seat_part(fx, truth).ok
    assert interference(fx, truth)[1] < 1e-3


@pytest.mark.parametrize(("half_angle_deg", "narrowing"), [(45.0, 1.0), (20.0, np.tan(np.radians(20.0))), (0.0, 0.0)])
def test_a_walls_narrowing_is_its_slope_towards_the_axis(half_angle_deg: float, narrowing: float) -> None:
    """Points on a hole's wall seen over a 140-degree arc from 1 to 5 mm deep, 0.1 mm of radial noise: a 45-degree
    countersink (the fit's 12 mm radius at its rim), a 20-degree taper and a cylinder. `wall_narrowing` recovers
    how fast the wall comes nearer the axis (tan of the half-angle) within three of its standard errors, which are
    small (under 0.05), and only the cones are refused by the default bounds."""
    from fixtures_design.verify import EvidenceConfig, wall_narrowing

    rng = np.random.default_rng(3)
    center, axis = np.array([0.01, -0.02, 0.5]), np.array([0.0, 0.6, 0.8])
    u = np.cross(axis, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    w = np.cross(axis, u)
    t = rng.uniform(0.001, 0.005, 400)
    phi = rng.uniform(-np.radians(70), np.radians(70), 400)
    r = 0.012 - narrowing * t + rng.normal(0.0, 1e-4, 400)
    pts = center + np.outer(t, axis) + r[:, None] * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w)
    slope, se, n = wall_narrowing(center, axis, 0.012, 0.010, pts)
    assert n == 400
    assert 0 < se < 0.05 and abs(slope - narrowing) < 3 * se
    cfg = EvidenceConfig()
    assert (slope - cfg.wall_narrowing_z * se > cfg.wall_max_narrowing) == (half_angle_deg > 17.0)
