"""exporters guards: degenerate edges, intersection edges without an intersection curve."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepCheck import BRepCheck_Analyzer

from exporters import step
from exporters.brep import BrepConfig, build_brep, check_faces
from exporters.brep_edges import EdgeBuilder
from exporters.frames import FrameMap
from exporters.occ_surfaces import distance_to_surface
from v2c.vbrep.model import EdgeType, VEdge, VertexKind, VVertex

from scenes.vbrep import box_corner

CAMERA = FrameMap(np.eye(3), np.zeros(3))  # camera frame, millimetres


def _closed_point_edge():
    """Box corner with a closed edge shrunk to a point inside face 0, as an inner loop of that face."""
    vb = box_corner()
    p = np.mean([vb.vertices[i].position for i in (0, 1, 2, 4)], axis=0)
    vb.vertices.append(VVertex(7, VertexKind.OTHER, p, np.array([300.0, 200.0])))
    vb.edges.append(VEdge(9, EdgeType.SILHOUETTE, 0.9, (0,), np.repeat(p[None], 3, 0), 7, 7, None))
    vb.faces[0].loops.append([(9, False)])
    return vb


def _zero_length_edge():
    """Box corner with vertex 4 split in two at the same point, joined by a zero-length edge in face 0's loop."""
    vb = box_corner()
    p = vb.vertices[4].position.copy()
    vb.vertices.append(VVertex(7, VertexKind.OTHER, p, vb.vertices[4].pixel.copy()))
    vb.edges.append(VEdge(9, EdgeType.SILHOUETTE, 0.9, (0,), np.stack([p, p]), 4, 7, None))
    vb.edges[4].v0 = 7
    vb.faces[0].loops = [[(0, False), (3, False), (9, False), (4, False), (1, True)]]
    return vb


def test_degenerate_edges_are_dropped_and_the_shape_stays_valid(tmp_path: Path) -> None:
    # Before: the closed point edge failed its pcurve fit ("degenerate polyline"), became a free B-spline
    # edge of zero length and the assembled shape failed BRepCheck; the zero-length edge failed
    # BRepBuilderAPI_MakeEdge and face 0 fell back to its mesh outline.
    for make in (_closed_point_edge, _zero_length_edge):
        vb = make()
        built = build_brep(vb, CAMERA)
        assert 9 not in built.edges and 9 not in built.free_edges
        assert built.fallback_faces == [] and built.skipped_faces == []
        assert all(check_faces(built).values()) and BRepCheck_Analyzer(built.shape).IsValid()
        assert built.face_edges[0] == {0, 1, 3, 4}
        assert any("edge 9: degenerate" in w for w in built.warnings)
        assert not any("pcurve fit failed" in w or "BRepCheck" in w for w in built.warnings)
        report = step.write(vb, tmp_path / f"{make.__name__}.step", frame="camera")
        assert report.fallback_faces == [] and report.free_edges == []
        back = step.read_typed(tmp_path / f"{make.__name__}.step")
        assert len(back.faces) == 3 and back.edge(9) == []


def test_intersection_edge_without_curve_fitted_on_the_nearer_face() -> None:
    # Face 0's plane moved 6 mm along its normal: edges 0 (faces 0, 1) and 1 (faces 0, 2) have no intersection
    # branch near their polylines, which lie on faces 1 and 2. Before, each was fitted on its first face (0),
    # leaving it 6 mm off the second face's surface without a word.
    vb = box_corner()
    prm = vb.faces[0].primitive["params"]
    prm["origin"] = (np.asarray(prm["origin"]) + 0.006 * np.asarray(prm["normal"])).tolist()
    eb = EdgeBuilder(vb, CAMERA, BrepConfig()).run()
    assert eb.fit_face == {0: 1, 1: 2}
    for eid, near in eb.fit_face.items():
        c = BRepAdaptor_Curve(eb.edges[eid])
        pts = np.array([c.Value(t).Coord() for t in np.linspace(c.FirstParameter(), c.LastParameter(), 17)])
        assert distance_to_surface(eb.surfaces[near], pts).max() < 1e-6
        other, off = eb.off_surface[eid]
        assert other == 0 and 5.5 < off < 6.5
        assert any(w.startswith(f"edge {eid}: fitted on face {near}, ") and "off face 0" in w for w in eb.warnings)


