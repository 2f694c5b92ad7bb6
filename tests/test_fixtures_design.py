"""Fixtures on generated scans whose true part is known (gt/part.step, camera frame, mm).

For each fixture: its mating faces lie within max(0.5 mm, 1 % of the part size) of the true face they reference
(the true part as a whole for a nest's pocket walls), and it does not cut into the true part (OCCT common volume
under 0.1 % of the fixture's volume). Ground-truth VB-Reps come from `scenes.truth.vbrep_from_scan` (tests/scenes);
the last test uses the real reconstruction (`v2c.pipeline.reconstruct`, oracle segmentation).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fixtures_design import CradleParams, check_mating, design_fixture, interference
from fixtures_design.frames import camera_mm_matrix, up_vector
from fixtures_design.model import transformed

from scenes.truth import synthetic_scan, true_faces, vbrep_from_scan

#: (family, seed) of the generated scans and the fixtures each one gets (seeds chosen for the needed feature).
CASES = [
    ("block", 0, "corner"),
    ("block", 0, "nest"),
    ("bracket", 0, "pin"),
    ("bracket", 1, "corner"),
    ("shaft", 0, "cradle"),
    ("shaft", 2, "cradle"),
]


@pytest.fixture(scope="module")
def scans(tmp_path_factory: pytest.TempPathFactory) -> dict[tuple[str, int], tuple]:
    out = tmp_path_factory.mktemp("fixture_scans")
    res = {}
    for family, seed in sorted({(f, s) for f, s, _ in CASES}):
        path = synthetic_scan(out, family, seed)
        vb, truth_cam = vbrep_from_scan(path)
        res[(family, seed)] = (path, vb, truth_cam)
    return res


def _measure(vb, truth_cam, fx, points_per_face: int = 40):
    m = camera_mm_matrix(fx.fmap)
    truth = transformed(truth_cam, m)
    mating = check_mating(fx, truth, true_faces(vb, truth_cam, m), max_points_per_face=points_per_face)
    common, frac = interference(fx, truth)
    return mating, common, frac


@pytest.mark.parametrize("family,seed,kind", CASES)
def test_fixture_mates_with_the_true_part_and_does_not_cut_it(scans, family, seed, kind):
    _, vb, truth_cam = scans[(family, seed)]
    fx = design_fixture(vb, kind, frame="part")
    tol = max(0.5, 0.01 * vb.scale * 1000.0)
    mating, common, frac = _measure(vb, truth_cam, fx, 8 if kind == "nest" else 40)
    assert fx.solid.is_valid and fx.volume_mm3 > 1000.0
    # A pin's side is a cone below its flange: it stands off the hole's wall by the clearance at the flange and by
    # up to the clearance + its taper at the cone's foot, half the taper more at its middle.
    taper = fx.params.taper if kind == "pin" else 0.0
    assert mating.max < tol + taper, (kind, mating)
    # The clearance is the designed gap: every mating face sits about that far from its true face.
    clearance = fx.params.clearance
    assert clearance - 0.25 <= mating.median <= clearance + taper / 2 + 0.25, (kind, mating.median)
    assert frac < 1e-3, (kind, common, fx.volume_mm3)
    assert len(fx.mating_faces) == len(fx.mating_refs) >= 1


def test_corner_in_camera_and_part_frames_is_the_same_block(scans):
    _, vb, truth_cam = scans[("block", 0)]
    a = design_fixture(vb, "corner", frame="part")
    b = design_fixture(vb, "corner", frame="camera")
    assert a.reference.edge_id == b.reference.edge_id
    assert a.volume_mm3 == pytest.approx(b.volume_mm3, rel=1e-9)
    # The camera-frame block, moved by the camera -> part map, lands on the part-frame block.
    m = camera_mm_matrix(a.fmap)
    va = np.array(sorted(np.round([tuple(v) for v in a.solid.vertices()], 6).tolist()))
    vb_ = np.array([tuple(v) for v in transformed(b.solid, m).vertices()])
    vb_ = np.array(sorted(np.round(vb_, 6).tolist()))
    assert va.shape == vb_.shape == (12, 3)
    assert np.abs(va - vb_).max() < 1e-5
    for fx in (a, b):
        mating, _, frac = _measure(vb, truth_cam, fx)
        assert mating.max < 0.3 and frac == 0.0
    # In the part frame the ground is Z = 0 and the part's up axis is +Z.
    assert np.allclose(up_vector(vb, a.fmap), [0, 0, 1])


def test_v_cradle_touches_along_two_lines(scans):
    _, vb, truth_cam = scans[("shaft", 0)]
    fx = design_fixture(vb, "cradle", CradleParams(style="V", clearance=0.3))
    m = camera_mm_matrix(fx.fmap)
    from fixtures_design.verify import distances_mm

    d = distances_mm(fx.contact_points, transformed(truth_cam, m))
    assert np.abs(d - 0.3).max() < 0.01
    assert interference(fx, transformed(truth_cam, m))[1] == 0.0
    assert len(fx.mating_faces) == 2


def test_pin_fits_the_hole(scans):
    _, vb, _ = scans[("bracket", 0)]
    fx = design_fixture(vb, "pin")
    ref = fx.reference
    assert fx.notes["pin_radius_mm"] == pytest.approx(1000 * ref.radius - fx.params.clearance)
    assert 0 < fx.notes["depth_mm"] <= fx.params.depth
    assert fx.notes["flange_radius_mm"] <= 1000 * ref.land


def test_cradle_refuses_an_upright_cylinder():
    from fixtures_design import NoReferenceError

    from scenes.vbrep import cylinder_upright

    with pytest.raises(NoReferenceError, match="90 deg off the horizontal"):
        design_fixture(cylinder_upright(), "cradle")


def test_corner_on_the_reconstruction_of_a_generated_scan(scans):
    """The real pipeline (oracle segmentation) on a generated block: its corner locator still mates."""
    from v2c.pipeline import reconstruct

    path, vb_true, truth_cam = scans[("bracket", 1)]
    vb = reconstruct(Path(path), segmentation="oracle")
    # The kind's own 0.2 mm clearance (clearance_k=0): this checks where the reconstruction puts the faces; the
    # default k x sigma clearance is tests/test_fixtures_clearance.py's and `v2c bench --stage fixtures`'s.
    fx = design_fixture(vb, "corner", min_confidence=0.5, clearance_k=0.0)
    m = camera_mm_matrix(fx.fmap)
    truth = transformed(truth_cam, m)
    mating = check_mating(fx, truth)
    common, frac = interference(fx, truth)
    tol = max(0.5, 0.01 * vb_true.scale * 1000.0)
    assert mating.max < tol, mating
    assert frac < 1e-3, common


def _pillow_block(plate_mm=(120.0, 60.0, 12.0), radius_mm: float = 20.0, length_mm: float = 40.0):
    """A plate (its own frame, mm, on Z = 0) with a horizontal cylinder along Y standing in it: its axis 6 mm
    above the plate's top, so the plate's body fills the space under the cylinder."""
    from build123d import Box, Cylinder, Pos, Rot

    lx, ly, lz = plate_mm
    plate = Pos(0, 0, lz / 2) * Box(lx, ly, lz)
    return plate + Pos(0, 0, lz + 6.0) * Rot(90, 0, 0) * Cylinder(radius_mm, length_mm)


def test_cradle_refuses_a_cylinder_standing_in_a_plate_and_keeps_a_lying_rod():
    """A cradle under a pillow block's cylinder would lie inside the plate (its top is above the cradle's block,
    so no scan point or face mesh is inside the block): the plate's mesh beside the cylinder refuses it, naming the
    plate's face. A free lying rod (nothing beside it but the ground) still gets its cradle, and it does not cut
    the rod."""
    from fixtures_design import NoReferenceError
    from fixtures_design.cradle import resting_plane
    from fixtures_design.frames import output_frame
    from fixtures_design.references import select_references

    from scenes.truth import lying_rod, posed_part, vbrep_from_shape

    block, axes = posed_part(_pillow_block(), azimuth_deg=-60)
    vb = vbrep_from_shape(block, axes)
    boss = [r for r in select_references(vb, ["boss"]) if r.radius == pytest.approx(0.02, abs=1e-6)]
    assert boss, "the cylinder's rim must be a boss reference"
    fmap = output_frame(vb, "part")
    plate_top = resting_plane(vb, boss[0], fmap, up_vector(vb, fmap))
    assert plate_top is not None
    normal = np.asarray(next(f for f in vb.faces if f.id == plate_top).primitive["params"]["normal"], float)
    assert normal @ axes[2] == pytest.approx(1.0, abs=1e-6)  # the plate's top, facing up
    with pytest.raises(NoReferenceError, match=f"stands in the body of face {plate_top}"):
        design_fixture(vb, "cradle", frame="part")

    rod, axes = posed_part(lying_rod(), azimuth_deg=-60)
    vb = vbrep_from_shape(rod, axes)
    fx = design_fixture(vb, "cradle", frame="part")
    assert resting_plane(vb, fx.reference, fx.fmap, up_vector(vb, fx.fmap)) is None
    truth = transformed(rod, camera_mm_matrix(fx.fmap))
    assert interference(fx, truth)[1] < 1e-3


def _ledge_block() -> object:
    """A 60 x 40 x 20 mm block (its own frame, Z up) with a 15 mm riser on its top whose front wall runs askew,
    leaving a ledge along the front edge (Y = -20) that narrows from 20 mm (X = -30) to 6 mm (X = +30)."""
    from build123d import Box, Plane, Polyline, Pos, extrude, make_face

    base = Pos(0, 0, 10) * Box(60, 40, 20)
    outline = Polyline((-30, 0), (30, -14), (30, 20), (-30, 20), close=True)
    riser = extrude(make_face(Plane.XY.offset(20) * outline), 15)
    return base + riser


def test_a_corner_leg_stops_short_of_where_its_ledge_narrows():
    """The corner on the ledge's front edge (ground-truth VB-Rep, the kind's own 0.2 mm clearance): its ledge leg
    ends 3 mm short of the ledge's narrowest width over the block's span (40 mm centred: 8.3 mm at X = +20), so the
    locator clears the riser and, pushed home, holds the true part without cutting it; with the leg from the
    ledge's widest reach anywhere along the edge (the design before) it runs 15 mm into the riser's wall."""
    from dataclasses import replace

    from fixtures_design.references import select_references
    from fixtures_design.seat import seat_part

    from scenes.truth import posed_part, vbrep_from_shape

    part, axes = posed_part(_ledge_block(), elevation_deg=35.0, azimuth_deg=-70.0)
    vb = vbrep_from_shape(part, axes)
    # The ledge's front edge: along X, between the ledge (facing up) and the front face (facing -Y).
    (ref,) = [
        r
        for r in select_references(vb, ["dihedral"])
        if abs(r.direction @ axes[0]) > 0.99
        and sorted(round(2 * n @ axes[2] + n @ axes[1]) for n in r.normals) == [-1, 2]
    ]
    fx = design_fixture(vb, "corner", reference=ref, clearance_k=0.0)
    ledge = next(i for i, n in enumerate(ref.normals) if n @ axes[2] > 0.99)
    assert fx.notes["leg_mm"][ledge] == pytest.approx(20 - 14 * 50 / 60 - 3.0, abs=0.3)
    truth = transformed(part, camera_mm_matrix(fx.fmap))
    assert interference(fx, truth)[1] < 1e-3
    seat = seat_part(fx, truth)
    assert seat.ok and seat.move_mm < 0.5
    before = design_fixture(vb, "corner", reference=replace(ref, reach_at=np.zeros(0)), clearance_k=0.0)
    assert before.notes["leg_mm"][ledge] == pytest.approx(15.0)
    assert interference(before, truth)[1] > 0.01


def _seen_meshes(vb):
    """``vb`` with each face's mesh cut to the triangles that face the camera (outward winding), as a
    reconstruction's meshes are: a ground-truth VB-Rep meshes whole faces, the far side of a rod too."""
    from dataclasses import replace

    from fixtures_design.occ import camera_facing

    faces = []
    for f in vb.faces:
        v, t = np.asarray(f.mesh_vertices), np.asarray(f.mesh_triangles).reshape(-1, 3)
        faces.append(replace(f, mesh_triangles=t[camera_facing(v, t)]))
    return replace(vb, faces=faces)


