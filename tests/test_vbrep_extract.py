"""VB-Rep extraction on analytic scenes ray-cast in numpy (tests/scenes/raycast.py), with exact and perturbed fits."""

from __future__ import annotations

import numpy as np
import pytest

from v2c.bench.vbrep import chamfer, edge_type_accuracy
from v2c.camera import project
from v2c.primitives import from_dict
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.extract import extract_vbrep
from v2c.vbrep.model import EdgeType, VertexKind

from scenes.raycast import box_scene, cylinder_scene, planes_depth, plate_feature_scene, scene_inputs

NOISE_M = 0.0004  # depth noise of the scenes (metres), about a RealSense at 0.45 m


def _perturb(prim: dict, rng: np.random.Generator) -> dict:
    """A fitted-like primitive: origin moved by ~0.3 mm, axis/normal turned by ~0.2 degrees, radius +-0.2 mm."""
    p = {k: (np.asarray(v, float) if isinstance(v, list) else v) for k, v in prim["params"].items()}
    p["origin"] = p["origin"] + rng.normal(0, 0.0003, 3)
    for k in ("normal", "axis"):
        if k in p:
            d = p[k] + rng.normal(0, np.deg2rad(0.2), 3)
            p[k] = d / np.linalg.norm(d)
    if "radius" in p:
        p["radius"] = float(p["radius"] + rng.normal(0, 0.0002))
    return {"type": prim["type"], "params": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in p.items()}}


@pytest.fixture(scope="module", params=["exact", "perturbed"])
def box(request):
    inp = scene_inputs(box_scene(), noise_m=NOISE_M, seed=1, perturb=_perturb if request.param == "perturbed" else None)
    return inp, extract_vbrep(inp.scan, inp.seg, inp.fit)


def test_box_corner_topology(box):
    _inp, v = box
    assert len(v.faces) == 3 and all(f.primitive["type"] == "plane" for f in v.faces)
    ints = v.edges_of_type(EdgeType.INTERSECTION)
    assert len(ints) == 3
    assert sorted(tuple(sorted(e.faces)) for e in ints) == [(0, 1), (0, 2), (1, 2)]
    corners = v.vertices_of_kind(VertexKind.CORNER)
    assert len(corners) == 1
    assert all(corners[0].id in (e.v0, e.v1) for e in ints)
    sil = v.edges_of_type(EdgeType.SILHOUETTE)
    assert len(sil) == 6 and sorted(len([e for e in sil if e.faces == (f,)]) for f in range(3)) == [2, 2, 2]
    assert not v.edges_of_type(EdgeType.VISIBILITY) and not v.edges_of_type(EdgeType.OCCLUDED)
    assert all(e.curve["kind"] == "line" for e in ints)


def test_box_corner_position_and_lines(box):
    inp, v = box
    r = inp.render
    sx, sy, sz = 0.10, 0.08, 0.06
    true_corner = r.R @ (np.array([sx / 2, sy / 2, sz]) - box_scene().eye)
    corner = v.vertices_of_kind(VertexKind.CORNER)[0].position
    assert np.linalg.norm(corner - true_corner) < 0.001  # metres
    for e in v.edges_of_type(EdgeType.INTERSECTION):
        d = e.curve["direction"]
        pts = e.polyline - e.curve["origin"]
        off = pts - np.outer(pts @ d, d)
        assert np.abs(off).max() < 1e-9  # the polyline lies on the analytic line
        # the line is the intersection of the two faces' planes
        for f in e.faces:
            pl = from_dict(v.faces[f].primitive)
            assert np.abs(pl.signed_distance(e.polyline)).max() < 1e-6


def test_box_metrics(box):
    inp, v = box
    acc = edge_type_accuracy(v, inp.scan)
    assert acc["accuracy"] > 0.97 and acc["coverage"] > 0.98
    assert chamfer(v, inp.scan) < 0.01


@pytest.fixture(scope="module")
def cylinder():
    inp = scene_inputs(cylinder_scene(), noise_m=NOISE_M, seed=2)
    return inp, extract_vbrep(inp.scan, inp.seg, inp.fit)


def test_upright_cylinder_has_two_visibility_edges(cylinder):
    inp, v = cylinder
    vis = v.edges_of_type(EdgeType.VISIBILITY)
    assert len(vis) == 2
    cyl = next(f for f in v.faces if f.primitive["type"] == "cylinder")
    prim = from_dict(cyl.primitive)
    for e in vis:
        assert e.faces == (cyl.id,)
        x = e.polyline
        cos = np.abs(np.einsum("ij,ij->i", prim.normal(x), x / np.linalg.norm(x, axis=1, keepdims=True)))
        assert np.median(cos) < 0.05  # normal orthogonal to the view ray
        assert np.abs(prim.signed_distance(x)).max() < 1e-4
        # they run along the axis, roughly the cylinder's height (0.08 m)
        extent = np.ptp(x @ prim.axis)
        assert 0.06 < extent < 0.09
    ints = v.edges_of_type(EdgeType.INTERSECTION)
    assert len(ints) == 1 and ints[0].curve["kind"] == "circle"
    assert ints[0].curve["radius"] == pytest.approx(0.035, abs=1e-6)
    assert len(v.vertices_of_kind(VertexKind.INTERSECTION_VISIBILITY)) == 2
    assert edge_type_accuracy(v, inp.scan)["accuracy"] > 0.95