def test_exact_intersections_need_no_guard() -> None:
    eb = EdgeBuilder(box_corner(), CAMERA, BrepConfig()).run()
    assert eb.fit_face == {} and eb.off_surface == {} and eb.degenerate == set() and eb.warnings == []


def test_a_face_without_a_mesh_is_not_written_from_its_loops(tmp_path: Path) -> None:
    """A VB-Rep face whose mesh is empty (the VB-Rep left it so: its depth readings contradict its surface) holds
    no reconstructed area: the file skips it with a warning instead of writing its loops' face, which the
    read-back would find infinitely larger than the reconstruction."""
    from dataclasses import replace as dc_replace

    from exporters.readback import check_written

    vb = box_corner()
    gone = vb.faces[0].id
    emptied = dc_replace(vb.faces[0], mesh_vertices=np.zeros((0, 3)), mesh_triangles=np.zeros((0, 3), np.int64))
    vb2 = dc_replace(vb, faces=[emptied, *vb.faces[1:]])
    rep = step.write(vb2, tmp_path / "e.step", frame="camera")
    assert gone in rep.skipped_faces
    assert rep.n_faces == len(vb.faces) - 1
    assert any(w.startswith(f"face {gone}: no mesh") for w in rep.warnings)
    rb = check_written(vb2, tmp_path / "e.step", rep.frame_map)
    assert not rb.off_faces()
    assert all(f.written == 0 for f in rb.faces if f.id == gone)
    # the full box is written whole
    rep_full = step.write(vb, tmp_path / "b.step", frame="camera")
    assert rep_full.n_faces == len(vb.faces) and not rep_full.skipped_faces


def _lens_face():
    """A thin planar face (face 0, plane z = 0.5 m) whose loop is two intersection edges between the same two
    vertices: its sides meet at vertex 0 at 10 degrees, and its 3.5 mm far end, under a pixel in the image, was
    lost, so both sides end at vertex 1 in the middle of it. Faces 1 and 2 are the planes through the sides."""
    from v2c.vbrep.model import VBRep, VFace

    def unit(v):
        return np.asarray(v, float) / np.linalg.norm(v)

    a = np.deg2rad(5.0)
    va = np.array([0.0, 0.0, 0.5])
    d1, d2 = np.array([np.cos(a), -np.sin(a), 0.0]), np.array([np.cos(a), np.sin(a), 0.0])
    a1, a2 = va + 0.02 * d1, va + 0.02 * d2
    vb_ = (a1 + a2) / 2
    n1 = unit(0.8 * np.array([-np.sin(a), -np.cos(a), 0.0]) - 0.6 * np.array([0.0, 0.0, 1.0]))
    n2 = unit(0.8 * np.array([-np.sin(a), np.cos(a), 0.0]) - 0.6 * np.array([0.0, 0.0, 1.0]))
    K = np.array([[615.0, 0.0, 320.0], [0.0, 615.0, 240.0], [0.0, 0.0, 1.0]])

    def pix(p):
        q = K @ p
        return q[:2] / q[2]

    def plane(o, n):
        return {"type": "plane", "params": {"origin": np.asarray(o).tolist(), "normal": np.asarray(n).tolist()}}

    verts = [VVertex(0, VertexKind.CORNER, va, pix(va)), VVertex(1, VertexKind.OTHER, vb_, pix(vb_))]
    edges = [
        VEdge(0, EdgeType.INTERSECTION, 0.9, (0, 1), np.stack([va, a1, vb_]), 0, 1, None),
        VEdge(1, EdgeType.INTERSECTION, 0.9, (0, 2), np.stack([vb_, a2, va]), 1, 0, None),
    ]
    mesh_v = np.stack([va, a1, vb_, a2])
    mesh_t = np.array([[0, 1, 2], [0, 2, 3]])
    empty_v, empty_t = np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    faces = [
        VFace(0, 1, plane(va, [0.0, 0.0, -1.0]), "Z", [[(0, False), (1, False)]], mesh_v, mesh_t, 0.9),
        VFace(1, 2, plane(va, n1), "?", [], empty_v, empty_t, 0.9),
        VFace(2, 3, plane(va, n2), "?", [], empty_v, empty_t, 0.9),
    ]
    return VBRep(faces, edges, verts, frame=np.eye(3), K=K, image_size=(640, 480), scale=0.02, meta={})


