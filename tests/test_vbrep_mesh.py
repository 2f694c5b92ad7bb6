"""Face meshes (v2c.vbrep.mesh.face_mesh): every vertex on its surface and in front of the camera."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from v2c.camera import project
from v2c.primitives import from_dict
from v2c.vbrep.extract import extract_vbrep
from v2c.vbrep.mesh import beyond_measured, clip_to_measured, face_mesh, grazing, read_vertices, refine_curved

from scenes.raycast import box_scene, scene_inputs

K = np.array([[600.0, 0, 160], [0, 600.0, 120], [0, 0, 1]])
H, W = 240, 320
WINDOW = (0.3, 1.5)  # metres: depth range of the scene


def _region(u0: int, v0: int, u1: int, v1: int) -> np.ndarray:
    r = np.zeros((H, W), bool)
    r[v0:v1, u0:u1] = True
    return r


def test_plane_through_the_camera_centre_gives_no_vertex_at_the_camera():
    # A plane seen edge-on through the camera centre (a fallback plane of a grazing face, scan_00021 of the
    # sensor benchmark set): every ray meets it at z = 0. Before the fix the whole face mesh sat at the camera
    # centre and, rendered, covered the image.
    n = np.array([0.99992700, 0.0, 0.01208298])
    plane = from_dict(
        {"type": "plane", "params": {"origin": (0.78 * np.array([-n[2], 0, n[0]])).tolist(), "normal": n.tolist()}}
    )
    region = _region(150, 60, 170, 180)
    verts, tris = face_mesh(plane, 0, region, np.zeros((H, W), np.float32), K, WINDOW, 2, 0.02, np.inf)
    assert len(verts) == 0 or verts[:, 2].min() >= WINDOW[0]
    assert len(tris) == 0 or tris.max() < len(verts)


def test_rays_missing_a_cylinder_leave_no_vertex_off_the_surface():
    # An upright cylinder (radius 5 cm at 0.8 m) and a region twice as wide as its image: the rays beside it
    # miss it; their closest-approach fallback is off the surface (up to 5 cm here) and must not become mesh
    # vertices: dropped beyond the tolerance, moved onto the surface within it.
    cyl = from_dict(
        {"type": "cylinder", "params": {"origin": [0.0, 0.0, 0.8], "axis": [0.0, 1.0, 0.0], "radius": 0.05}}
    )
    region = _region(80, 40, 240, 200)
    tol = 0.005
    verts, tris = face_mesh(cyl, 0, region, np.zeros((H, W), np.float32), K, WINDOW, 2, 0.02, tol)
    assert len(tris) > 100
    assert np.abs(cyl.signed_distance(verts)).max() <= 1e-7
    assert verts[:, 2].min() >= WINDOW[0]
    # the mesh still spans the cylinder's image (its contour at u = 160 +- 600 * 0.05 / sqrt(0.8^2 - 0.05^2))
    half = 600 * 0.05 / np.sqrt(0.8**2 - 0.05**2)
    uv = project(verts, K)
    assert uv[:, 0].min() < 160 - half + 2.5 and uv[:, 0].max() > 160 + half - 2.5
    assert uv[:, 0].min() > 160 - half - 1.5 and uv[:, 0].max() < 160 + half + 1.5


def test_plane_mesh_is_unchanged_by_the_guards():
    plane = from_dict({"type": "plane", "params": {"origin": [0.0, 0.0, 0.8], "normal": [0.0, 0.3, -1.0]}})
    region = _region(100, 80, 200, 160)
    args = (plane, 0, region, np.zeros((H, W), np.float32), K, WINDOW, 2, 0.02)
    v0, t0 = face_mesh(*args, np.inf)
    v1, t1 = face_mesh(*args, 1e-4)
    np.testing.assert_array_equal(t0, t1)
    np.testing.assert_allclose(v0, v1)


def _covered(verts: np.ndarray, tris: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(n,) bool: which image points (n, 2) lie strictly inside some projected triangle of the mesh."""
    uv = project(verts, K)
    a, e1, e2 = uv[tris[:, 0]], uv[tris[:, 1]] - uv[tris[:, 0]], uv[tris[:, 2]] - uv[tris[:, 0]]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    q = pts[:, None, :] - a[None]
    x = (q[..., 0] * e2[:, 1] - q[..., 1] * e2[:, 0]) / det
    y = (e1[:, 0] * q[..., 1] - e1[:, 1] * q[..., 0]) / det
    return np.any((x > 0.01) & (y > 0.01) & (x + y < 0.99), axis=1)