def _filleted_rod(radius_mm: float = 15.0, length_mm: float = 80.0, fillet_mm: float = 3.0, chamfer: bool = False):
    """A round rod (its own frame, mm) lying on Z = 0 along X, its two end circles filleted (or chamfered): the
    cylinder meets a torus (a cone) at each end, and no plane."""
    from build123d import chamfer as chamfer_edges
    from build123d import fillet

    from scenes.truth import lying_rod

    rod = lying_rod(length_mm, 2 * radius_mm)
    ends = rod.edges().filter_by(lambda e: e.geom_type.name == "CIRCLE")
    return chamfer_edges(ends, fillet_mm) if chamfer else fillet(ends, fillet_mm)


def _assert_cradle_holds(vb, rod, site: str) -> None:
    """The default cradle of ``vb`` rests on a reference of ``site``, does not cut the true ``rod`` (camera frame,
    mm) and, pushed home, holds it within its clearance."""
    from fixtures_design.seat import seat_part

    fx = design_fixture(vb, "cradle", frame="part")
    assert fx.reference.site == site
    truth = transformed(rod, camera_mm_matrix(fx.fmap))
    assert interference(fx, truth)[1] < 1e-3
    seat = seat_part(fx, truth)
    assert seat.ok and seat.move_mm < fx.params.clearance + 0.05