def test_a_loop_of_two_exact_lines_is_written_along_its_polylines() -> None:
    # Two lines meet once: with both sides on their exact intersection lines, vertex 1 went to where the lines
    # cross (vertex 0) and face 0 was written from its loop as a sliver of almost no area, then fell back to its
    # mesh outline. Its sides now follow their polylines on face 0's plane, and the face is written from its loop
    # at the area of its mesh.
    vb = _lens_face()
    eb = EdgeBuilder(vb, CAMERA, BrepConfig()).run()
    assert eb.fit_face == {0: 0, 1: 0}
    built = build_brep(vb, CAMERA)
    assert 0 not in built.fallback_faces and 0 in built.built_area
    mesh_mm2 = 0.5 * 20.0 * 20.0 * np.sin(np.deg2rad(10.0))  # the triangle vA, a1, a2 (vB halfway from a1 to a2)
    assert abs(built.built_area[0] / built.mesh_area[0] - 1) <= 0.02
    assert abs(built.mesh_area[0] / mesh_mm2 - 1) < 0.01
    assert built.face_edges[0] == {0, 1}


def _vertex_tolerances(eb: EdgeBuilder, eid: int) -> list[tuple[object, float]]:
    """(vertex, tolerance) of the built edge ``eid``'s ends, from its VEdge's v0 to its v1."""
    from OCP.BRep import BRep_Tool
    from OCP.TopExp import TopExp

    e = eb.edges[eid]
    return [(v, BRep_Tool.Tolerance_s(v)) for v in (TopExp.FirstVertex_s(e, True), TopExp.LastVertex_s(e, True))]


def test_an_edge_end_far_from_its_vertex_does_not_join_it() -> None:
    """A vertex joins the edge ends within join_tol of it, its tolerance covering that gap; an end farther off
    gets a vertex of its own (the file states no gap wider than join_tol as joined, a warning names the edge).
    Box corner, its corner vertex 0 (where edges 0, 1 and 2 end) moved after the edges' geometry is fixed."""
    vb = box_corner()
    eb = EdgeBuilder(vb, CAMERA, BrepConfig()).run()
    assert eb.join_tol == 1.0  # max(0.5 mm, 1 % of the 100 mm part)
    # exact corner: the three intersection edges share one vertex of the minimum tolerance
    ends = [_vertex_tolerances(eb, e)[0] for e in (0, 1, 2)]
    assert all(tol < 1e-3 for _, tol in ends)
    shared = {e: _vertex_tolerances(eb, e)[0][0] for e in (0, 1, 2)}
    assert shared[0].IsSame(shared[1]) and shared[0].IsSame(shared[2])

    corner = eb.vpos[0].copy()
    eb.vpos[0] = corner + np.array([0.5, 0.0, 0.0])  # 0.5 mm: within join_tol, joined, its tolerance covers it
    eb.warnings.clear()
    eb.edges = eb.build_edges()
    (v0, tol0), *_ = _vertex_tolerances(eb, 0)
    assert 0.5 <= tol0 <= 0.55 and v0.IsSame(_vertex_tolerances(eb, 1)[0][0])
    assert not any("does not join" in w for w in eb.warnings)

    eb.vpos[0] = corner + np.array([10.0, 0.0, 0.0])  # 10 mm: beyond join_tol, each edge ends on its own
    eb.warnings.clear()
    eb.edges = eb.build_edges()
    starts = [_vertex_tolerances(eb, e)[0] for e in (0, 1, 2)]
    assert all(tol <= eb.join_tol for _, tol in starts)
    assert not starts[0][0].IsSame(starts[1][0]) and not starts[1][0].IsSame(starts[2][0])
    for e in (0, 1, 2):
        assert any(w.startswith(f"edge {e}: ends 10.0") and "does not join it" in w for w in eb.warnings), e
    # the far ends of those edges (vertices A, B, C) keep their shared vertices
    assert _vertex_tolerances(eb, 0)[1][0].IsSame(_vertex_tolerances(eb, 3)[0][0])


