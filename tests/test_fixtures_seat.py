"""Seating the true part in its fixture (`fixtures_design.seat`, docs/fixtures.md "Seated: the part pushed home").

A generated bracket's true part (gt/part.step) is moved by a known offset, as the scan's depth offset moves the
reconstruction; the seat of a corner locator designed on its ground-truth VB-Rep moves it back into the corner: the
move recovers the offset along the two faces' normals (plus the clearance) within 0.05 mm, leaves the part free
along the edge, and seated the locator touches the part. An offset larger than the seat's bound fails the design.
"""

from __future__ import annotations

import numpy as np
import pytest

from fixtures_design import CornerParams, check_mating, design_fixture, interference
from fixtures_design.frames import camera_mm_matrix
from fixtures_design.model import transformed
from fixtures_design.seat import SeatConfig, seat_bound_mm, seat_part

from scenes.truth import synthetic_scan, vbrep_from_scan

#: The corner's clearance (mm): each inner face lies this far off its true plane before the offset.
CLEARANCE_MM = 0.5


def _moved(shape, offset_mm: np.ndarray):
    m = np.eye(4)
    m[:3, 3] = offset_mm
    return transformed(shape, m)


@pytest.fixture(scope="module")
def corner(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    path = synthetic_scan(tmp_path_factory.mktemp("seat_scans"), "bracket", 1)
    vb, truth_cam = vbrep_from_scan(path)
    fx = design_fixture(vb, "corner", CornerParams(clearance=CLEARANCE_MM))
    return fx, transformed(truth_cam, camera_mm_matrix(fx.fmap))


@pytest.mark.parametrize(
    "coeffs",  # the offset in (face A's normal, face B's normal, the edge) coordinates, mm
    [(0.0, 0.0, 0.0), (0.7, -0.4, 1.5), (-0.9, 0.6, -2.0), (0.3, 1.2, 0.0)],
)
def test_seating_recovers_a_known_offset_in_a_corner(corner: tuple, coeffs: tuple) -> None:
    fx, truth = corner
    a, b = fx.seating.directions
    edge = np.cross(a, b)
    offset = coeffs[0] * a + coeffs[1] * b + coeffs[2] * edge
    part = _moved(truth, offset)
    seat = seat_part(fx, part)
    # Home: back by the offset along both normals, then the clearance further into the corner; nothing along the edge.
    expected = (CLEARANCE_MM - coeffs[0]) * a + (CLEARANCE_MM - coeffs[1]) * b
    assert seat.ok, seat.reason
    assert np.abs(seat.move - expected).max() < 0.05, (seat.move, expected)
    assert abs(seat.move @ edge) < 0.05
    assert seat.min_gap_mm == pytest.approx(0.0, abs=0.05) and seat.contacts > 10
    seated = _moved(part, seat.move)
    assert interference(fx, seated)[1] < 1e-4
    assert check_mating(fx, seated, None, max_points_per_face=40).median < 0.05  # both faces on their planes


@pytest.mark.parametrize("coeffs", [(4.0, 0.0), (-4.0, -4.0)])  # away from the corner, and into it
def test_a_seat_larger_than_the_bound_fails_the_design(corner: tuple, coeffs: tuple) -> None:
    fx, truth = corner
    a, b = fx.seating.directions
    bound = seat_bound_mm(fx)
    assert bound == pytest.approx(3 * CLEARANCE_MM + 2.0)  # SeatConfig's default: 3 x the clearance + 2 mm
    seat = seat_part(fx, _moved(truth, coeffs[0] * a + coeffs[1] * b))
    assert not seat.ok and seat.reason
    # The same part is seated when the bound allows it: the failure is the bound's, not the search's.
    wide = seat_part(fx, _moved(truth, coeffs[0] * a + coeffs[1] * b), SeatConfig(bound_mm=8.0))
    assert wide.ok, wide.reason
    expected = (CLEARANCE_MM - coeffs[0]) * a + (CLEARANCE_MM - coeffs[1]) * b
    assert np.abs(wide.move - expected).max() < 0.05
    assert wide.move_mm > bound


@pytest.fixture(scope="module")
def designs(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Pin (bracket seed 0), cradle (shaft seed 0) and nest (block seed 0) on ground-truth VB-Reps, default
    parameters with the kinds' own clearances (no uncertainty term: clearance_k and pin_k 0), with their true parts
    in the output frame."""
    out = tmp_path_factory.mktemp("seat_kinds")
    res = {}
    for family, seed, kind in [("bracket", 0, "pin"), ("shaft", 0, "cradle"), ("block", 0, "nest")]:
        vb, truth_cam = vbrep_from_scan(synthetic_scan(out, family, seed))
        fx = design_fixture(vb, kind, clearance_k=0.0, pin_k=0.0)
        res[kind] = (fx, transformed(truth_cam, camera_mm_matrix(fx.fmap)))
    return res


@pytest.mark.parametrize("taper", [0.0, 2.0])
def test_a_pin_seats_the_hole_on_its_flange_and_clears_it_across_the_axis(designs: dict, taper: float) -> None:
    """The hole moved 0.6 mm across its axis (into the pin, clearance 0.1) and 0.4 mm onto the flange: the seat
    lifts it back to the flange (0.3 mm) and moves it across by 0.5 mm, just clear of the pin, a plain cylinder or
    the default tapered one (whose cone's top circle is what meets the rim)."""
    from fixtures_design import PinParams, design_pin

    fx, truth = designs["pin"]
    fx = design_pin(fx.reference, fx.fmap, PinParams(clearance=fx.params.clearance, taper=taper))
    c = fx.params.clearance
    z = -fx.seating.push  # the hole's axis, into the part
    r = np.cross(z, [1.0, 0.0, 0.0])
    r /= np.linalg.norm(r)
    seat = seat_part(fx, _moved(truth, 0.6 * r - 0.4 * z))
    assert seat.ok, seat.reason
    assert seat.move @ z == pytest.approx(0.4 - c, abs=0.05)
    across = seat.move - (seat.move @ z) * z
    assert np.abs(across - (-(0.6 - c) * r)).max() < 0.05
    assert interference(fx, _moved(_moved(truth, 0.6 * r - 0.4 * z), seat.move))[1] < 1e-4


def test_a_cradle_lets_the_cylinder_down_into_its_groove(designs: dict) -> None:
    """The shaft moved 0.4 mm sideways and 0.3 mm up: seated it is back under the groove's axis and down on the
    groove (0.3 mm + the clearance), nothing along its axis."""
    fx, truth = designs["cradle"]
    x, y = fx.seating.directions
    axis = np.cross(x, y)
    seat = seat_part(fx, _moved(truth, 0.4 * x + 0.3 * y + 1.0 * axis))
    assert seat.ok, seat.reason
    expected = -0.4 * x - (0.3 + fx.params.clearance) * y
    assert np.abs(seat.move - expected).max() < 0.05, (seat.move, expected)


def test_a_nest_lets_the_part_down_to_its_floor_and_off_its_walls(designs: dict) -> None:
    """The block moved 0.7 mm against a wall and 0.3 mm up: seated it drops onto the floor (0.3 mm + the clearance
    + the floor gap, which the bound allows) and moves off the wall by less than the offset, clear of the nest."""
    fx, truth = designs["nest"]
    up = -fx.seating.push
    side = np.cross(up, [1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    part = _moved(truth, 0.7 * side + 0.3 * up)
    assert interference(fx, part)[1] > 1e-4  # against the wall it cuts
    seat = seat_part(fx, part)
    assert seat.ok, seat.reason
    assert seat.push_mm == pytest.approx(0.3 + fx.params.clearance + fx.params.floor_gap, abs=0.05)
    assert seat.bound_mm == pytest.approx(3 * fx.params.clearance + 2.0 + fx.params.floor_gap)
    across = seat.move - (seat.move @ up) * up
    assert 0.2 < -(across @ side) < 0.7
    assert interference(fx, _moved(part, seat.move))[1] < 1e-4


def test_a_pin_wider_than_its_hole_cannot_be_seated_and_says_by_how_much(designs: dict) -> None:
    """A plain cylindrical pin (no taper) 0.4 mm wider in radius than the true hole (a negative clearance): no move
    clears it, the seat fails and reports the least overlap, 0.4 mm. (It was 0.5 mm until 2026-11-28: the seat's
    bound is then 3 x -0.5 + 2 = 0.5 mm, exactly the overlap, where the rule that a point deeper than the bound
    does not steer the seat flips on 1e-13 mm of rounding; an exporter change that moved the output frame by that
    much made the seat ignore the pin and report a 26.7 mm move instead.)"""
    from fixtures_design import PinParams, design_pin
    from fixtures_design.seat import seat_bound_mm

    fx, truth = designs["pin"]
    tight = design_pin(fx.reference, fx.fmap, PinParams(clearance=-0.4, taper=0.0))
    assert seat_bound_mm(tight) == pytest.approx(0.8)  # the overlap is well inside the bound
    seat = seat_part(tight, truth)
    assert not seat.ok and "too tight" in seat.reason
    assert seat.overlap_mm == pytest.approx(0.4, abs=0.05)


@pytest.mark.parametrize("too_wide_mm", [1.0, 1.5])
def test_a_tapered_pin_takes_a_hole_fitted_too_wide_on_its_cone(designs: dict, too_wide_mm: float) -> None:
    """The hole's radius fitted 1 or 1.5 mm too wide, the pin's clearance 0.66 mm (the default, 3 x 0.22): the pin's
    top is 0.34 or 0.84 mm wider than the true hole. A plain cylinder cannot be seated; the default pin, whose side
    narrows by 2 mm along a 45-degree cone below the flange, takes the hole: seated, the rim rests on the cone and
    the part's plane stands (top radius - true radius) / tan(45) above the flange (no higher; lower by at most the
    seat's sample spacing along the cone's 2.8 mm side, 0.3 mm), cutting under the bench's 0.1 % and touching
    (median under 1 mm)."""
    import dataclasses

    from fixtures_design import PinParams, design_pin

    fx, truth = designs["pin"]
    c = 0.66
    wide = dataclasses.replace(fx.reference, radius=fx.reference.radius + too_wide_mm / 1000.0)
    plain = design_pin(wide, fx.fmap, PinParams(clearance=c, taper=0.0))
    assert not seat_part(plain, truth).ok
    tapered = design_pin(wide, fx.fmap, PinParams(clearance=c))
    assert tapered.notes["shank_radius_mm"] == pytest.approx(tapered.notes["pin_radius_mm"] - PinParams().taper)
    seat = seat_part(tapered, truth)
    assert seat.ok, seat.reason
    z = -tapered.seating.push  # the hole's axis, into the part; the flange's underside lies at -c along it
    above_flange = seat.move @ z + c
    expected = too_wide_mm - c  # the top radius less the true one, over tan(45 degrees)
    assert expected - 0.3 <= above_flange <= expected + 0.05, (above_flange, expected)
    seated = _moved(truth, seat.move)
    assert interference(tapered, seated)[1] < 1e-3
    assert check_mating(tapered, seated, None, max_points_per_face=120).median < 1.0
