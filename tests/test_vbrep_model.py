"""VB-Rep data model: JSON round trip, format version, the hand-built examples."""

from __future__ import annotations

import json

import numpy as np
import pytest

from v2c.vbrep.model import FORMAT_VERSION, EdgeType, VBRep, VertexKind

from scenes.vbrep import box_corner, cylinder_upright, project


@pytest.mark.parametrize("make", [box_corner, cylinder_upright])
def test_save_load_roundtrip_is_exact(make, tmp_path):
    v = make()
    v.meta["timings"] = {"vbrep": 0.125}
    path = v.save(tmp_path / "x.vbrep.json")
    w = VBRep.load(path)
    assert w == v
    # arrays come back as arrays with the same dtype kind and shape
    for fa, fb in zip(v.faces, w.faces):
        assert fb.mesh_vertices.shape == fa.mesh_vertices.shape and fb.mesh_vertices.dtype.kind == "f"
        assert fb.mesh_triangles.dtype.kind == "i"
    for ea, eb in zip(v.edges, w.edges):
        assert isinstance(eb.type, EdgeType)
        if ea.curve is not None:
            for k, val in ea.curve.items():
                if isinstance(val, np.ndarray):
                    assert np.array_equal(eb.curve[k], val)
    assert json.loads(path.read_text())["format_version"] == FORMAT_VERSION


def test_changed_model_is_not_equal():
    v, w = box_corner(), box_corner()
    w.edges[0].polyline = w.edges[0].polyline + 1e-9
    assert v != w


def test_wrong_version_is_rejected(tmp_path):
    d = box_corner().to_dict()
    d["format_version"] = FORMAT_VERSION + 1
    with pytest.raises(ValueError, match="version"):
        VBRep.from_dict(d)


def test_box_example_topology():
    v = box_corner()
    assert len(v.faces) == 3 and all(f.primitive["type"] == "plane" for f in v.faces)
    ints = v.edges_of_type(EdgeType.INTERSECTION)
    assert len(ints) == 3 and len(v.edges_of_type(EdgeType.SILHOUETTE)) == 6
    corners = v.vertices_of_kind(VertexKind.CORNER)
    assert len(corners) == 1
    assert all(corners[0].id in (e.v0, e.v1) for e in ints)
    assert all(e.curve["kind"] == "line" for e in ints)
    # every face loop closes: consecutive edges share a vertex
    for f in v.faces:
        ends = [(v.edges[e].v1, v.edges[e].v0)[r] for e, r in f.loops[0]]
        starts = [(v.edges[e].v0, v.edges[e].v1)[r] for e, r in f.loops[0]]
        assert ends == starts[1:] + starts[:1]
    # visible faces: outward normals towards the camera
    for f in v.faces:
        n, o = np.asarray(f.primitive["params"]["normal"]), np.asarray(f.primitive["params"]["origin"])
        assert n @ o < 0
    # vertex pixels are the projections of their positions
    for vx in v.vertices:
        assert np.allclose(project(vx.position[None])[0], vx.pixel)


def test_cylinder_example_visibility_edges_are_contours():
    v = cylinder_upright()
    vis = v.edges_of_type(EdgeType.VISIBILITY)
    assert len(vis) == 2
    p = v.faces[0].primitive["params"]
    o, a = np.asarray(p["origin"]), np.asarray(p["axis"])
    for e in vis:
        x = e.polyline
        radial = (x - o) - np.outer((x - o) @ a, a)
        n = radial / np.linalg.norm(radial, axis=1, keepdims=True)
        cos = np.abs(np.einsum("ij,ij->i", n, x / np.linalg.norm(x, axis=1, keepdims=True)))
        assert cos.max() < 1e-9
    circle = v.edges_of_type(EdgeType.INTERSECTION)[0].curve
    assert circle["kind"] == "circle" and circle["radius"] == pytest.approx(p["radius"])
    assert len(v.vertices_of_kind(VertexKind.INTERSECTION_VISIBILITY)) == 2
