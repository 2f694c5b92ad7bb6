"""Topological soundness of the VB-Rep (v2c.vbrep.topology): closed loops through shared vertices, polylines
ending at their vertices and lying on their faces' surfaces, valid primitives, and what that buys the STEP
exporter: faces trimmed by their own loops instead of their mesh outline."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from exporters import step
from v2c.primitives import Cone, Plane, Torus
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.extract import extract_vbrep
from v2c.vbrep.topology import check_topology, solve_on_surfaces, valid_primitive
from v2c.vbrep.vertices import face_groups

from scenes.raycast import box_scene, cylinder_scene, scene_inputs

SAMPLES = Path(__file__).resolve().parents[1] / "samples"


def test_face_groups_split_t_junctions_and_join_corners():
    # T-junction: near face 1 (silhouettes against the background and against face 2), far face 2 (its
    # occluded edge and its silhouette): two vertices, one per depth layer
    groups = face_groups([(1,), (1,), (2,), (2,)])
    assert [g.tolist() for g in groups] == [[0, 1], [2, 3]]
    # a corner: three intersection edges of faces 1, 2, 3 and a silhouette of face 3: one vertex
    assert len(face_groups([(1, 2), (2, 3), (1, 3), (3,)])) == 1


def test_valid_primitive():
    assert valid_primitive(Torus([0, 0, 1], [0, 0, 1], 0.05, 0.01))
    assert not valid_primitive(Torus([0, 0, 1], [0, 0, 1], -0.0088, 0.086))  # seen on a generated scan
    assert not valid_primitive(Cone([0, 0, 1], [0, 0, 1], 0.0))
    assert valid_primitive(Plane([0, 0, 1], [0, 0, -1]))


def test_solve_on_surfaces_finds_the_corner():
    planes = [Plane([0.1, 0, 0], [1, 0, 0]), Plane([0, 0.2, 0], [0, 1, 0]), Plane([0, 0, 0.3], [0, 0, 1])]
    x, res = solve_on_surfaces(planes, np.array([0.0, 0.0, 0.0]), VBRepConfig().snap_iters)
    assert np.allclose(x, [0.1, 0.2, 0.3]) and res < 1e-12


@pytest.mark.parametrize("scene", [box_scene, cylinder_scene])
def test_scene_vbrep_is_consistent(scene):
    inp = scene_inputs(scene(), noise_m=0.0004, seed=0)
    v = extract_vbrep(inp.scan, inp.seg, inp.fit)
    t = check_topology(v)
    assert t["open_loops"] == 0 and t["faces_without_loops"] == 0 and not t["invalid_primitives"]
    assert t["end_gap_m"] == 0.0
    assert t["off_surface_m"] < 1e-6


# Measured 2026-11-21 (oracle segmentation, the geometry stage of that day), faces bounded by their mesh outline
# by exporters.step.write / faces: before v2c.vbrep.topology bracket 5/12, knob 4/5, turned 6/10 (103/197 over
# these three plus 20 generated `sensor` scans, `v2c synth --n 20 --seed 7`, and 6 faces skipped); now bracket
# 0/12, turned 0/8 (two slivers of 23 and 26 px whose edges were all shorter than min_edge_px are left out), knob
# 2/5 (27/188, 5 skipped). The knob's are curved faces whose fitted surfaces do not meet their neighbours
# (GeomAPI_IntSS finds no curve there), a limit of the fits; with the fits of earlier that day it had 4/5.
#
# 2026-11-25: the STEP must be the reconstruction, so a face whose loops bound far more (or less) than its mesh,
# or reach outside the part's box, is now written from its mesh outline. The bracket's face 4 (a plane whose
# silhouette edge, a 3-point polyline, is fitted as a curve that swings out) had loops bounding 17,900 mm² for
# an 8,608 mm² mesh, reaching outside the part's box: it was counted as a good face before and is an outline
# face now. Its face 8 (6,881 mm²) was built valid but OCCT's STEP reader split it and lost its name: the file
# held it as two unnamed faces, and the loss went unseen. Faces a round trip changes are now written from their
# outline. Every face of these samples is written at its reconstructed area (checked below).
#
# 2026-11-28: the area gate is the read-back's 2 % (docs/step.md, "The area gate"; it was half the area), so every
# face is now checked within 2 % of its mesh (it was 0.5-1.5), and loops 2-9 % off their mesh give way to the
# outline: bracket 2 -> 5 outline faces (its f10's loops bound 2,231 mm² of a 2,183 mm² mesh), turned 1 -> 4 (f7:
# 129 of 142 mm²), knob 4 -> 4. The cost shows on the bracket's grazing plane f1: its loops (0.57 of a mesh that
# runs past the plate) were right, and its outline now follows the mesh.
@pytest.mark.parametrize(
    "name, max_fallback", [("bracket_planes_cylinders", 5), ("turned_unaligned", 4), ("knob_cone_torus_sphere", 4)]
)
def test_samples_export_with_few_fallback_faces(name, max_fallback, tmp_path):
    from exporters.readback import check_written
    from v2c.pipeline import reconstruct

    v = reconstruct(SAMPLES / name, "oracle")
    t = check_topology(v)
    assert t["open_loops"] == 0 and t["end_gap_m"] == 0.0 and not t["invalid_primitives"]
    rep = step.write(v, tmp_path / "x.step", frame="camera")
    assert rep.shape_valid and not rep.invalid_faces
    assert len(rep.fallback_faces) <= max_fallback, rep.warnings
    back = check_written(v, tmp_path / "x.step", rep.frame_map)
    assert back.untyped_edges == 0 and back.box_inside(0.05)
    # every face is in the file (read back by name), at its mesh area within the read-back's 2 %
    assert all(0.98 <= f.ratio <= 1.02 for f in back.faces), [(f.id, f.ratio) for f in back.faces]


def _on_plane(uv: list[tuple[float, float]], K: np.ndarray, z: float = 0.5) -> np.ndarray:
    """(N, 3) camera-frame points at depth ``z`` seen at the pixels ``uv``."""
    p = np.c_[np.asarray(uv, float), np.ones(len(uv))] @ np.linalg.inv(K).T
    return p * z


def test_drop_end_hooks_removes_a_hook_past_the_corner_and_nothing_else():
    from v2c.vbrep.model import EdgeType
    from v2c.vbrep.postprocess import ProtoEdge
    from v2c.vbrep.topology import drop_end_hooks

    K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])
    # the vertex at (100, 100); the first sample 6 px past it, then the edge runs down from (102, 102): the
    # path turns back by 153 degrees at the first sample (a hook), by 45 at the second (a corner of the edge)
    hooked_uv = [(100, 100), (106, 100), (102, 102), (102, 110), (102, 120), (102, 130)]
    hooked = ProtoEdge(EdgeType.OCCLUDED, (1,), _on_plane(hooked_uv, K), v0=0, v1=1)
    straight = ProtoEdge(EdgeType.OCCLUDED, (1,), _on_plane([(0, 0), (5, 1), (10, 0), (15, 1)], K), v0=2, v1=3)
    # a closed edge round a thin sliver turns back by 169 degrees at its far sample: left as it is
    closed_uv = [(200, 200), (220, 202), (200, 204), (200, 200)]
    closed = ProtoEdge(EdgeType.SILHOUETTE, (2,), _on_plane(closed_uv, K), v0=4, v1=4)
    before = [p.pts.copy() for p in (hooked, straight, closed)]
    assert drop_end_hooks([hooked, straight, closed], K, 45.0) == 1
    np.testing.assert_allclose(hooked.pts, np.delete(before[0], 1, axis=0))
    np.testing.assert_allclose(straight.pts, before[1])
    np.testing.assert_allclose(closed.pts, before[2])
    # the end, too: the same polyline reversed loses the same sample; 0 degrees leaves it
    rev = ProtoEdge(EdgeType.OCCLUDED, (1,), before[0][::-1].copy(), v0=1, v1=0)
    assert drop_end_hooks([rev], K, 0.0) == 0 and len(rev.pts) == 6
    assert drop_end_hooks([rev], K, 45.0) == 1
    np.testing.assert_allclose(rev.pts, np.delete(before[0], 1, axis=0)[::-1])


def test_a_boundary_run_past_its_turn_and_back_becomes_one_edge():
    from v2c.vbrep.model import EdgeType, VertexKind
    from v2c.vbrep.postprocess import ProtoEdge, ProtoVertex, _drop_fold_backs

    K = np.array([[600.0, 0.0, 320.0], [0.0, 600.0, 240.0], [0.0, 0.0, 1.0]])

    def vertex(uv):
        return ProtoVertex(VertexKind.CORNER, _on_plane([uv], K)[0], np.asarray(uv, float))

    # one intersection edge of faces 1 and 2 from A (100, 100) to V (140, 140), and a second one of the same faces
    # from V back to B (132, 131): B lies 0.7 px off the first edge's path, 8 px short of V (the real corpus part's
    # top face, 10,400 mm2, went to its mesh outline for this)
    verts = [vertex((100, 100)), vertex((140, 140)), vertex((132, 131)), vertex((150, 90))]
    run = [(100 + 4 * k, 100 + 4 * k) for k in range(11)]
    long = ProtoEdge(EdgeType.INTERSECTION, (1, 2), _on_plane(run, K), np.asarray(run, float), v0=0, v1=1)
    back = [(140, 140), (137, 136), (132, 131)]
    short = ProtoEdge(EdgeType.INTERSECTION, (2, 1), _on_plane(back, K), np.asarray(back, float), v0=1, v1=2)
    other = ProtoEdge(EdgeType.SILHOUETTE, (1,), _on_plane([(132, 131), (150, 90)], K), v0=2, v1=3)
    out = _drop_fold_backs([long, short, other], verts, K, 30.0, 3.0)
    assert len(out) == 2 and other in out
    merged = next(p for p in out if p is not other)
    assert (merged.v0, merged.v1) == (0, 2) and merged.faces == (1, 2)
    np.testing.assert_allclose(merged.pts[-1], verts[2].position)
    # the run up to the start of its segment nearest B, (128, 128), then B
    assert len(merged.pts) == 9 and len(merged.uv) == 9
    np.testing.assert_allclose(merged.pts[:-1], long.pts[:8])
    # a turn (B well off the first edge's path), other faces or other types, and fold_deg 0 change nothing
    turned = [(140, 140), (150, 135), (160, 131)]
    verts[2] = vertex((160, 131))
    short_t = ProtoEdge(EdgeType.INTERSECTION, (1, 2), _on_plane(turned, K), np.asarray(turned, float), v0=1, v1=2)
    assert len(_drop_fold_backs([long, short_t], verts, K, 30.0, 3.0)) == 2
    verts[2] = vertex((132, 131))
    for kind, faces in ((EdgeType.INTERSECTION, (1, 3)), (EdgeType.OCCLUDED, (1, 2))):
        q = ProtoEdge(kind, faces, _on_plane(back, K), np.asarray(back, float), v0=1, v1=2)
        assert len(_drop_fold_backs([long, q], verts, K, 30.0, 3.0)) == 2
    assert len(_drop_fold_backs([long, short], verts, K, 0.0, 3.0)) == 2