def _pixels(mask: np.ndarray, off: float = 0.0) -> np.ndarray:
    """The centres of the pixels of mask, moved by ``off`` px (grid vertices sit on the centres of the face's own
    pixels, on triangle sides: its pixels are tested just off them)."""
    vs, us = np.nonzero(mask)
    return np.stack([us + off, vs + 0.7 * off], 1).astype(float)


PLANE = {"type": "plane", "params": {"origin": [0.0, 0.0, 0.8], "normal": [0.0, 0.3, -1.0]}}


def test_plane_mesh_leaves_a_small_hole_open():
    # A plane face with a 5 x 9 px hole (a drilled hole seen at an angle; its wall is another face): the grid
    # points in the hole are snapped onto its outline, and triangles of those points alone spanned it (27 % of the
    # hole's pixels covered), so the plane hid the hole's wall when rendered (scan_00042 of the sensor benchmark
    # set: four walls drawn at 0-2 px). The face around the hole stays covered.
    region = _region(100, 80, 200, 160)
    region[118:123, 146:155] = False
    verts, tris = face_mesh(from_dict(PLANE), 0, region, np.zeros((H, W), np.float32), K, WINDOW, 2, 0.02, np.inf)
    box = _region(100, 80, 200, 160)
    assert _covered(verts, tris, _pixels(box & ~region)).mean() < 0.05
    assert _covered(verts, tris, np.array([[131.3, 101.7], [171.3, 141.7]])).all()


def test_plane_mesh_leaves_a_narrow_notch_open():
    # A notch 3 px wide and 12 deep cut into the face from its edge (a small wall under the plane's rim, or a slot):
    # triangles from the grid points inside it, snapped onto both of its sides, spanned it with an inside corner
    # (scan_00017 and scan_00002 of the sensor benchmark: 16 of a 58-px and of a 37-px wall drawn by the plane in
    # front). A triangle with an outline corner whose centre pixel lies off the region is left out; the face's
    # own pixels stay covered.
    region = _region(100, 80, 200, 160)
    notch = np.zeros_like(region)
    notch[148:160, 151:154] = True
    region &= ~notch
    verts, tris = face_mesh(from_dict(PLANE), 0, region, np.zeros((H, W), np.float32), K, WINDOW, 2, 0.02, np.inf)
    assert _covered(verts, tris, _pixels(notch)).mean() < 0.1
    assert _covered(verts, tris, _pixels(region, 0.3)[::5]).mean() > 0.99


def test_extracted_meshes_lie_in_front_of_the_camera_on_their_surfaces():
    inp = scene_inputs(box_scene())
    v = extract_vbrep(inp.scan, inp.seg, inp.fit)
    for f in v.faces:
        mv = np.asarray(f.mesh_vertices, float)
        assert len(mv) and mv[:, 2].min() > 0.1
        assert np.abs(from_dict(f.primitive).signed_distance(mv)).max() <= 1e-7