@pytest.fixture(scope="module")
def hole_and_boss():
    out = {}
    for kind in ("hole", "boss"):
        inp = scene_inputs(plate_feature_scene(kind), noise_m=NOISE_M, seed=3)
        out[kind] = (inp, extract_vbrep(inp.scan, inp.seg, inp.fit))
    return out


def test_hole_and_boss_are_told_apart(hole_and_boss):
    for kind, (inp, v) in hole_and_boss.items():
        cyl = next(f for f in v.faces if f.primitive["type"] == "cylinder")
        info = v.meta["faces"][str(cyl.id)]
        assert info["concave"] is (kind == "hole")
        # the mesh lies on the observed surface: median depth error under 1 mm
        uv = np.rint(project(cyl.mesh_vertices, inp.scan.K)).astype(int)
        h, w = inp.scan.depth.shape
        ok = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        z_clean = inp.scan.gt.depth_clean[uv[ok, 1], uv[ok, 0]]
        good = z_clean > 0
        assert np.median(np.abs(cyl.mesh_vertices[ok][good, 2] - z_clean[good])) < 0.001


def test_a_hole_wall_without_readings_is_placed_deeper_than_its_rim():
    """The sensor read none of a hole's wall (a shiny or dark bore, a wall seen at a grazing angle): the wall
    takes the sheet that meets the readings around it (`VBRepConfig.sheet_ring_px`), the far side of its
    cylinder seen from inside, not the near side (the first crossing of every ray, which lies in front of the
    plate around the hole)."""
    from dataclasses import replace

    inp = scene_inputs(plate_feature_scene("hole"), noise_m=NOISE_M, seed=3)
    inst = np.asarray(inp.seg.instances)
    cyl_inst = next(i for i, p in inp.fit.primitives.items() if p.type == "cylinder")
    depth = np.asarray(inp.scan.depth).copy()
    depth[inst == cyl_inst] = 0.0
    v = extract_vbrep(replace(inp.scan, depth=depth), inp.seg, inp.fit)
    cyl = next(f for f in v.faces if f.primitive["type"] == "cylinder")
    assert v.meta["faces"][str(cyl.id)]["concave"]
    uv = np.rint(project(cyl.mesh_vertices, inp.scan.K)).astype(int)
    h, w = depth.shape
    ok = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    z_clean = inp.scan.gt.depth_clean[uv[ok, 1], uv[ok, 0]]
    good = z_clean > 0
    assert good.sum() > 20
    assert np.median(np.abs(cyl.mesh_vertices[ok][good, 2] - z_clean[good])) < 0.001
    # without the ring's readings (the option off) the wall is put on the near side of its cylinder
    off = extract_vbrep(replace(inp.scan, depth=depth), inp.seg, inp.fit, replace(VBRepConfig(), sheet_ring_px=0))
    near = next(f for f in off.faces if f.primitive["type"] == "cylinder")
    assert not off.meta["faces"][str(near.id)]["concave"]


def test_hole_has_occluded_far_wall_boss_has_visibility(hole_and_boss):
    _, hole = hole_and_boss["hole"]
    _, boss = hole_and_boss["boss"]
    cyl_h = next(f.id for f in hole.faces if f.primitive["type"] == "cylinder")
    cyl_b = next(f.id for f in boss.faces if f.primitive["type"] == "cylinder")
    assert any(e.faces == (cyl_h,) for e in hole.edges_of_type(EdgeType.OCCLUDED))
    assert not any(cyl_h in e.faces for e in hole.edges_of_type(EdgeType.VISIBILITY))
    assert len([e for e in boss.edges_of_type(EdgeType.VISIBILITY) if e.faces == (cyl_b,)]) == 2


def test_edges_and_vertices_are_consistent(box, cylinder, hole_and_boss):
    for v in [box[1], cylinder[1]] + [x[1] for x in hole_and_boss.values()]:
        for e in v.edges:
            assert np.allclose(e.polyline[0], v.vertices[e.v0].position)
            assert np.allclose(e.polyline[-1], v.vertices[e.v1].position)
            assert len(e.faces) == (2 if e.type is EdgeType.INTERSECTION else 1)
            assert 0.0 <= e.confidence <= 1.0
        for f in v.faces:
            assert sorted(e for lp in f.loops for e, _ in lp) == sorted(e.id for e in v.edges if f.id in e.faces)
            # triangles face the camera
            V, T = f.mesh_vertices, f.mesh_triangles
            n = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])
            assert np.all(np.einsum("ij,ij->i", n, V[T[:, 0]]) <= 0)