def _moved_face(face: int, shift_mm: float):
    """Box corner (a 100 mm part: join_tol 1 mm, branch_tol 3 mm) with ``face``'s plane moved along its normal,
    its mesh with it along the camera rays (as the VB-Rep lifts a face's mesh onto its surface)."""
    from dataclasses import replace as dc_replace

    vb = box_corner()
    params = vb.faces[face].primitive["params"]
    n = np.asarray(params["normal"], float)
    params["origin"] = (np.asarray(params["origin"]) + shift_mm / 1000 * n).tolist()
    mv = np.asarray(vb.faces[face].mesh_vertices, float)
    mv = mv * ((np.asarray(params["origin"]) @ n) / (mv @ n))[:, None]
    vb.faces[face] = dc_replace(vb.faces[face], mesh_vertices=mv)
    return vb


def test_a_face_an_edge_lies_off_by_more_than_join_tol_is_not_bounded_by_it(tmp_path: Path) -> None:
    """An intersection edge fitted on one face that lies farther than join_tol off the other face's surface is a
    gap between them: without a copy of its own (``face_copies`` off, or no camera ray through the edge meets
    it) the other face is bounded by its mesh outline (a warning names the edge and the gap), not by that edge
    with its tolerance raised to the gap. Within join_tol the edge still bounds both faces. Face 2's plane moved
    along its normal: at 0.5 mm the edges are the planes' exact intersections, at 5 mm they are fitted on faces
    0 and 1."""
    from exporters.readback import check_written

    for shift_mm, refused in ((0.5, False), (5.0, True)):
        vb = _moved_face(2, shift_mm)
        path = tmp_path / f"shift{shift_mm:g}.step"
        report = step.write(vb, path, frame="camera", config=BrepConfig(face_copies=False))
        mine = [w for w in report.warnings if w.startswith("face 2: its edge")]
        if refused:
            assert 2 in report.fallback_faces
            assert len(mine) == 1 and "off its surface (more than 1 mm)" in mine[0], report.warnings
            assert mine[0].startswith("face 2: its edge 1 lies 5.01 mm") or mine[0].startswith("face 2: its edge 2")
        else:
            assert mine == [] and 2 not in report.fallback_faces
        back = check_written(vb, path, report.frame_map)
        assert back.max_tolerance <= 1.05 * 1.0 + 1e-3


def test_a_face_an_edge_lies_off_is_bounded_by_its_own_copy(tmp_path: Path) -> None:
    """The faces of an intersection edge fitted on one of them that lies farther than join_tol off the other do
    not meet there: the other face is bounded by a copy of its own, on its surface where the camera rays through
    the edge's polyline meet it (where its loop mesh has the edge), not by its mesh outline (before: face 2 was
    written from its outline). Its copies join at a vertex of their own; the file joins nothing across the gap.
    Face 2's plane moved 5 mm along its normal: edges 1 (faces 0, 2) and 2 (faces 1, 2) are fitted on faces 0 and
    1 and lie 5 mm off face 2."""
    from OCP.BRepAdaptor import BRepAdaptor_Curve
    from OCP.TopExp import TopExp

    from exporters.readback import check_written
    from v2c.camera import project

    vb = _moved_face(2, 5.0)
    built = build_brep(vb, CAMERA)
    assert built.fallback_faces == [] and built.skipped_faces == []
    assert built.copied_edges == {1: [2], 2: [2]}
    assert built.face_edges[2] == {1, 2, 7, 8}
    eb = EdgeBuilder(vb, CAMERA, BrepConfig()).run()
    assert set(eb.copies) == {(2, 1), (2, 2)}
    for eid in (1, 2):
        c = BRepAdaptor_Curve(eb.copies[(2, eid)])
        pts = np.array([c.Value(t).Coord() for t in np.linspace(c.FirstParameter(), c.LastParameter(), 17)])
        assert distance_to_surface(eb.surfaces[2], pts).max() < 1e-6
        # seen from the camera it runs along the edge's polyline (camera frame in mm here, K in pixels) between
        # its ends, which are where face 2's other edges end (its vertices moved along their rays onto it)
        seg = project(np.asarray(vb.edges[eid].polyline, float) * 1000.0, vb.K)
        got = project(pts[3:-3], vb.K)
        a, b = seg[0], seg[-1]
        d = (b - a) / np.linalg.norm(b - a)
        off = np.abs(d[0] * (got - a)[:, 1] - d[1] * (got - a)[:, 0])
        assert off.max() < 0.05, off.max()
    # the copies meet at the corner on face 2, 5 mm from the corner faces 0 and 1 share
    v1 = TopExp.FirstVertex_s(eb.copies[(2, 1)], True)
    v2 = TopExp.FirstVertex_s(eb.copies[(2, 2)], True)
    assert v1.IsSame(v2)
    report = step.write(vb, tmp_path / "copies.step", frame="camera")
    assert report.fallback_faces == [] and report.copied_edges == {1: [2], 2: [2]}
    back = check_written(vb, tmp_path / "copies.step", report.frame_map)
    assert back.max_tolerance <= 1.05 * 1.0 + 1e-3
    assert not back.off_faces()
    typed = step.read_typed(tmp_path / "copies.step")
    # edge 1: on face 0 (the edge) and on face 2 (its copy), neither shared; edge 0: shared by faces 0 and 1
    assert sorted(g.n_faces for g in typed.edge(1)) == [1, 1] and sorted(g.n_faces for g in typed.edge(2)) == [1, 1]
    assert [g.n_faces for g in typed.edge(0)] == [2]
    assert all(g.type is EdgeType.INTERSECTION for g in typed.edge(1) + typed.edge(2))


