"""exporters.step: VB-Rep -> STEP AP242 -> read back with OCCT.

Hand-built VB-Reps with exact geometry (a box corner, an upright cylinder, a part of revolution with a
cylinder, cone, torus, sphere and plane): analytic surface types survive, every intersection edge is shared by
its two faces, every edge's type comes back from its name, its layer and its colour, and the geometry lands
where the VB-Rep says (millimetres, in the camera and in the part frame).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.BRepBndLib import BRepBndLib
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_SHELL
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopoDS import TopoDS

from exporters import step
from exporters.brep import BrepConfig, check_faces
from v2c.vbrep.model import EdgeType

from scenes.revolved import revolved_all_types
from scenes.vbrep import box_corner, cylinder_upright

EXAMPLES = {"box_corner": box_corner, "cylinder_upright": cylinder_upright, "revolved": revolved_all_types}


@pytest.fixture(scope="module", params=sorted(EXAMPLES))
def example(request: pytest.FixtureRequest):
    return EXAMPLES[request.param]()


@pytest.fixture(scope="module", params=["part", "camera"])
def written(request: pytest.FixtureRequest, example, tmp_path_factory: pytest.TempPathFactory):
    """(vbrep, report, read-back) of one example written in one frame."""
    path = tmp_path_factory.mktemp("step") / f"{example.meta['example']}_{request.param}.step"
    report = step.write(example, path, frame=request.param)
    return example, report, step.read_typed(path)


def _edge_points(edge, n: int = 9) -> np.ndarray:
    c = BRepAdaptor_Curve(edge)
    ts = np.linspace(c.FirstParameter(), c.LastParameter(), n)
    return np.array([[c.Value(t).X(), c.Value(t).Y(), c.Value(t).Z()] for t in ts])


def _dist_to_polyline(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance of each point to a densely sampled polyline (same units)."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    t = np.clip(np.einsum("pkj,kj->pk", points[:, None] - a[None], d) / np.einsum("kj,kj->k", d, d), 0, 1)
    foot = a[None] + t[..., None] * d[None]
    return np.linalg.norm(points[:, None] - foot, axis=2).min(1)


def test_write_reports_a_clean_build(written) -> None:
    vb, report, _ = written
    assert report.warnings == []
    assert report.invalid_faces == [] and report.fallback_faces == [] and report.skipped_faces == []
    assert report.shape_valid
    assert report.n_faces == len(vb.faces) and report.n_edges == len(vb.edges)
    assert report.free_edges == []
    assert report.path.is_file()
    assert list(report.path.parent.glob(".*tmp*")) == []  # no temporary left behind


def test_faces_stay_analytic_and_named(written) -> None:
    vb, _, back = written
    assert back.products == [back.path.stem]
    assert len(back.faces) == len(vb.faces)
    by_id = {f.id: f for f in back.faces}
    assert sorted(by_id) == [f.id for f in vb.faces]
    for f in vb.faces:
        got = by_id[f.id]
        assert got.surface == f.primitive["type"], (got, f.primitive["type"])
        assert got.type.value == f.primitive["type"]
        assert got.axis == f.axis_label
        assert got.name == step.face_name(f)


def test_every_edge_typed_by_name_layer_and_colour(written) -> None:
    vb, _, back = written
    assert len(back.edges) == len(vb.edges)  # no extra (unnamed) edges
    for e in vb.edges:
        got = back.edge(e.id)
        assert len(got) == 1, (e.id, got)
        g = got[0]
        t = EdgeType(e.type)
        assert g.type is t and g.layer_type is t and g.color_type is t
        assert g.layer == f"edge_{t.value}"
        assert g.color == pytest.approx(step.EDGE_COLORS[t], abs=1e-3)
        assert g.confidence == pytest.approx(e.confidence, abs=0.005)
        assert g.name == step.edge_name(e)


def test_intersection_edges_shared_by_their_two_faces(written) -> None:
    vb, _, back = written
    for e in vb.edges:
        (g,) = back.edge(e.id)
        assert g.n_faces == len(e.faces), (e.id, e.type, g.n_faces)
    n_int = len(vb.edges_of_type(EdgeType.INTERSECTION))
    assert sum(g.n_faces == 2 for g in back.edges) == n_int > 0


def test_read_back_faces_valid_in_one_open_shell(written) -> None:
    _, _, back = written
    exp = TopExp_Explorer(back.shape, TopAbs_FACE)
    n = 0
    while exp.More():
        assert BRepCheck_Analyzer(exp.Current()).IsValid()
        n += 1
        exp.Next()
    assert n == len(back.faces)
    shells = TopExp_Explorer(back.shape, TopAbs_SHELL)
    count = 0
    while shells.More():
        count += 1
        shells.Next()
    assert count == 1  # every example's faces are connected through intersection edges


def test_edges_follow_the_vbrep_polylines(written) -> None:
    """Each edge of the file lies on its VB-Rep polyline, mapped to millimetres in the written frame:
    intersection edges (exact curves) within the polyline's chord sagitta, fitted edges within the fit
    tolerance on top."""
    vb, report, back = written
    fmap = report.frame_map
    cfg = BrepConfig()
    fit_tol = max(cfg.fit_tol_abs, cfg.fit_tol_rel * vb.scale * 1000)
    for g in back.edges:
        poly = fmap.points(vb.edges[g.id].polyline)
        d = _dist_to_polyline(_edge_points(TopoDS.Edge_s(_shape_of(back, g))), poly)
        # polylines are chords of curved edges: allow their sagitta (segment^2 / 8 R, smallest radius here 5
        # mm)
        sagitta = np.linalg.norm(np.diff(poly, axis=0), axis=1).max() ** 2 / 8 / 5.0
        bound = sagitta + (1e-6 if g.type is EdgeType.INTERSECTION else fit_tol)
        assert d.max() < bound, (g.name, d.max(), bound)


def _shape_of(back: step.TypedStep, g: step.TypedEdge):
    exp = TopExp_Explorer(back.shape, TopAbs_EDGE)
    names = {}
    while exp.More():
        names.setdefault(len(names), exp.Current())
        exp.Next()
    # read_typed lists unique edges in TopExp order: the i-th typed edge is the i-th unique edge
    idx = back.edges.index(g)
    from OCP.TopTools import TopTools_IndexedMapOfShape

    um = TopTools_IndexedMapOfShape()
    TopExp.MapShapes_s(back.shape, TopAbs_EDGE, um)
    return um.FindKey(idx + 1)


def test_box_corner_geometry_in_both_frames(tmp_path: Path) -> None:
    """Box 100 x 80 x 60 mm seen from its (+X, +Y, +Z) corner: in the part frame the visible faces span the
    whole box, so the bounding box is [-50, 50] x [-40, 40] x [0, 60] (footprint origin at the bottom centre);
    in the camera frame the corner vertex sits at 1000 x its camera-frame position."""
    vb = box_corner()
    for frame in ("part", "camera"):
        path = tmp_path / f"box_{frame}.step"
        step.write(vb, path, frame=frame)
        back = step.read_typed(path)
        box = Bnd_Box()
        box.SetGap(0.0)
        BRepBndLib.AddOptimal_s(back.shape, box, False, False)
        lo = np.array(box.CornerMin().Coord())
        hi = np.array(box.CornerMax().Coord())
        if frame == "part":
            np.testing.assert_allclose(lo, [-50, -40, 0], atol=1e-3)
            np.testing.assert_allclose(hi, [50, 40, 60], atol=1e-3)
        else:
            pts = np.stack([v.position for v in vb.vertices]) * 1000
            np.testing.assert_allclose(lo, pts.min(0), atol=1e-3)
            np.testing.assert_allclose(hi, pts.max(0), atol=1e-3)
            corner = vb.vertices[0].position * 1000
            (e0,) = back.edge(0)
            ends = _edge_points(TopoDS.Edge_s(_shape_of(back, e0)), 2)
            assert min(np.linalg.norm(ends - corner, axis=1)) < 1e-6


def test_intersection_edges_are_exact_surface_intersections(example) -> None:
    """The built intersection edges are the analytic curves: lines stay lines and circles stay circles with
    the VB-Rep's radius (mm), and the edges carry no tolerance beyond OCCT's default (1e-7 mm)."""
    built = step.build(example, "camera")
    assert all(check_faces(built).values())
    for e in example.edges_of_type(EdgeType.INTERSECTION):
        (edge,) = built.edges[e.id]
        c = BRepAdaptor_Curve(edge)
        kind = e.curve["kind"]
        if kind == "line":
            assert c.GetType().name == "GeomAbs_Line"
        elif kind == "circle":
            assert c.GetType().name == "GeomAbs_Circle"
            assert c.Circle().Radius() == pytest.approx(e.curve["radius"] * 1000, abs=1e-6)
        assert BRep_Tool.Tolerance_s(edge) < 1e-6


def test_all_surface_types_exercised() -> None:
    vb = revolved_all_types()
    assert sorted(f.primitive["type"] for f in vb.faces) == ["cone", "cylinder", "plane", "sphere", "torus"]
    assert {EdgeType(e.type) for e in vb.edges} == set(EdgeType)


def test_broken_loop_falls_back_and_keeps_every_edge(tmp_path: Path) -> None:
    """A face whose loop misses an edge is rebuilt from its mesh outline (a warning, not a crash) at its full
    area; the outline's edges carry the names, layers and colours of the VB-Rep edges they follow, so no edge
    of the file is untyped and the edges only that face held are not written twice."""
    from exporters.readback import check_written

    vb = box_corner()
    vb.faces[0].loops = [[(0, False), (3, False), (1, True)]]  # edge 4 missing: the loop does not close
    path = tmp_path / "broken.step"
    report = step.write(vb, path)
    assert report.fallback_faces == [0]
    assert any("mesh outline" in w for w in report.warnings)
    assert report.free_edges == []
    back = step.read_typed(path)
    assert len(back.faces) == 3 and {f.surface for f in back.faces} == {"plane"}
    assert all(e.type is not None for e in back.edges)
    for e in vb.edges:
        got = back.edge(e.id)
        assert got, e.id
        t = EdgeType(e.type)
        assert all(g.type is t and g.layer_type is t and g.color_type is t for g in got)
    (f0,) = [f for f in back.faces if f.id == 0]
    assert f0.name == "plane:X:f0"
    # the outline face spans the X face of the box: its full mesh area, within 1 %
    rb = check_written(vb, path, report.frame_map)
    (a0,) = [f for f in rb.faces if f.id == 0]
    assert a0.written == pytest.approx(a0.reconstructed, rel=0.01) and a0.reconstructed > 0
    assert rb.untyped_edges == 0 and rb.box_inside(0.01)


def test_readback_reports_the_largest_tolerance(tmp_path: Path) -> None:
    """The read-back reports the widest gap the file's topology bridges: OCCT's precision (1e-7 mm) for a box
    corner whose three planes meet exactly, and a vertex tolerance set on a solid is found as set."""
    from OCP.BRep import BRep_Builder
    from OCP.BRepPrimAPI import BRepPrimAPI_MakeBox
    from OCP.TopAbs import TopAbs_VERTEX
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    from exporters.readback import check_written, largest_tolerance

    vb = box_corner()
    path = tmp_path / "corner.step"
    report = step.write(vb, path)
    rb = check_written(vb, path, report.frame_map)
    assert rb.max_tolerance == pytest.approx(1e-7, abs=1e-9)
    assert rb.part_size > 0 and rb.max_tolerance_rel < 1e-8
    assert "largest tolerance" in rb.summary()

    solid = BRepPrimAPI_MakeBox(10.0, 20.0, 30.0).Shape()
    assert largest_tolerance(solid) == pytest.approx(1e-7)
    vertex = TopoDS.Vertex_s(TopExp_Explorer(solid, TopAbs_VERTEX).Current())
    BRep_Builder().UpdateVertex(vertex, 0.37)
    assert largest_tolerance(solid) == pytest.approx(0.37)


def test_write_is_atomic(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A failure while writing leaves an existing file untouched and no temporary file."""
    path = tmp_path / "out.step"
    path.write_text("previous")

    def boom(tmp, *args, **kwargs):
        Path(tmp).write_text("ISO-10303-21;\nhalf")
        raise RuntimeError("disk full")

    monkeypatch.setattr(step, "write_xcaf_step", boom)
    with pytest.raises(RuntimeError, match="disk full"):
        step.write(box_corner(), path)
    assert path.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.step"]