def test_axis_cylinder_fallback_recovers_a_small_arc() -> None:
    # a 40-degree arc of a 12 mm hole wall, 0.2 mm noise: the fallback for a labelled but unfitted cylinder keeps
    # the type and gets the radius and axis line from the frame axis alone
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.pointfit import fit_axis_cylinder_points

    rng = np.random.default_rng(0)
    axis = np.array([0.0, -0.6, 0.8])
    t1 = np.array([1.0, 0.0, 0.0])
    t2 = np.cross(axis, t1)
    ang = rng.uniform(0, np.deg2rad(40), 200)
    h = rng.uniform(0, 0.01, 200)
    centre = np.array([0.02, 0.01, 0.5])
    X = centre + 0.012 * (np.cos(ang)[:, None] * t1 + np.sin(ang)[:, None] * t2) + h[:, None] * axis
    X += rng.normal(0, 2e-4, X.shape)
    cyl, rms = fit_axis_cylinder_points(X, axis, VBRepConfig().fallback_fit_iters)
    assert abs(cyl.radius - 0.012) < 1e-3 and rms < 3e-4
    off = (cyl.origin - centre) - ((cyl.origin - centre) @ axis) * axis  # axis-line offset
    assert np.linalg.norm(off) < 1e-3
    assert fit_axis_cylinder_points(X[:4], axis, VBRepConfig().fallback_fit_iters) is None


def test_labelled_plane_fallback_uses_the_frame_axis() -> None:
    # a face seen at a grazing angle has no depth of its own: its evidence is its two edges with fitted neighbours
    # (two lines, which a free plane fit cannot tell from other planes through them); labelled plane Y, it becomes
    # the plane normal to the frame's Y axis through them. Plane U gets no labelled fallback; scattered evidence none.
    from types import SimpleNamespace

    from v2c.labels import label_of
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import labelled_fallback
    from v2c.vbrep.pointfit import fit_axis_plane_points

    rng = np.random.default_rng(1)
    c, s = np.cos(0.3), np.sin(0.3)
    frame = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]]) @ np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])
    y = frame[1]
    on_plane = 0.04 * y + np.array([0.0, 0.0, 0.5])
    t = rng.uniform(-0.03, 0.03, (2, 60))
    X = np.concatenate([on_plane + t[0][:, None] * frame[0], on_plane + 0.01 * frame[2] + t[1][:, None] * frame[0]])
    X += rng.normal(0, 2e-4, X.shape)
    cfg = VBRepConfig()
    fit = SimpleNamespace(frame=frame, axis_labels={})
    seg = SimpleNamespace(labels=np.array([0, label_of("plane", "Y"), label_of("plane", "U")], np.uint8))
    plane, rms, axl = labelled_fallback(1, seg, fit, X, 0.1, cfg)
    assert axl == "Y" and abs(abs(plane.axis_vector @ y) - 1.0) < 1e-12 and rms < 5e-4
    assert abs(plane.signed_distance(on_plane[None])[0]) < 2e-4
    assert labelled_fallback(2, seg, fit, X, 0.1, cfg) is None
    scattered = X + rng.normal(0, 0.01, X.shape)
    assert labelled_fallback(1, seg, fit, scattered, 0.1, cfg) is None
    assert fit_axis_plane_points(X[:2], y) is None


def test_labelled_plane_fallback_when_the_frame_has_one_found_axis() -> None:
    # The fit found only Z faces (a turned part): the frame's X and Y rows are a guess about Z. A grazing face
    # labelled plane X (its true normal 35 degrees from the guessed X, across Z) is fitted with its normal across
    # Z through its evidence, not normal to the guessed X; it is not called X of that frame. A labelled cylinder
    # gets no fallback then.
    from types import SimpleNamespace

    from v2c.labels import label_of
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import labelled_fallback
    from v2c.vbrep.pointfit import fit_plane_normal_across

    rng = np.random.default_rng(2)
    frame = np.eye(3)
    a = np.deg2rad(35.0)
    n = np.array([np.cos(a), np.sin(a), 0.0])  # across Z
    d = np.cross(n, frame[2])  # in the plane, across Z
    base = np.array([0.02, -0.01, 0.5])
    t = rng.uniform(-0.03, 0.03, (2, 60))
    X = np.concatenate([base + t[0][:, None] * d, base + 0.02 * frame[2] + t[1][:, None] * d])
    X += rng.normal(0, 2e-4, X.shape)
    cfg = VBRepConfig()
    seg = SimpleNamespace(labels=np.array([0, label_of("plane", "X"), label_of("cylinder", "X")], np.uint8))
    fit = SimpleNamespace(frame=frame, axis_labels={5: "Z", 6: "Z", 7: "U"})
    plane, rms, axl = labelled_fallback(1, seg, fit, X, 0.1, cfg)
    assert axl is None and rms < 5e-4
    assert abs(abs(plane.axis_vector @ n) - 1.0) < 1e-4
    assert abs(plane.signed_distance(base[None])[0]) < 2e-4
    assert labelled_fallback(2, seg, fit, X, 0.1, cfg) is None
    # with X faces found too, the frame's X is measured and the label's axis is used as before: these points,
    # spread 6 cm along a line 35 degrees off X's plane, fit no plane normal to X
    fit_xz = SimpleNamespace(frame=frame, axis_labels={5: "Z", 6: "X"})
    assert labelled_fallback(1, seg, fit_xz, X, 0.1, cfg) is None
    on_x = np.concatenate([base + t[0][:, None] * frame[1], base + 0.02 * frame[2] + t[1][:, None] * frame[1]])
    plane_x, _, axl_x = labelled_fallback(1, seg, fit_xz, on_x, 0.1, cfg)
    assert axl_x == "X" and abs(abs(plane_x.axis_vector[0]) - 1.0) < 1e-12
    assert fit_plane_normal_across(X[:2], frame[2]) is None


