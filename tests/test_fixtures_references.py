"""Mating-reference selection (fixtures_design.references): only intersection edges, by confidence and geometry."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fixtures_design.references import (
    CircleReference,
    DihedralReference,
    NoReferenceError,
    ReferenceKind,
    explain_edges,
    select_references,
)
from v2c.vbrep.model import EdgeType

from scenes.truth import holed_block, lying_rod, posed_part, vbrep_from_shape
from scenes.vbrep import box_corner, cylinder_upright


def test_box_corner_gives_its_three_convex_right_angle_edges():
    vb = box_corner()
    refs = select_references(vb, ["dihedral"], min_confidence=0.9)
    assert sorted(r.edge_id for r in refs) == [0, 1, 2]
    for r in refs:
        assert isinstance(r, DihedralReference)
        assert abs(r.angle_deg - 90.0) < 1e-6
        # Outward normals face the camera (at the origin) and are the box's axes.
        assert all(n @ r.start < 0 for n in r.normals)
        assert abs(r.normals[0] @ r.normals[1]) < 1e-9
    # The longest edge (0.10 m, along the box's X) comes first among equal confidences.
    assert refs[0].length == pytest.approx(0.10, abs=1e-9)
    # Each face reaches the box's other sides: depths are the two other box dimensions.
    depths = {tuple(sorted(np.round(r.depths, 6))) for r in refs}
    assert depths == {(0.06, 0.08), (0.06, 0.1), (0.08, 0.1)}


def test_only_intersection_edges_are_ever_references():
    vb = box_corner()
    for e in vb.edges:  # make every edge very confident: silhouettes must still never qualify
        e.confidence = 1.0
    refs = select_references(vb, min_confidence=0.99)
    assert {r.edge_id for r in refs} == {e.id for e in vb.edges if EdgeType(e.type) is EdgeType.INTERSECTION}
    for e in vb.edges:
        if EdgeType(e.type) is EdgeType.INTERSECTION:
            e.type = EdgeType.VISIBILITY
    with pytest.raises(NoReferenceError) as err:
        select_references(vb)
    msg = str(err.value)
    assert "dihedral" in msg and "9 edges" in msg
    assert msg.count("never a reference") == 9 and "visibility" in msg and "silhouette" in msg


def test_confidence_threshold_and_clear_message():
    vb = box_corner()
    vb.edges[1].confidence = 0.4
    assert {r.edge_id for r in select_references(vb, ["dihedral"], min_confidence=0.5)} == {0, 2}
    with pytest.raises(NoReferenceError) as err:
        select_references(vb, ["dihedral"], min_confidence=0.96)
    msg = str(err.value)
    assert "confidence >= 0.96" in msg and "a dihedral reference" in msg
    assert msg.count("confidence under 0.96") == 3
    assert "e1: intersection conf 0.40" in msg


def test_concave_edge_is_not_a_corner_reference():
    vb = box_corner()
    # Mirror face 1 through the edge e0 line: the two faces now make a concave (inside) corner.
    f0, f1 = vb.faces[0], vb.faces[1]
    e = vb.edges[0]
    o, d = e.curve["origin"], e.curve["direction"]
    rel = f1.mesh_vertices - o
    along = np.outer(rel @ d, d)
    f1.mesh_vertices = o + along - (rel - along)
    line = explain_edges(vb).splitlines()[0]
    assert line.startswith("  e0:") and "concave" in line
    assert 0 not in {r.edge_id for r in select_references(vb, ["dihedral"])}
    assert f0.primitive["type"] == "plane"


def test_cylinder_cap_is_a_boss_and_not_a_hole():
    vb = cylinder_upright()
    (ref,) = select_references(vb)
    assert isinstance(ref, CircleReference)
    assert ref.kind is ReferenceKind.BOSS and ref.site == "cap"
    assert ref.radius == pytest.approx(0.04)
    # The axis points from the top circle down into the cylinder's body, which the view shows 80 mm of.
    assert ref.axis @ vb.faces[1].primitive["params"]["normal"] == pytest.approx(-1.0)
    assert ref.extent == pytest.approx(0.08, abs=1e-6)
    with pytest.raises(NoReferenceError, match="a boss, not wanted here"):
        select_references(vb, ["hole"])


def test_hole_in_a_block_and_boss_of_a_rod_from_true_parts():
    block, axes = posed_part(holed_block())
    refs = select_references(vbrep_from_shape(block, axes), ["hole"])
    (hole,) = refs
    assert hole.site == "rim" and hole.radius == pytest.approx(0.005, abs=1e-9)
    assert hole.extent == pytest.approx(0.020, abs=1e-6)  # a through hole: its whole 20 mm wall
    assert hole.axis @ axes[2] == pytest.approx(-1.0)  # into the block = down the part's Z
    rod, axes = posed_part(lying_rod(), azimuth_deg=-60)
    (boss,) = select_references(vbrep_from_shape(rod, axes))
    assert boss.kind is ReferenceKind.BOSS and boss.radius == pytest.approx(0.01, abs=1e-9)
    assert abs(boss.axis @ axes[0]) == pytest.approx(1.0)


def test_fillet_arcs_are_not_holes(tmp_path):
    """A block's rounded vertical corners meet its top in quarter circles: never a hole or a boss."""
    from scenes.truth import synthetic_scan, vbrep_from_scan

    vb, _ = vbrep_from_scan(synthetic_scan(tmp_path, "block", 0))
    text = explain_edges(vb)
    assert text.count("a fillet or part-round") >= 3
    holes = select_references(vb, ["hole"])
    assert holes and all(r.site == "rim" for r in holes)
    radii = {round(r.radius * 1000, 1) for r in holes}
    assert len(radii) == 1  # the block's bolt holes, one radius; the fillets' larger radius is gone


