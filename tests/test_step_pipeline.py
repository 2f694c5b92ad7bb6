"""The STEP export of what the pipeline really produces: a synthetic 640 x 480 scan (oracle segmentation)
through `v2c.pipeline.reconstruct`, then `exporters.step.write` in both frames.

Whatever the VB-Rep's quality, the file is valid and complete: every face passes BRepCheck with its
primitive's analytic surface type, every VB-Rep edge comes back exactly once with its type from its name,
layer and colour, intersection edges between two faces built from their loops are shared by both, and FreeCAD
0.20 imports the same faces and edges (when installed).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from OCP.BRepCheck import BRepCheck_Analyzer
from test_step_freecad import FREECAD_SURFACE, freecad_import

from exporters import step
from v2c.vbrep.model import EdgeType


@pytest.fixture(scope="module")
def pipeline_vbrep(tmp_path_factory: pytest.TempPathFactory):
    from v2c.pipeline import reconstruct
    from v2c.synth.dataset import SynthConfig, generate_scan

    folder = generate_scan(tmp_path_factory.mktemp("synth"), seed=0, index=0, cfg=SynthConfig())
    return reconstruct(folder, segmentation="oracle")


@pytest.mark.parametrize("frame", ["part", "camera"])
def test_pipeline_vbrep_exports_valid_and_typed(pipeline_vbrep, frame: str, tmp_path: Path) -> None:
    vb = pipeline_vbrep
    assert vb.image_size == (640, 480) and vb.faces and vb.edges
    path = tmp_path / f"scan_{frame}.step"
    report = step.write(vb, path, frame=frame)
    assert report.invalid_faces == []
    back = step.read_typed(path)
    assert BRepCheck_Analyzer(back.shape).IsValid()
    built = {f.id for f in back.faces}
    assert built == {f.id for f in vb.faces} - set(report.skipped_faces)
    for f in vb.faces:
        if f.id in built:
            # an outline-bounded face may be written in several pieces, each named after it
            for got in [g for g in back.faces if g.id == f.id]:
                assert got.type.value == f.primitive["type"]
                assert got.surface == f.primitive["type"] or (got.surface == "revolution" and got.type.value == "torus")
    assert all(g.type is not None for g in back.edges)  # every edge of the file is typed
    for e in vb.edges:
        t = EdgeType(e.type)
        assert all(g.type is t and g.layer_type is t and g.color_type is t for g in back.edge(e.id))
    assert report.shape_valid
    held_by_loops = set().union(*report.face_edges.values())
    for e in vb.edges:
        if e.id not in held_by_loops and e.id not in report.free_edges:
            continue  # an outline face's edge: its outline's edges carry its name
        # the edge itself is shared by exactly the faces whose boundary holds it (both, for an intersection edge
        # whose two faces were trimmed by their loops); free edges by none. (Outline edges named after it, on
        # an outline face next to it, may sit beside it, and so may a face's own copy of it, on that face only.)
        copied = report.copied_edges.get(e.id, [])
        expected = sum(e.id in held and fid not in copied for fid, held in report.face_edges.items())
        if copied:
            assert sum(g.n_faces == 1 for g in back.edge(e.id)) >= len(copied)
            if expected == 0:  # its own face is bounded by its outline: the copies carry its name
                assert e.id not in report.free_edges
                continue
        assert expected in [g.n_faces for g in back.edge(e.id)], (e.id, e.type)
        assert (expected == 0) == (e.id in report.free_edges)
    n_shared = sum(
        max(g.n_faces for g in back.edge(e.id)) == 2 for e in vb.edges_of_type(EdgeType.INTERSECTION) if back.edge(e.id)
    )
    assert n_shared >= 1
    if shutil.which("freecadcmd"):
        fc = freecad_import(path, tmp_path)
        assert fc["ok"], fc.get("error")
        for how in ("part", "doc"):
            assert fc[how]["faces"] == len(back.faces) and fc[how]["edges"] == len(back.edges)
            assert sorted(fc[how]["surfaces"]) == sorted(FREECAD_SURFACE[f.surface] for f in back.faces)
        assert fc["doc"]["objects"] == 1