def test_a_vertex_is_not_drawn_along_near_parallel_curves() -> None:
    """Alternating projection onto a vertex's intersection curves finds the corner where they meet; where two
    of them are skew and nearly parallel it walks along them toward their closest approach (on the corpus
    validation VB-Reps, vertices up to 0.9 part sizes away, the edges trimmed there running their faces out that
    far). It stops where its next step would take the vertex more than vertex_move_* (3 % of the 100 mm part)
    from the VB-Rep's vertex. Box corner, the curves of edges 0 and 1 (at vertex 0) replaced by two lines 3
    degrees apart that pass 5 mm from each other at the corner and come closest 100 mm along edge 0."""
    from OCP.Geom import Geom_Line
    from OCP.gp import gp_Ax1, gp_Dir, gp_Pnt

    def line(p, d):
        return Geom_Line(gp_Ax1(gp_Pnt(*map(float, p)), gp_Dir(*map(float, d))))

    def placed(cfg: BrepConfig) -> float:
        eb = EdgeBuilder(box_corner(), CAMERA, cfg)
        eb.build_surfaces()
        eb.find_degenerate_edges()
        eb.build_intersection_curves()
        v0 = CAMERA.points(eb.vb.vertices[0].position)
        d1 = np.asarray(eb.vb.edges[0].polyline[-1] - eb.vb.edges[0].polyline[0], float)
        d1 /= np.linalg.norm(d1)
        n = np.cross(d1, [0.0, 0.0, 1.0])
        n /= np.linalg.norm(n)
        m = np.cross(d1, n)
        a = np.radians(3.0)
        eb.curves = {0: line(v0, d1), 1: line(v0 + 100.0 * d1 + 1.0 * n, np.cos(a) * d1 + np.sin(a) * m)}
        eb.place_vertices()
        return float(np.linalg.norm(eb.vpos[0] - v0))

    assert placed(BrepConfig(vertex_iterations=5000)) <= 3.0  # 3 % of the part
    assert placed(BrepConfig(vertex_iterations=5000, vertex_move_rel=10.0)) > 50.0  # unguarded it runs off