def test_labelled_fallback_from_one_edge() -> None:
    # A grazing ledge under a face-on plane: the ledge has no depth and one fitted neighbour, so its evidence is a
    # single line (its edge with that plane). A free plane is not fixed by one line and is not drawn; labelled
    # plane Y, the ledge becomes the plane normal to the frame's Y axis through that edge.
    from types import SimpleNamespace

    from v2c.labels import label_of
    from v2c.primitives import Plane
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import face_geoms

    K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])
    inst = np.zeros((240, 320), np.int32)
    inst[60:140, 100:220] = 1
    inst[140:150, 100:220] = 2
    depth = np.where(inst == 1, 0.5, 0.0)
    fit = SimpleNamespace(
        primitives={1: Plane([0.0, 0.0, 0.5], [0.0, 0.0, -1.0])},
        residuals={1: 0.0},
        axis_labels={1: "Z"},
        frame=np.eye(3),
    )
    edge_y = (139.5 - 120.0) / 600.0 * 0.5  # metres: where the ledge meets the plane (between rows 139 and 140)
    for label, drawn in ((label_of("plane", "Y"), True), (label_of("plane", "U"), False)):
        seg = SimpleNamespace(instances=inst, labels=np.array([0, label_of("plane", "Z"), label], np.uint8))
        faces, _ = face_geoms(fit, seg, depth, K, (0.05, 5.0), 0.1, VBRepConfig(), {})
        assert (2 in faces) == drawn
        if drawn:
            ledge = faces[2].prim
            assert abs(abs(ledge.axis_vector[1]) - 1.0) < 1e-12  # the frame's Y axis
            assert abs(abs(ledge.axis_vector @ ledge.origin) - edge_y) < 0.001  # through the edge: within 1 mm
            assert faces[2].extra.get("fallback")


def _chamfer_strip_scene(noise_m: float, seed: int = 0):
    """A face-on plane A (rows 60-99), a 45-degree chamfer strip B (rows 100-104, unfitted) and a steep wall C
    (rows 105-140), meeting at the pixel sides between rows 99 / 100 and 104 / 105; depth of B with noise."""
    from v2c.camera import pixel_rays
    from v2c.primitives import Plane

    K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])

    def row_ray(v: float) -> np.ndarray:
        return pixel_rays(np.array([[160.0, v]]), K)[0]

    a = Plane([0.0, 0.0, 0.5], [0.0, 0.0, -1.0])
    p0 = row_ray(99.5) * 0.5  # on A, on the A-B edge
    nb = np.array([0.0, 1.0, -1.0]) / np.sqrt(2.0)
    b = Plane(p0, nb)
    p1 = row_ray(104.5) * float(nb @ p0 / (nb @ row_ray(104.5)))  # on B, on the B-C edge
    nc = np.array([0.0, 1.0, -0.2]) / np.hypot(1.0, 0.2)
    c = Plane(p1, nc)
    inst = np.zeros((240, 320), np.int32)
    inst[60:100, 100:220], inst[100:105, 100:220], inst[105:141, 100:220] = 1, 2, 3
    depth = planes_depth(inst, K, {1: a, 2: b, 3: c})
    rng = np.random.default_rng(seed)
    depth[inst == 2] += rng.normal(0.0, noise_m, int((inst == 2).sum()))
    return K, inst, depth, a, b, c