def test_edge_on_plane_keeps_long_triangles_inside_the_part_box_only():
    # A plane seen nearly edge-on (a floor 5 cm below the camera's axis, rows 145-180): its depth runs from
    # 1.2 m to 0.5 m over 35 rows, up to 4 cm per pixel step. Those triangles are longer than max_edge (2 cm), so
    # without a box the far rows are dropped; inside the part's box they are kept, and nothing outside the box
    # is (the far end of a wrong plane running past the part).
    plane = from_dict({"type": "plane", "params": {"origin": [0.0, 0.05, 0.8], "normal": [0.0, 1.0, 0.0]}})
    region = _region(100, 146, 200, 180)
    depth = np.zeros((H, W), np.float32)
    inner = _pixels(_region(100, 147, 200, 179), 0.3)[::3]
    z_of = 0.05 * K[1, 1] / (inner[:, 1] - K[1, 2])  # the plane's depth at those image points (metres)
    args = (plane, 0, region, depth, K, WINDOW, 1, 0.02)
    v0, t0 = face_mesh(*args, np.inf)
    assert _covered(v0, t0, inner[z_of > 0.9]).mean() < 0.05  # far rows: steps over 2 cm
    assert _covered(v0, t0, inner[z_of < 0.6]).mean() > 0.99
    box = (np.array([-1.0, -1.0, 0.3]), np.array([1.0, 1.0, 1.5]))
    v1, t1 = face_mesh(*args, np.inf, box, True)
    assert _covered(v1, t1, inner).mean() > 0.99
    near = (np.array([-1.0, -1.0, 0.3]), np.array([1.0, 1.0, 0.8]))
    v2, t2 = face_mesh(*args, np.inf, near, True)
    assert v2[:, 2].max() <= 0.8 + 1e-9
    assert _covered(v2, t2, inner[z_of < 0.75]).mean() > 0.99
    assert _covered(v2, t2, inner[z_of > 0.85]).mean() == 0.0
    # a box without long_in_bounds only clips: the far rows stay dropped
    _, t3 = face_mesh(*args, np.inf, box, False)
    assert len(t3) == len(t0)


def _area(v: np.ndarray, t: np.ndarray) -> float:
    return float(np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1).sum() / 2)


def test_a_small_hole_wall_is_meshed_to_its_surface_area():
    # A 1.7 mm radius hole wall at 0.8 m is 2.5 pixels wide: its pixel-grid mesh across the curvature is a few
    # flat facets, here 5 on a half cylinder (1.6 % short of the surface area; 6 % on a corpus part, where its STEP
    # face read back that much larger). refine_curved splits the edges that lie off the surface like chords of
    # more than chord_angle, at their midpoints moved onto it: the area comes within chord_angle^2 / 24.
    r, length, n = 0.0017, 0.01, 5
    cyl = from_dict({"type": "cylinder", "params": {"origin": [0.0, 0.0, 0.8], "axis": [0.0, 1.0, 0.0], "radius": r}})
    th = np.linspace(np.pi, 2 * np.pi, n + 1)  # the half facing the camera (z < 0.8)
    verts = np.array([[r * np.cos(t), y, 0.8 + r * np.sin(t)] for y in (0.0, length) for t in th])
    tris = np.array([t for i in range(n) for t in ([i, i + 1, n + 2 + i], [i, n + 2 + i, n + 1 + i])])
    true = np.pi * r * length
    assert _area(verts, tris) < 0.99 * true
    v2, t2 = refine_curved(cyl, verts, tris, 0.25, 4, 400_000)
    assert abs(_area(v2, t2) - true) <= 0.25**2 / 24 * true
    assert np.abs(cyl.signed_distance(v2)).max() <= 1e-9  # every new vertex on the surface
    # conforming: every edge is used by one triangle (the rim) or two, none more; and the winding is kept
    e = np.sort(np.concatenate([t2[:, [0, 1]], t2[:, [1, 2]], t2[:, [2, 0]]]), axis=1)
    _, uses = np.unique(e, axis=0, return_counts=True)
    assert set(uses) <= {1, 2}

    def facing(v, t):
        return np.sign(np.einsum("ij,ij->i", np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), v[t[:, 0]]))

    assert set(facing(verts, tris)) == set(facing(v2, t2))
    # edges along the axis lie on the surface, however long: a fine mesh across the curvature (40 facets on the
    # half of a 5 cm cylinder) with 20 cm edges along it is left as it is
    r, length, n = 0.05, 0.2, 40
    th = np.linspace(np.pi, 2 * np.pi, n + 1)
    verts = np.array([[r * np.cos(t), y, 0.8 + r * np.sin(t)] for y in (0.0, length) for t in th])
    tris = np.array([t for i in range(n) for t in ([i, i + 1, n + 2 + i], [i, n + 2 + i, n + 1 + i])])
    big = from_dict({"type": "cylinder", "params": {"origin": [0.0, 0.0, 0.8], "axis": [0.0, 1.0, 0.0], "radius": r}})
    v3, t3 = refine_curved(big, verts, tris, 0.25, 4, 400_000)
    assert len(t3) == len(tris) and np.array_equal(v3, verts)