def test_reference_dataclasses_are_frozen():
    ref = select_references(box_corner())[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        ref.confidence = 0.0


def test_a_hole_whose_plane_mesh_stops_short_of_the_rim_keeps_its_land_and_the_pin_its_flange():
    """A reconstruction's plane mesh stops short of a hole's rim (the depth loses its edge pixels): with the plane
    cut back to 1.15 x the radius around the hole of a 60 x 40 x 20 mm block (hole 10 mm, 15 mm from the block's
    end), the land still reaches out to about 3 x the radius (`SelectionConfig.land_closure`: the first ring found
    on the plane on 90 % of its directions, out to the block's end), so the pin's flange is the full 4 mm wider
    than the pin and, seated on the true block, rests on its top."""
    from fixtures_design import PinParams, design_pin
    from fixtures_design.frames import camera_mm_matrix, output_frame
    from fixtures_design.model import transformed
    from fixtures_design.seat import seat_part
    from fixtures_design.verify import interference

    block, axes = posed_part(holed_block())
    vb = vbrep_from_shape(block, axes)
    (full,) = select_references(vb, ["hole"])
    assert full.land / full.radius == pytest.approx(3.0, abs=0.2)
    plane = next(f for f in vb.faces if f.id == full.plane_face)
    tri = np.asarray(plane.mesh_vertices, float)[np.asarray(plane.mesh_triangles, int)]  # (T, 3 corners, 3)
    for _ in range(5):  # split each triangle in four at its edge midpoints: 1024 x finer
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        ab, bc, ca = (a + b) / 2, (b + c) / 2, (c + a) / 2
        tri = np.concatenate([np.stack(t, axis=1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    rel = tri - full.center
    rho = np.linalg.norm(rel - (rel @ full.plane_normal)[..., None] * full.plane_normal, axis=2)
    tri = tri[(rho > 1.15 * full.radius).all(axis=1)]
    plane.mesh_vertices = tri.reshape(-1, 3)
    plane.mesh_triangles = np.arange(len(tri) * 3).reshape(-1, 3)
    (hole,) = select_references(vb, ["hole"])
    assert hole.land / hole.radius == pytest.approx(full.land / full.radius, abs=0.15)
    fmap = output_frame(vb, "camera")
    fx = design_pin(hole, fmap, PinParams(clearance=0.2))
    assert fx.notes["flange_radius_mm"] == pytest.approx(fx.notes["pin_radius_mm"] + PinParams().flange)
    truth = transformed(block, camera_mm_matrix(fmap))
    seat = seat_part(fx, truth)
    assert seat.ok and seat.push_mm == pytest.approx(0.2, abs=0.02)  # down by the flange's clearance onto the top
    m = np.eye(4)
    m[:3, 3] = seat.move
    assert interference(fx, transformed(truth, m))[1] < 1e-4