@pytest.mark.parametrize("chamfer", [False, True])
def test_a_cradle_takes_a_shafts_filleted_or_chamfered_end_as_its_boss(chamfer):
    """A lying rod whose ends are filleted (chamfered) shows no cylinder/plane circle: its cylinder meets a torus
    (a cone) at each end. That circle is a boss reference of site "shoulder" (the cylinder's radius, the axis into
    its body, its seen length), and the cradle designed from it (ground-truth VB-Rep, default clearance) does not
    cut the rod and, pushed home, holds it with its groove within the clearance."""
    from fixtures_design.references import select_references

    from scenes.truth import posed_part, vbrep_from_shape

    rod, axes = posed_part(_filleted_rod(chamfer=chamfer), elevation_deg=30.0, azimuth_deg=-60.0)
    vb = _seen_meshes(vbrep_from_shape(rod, axes, curved=True))
    other = "cone" if chamfer else "torus"
    assert {f.primitive["type"] for f in vb.faces} >= {"cylinder", other}
    refs = select_references(vb, ["boss"])
    assert refs and all(r.site == "shoulder" for r in refs)
    for r in refs:
        assert r.radius == pytest.approx(0.015, abs=1e-6)
        assert abs(r.axis @ axes[0]) == pytest.approx(1.0, abs=1e-6)  # along the rod
        assert 0.07 < r.extent < 0.08  # from one end circle to the other: 80 mm less the two blends
    _assert_cradle_holds(vb, rod, "shoulder")