def test_build123d_and_cadquery_shapes() -> None:
    import build123d as bd
    import cadquery as cq

    from exporters.shapes import to_build123d, to_cadquery

    vb = revolved_all_types()
    comp = to_build123d(vb)
    assert isinstance(comp, bd.Compound)
    assert sorted(f.geom_type.name for f in comp.faces()) == ["CONE", "CYLINDER", "PLANE", "SPHERE", "TORUS"]
    assert len(comp.edges()) == len(vb.edges)
    bb = comp.bounding_box()
    # part frame: axis of revolution on Z, bottom (z = 0) to top disc (z = 70 mm)
    assert bb.min.Z == pytest.approx(0.0, abs=1e-3) and bb.max.Z == pytest.approx(70.0, abs=1e-3)
    shape = to_cadquery(vb, frame="camera")
    assert isinstance(shape, cq.Shape) and shape.isValid()
    assert len(shape.Faces()) == 5 and len(shape.Edges()) == len(vb.edges)


def test_no_face_means_no_file(tmp_path: Path) -> None:
    """A VB-Rep none of whose faces can be built (here: negative radii) is refused with a clear error, not
    written as an edge-only product (which FreeCAD 0.20 cannot import)."""
    vb = cylinder_upright()
    vb.faces = vb.faces[:1]
    vb.faces[0].primitive = {"type": "cylinder", "params": dict(vb.faces[0].primitive["params"], radius=-0.04)}
    vb.edges = [e for e in vb.edges if set(e.faces) <= {0}]
    path = tmp_path / "none.step"
    with pytest.raises(step.StepExportError, match="no face could be built.*face 0: no surface"):
        step.write(vb, path)
    assert list(tmp_path.iterdir()) == []
