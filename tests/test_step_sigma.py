"""The 1-sigma position error in the STEP names (issue 18 deliverable 2, docs/step.md "Confidence and positional
uncertainty"): every written edge and face name carries ``:s<sigma>`` equal, to two significant digits, to the
VB-Rep's `sigma_mm`; `exporters.step.read_typed` (the build123d way), `fixtures_design.vbrep_from_step` and the
FreeCAD macro's plain-Python parser read it back; names without the field (files written before it) still parse,
with sigma None. The FreeCAD document itself is checked in tests/test_freecad_import.py."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from exporters import freecad_import as fci
from exporters import step
from v2c.vbrep.model import EdgeType

from scenes.vbrep import box_corner

REPO = Path(__file__).resolve().parents[1]


def _two_digits(x: float) -> float:
    """``x`` rounded to two significant digits, computed independently of `step.sigma_field`."""
    return float(f"{x:.2g}")


def _box_with_sigma():
    vb = box_corner()
    for i, f in enumerate(vb.faces):
        f.sigma_mm = [0.0234, 0.31, 12.61][i % 3]
    for i, e in enumerate(vb.edges):
        e.sigma_mm = [0.8, 1.0449, 0.0051, 123.4, 0.995][i % 5]
    return vb


@pytest.mark.parametrize(
    ("sigma", "field"),
    [(0.31, ":s0.31"), (0.0234, ":s0.023"), (0.8, ":s0.8"), (12.61, ":s13"), (123.4, ":s120"), (0.995, ":s0.99")],
)
def test_sigma_field_two_significant_digits(sigma: float, field: str) -> None:
    assert step.sigma_field(sigma) == field
    assert float(field[2:]) == _two_digits(sigma)


@pytest.mark.parametrize("sigma", [None, float("nan"), float("inf"), -0.1])
def test_no_sigma_field_without_a_usable_sigma(sigma: float | None) -> None:
    assert step.sigma_field(sigma) == ""


def test_names_place_sigma_after_the_id_and_before_tangent() -> None:
    vb = _box_with_sigma()
    e = vb.edges[0]
    e.confidence, e.sigma_mm = 0.95, 0.31
    assert step.edge_name(e) == f"{EdgeType(e.type).value}:0.95:e{e.id}:s0.31"
    e.type, e.tangent = EdgeType.INTERSECTION, True
    assert step.edge_name(e) == f"intersection:0.95:e{e.id}:s0.31:tangent"
    e.sigma_mm = None
    assert step.edge_name(e) == f"intersection:0.95:e{e.id}:tangent"
    f = vb.faces[0]
    f.sigma_mm = 0.02
    assert step.face_name(f) == f"{f.primitive['type']}:{f.axis_label}:f{f.id}:s0.02"


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("intersection:0.95:e12:s0.31", (12, EdgeType.INTERSECTION, 0.95, 0.31, False)),
        ("intersection:0.95:e12:s0.31:tangent", (12, EdgeType.INTERSECTION, 0.95, 0.31, True)),
        ("silhouette:0.81:e7:s120", (7, EdgeType.SILHOUETTE, 0.81, 120.0, False)),
        # the old format, written before the sigma field
        ("intersection:0.95:e12", (12, EdgeType.INTERSECTION, 0.95, None, False)),
        ("intersection:0.90:e7:tangent", (7, EdgeType.INTERSECTION, 0.90, None, True)),
        ("occluded:0.50:e3", (3, EdgeType.OCCLUDED, 0.50, None, False)),
        # not ours
        ("intersection:0.95:e12:tangent:s0.31", (None, None, None, None, False)),
        ("Edge1", (None, None, None, None, False)),
        (None, (None, None, None, None, False)),
    ],
)
def test_edge_names_parse_old_and_new(name: str | None, expected: tuple) -> None:
    assert step.parse_edge_name(name) == expected
    rec = fci._NAME.match(name or "")  # the FreeCAD macro's parser agrees
    assert (rec is not None) == (expected[0] is not None)
    if rec:
        assert (int(rec.group(3)), None if rec.group(4) is None else float(rec.group(4))) == (expected[0], expected[3])


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("plane:Z:f3:s0.02", (3, "plane", "Z", 0.02)),
        ("sphere:-:f4:s1.5", (4, "sphere", None, 1.5)),
        ("plane:Z:f3", (3, "plane", "Z", None)),  # the old format
        ("cylinder:U:f10", (10, "cylinder", "U", None)),
        ("Face1", (None, None, None, None)),
    ],
)
def test_face_names_parse_old_and_new(name: str, expected: tuple) -> None:
    fid, ptype, axis, sigma = step.parse_face_name(name)
    assert (fid, None if ptype is None else ptype.value, axis, sigma) == expected


@pytest.fixture(scope="module")
def box_files(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    out = tmp_path_factory.mktemp("sigma")
    vb = _box_with_sigma()
    step.write(vb, out / "sigma.step")
    old = box_corner()  # no sigma in the VB-Rep: names as before
    step.write(old, out / "old.step")
    return vb, out / "sigma.step", old, out / "old.step"


def test_every_written_name_carries_the_vbreps_sigma(box_files: tuple) -> None:
    vb, path, _, _ = box_files
    back = step.read_typed(path)
    assert sorted(f.id for f in back.faces) == sorted(f.id for f in vb.faces)
    assert len(back.edges) == len(vb.edges)
    for f in vb.faces:
        got = [g for g in back.faces if g.id == f.id]
        assert len(got) == 1 and got[0].sigma_mm == _two_digits(f.sigma_mm), (f.id, got)
    for e in vb.edges:
        got = back.edge(e.id)
        assert len(got) == 1 and got[0].sigma_mm == _two_digits(e.sigma_mm), (e.id, got)
    # the STEP text carries the same names on EDGE_CURVE / ADVANCED_FACE (what FreeCAD users can read)
    text = path.read_text()
    records = fci.parse_typed_edges(text)
    assert sorted((r.edge_id, r.sigma_mm) for r in records) == sorted((e.id, _two_digits(e.sigma_mm)) for e in vb.edges)
    faces = fci.parse_typed_faces(text)
    assert [(d["id"], d["sigma_mm"]) for d in faces] == sorted((f.id, _two_digits(f.sigma_mm)) for f in vb.faces)


def test_a_file_without_sigma_reads_as_before(box_files: tuple) -> None:
    _, _, old, path = box_files
    back = step.read_typed(path)
    assert all(":s" not in (g.name or "") for g in [*back.faces, *back.edges])
    assert sorted(f.id for f in back.faces) == sorted(f.id for f in old.faces)
    assert all(f.sigma_mm is None for f in back.faces)
    assert sorted(e.id for e in back.typed_edges) == sorted(e.id for e in old.edges)
    assert all(e.sigma_mm is None for e in back.edges)
    records = fci.parse_typed_edges(path.read_text())
    assert len(records) == len(old.edges) and all(r.sigma_mm is None for r in records)


def test_build123d_script_reads_sigma(box_files: tuple) -> None:
    """The two lines of docs/step.md for a build123d script, on the same file as a build123d shape."""
    from build123d import import_step

    vb, path, _, _ = box_files
    shape = import_step(str(path))
    sig = {e.id: e.sigma_mm for e in step.read_typed(path).edges}
    assert sig == {e.id: _two_digits(e.sigma_mm) for e in vb.edges}
    assert len(shape.faces()) == len(vb.faces)


def test_fixtures_design_reads_sigma_from_the_step(box_files: tuple) -> None:
    from fixtures_design.step_input import vbrep_from_step

    vb, path, _, old_path = box_files
    got = vbrep_from_step(path)
    assert sorted(f.sigma_mm for f in got.faces) == sorted(_two_digits(f.sigma_mm) for f in vb.faces)
    assert sorted(e.sigma_mm for e in got.edges) == sorted(_two_digits(e.sigma_mm) for e in vb.edges)
    old = vbrep_from_step(old_path)
    assert len(old.faces) == len(got.faces) and len(old.edges) == len(got.edges)
    assert all(f.sigma_mm is None for f in old.faces) and all(e.sigma_mm is None for e in old.edges)


def test_pipeline_reconstruction_sigma_in_the_step(tmp_path: Path) -> None:
    """A reconstructed sample: every VB-Rep sigma is known and every named face and edge of its STEP carries it."""
    from v2c.api import reconstruct
    from v2c.scan import load_scan

    vb = reconstruct(load_scan(REPO / "samples" / "bracket_planes_cylinders"))
    assert all(f.sigma_mm is not None for f in vb.faces) and all(e.sigma_mm is not None for e in vb.edges)
    report = step.write(vb, tmp_path / "bracket.step")
    back = step.read_typed(report.path)
    faces = {f.id: f for f in vb.faces}
    edges = {e.id: e for e in vb.edges}
    named_faces = [g for g in back.faces if g.id is not None]
    assert {g.id for g in named_faces} == {f.id for f in vb.faces} - set(report.skipped_faces)
    for g in named_faces:
        assert g.sigma_mm == _two_digits(faces[g.id].sigma_mm), g.name
    typed = back.typed_edges
    # every written edge, and the dropped edges of a face bounded by its mesh outline only where its outline
    # segments carry their names (docs/step.md, Robustness)
    ids = {g.id for g in typed}
    assert set(edges) - set(report.dropped_edges) <= ids <= set(edges)
    for g in typed:
        assert g.sigma_mm == _two_digits(edges[g.id].sigma_mm), g.name
        assert math.isclose(g.sigma_mm, edges[g.id].sigma_mm, rel_tol=0.05)