def test_fallback_edges_are_lifted_at_the_shared_pixel_sides() -> None:
    # An unfitted chamfer strip between two fitted planes: its edges with them, lifted onto them, lie on the strip's
    # own plane (the true edge lines), not a pixel's footprint times the angle off it as its boundary pixels do.
    from v2c.vbrep.classify import FaceGeom
    from v2c.vbrep.faces import fallback_sources

    K, inst, depth, a, b, c = _chamfer_strip_scene(0.0)
    faces = {1: FaceGeom(1, a), 3: FaceGeom(3, c)}
    own, edges = fallback_sources(2, inst, depth, K, faces, (0.05, 5.0))
    assert len(own) == 5 * 120 and len(edges) == 2
    for pts in edges:
        assert np.abs(b.signed_distance(pts)).max() < 1e-9  # metres: on both planes, exactly
    boundary = np.array([[160.0, 100.0]])  # the strip's own first row, lifted onto A: off B by ~0.3 mm
    from v2c.camera import pixel_rays

    off = pixel_rays(boundary, K)[0] * 0.5
    assert abs(float(b.signed_distance(off[None])[0])) > 2.5e-4


def test_small_unlabelled_strip_gets_its_own_plane() -> None:
    # The same strip with 0.4 mm depth noise and no usable label: its fallback plane is the chamfer's, within 1.5
    # degrees (0.1-0.6 over five noise seeds; 3.1 with its boundary pixels lifted instead of the pixel sides).
    from types import SimpleNamespace

    from v2c.labels import label_of
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import face_geoms

    K, inst, depth, a, b, c = _chamfer_strip_scene(NOISE_M, seed=3)
    fit = SimpleNamespace(
        primitives={1: a, 3: c}, residuals={1: 0.0, 3: 0.0}, axis_labels={1: "Z", 3: None}, frame=np.eye(3)
    )
    labels = [0, label_of("plane", "Z"), label_of("plane", "U"), label_of("plane", "U")]
    seg = SimpleNamespace(instances=inst, labels=np.array(labels, np.uint8))
    faces, _ = face_geoms(fit, seg, depth, K, (0.05, 5.0), 0.1, VBRepConfig(), {})
    assert faces[2].extra.get("fallback")
    cos = abs(float(faces[2].prim.axis_vector @ b.axis_vector))
    assert np.degrees(np.arccos(min(1.0, cos))) < 1.5


@pytest.mark.parametrize(("far_m", "drawn"), [(0.52, True), (0.6, False)])
def test_free_fallback_plane_seen_edge_on_is_not_drawn(far_m: float, drawn: bool) -> None:
    # A strip without depth between a face-on plane at 0.5 m (rows 60-99) and one at far_m (rows 105-140): its
    # evidence is its two edges, and the plane through them is seen 12 degrees from edge-on (0.52 m: drawn) or
    # 2.6 degrees (0.6 m: under VBRepConfig.fallback_min_view_deg, 5; its pixels cannot be on it).
    from types import SimpleNamespace

    from v2c.labels import label_of
    from v2c.primitives import Plane
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import face_geoms

    K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])
    inst = np.zeros((240, 320), np.int32)
    inst[60:100, 100:220], inst[100:105, 100:220], inst[105:141, 100:220] = 1, 2, 3
    depth = np.where(inst == 1, 0.5, np.where(inst == 3, far_m, 0.0))
    fit = SimpleNamespace(
        primitives={1: Plane([0.0, 0.0, 0.5], [0.0, 0.0, -1.0]), 3: Plane([0.0, 0.0, far_m], [0.0, 0.0, -1.0])},
        residuals={1: 0.0, 3: 0.0},
        axis_labels={1: "Z", 3: "Z"},
        frame=np.eye(3),
    )
    labels = [0, label_of("plane", "Z"), label_of("plane", "U"), label_of("plane", "Z")]
    seg = SimpleNamespace(instances=inst, labels=np.array(labels, np.uint8))
    faces, _ = face_geoms(fit, seg, depth, K, (0.05, 5.0), 0.1, VBRepConfig(), {})
    assert (2 in faces) == drawn
    if drawn:
        assert faces[2].extra.get("fallback")


def _fillet_scene(noise_m: float, seed: int = 0):
    """A face-on plane A (z = 0.5 m, rows 60-99), a 5 mm fillet along the x axis (rows 100-104, labelled
    cylinder, unfitted: too few points for RANSAC) and the plane C it blends into, 60 degrees on (rows 105-140):
    the fillet is tangent to A at the pixel side between rows 99 and 100. Returns K, instances, depth, A, C, the
    fillet's axis centre (y, z) and radius (metres)."""
    from v2c.camera import pixel_rays
    from v2c.primitives import Plane

    K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])
    r, theta1 = 0.005, np.deg2rad(60.0)
    yc, zc = (99.5 - 120.0) / 600.0 * 0.5, 0.5 + r  # tangent to A on row 99.5
    a = Plane([0.0, 0.0, 0.5], [0.0, 0.0, -1.0])
    nc = np.array([0.0, np.sin(theta1), -np.cos(theta1)])
    c = Plane([0.0, yc + r * np.sin(theta1), zc - r * np.cos(theta1)], nc)
    inst = np.zeros((240, 320), np.int32)
    inst[60:100, 100:220], inst[100:105, 100:220], inst[105:141, 100:220] = 1, 2, 3
    vs, us = np.nonzero(inst > 0)
    rays = pixel_rays(np.stack([us, vs], 1).astype(float), K)
    depth = np.zeros(inst.shape)
    for k, p in ((1, a), (3, c)):
        sel = inst[vs, us] == k
        n = np.asarray(p.axis_vector, float)
        depth[vs[sel], us[sel]] = float(n @ np.asarray(p.origin, float)) / (rays[sel] @ n)
    sel = inst[vs, us] == 2  # the front crossing of each ray with the cylinder (y - yc)^2 + (z - zc)^2 = r^2
    dy, dz = rays[sel, 1], rays[sel, 2]  # rays scaled to z = 1: depth is the ray parameter
    qa, qb, qc = dy**2 + dz**2, -2.0 * (dy * yc + dz * zc), yc**2 + zc**2 - r**2
    depth[vs[sel], us[sel]] = (-qb - np.sqrt(qb**2 - 4.0 * qa * qc)) / (2.0 * qa)
    rng = np.random.default_rng(seed)
    depth[inst > 0] += rng.normal(0.0, noise_m, int((inst > 0).sum()))
    return K, inst, depth, a, c, (yc, zc), r