def _two_piece_face(second_meshed: bool = True):
    """A plane (z = 0.5 m, facing the camera) seen in two pieces, 20 x 20 mm squares 20 mm apart (an occluder
    between them): one VB-Rep face whose two loops are both outer loops, each of four silhouette edges, and the
    mesh of both squares (of the first only, without ``second_meshed``)."""
    from v2c.vbrep.model import VBRep, VFace

    from scenes.vbrep import K_DEFAULT, _quad_mesh, _segment, project

    z = 0.5
    squares = [(-0.03, -0.01), (0.01, 0.03)]
    verts, edges, loops, mv, mt = [], [], [], [], []
    for x0, x1 in squares:
        corners = np.array([[x0, -0.01, z], [x1, -0.01, z], [x1, 0.01, z], [x0, 0.01, z]])
        ids = []
        for c in corners:
            ids.append(len(verts))
            verts.append(VVertex(len(verts), VertexKind.OTHER, c, project(c, K_DEFAULT)[0]))
        loop = []
        for k in range(4):
            a, b = ids[k], ids[(k + 1) % 4]
            edges.append(
                VEdge(
                    len(edges), EdgeType.SILHOUETTE, 0.9, (0,), _segment(corners[k], corners[(k + 1) % 4]), a, b, None
                )
            )
            loop.append((len(edges) - 1, False))
        loops.append(loop)
        if second_meshed or not mt:
            v, t = _quad_mesh(corners)
            mt.append(t + sum(len(x) for x in mv))
            mv.append(v)
    plane = {"type": "plane", "params": {"origin": [0.0, 0.0, z], "normal": [0.0, 0.0, -1.0]}}
    face = VFace(0, 1, plane, "Z", loops, np.concatenate(mv), np.concatenate(mt), 0.9)
    return VBRep([face], edges, verts, frame=np.eye(3), K=K_DEFAULT, image_size=(640, 480), scale=0.06, meta={})


def test_a_face_seen_in_two_pieces_is_written_from_its_loops_in_two_pieces(tmp_path: Path) -> None:
    """One face with two outer loops (no loop inside the other) cannot be one OCCT face with a hole: it is written
    as two faces, each bounded by its own loop, both named after the VB-Rep face, not from its mesh outline."""
    from exporters.readback import check_written

    vb = _two_piece_face()
    rep = step.write(vb, tmp_path / "two.step", frame="camera")
    assert rep.fallback_faces == [] and rep.skipped_faces == [] and rep.free_edges == []
    built = build_brep(vb, CAMERA)
    pieces = built.face_parts[0]
    assert len(pieces) == 2 and all(BRepCheck_Analyzer(p).IsValid() for p in pieces)
    assert built.face_edges[0] == set(range(8))
    rb = check_written(vb, tmp_path / "two.step", rep.frame_map)
    assert not rb.off_faces()
    (face,) = rb.faces
    assert abs(face.written - 800.0) < 1.0 and abs(face.reconstructed - 800.0) < 1.0  # two 400 mm² squares


def test_a_piece_of_a_face_that_holds_none_of_its_mesh_is_not_written(tmp_path: Path) -> None:
    """The second square's mesh is gone (its pixels' mesh dropped as a stray island): the file writes the first
    square from its loop, leaves the second out with a warning, and the face reads back at its mesh's area."""
    from exporters.readback import check_written

    vb = _two_piece_face(second_meshed=False)
    rep = step.write(vb, tmp_path / "one.step", frame="camera")
    assert rep.fallback_faces == [] and rep.skipped_faces == []
    assert any(w.startswith("face 0: a piece of it bounded by 1 loop(s) holds 0 % of its mesh") for w in rep.warnings)
    built = build_brep(vb, CAMERA)
    assert 0 not in built.face_parts and built.face_edges[0] == {0, 1, 2, 3}
    (face,) = check_written(vb, tmp_path / "one.step", rep.frame_map).faces
    assert abs(face.written - 400.0) < 1.0 and abs(face.reconstructed - 400.0) < 1.0