def _grid_patch(x0: float, y0: float, z: float, n: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """A flat (n x n)-vertex grid at depth z (metres) with two triangles per cell."""
    xs, ys = np.meshgrid(x0 + step * np.arange(n), y0 + step * np.arange(n))
    v = np.stack([xs.ravel(), ys.ravel(), np.full(n * n, z)], 1)
    i = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    t = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    return v, t


def test_a_small_mesh_island_far_behind_the_measured_part_is_dropped():
    # A 40 x 40 mm face at 0.6 m (its measured points are its own vertices) with two small pieces: one 0.26 m
    # behind the part, where rays through a curved face's near sheet met its far one (corpus validation: a
    # 0.3 mm² island that set the reconstruction's box), and one seen past an occluder, on measured points.
    from scipy.spatial import cKDTree

    from v2c.vbrep.mesh import drop_stray_islands

    main_v, main_t = _grid_patch(0.0, 0.0, 0.60, 41, 0.001)
    far_v, far_t = _grid_patch(0.01, 0.01, 0.86, 3, 0.001)
    near_v, near_t = _grid_patch(0.05, 0.0, 0.60, 3, 0.001)
    measured = cKDTree(np.concatenate([main_v, near_v]))
    verts = np.concatenate([main_v, far_v, near_v])
    tri = np.concatenate([main_t, far_t + len(main_v), near_t + len(main_v) + len(far_v)])
    out_v, out_t = drop_stray_islands(verts, tri, measured, max_share=0.01, max_dist=0.05 * 0.04)
    assert len(out_t) == len(main_t) + len(near_t)
    assert out_v[:, 2].max() == 0.60  # the far piece is gone, the occluded one kept
    assert np.isclose(out_v[out_t].reshape(-1, 3)[:, 0].max(), 0.052)
    # a piece that is a visible share of the face stays wherever it lies (a wrong surface is not this step's call)
    big_v, big_t = _grid_patch(0.01, 0.01, 0.86, 8, 0.001)
    verts = np.concatenate([main_v, big_v])
    tri = np.concatenate([main_t, big_t + len(main_v)])
    kept_v, kept_t = drop_stray_islands(verts, tri, measured, max_share=0.01, max_dist=0.05 * 0.04)
    assert len(kept_t) == len(tri) and len(kept_v) == len(verts)
    # without measured points nothing is dropped
    assert len(drop_stray_islands(verts, tri, None, 0.01, 0.002)[1]) == len(tri)


def _floor_depth(region: np.ndarray, y: float) -> np.ndarray:
    """The depth (metres) of the plane y = ``y`` (camera frame) at the pixels of ``region``, 0 elsewhere."""
    depth = np.zeros((H, W), np.float32)
    vs, us = np.nonzero(region)
    depth[vs, us] = y * K[1, 1] / (vs - K[1, 2])
    return depth


def _measured(region: np.ndarray, depth: np.ndarray) -> np.ndarray:
    vs, us = np.nonzero(region & (depth > 0))
    z = depth[vs, us].astype(float)
    return np.column_stack([(us - K[0, 2]) / K[0, 0] * z, (vs - K[1, 2]) / K[1, 1] * z, z])


def test_an_edge_on_plane_a_little_off_keeps_to_what_its_pixels_measured():
    # The true surface: a floor 5 cm below the camera's axis, seen nearly edge-on (rows 150-175: 0.6-1.0 m away,
    # about 87 degrees from the view). The fitted plane is tilted 0.5 degrees about the x axis through the
    # floor's point at 0.8 m: along the rays its crossings run centimetres past the floor the sensor saw (a
    # corpus part's edge-on faces, oracle segmentation). Clipped, the mesh keeps to the measured points.
    region = _region(100, 150, 200, 176)
    depth = _floor_depth(region, 0.05)
    plane = from_dict({"type": "plane", "params": {"origin": [0.0, 0.05, 0.8], "normal": _tilted(0.5)}})
    box = (np.array([-1.0, -1.0, 0.3]), np.array([1.0, 1.0, 1.5]))
    v0, t0 = face_mesh(plane, 0, region, depth, K, WINDOW, 1, 0.02, np.inf, box, True)
    seen = _measured(region, depth)
    tree = cKDTree(seen)
    read = read_vertices(v0, region, depth, K)
    assert read.all()  # every pixel has a reading: every vertex is judged
    v1, t1 = clip_to_measured(v0, t0, read, tree, 0.005)
    lo, hi = seen[:, 2].min(), seen[:, 2].max()

    def beyond(v: np.ndarray) -> float:
        """How far (metres, along z) the mesh runs past the depths the sensor saw."""
        return float(np.max(np.maximum(np.maximum(lo - v[:, 2], v[:, 2] - hi), 0.0)))

    assert beyond(v0) > 0.02  # the crossings run past the floor seen
    assert beyond(v1) <= 0.005 and tree.query(v1)[0].max() <= 0.005  # clipped: on what was measured
    assert _area(v1, t1) > 0.3 * _area(v0, t0)  # the part of the face the sensor saw stays
    # as a loop mesh (a trimmed face) the whole face lies past its readings at its median vertex: not used
    assert beyond_measured(v0, read, tree, 0.002)
    assert not beyond_measured(v1, read_vertices(v1, region, depth, K), tree, 0.005)
    assert clip_to_measured(v0, t0, read, None, 0.005)[1] is t0  # no readings to judge by (a face its edges place)
    judged = grazing(plane, v0, np.cos(np.radians(80.0)))
    assert judged.all()  # 87 degrees from the view: every crossing is judged
    assert np.array_equal(clip_to_measured(v0, t0, read, tree, 0.005, 0.0, judged)[1], t1)
    assert len(clip_to_measured(v0, t0, read, tree, 0.005, 0.99, judged)[1]) == 0  # most of it contradicted: none


def _tilted(deg: float) -> list[float]:
    """The floor's normal (0, 1, 0) tilted ``deg`` degrees about the x axis."""
    t = np.radians(deg)
    return [0.0, float(np.cos(t)), float(-np.sin(t))]


def test_a_well_seen_plane_is_not_clipped():
    # A plane at 30 degrees to the view at 0.8 m with depth noise of 3 sensor sigmas (0.0015 z^2) at most: every
    # lifted vertex lies within millimetres of a measured point, so nothing is clipped at 5 mm.
    rng = np.random.default_rng(3)
    n = np.array([0.0, np.sin(np.radians(30)), -np.cos(np.radians(30))])
    plane = from_dict({"type": "plane", "params": {"origin": [0.0, 0.0, 0.8], "normal": n.tolist()}})
    region = _region(110, 80, 210, 160)
    vs, us = np.nonzero(region)
    rays = np.column_stack([(us - K[0, 2]) / K[0, 0], (vs - K[1, 2]) / K[1, 1], np.ones(len(us))])
    z = (np.array([0.0, 0.0, 0.8]) @ n) / (rays @ n)
    depth = np.zeros((H, W), np.float32)
    depth[vs, us] = z + np.clip(rng.normal(0.0, 1.0, len(z)), -3, 3) * 0.0015 * z**2
    v0, t0 = face_mesh(plane, 0, region, depth, K, WINDOW, 1, 0.02, np.inf)
    tree = cKDTree(_measured(region, depth))
    read = read_vertices(v0, region, depth, K)
    v1, t1 = clip_to_measured(v0, t0, read, tree, 0.005)
    assert np.array_equal(t0, t1) and np.array_equal(v0, v1)
    assert not beyond_measured(v0, read, tree, 0.005)
    # the same plane fitted 2 cm off: every crossing lies 2 cm from the readings, but 30 degrees from face-on
    # that is the fit's error, not the ray's: no vertex is judged, nothing clipped
    off = from_dict(
        {"type": "plane", "params": {"origin": (np.array([0.0, 0.0, 0.8]) + 0.02 * n).tolist(), "normal": n.tolist()}}
    )
    v2, t2 = face_mesh(off, 0, region, depth, K, WINDOW, 1, 0.02, np.inf)
    judged = grazing(off, v2, np.cos(np.radians(80.0)))
    assert not judged.any()
    read2 = read_vertices(v2, region, depth, K)
    assert np.array_equal(clip_to_measured(v2, t2, read2, tree, 0.005, 0.0, judged)[1], t2)


def test_a_dropout_inside_a_face_is_kept_and_a_piece_past_the_readings_dropped():
    # The edge-on floor, fitted exactly, with readings only on rows 150-162 and a dropout (a dark band the
    # sensor did not read) on rows 163-175. The vertices the sensor read or that lie next to a reading are
    # judged and stay (they lie on the readings); the dropout's vertices stay with them (nothing contradicts
    # them, and the piece they form holds vertices the sensor confirmed). A second, separate patch of the same
    # face (columns 220-240, no reading, cut off from the rest) forms a piece with no confirmed vertex: dropped.
    region = _region(100, 150, 200, 176) | _region(220, 150, 240, 176)
    depth = _floor_depth(_region(100, 150, 200, 163), 0.05)
    plane = from_dict({"type": "plane", "params": {"origin": [0.0, 0.05, 0.8], "normal": [0.0, 1.0, 0.0]}})
    box = (np.array([-1.0, -1.0, 0.3]), np.array([1.0, 1.0, 1.5]))
    v0, t0 = face_mesh(plane, 0, region, depth, K, WINDOW, 1, 0.02, np.inf, box, True)
    read = read_vertices(v0, region, depth, K)
    tree = cKDTree(_measured(region, depth))
    v1, t1 = clip_to_measured(v0, t0, read, tree, 0.03)  # a pixel row spans 17 mm of floor here
    uv0, uv1 = project(v0, K), project(v1, K)
    dropout = (uv0[:, 1] > 164) & (uv0[:, 0] < 210)  # vertices of the dropout band, none read
    assert not read[dropout].any()
    kept_dropout = (uv1[:, 1] > 164) & (uv1[:, 0] < 210)
    assert kept_dropout.sum() > 0.5 * dropout.sum()  # the band stays with the part the sensor confirmed
    assert not (uv1[:, 0] > 210).any()  # the separate patch with no reading at all is dropped
    assert tree.query(v1[read_vertices(v1, region, depth, K)])[0].max() <= 0.03


def test_a_face_whose_surface_misses_its_own_readings_gets_no_mesh():
    """A face whose fitted surface lies 2 cm (a fifth of the box) off what its pixels measured, at any angle to the
    view, gets no mesh (`VBRepConfig.mesh_evidence_median`: a wrong primitive; a corpus part's 19 px face came out
    a 101 mm cylinder 25 mm off its readings and lay 0.08 part sizes from the part); the other faces keep theirs,
    and with the rule off the wrong face keeps its mesh."""
    from dataclasses import replace

    from v2c.vbrep.config import VBRepConfig

    shifted = []

    def shift_first_plane(p: dict, rng: np.random.Generator) -> dict:
        if p["type"] != "plane" or shifted:
            return p
        n = np.asarray(p["params"]["normal"], float)
        shifted.append(True)
        origin = (np.asarray(p["params"]["origin"], float) + 0.02 * n / np.linalg.norm(n)).tolist()
        return {**p, "params": {**p["params"], "origin": origin}}

    inp = scene_inputs(box_scene(), perturb=shift_first_plane)
    assert shifted
    cfg = VBRepConfig()
    v = extract_vbrep(inp.scan, inp.seg, inp.fit, cfg)
    meshed = {f.instance: len(f.mesh_triangles) > 0 for f in v.faces}
    assert not meshed[1] and all(meshed[i] for i in meshed if i != 1)
    gone = [f.id for f in v.faces if f.instance == 1]
    assert v.meta["extract"]["faces_off_their_readings"] == gone  # said in the VB-Rep, by face id
    off = extract_vbrep(inp.scan, inp.seg, inp.fit, replace(cfg, mesh_evidence_median=False))
    assert all(len(f.mesh_triangles) > 0 for f in off.faces)