def test_small_curved_face_keeps_its_labelled_type() -> None:
    # An unfitted 5-row fillet labelled cylinder (axis class U) between two fitted planes: it becomes a cylinder on
    # the planes' line of intersection (the x axis; within 2 degrees, radius within 1 mm), not a free plane whose
    # normal is 90 degrees off the true axis (VBRepConfig.fallback_curved off: the old plane).
    from types import SimpleNamespace

    from v2c.labels import label_of
    from v2c.primitives import Cylinder, Plane
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import face_geoms

    K, inst, depth, a, c, (yc, zc), r = _fillet_scene(2e-4, seed=4)
    frame = np.array([[0.8, 0.6, 0.0], [-0.6, 0.8, 0.0], [0.0, 0.0, 1.0]])  # x is no frame axis
    fit = SimpleNamespace(
        primitives={1: a, 3: c}, residuals={1: 0.0, 3: 0.0}, axis_labels={1: None, 3: None}, frame=frame
    )
    labels = [0, label_of("plane", "U"), label_of("cylinder", "U"), label_of("plane", "U")]
    seg = SimpleNamespace(instances=inst, labels=np.array(labels, np.uint8))
    faces, _ = face_geoms(fit, seg, depth, K, (0.05, 5.0), 0.1, VBRepConfig(), {})
    cyl = faces[2].prim
    assert isinstance(cyl, Cylinder) and faces[2].extra.get("fallback")
    assert np.degrees(np.arccos(min(1.0, abs(float(cyl.axis_vector[0]))))) < 2.0
    assert abs(cyl.radius - r) < 1e-3
    off = np.asarray(cyl.origin, float)[1:] - np.array([yc, zc])  # the axis line: within 1 mm
    assert np.hypot(*off) < 1e-3
    old, _ = face_geoms(fit, seg, depth, K, (0.05, 5.0), 0.1, VBRepConfig(fallback_curved=False), {})
    assert isinstance(old[2].prim, Plane)


def test_small_fillet_beside_one_plane_takes_its_strip_direction() -> None:
    # The same fillet with only one of its two planes fitted: the one neighbour suggests its normal, 90 degrees off
    # the fillet's axis, and no line of intersection. The evidence's long direction (the strip along the axis) is
    # a candidate too (VBRepConfig.fallback_strip_axis): the cylinder comes back on the x axis within 2 degrees,
    # its radius within 1 mm; without it the one candidate there is lies 90 degrees off or fits nothing.
    from types import SimpleNamespace

    from v2c.labels import label_of
    from v2c.primitives import Cylinder
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import _add_fitted, _FaceSet, curved_fallback, fallback_sources

    K, inst, depth, a, c, (yc, zc), r = _fillet_scene(2e-4, seed=4)
    frame = np.array([[0.8, 0.6, 0.0], [-0.6, 0.8, 0.0], [0.0, 0.0, 1.0]])  # x is no frame axis
    fit = SimpleNamespace(primitives={1: a}, residuals={1: 0.0}, axis_labels={1: None}, frame=frame)
    labels = [0, label_of("plane", "U"), label_of("cylinder", "U"), label_of("plane", "U")]
    seg = SimpleNamespace(instances=inst, labels=np.array(labels, np.uint8))
    fs = _FaceSet(inst, depth, K, (0.05, 5.0), VBRepConfig())
    _add_fitted(fs, fit, 0.1)
    own, edges = fallback_sources(2, inst, depth, K, fs.faces, fs.window)
    evidence = np.concatenate([own, *edges])
    got = curved_fallback(2, seg, fit, fs.faces, [1, 3], evidence, 0.1, VBRepConfig())
    assert got is not None and isinstance(got[0], Cylinder)
    cyl = got[0]
    assert np.degrees(np.arccos(min(1.0, abs(float(cyl.axis_vector[0]))))) < 2.0
    assert abs(cyl.radius - r) < 1e-3
    off = np.asarray(cyl.origin, float)[1:] - np.array([yc, zc])  # the axis line: within 1 mm
    assert np.hypot(*off) < 1e-3
    old = curved_fallback(2, seg, fit, fs.faces, [1, 3], evidence, 0.1, VBRepConfig(fallback_strip_axis=False))
    assert old is None or abs(float(old[0].axis_vector[0])) < np.cos(np.deg2rad(10.0))