def _overshooting_corner():
    """A 20 x 20 mm square of the plane z = 0.5 m whose corner vertex (20, 0) mm was placed 4 mm out, at (24, 3):
    the bottom edge runs to it along y = 0 and then up, the right edge comes back from it below the square to
    (20, -1) and then up x = 20, so the two cross at (20, 1), 4.5 mm from their vertex."""
    from v2c.vbrep.model import VBRep, VFace

    from scenes.vbrep import K_DEFAULT, _quad_mesh, project

    z = 0.5

    def p(x_mm: float, y_mm: float) -> np.ndarray:
        return np.array([x_mm / 1000.0, y_mm / 1000.0, z])

    corners = [p(0, 0), p(24, 3), p(20, 20), p(0, 20)]
    verts = [VVertex(k, VertexKind.CORNER, c, project(c, K_DEFAULT)[0]) for k, c in enumerate(corners)]
    runs = [
        [p(0, 0), p(6, 0), p(12, 0), p(18, 0), p(24, 3)],
        [p(24, 3), p(20, -1), p(20, 6), p(20, 13), p(20, 20)],
        [p(20, 20), p(10, 20), p(0, 20)],
        [p(0, 20), p(0, 10), p(0, 0)],
    ]
    edges = [VEdge(k, EdgeType.SILHOUETTE, 0.9, (0,), np.stack(r), k, (k + 1) % 4, None) for k, r in enumerate(runs)]
    mv, mt = _quad_mesh(np.array([p(0, 0), p(20, 0), p(20, 20), p(0, 20)]))
    plane = {"type": "plane", "params": {"origin": [0.0, 0.0, z], "normal": [0.0, 0.0, -1.0]}}
    face = VFace(0, 1, plane, "Z", [[(k, False) for k in range(4)]], mv, mt, 0.9)
    return VBRep([face], edges, verts, frame=np.eye(3), K=K_DEFAULT, image_size=(640, 480), scale=0.03, meta={})


def test_two_edges_crossing_near_their_corner_are_cut_there(tmp_path: Path) -> None:
    """The face's boundary crosses itself 4.5 mm from the overshooting vertex (its tolerance would have to cover
    that): the face gets its own copies of the two edges, cut where they cross, and is written from its loop
    within 2 % of its mesh (the ear past the corner, 1 mm², left out). With the cut off it goes to its outline."""
    from exporters.readback import check_written

    vb = _overshooting_corner()
    rep = step.write(vb, tmp_path / "cut.step", frame="camera")
    assert rep.fallback_faces == [] and rep.skipped_faces == []
    assert any(w == "face 0: its edges [0, 1] cut at the corners where they cross" for w in rep.warnings)
    built = build_brep(vb, CAMERA)
    assert sorted(built.copied_edges) == [0, 1] and built.copied_edges[0] == [0]
    (face,) = check_written(vb, tmp_path / "cut.step", rep.frame_map).faces
    assert abs(face.written - face.reconstructed) <= 0.02 * face.reconstructed
    assert abs(face.written - 399.0) < 1.0  # the square less the 1 mm² triangle under the bottom edge's rise
    off = step.write(vb, tmp_path / "off.step", frame="camera", config=BrepConfig(corner_cut_samples=0))
    assert off.fallback_faces == [0]


def test_a_corner_cut_skips_an_edge_occt_could_not_make() -> None:
    """An edge of the loop that OCCT could not make (BRepBuilderAPI_MakeEdge failed: no TopoDS edge) leaves the
    face unbuildable from its loops; the corner cut must not fail on it (it raised a KeyError on a corpus part,
    whose whole scan then failed): the face is refused and goes to its outline."""
    from exporters.brep_edges import EdgeBuilder
    from exporters.brep_faces import FaceBuilder

    vb = _overshooting_corner()
    eb = EdgeBuilder(vb, CAMERA, BrepConfig()).run()
    del eb.edges[1]
    assert FaceBuilder(eb).build_face(vb.faces[0], eb.edges) is None


def test_a_face_the_extraction_wrote_as_its_readings_plane_is_named_in_the_warnings() -> None:
    # `v2c.vbrep.faces.planes_for_unseen_surfaces` lists, in the VB-Rep's meta, the instances whose curved fit missed
    # their readings and that became planes: the STEP writer says so for each such face, and only for those.
    vb = box_corner()
    vb.meta["extract"] = {"planes_for_unseen_surfaces": [vb.faces[1].instance]}
    built = build_brep(vb, CAMERA)
    named = [w for w in built.warnings if "written as the plane through them" in w]
    assert named == [
        f"face {vb.faces[1].id}: its curved fit missed its own readings; written as the plane through them"
    ]
    vb.meta["extract"] = {"planes_for_unseen_surfaces": []}
    assert not [w for w in build_brep(vb, CAMERA).warnings if "plane through them" in w]
