"""Loops that bound their faces (issue 16): a face enclosed in the image by one neighbour keeps a loop on its own
surface, never one collapsed onto the intersection line of two planes, and the STEP writes it from its loops,
not from its mesh outline."""

from __future__ import annotations

import numpy as np
import pytest

from exporters import step
from exporters.readback import check_written
from v2c.camera import pixel_rays, project
from v2c.primitives import Plane
from v2c.vbrep.extract import extract_vbrep
from v2c.vbrep.model import EdgeType, VertexKind
from v2c.vbrep.postprocess import ProtoEdge, ProtoVertex, collapsed_edges, lift_collapsed
from v2c.vbrep.topology import check_topology

from scenes.raycast import inlay_scene, scene_inputs
from scenes.vbrep import K_DEFAULT


def _image_area(uv: np.ndarray) -> float:
    x, y = uv[:, 0], uv[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _planes() -> dict[int, Plane]:
    # two planes 0.3 m in front of the camera meeting on the line x = 0 (z = 0.3): the far one tilted by 1 degree
    t = np.deg2rad(1.0)
    return {1: Plane([0, 0, 0.3], [0, 0, -1]), 2: Plane([0, 0, 0.3], [-np.sin(t), 0, -np.cos(t)])}


def _circle_uv(n: int = 60, r_px: float = 25.0) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, n)
    return np.stack([400 + r_px * np.cos(a), 240 + r_px * np.sin(a)], 1)  # right of the line x = 0 (u = 320)


def test_closed_plane_plane_edge_is_lifted_between_its_planes():
    prims, K = _planes(), K_DEFAULT
    uv = _circle_uv()
    line_pts = np.tile([0.0, 0.0, 0.3], (len(uv), 1))  # what lifting onto the planes' line made of it
    verts = [ProtoVertex(VertexKind.OTHER, line_pts[0].copy(), uv[0])]
    e = ProtoEdge(EdgeType.INTERSECTION, (1, 2), line_pts, uv.copy(), ("g", 0), ("g", 0), 0, None, {}, 0, 0)
    assert collapsed_edges([e], prims) == [0]
    assert lift_collapsed([e], verts, prims, K) == 1
    # it stays an intersection edge of both faces, on a vertex of its own that the snap leaves in place
    assert e.type is EdgeType.INTERSECTION and e.faces == (1, 2) and e.apart
    assert len(verts) == 2 and e.v0 == e.v1 == 1 and verts[1].free
    assert np.array_equal(e.pts[0], verts[1].position) and np.array_equal(e.pts[-1], verts[1].position)
    inner = e.pts[1:-1]
    # midway between the planes along each sample's ray, which projects back onto the sample
    rays = pixel_rays(uv[1:-1], K)
    assert np.allclose(np.cross(inner, rays), 0, atol=1e-12)
    d1, d2 = prims[1].signed_distance(inner), prims[2].signed_distance(inner)
    assert np.all(np.sign(d1) != np.sign(d2)) and np.abs(d1).max() > 1e-4  # between them, not on their line
    # it encloses what its image samples enclose
    assert abs(_image_area(project(inner, K)) - _image_area(uv[1:-1])) < 1e-6 * _image_area(uv)


def test_only_closed_plane_plane_edges_are_collapsed():
    prims = _planes()
    uv = _circle_uv(61)
    # two plane-plane edges of one face between the same two vertices (the long sides of a thin face whose ends
    # were contracted) are true intersection edges: they stay
    pair = [
        ProtoEdge(EdgeType.INTERSECTION, (1, 2), np.zeros((31, 3)), h.copy(), None, None, k, None, {}, k, 1 - k)
        for k, h in enumerate([uv[:31], uv[30:]])
    ]
    assert collapsed_edges(pair, prims) == []
    # a closed silhouette, or a closed intersection edge of a plane and a curved face, is no plane pair
    sil = ProtoEdge(EdgeType.SILHOUETTE, (1,), np.zeros((61, 3)), uv.copy(), None, None, 2, None, {}, 0, 0)
    assert collapsed_edges([sil], prims) == []