def test_cone_and_torus_on_a_given_axis_line() -> None:
    # A 45-degree chamfer and a 2 mm rounded rim at the mouth of a 10 mm hole, 0.1 mm noise, on 60 degrees of arc:
    # fitted on the hole's axis line they come back within 1.5 degrees and 0.3 mm; too few points give None.
    from v2c.primitives import Cone, Torus
    from v2c.vbrep.pointfit import fit_axis_line_cone_points, fit_axis_line_torus_points

    rng = np.random.default_rng(5)
    axis = np.array([0.0, 0.6, 0.8])
    centre = np.array([0.01, -0.02, 0.45])
    ang = rng.uniform(0.0, np.deg2rad(60.0), 300)
    t1 = np.array([1.0, 0.0, 0.0])
    t2 = np.cross(axis, t1)
    radial = np.cos(ang)[:, None] * t1 + np.sin(ang)[:, None] * t2
    h = rng.uniform(0.0, 0.003, 300)  # the chamfer: radius 10 + h mm at height h above the hole's mouth
    X = centre + (0.010 + h)[:, None] * radial + h[:, None] * axis + rng.normal(0, 1e-4, (300, 3))
    cone, rms = fit_axis_line_cone_points(X, centre + 0.05 * axis, axis)
    assert isinstance(cone, Cone) and rms < 2e-4
    assert abs(np.degrees(cone.half_angle) - 45.0) < 1.5
    apex = centre - 0.010 * axis  # the cone's apex on the axis, 10 mm below the mouth, opening along the axis
    assert np.linalg.norm(cone.origin - apex) < 3e-4 and cone.axis_vector @ axis > 0.999
    phi = rng.uniform(0.0, np.pi / 2, 300)  # the rim: a quarter tube of 2 mm round a 12 mm circle
    X = (
        centre
        + (0.012 - 0.002 * np.cos(phi))[:, None] * radial
        + (0.002 * np.sin(phi) - 0.002)[:, None] * axis
        + rng.normal(0, 1e-4, (300, 3))
    )
    torus, rms = fit_axis_line_torus_points(X, centre, axis, 10)
    assert isinstance(torus, Torus) and rms < 2e-4
    assert abs(torus.radius - 0.012) < 3e-4 and abs(torus.minor_radius - 0.002) < 3e-4
    assert np.linalg.norm(torus.origin - (centre - 0.002 * axis)) < 3e-4
    assert fit_axis_line_cone_points(X[:4], centre, axis) is None
    assert fit_axis_line_torus_points(X[:4], centre, axis, 10) is None


def test_small_chamfer_seen_beside_a_nearer_face_keeps_its_own_plane() -> None:
    # A 45-degree chamfer patch (rows 100-104, columns 150-169, 0.2 mm depth noise, unfitted) seen past a face-on
    # plane 5 cm nearer (around it on three sides: a step, not an edge of the chamfer) and meeting a wall below
    # at a true edge. Its boundary lifted onto the nearer plane lies on that plane, 5 cm off the chamfer; fitted
    # with its own points, the fallback plane is the chamfer's within 3 degrees, and the wall's edge (on the
    # chamfer) joins them. All sources together fit no plane within fallback_rms here (no face: 90 below); on a
    # corpus part's 16-pixel chamfers they gave planes 73-89 degrees off (training split, oracle).
    from dataclasses import replace
    from types import SimpleNamespace

    from v2c.camera import pixel_rays
    from v2c.labels import label_of
    from v2c.primitives import Plane
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import face_geoms

    K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])
    near = Plane([0.0, 0.0, 0.45], [0.0, 0.0, -1.0])
    p0 = pixel_rays(np.array([[160.0, 99.5]]), K)[0] * 0.5
    nb = np.array([0.0, 1.0, -1.0]) / np.sqrt(2.0)
    chamfer = Plane(p0, nb)
    p1 = pixel_rays(np.array([[160.0, 104.5]]), K)[0]
    p1 = p1 * float(nb @ p0 / (nb @ p1))
    wall = Plane(p1, np.array([0.0, 1.0, -0.2]) / np.hypot(1.0, 0.2))
    inst = np.zeros((240, 320), np.int32)
    inst[60:105, 100:220] = 1
    inst[100:105, 150:170] = 2
    inst[105:141, 100:220] = 3
    depth = planes_depth(inst, K, {1: near, 2: chamfer, 3: wall})
    depth[inst == 2] += np.random.default_rng(1).normal(0.0, 0.0002, int((inst == 2).sum()))
    fit = SimpleNamespace(
        primitives={1: near, 3: wall}, residuals={1: 0.0, 3: 0.0}, axis_labels={1: "Z", 3: None}, frame=np.eye(3)
    )
    labels = [0, label_of("plane", "Z"), label_of("plane", "U"), label_of("plane", "U")]
    seg = SimpleNamespace(instances=inst, labels=np.array(labels, np.uint8))

    def tilt(cfg: VBRepConfig) -> float:
        faces, _ = face_geoms(fit, seg, depth, K, (0.05, 5.0), 0.1, cfg, {})
        if 2 not in faces:
            return 90.0
        assert faces[2].extra.get("fallback")
        cos = abs(float(faces[2].prim.axis_vector @ nb))
        return float(np.degrees(np.arccos(min(1.0, cos))))

    assert tilt(VBRepConfig()) < 3.0
    assert tilt(replace(VBRepConfig(), fallback_own_first=False)) > 20.0