def test_a_filleted_holes_rim_is_no_shoulder():
    """A plate's vertical hole filleted at its rim: the hole's wall (concave, the camera sees its far side) meets
    the fillet's torus coaxially, but a shoulder needs a boss, so it is no cradle reference."""
    from build123d import Axis, Box, Cylinder, Pos, fillet

    from fixtures_design import NoReferenceError
    from fixtures_design.references import explain_edges, select_references

    from scenes.truth import posed_part, vbrep_from_shape

    plate = Pos(0, 0, 10) * Box(80, 80, 20) - Pos(0, 0, 10) * Cylinder(15, 20)
    rim = plate.edges().filter_by(lambda e: e.geom_type.name == "CIRCLE").sort_by(Axis.Z)[-1]
    part, axes = posed_part(fillet(rim, 3.0), elevation_deg=60.0, azimuth_deg=-60.0)
    vb = _seen_meshes(vbrep_from_shape(part, axes, curved=True))
    assert any(f.primitive["type"] == "torus" for f in vb.faces)
    with pytest.raises(NoReferenceError, match="the cylinder is concave"):
        select_references(vb, ["boss"])
    assert "concave (a hole's wall)" in explain_edges(vb)


def test_a_cradle_takes_a_bare_cylinder_face_when_no_edge_qualifies():
    """A shaft whose ends the view does not show gives the reconstruction no intersection edge (its coaxial
    sections meet at visibility edges: the fixture bench's validation scans 3 and 20 of seed 7200). Emulated on a
    lying rod's ground-truth VB-Rep with every edge typed visibility: its cylinder face alone is a boss reference
    of site "face" (the rod's radius, the axis along it, its seen length), and the cradle designed from it does not
    cut the rod and, pushed home, holds it within the clearance. With its end circles as intersection edges the
    rod's references start with them, and the face comes after every edge reference."""
    from dataclasses import replace

    from fixtures_design.references import select_references
    from v2c.vbrep.model import EdgeType

    from scenes.truth import lying_rod, posed_part, vbrep_from_shape

    rod, axes = posed_part(lying_rod(80.0, 30.0), elevation_deg=30.0, azimuth_deg=-60.0)
    vb = _seen_meshes(vbrep_from_shape(rod, axes))
    with_edges = select_references(vb, ["boss"])
    assert with_edges[0].site != "face"
    assert [r.site for r in with_edges].count("face") == 0  # the rod's face is taken by its circles' references

    bare = replace(vb, edges=[replace(e, type=EdgeType.VISIBILITY) for e in vb.edges])
    (ref,) = select_references(bare, ["boss"])
    assert ref.site == "face" and ref.edge_id == -1 and ref.label == f"face f{ref.cylinder_face}"
    assert ref.radius == pytest.approx(0.015, abs=1e-6)
    assert abs(ref.axis @ axes[0]) == pytest.approx(1.0, abs=1e-6)
    assert 0.079 < ref.extent < 0.0801  # the seen face runs the rod's whole length
    _assert_cradle_holds(bare, rod, "face")