def _inlay_face(v, inp):  # noqa: ANN001, ANN202 - test helper
    normal = np.asarray(inp.render.primitives[3]["params"]["normal"], float)
    return next(
        f
        for f in v.faces
        if f.primitive["type"] == "plane" and abs(np.dot(f.primitive["params"]["normal"], normal)) > 1 - 1e-9
    )


# (radius m, tilt degrees, least written / mesh area of the inlay). 30 mm at 1 degree: a tangent junction (two
# intersection edges kept between the planes by the contact solve), written within 2 % of its mesh. 4 mm at 9
# degrees (an 8 px radius): the loop is one closed plane-plane intersection edge; lifted onto the planes' line it
# enclosed nothing and the face was written from its mesh outline. Left between the planes it bounds the face in
# the STEP: 0.84 of the (pixel) mesh area on 2026-11-25; 0.93 of its mesh since the mesh is made from its loop
# (v2c.vbrep.loop_mesh) and its polyline is thinned at 0.1 px instead of 0.5 px; the rest is the smoothing spline
# of the closed edge's (u, v) fit (a known limit, docs/step.md). Since 2026-11-28 the exporter keeps loops only
# within 2 % of the mesh (docs/step.md, "The area gate"), so the 4 mm inlay is written from its outline, at its
# mesh's area (which is within 5 % of the true face, checked below) instead of 0.93 of it.
@pytest.mark.parametrize("radius, tilt_deg, loop_in_step", [(0.03, 1.0, True), (0.004, 9.0, False)])
def test_face_enclosed_by_one_neighbour_keeps_its_loop_in_the_step(radius, tilt_deg, loop_in_step, tmp_path):
    """A round inlay whose top (a plane tilted by ``tilt_deg``) is enclosed in the image by the plate's top alone:
    the two planes meet only on a line through the centre. Its VB-Rep loops enclose it; the STEP bounds it by
    them where they bound its area within 2 %, else by its mesh outline, and either way holds it whole."""
    inp = scene_inputs(inlay_scene(radius=radius, tilt_deg=tilt_deg), noise_m=0.0004, seed=0)
    v = extract_vbrep(inp.scan, inp.seg, inp.fit)
    t = check_topology(v)
    assert t["open_loops"] == 0 and t["end_gap_m"] == 0.0
    inlay = _inlay_face(v, inp)
    prims = {f.id: Plane(f.primitive["params"]["origin"], f.primitive["params"]["normal"]) for f in v.faces}
    loop_edges = [v.edges[e] for lp in inlay.loops for e, _ in lp]
    step_mm = 1000 * radius * np.tan(np.deg2rad(tilt_deg))  # how far the inlay stands proud of the plate at most
    region_px = int(np.sum(inp.seg.instances == inlay.instance))
    for e in loop_edges:
        # every edge of its loops lies within the step between the inlay and the plate of its plane
        poly = np.asarray(e.polyline, float)
        assert 1000 * np.abs(prims[inlay.id].signed_distance(poly)).max() <= step_mm + 1e-6
    # ... and its loops enclose the face in the image (none collapsed onto the planes' line)
    for lp in inlay.loops:
        poly = np.concatenate([np.asarray(v.edges[e].polyline)[::-1] if r else v.edges[e].polyline for e, r in lp])
        assert _image_area(project(poly, v.K)) >= 0.75 * region_px
    rep = step.write(v, tmp_path / "inlay.step", frame="camera")
    assert (inlay.id not in rep.fallback_faces) == loop_in_step, rep.warnings
    back = check_written(v, tmp_path / "inlay.step", rep.frame_map)
    got = next(f for f in back.faces if f.id == inlay.id)
    true_mm2 = np.pi * (1000 * radius) ** 2 / np.cos(np.deg2rad(tilt_deg))
    assert abs(got.reconstructed - true_mm2) <= 0.05 * true_mm2  # the mesh is the face
    assert 0.98 <= got.written / got.reconstructed <= 1.02, (got.written, got.reconstructed)