@pytest.mark.parametrize("noise_m", [0.0, 0.0008])
def test_curved_surface_that_misses_its_readings_becomes_their_plane(noise_m: float) -> None:
    # A flat patch at 0.6 m (rows 60-99) fitted as a torus that the patch's rays meet centimetres off its depth (the
    # real tuna can's lid piece): the extraction leaves its face without a mesh. The plane through its readings
    # meets them, so it takes the torus's place (and the extraction runs again). A face left with a mesh is not
    # passed; a plane that cannot meet a face's readings (a 50 mm cylinder's patch at a 1 mm bound) is not taken.
    from types import SimpleNamespace

    from v2c.camera import pixel_rays
    from v2c.labels import label_of
    from v2c.primitives import Cylinder, Plane, Torus
    from v2c.vbrep.config import VBRepConfig
    from v2c.vbrep.faces import face_geoms, planes_for_unseen_surfaces

    K = np.array([[600.0, 0.0, 160.0], [0.0, 600.0, 120.0], [0.0, 0.0, 1.0]])
    inst = np.zeros((240, 320), np.int32)
    inst[60:100, 100:220] = 1
    inst[120:180, 130:190] = 2
    vs, us = np.nonzero(inst > 0)
    rays = pixel_rays(np.stack([us, vs], 1).astype(float), K)
    cyl = Cylinder([0.0, 0.0, 0.66], [0.0, 1.0, 0.0], 0.05)  # axis along Y at z 0.66, radius 50 mm
    depth = np.zeros(inst.shape)
    z_plane = np.full(len(us), 0.6)
    # the cylinder's near sheet along each ray: |(r z - c) x a| = R, a = Y: (r_x z)^2 + (r_z z - 0.66)^2 = R^2
    rx, rz = rays[:, 0], rays[:, 2]
    qa, qb, qc = rx**2 + rz**2, -2 * rz * 0.66, 0.66**2 - 0.05**2
    z_cyl = (-qb - np.sqrt(np.maximum(qb**2 - 4 * qa * qc, 0.0))) / (2 * qa)
    depth[vs, us] = np.where(inst[vs, us] == 1, z_plane, z_cyl)
    depth[vs, us] += np.random.default_rng(0).normal(0.0, noise_m, len(us))
    assert np.all(depth[inst == 2] < 0.66)  # every cylinder pixel met its near sheet
    torus = Torus([0.0, 0.0, 0.45], [0.0, 0.0, 1.0], 0.05, 0.02)  # 15 cm in front of the patch
    fit = SimpleNamespace(
        primitives={1: torus, 2: cyl}, residuals={1: 0.0, 2: 0.0}, axis_labels={1: None, 2: "Y"}, frame=np.eye(3)
    )
    seg = SimpleNamespace(instances=inst, labels=np.array([0, label_of("torus", "Z"), label_of("cylinder", "Y")]))
    faces, sheets = face_geoms(fit, seg, depth, K, (0.05, 5.0), 0.1, VBRepConfig(), {})
    assert isinstance(faces[1].prim, Torus) and isinstance(faces[2].prim, Cylinder)
    args = (seg, depth, K, (0.05, 5.0), 0.1)
    tight = VBRepConfig(mesh_evidence_tol=0.01)  # 1 mm at this scale: the cylinder patch's plane misses by more
    assert planes_for_unseen_surfaces(*args, tight, faces, sheets, [2]) == []
    assert planes_for_unseen_surfaces(*args, VBRepConfig(), faces, sheets, [1]) == [1]
    plane = faces[1].prim
    assert isinstance(plane, Plane) and faces[1].extra.get("refit") == "plane"
    assert abs(abs(float(plane.axis_vector[2])) - 1.0) < 1e-3  # face-on, as the patch
    assert abs(abs(float(plane.axis_vector @ plane.origin)) - 0.6) < 1e-3  # at its 0.6 m
    assert isinstance(faces[2].prim, Cylinder) and sheets[1].sheet == 0
