"""Surface mesh extraction: each face's visible region as a triangle mesh on its surface.

The face's pixel region (its instance mask) is sampled on a regular pixel grid (``stride`` pixels); grid points
up to one step outside the region are pulled onto the region's outline (the nearest region pixel, moved half a
pixel outwards), so that the mesh reaches the face's edges. Every grid point is back-projected onto the face's
surface sheet by ray-surface intersection (exact on the surface, covering exactly what the camera sees of the
face), and the grid is triangulated: two triangles per grid square whose four corners are present, one where three
are. A triangle with a corner on the outline whose centre pixel is not the region's spans a gap of it (a small
hole, a narrow notch where another face cuts in) and is dropped. Triangles with a side longer than ``max_edge``
metres (a jump between crossings where the sheet is absent) are dropped, unless ``long_in_bounds`` (given for
planes, which have one crossing: a plane seen nearly edge-on spans much depth per pixel) and all three corners lie
in ``bounds``. With ``bounds`` (the part's box) no triangle with a corner outside it is kept, however short: the
box, not a side length, tells a face from a wrong surface running off past the part. Triangles are wound to face
the camera.

A grid point whose ray yields no usable point is left out with its triangles: a depth outside ``window`` (at or
behind the camera centre, e.g. a plane seen edge-on through the camera centre gives z = 0 for every ray) or not
finite, or a point farther than ``surface_tol`` metres from the surface (the closest-approach fallback of a ray
that misses the curved sheet by more than that). Closest-approach points within ``surface_tol`` (rays just beside
a contour, or where the fitted surface does not quite cover the face's pixels) are moved onto the surface (its
closest point). So every vertex lies on its surface (within 1e-7 m) and in front of the camera.

`clip_to_measured` then keeps a pixel mesh to what its face's pixels measured where its rays meet the surface
nearly edge-on (`grazing`, `read_vertices`), and `beyond_measured` tells a loop mesh lying past its readings
(docs/vbrep.md, "Meshes keep to what their pixels measured").
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import binary_dilation, distance_transform_edt
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from v2c.camera import pixel_rays, project
from v2c.primitives import Cone, Cylinder, Sphere, Torus
from v2c.primitives.base import Primitive
from v2c.vbrep.raycast import as_primitive, intersect, sheet_depth

#: closest-point steps moving a vertex onto its surface: one is exact for the quadrics, a good step for the torus
_CLOSEST_STEPS = 3


def face_mesh(
    prim: Primitive,
    sheet: int,
    region: np.ndarray,
    depth: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    stride: int,
    max_edge: float,
    surface_tol: float,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    long_in_bounds: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh of one face. region: (H, W) bool pixels of the face; depth: (H, W) observed depth (metres, 0 = none)
    used to pick the crossing where the sheet is absent; window: (near, far) depths (metres) a vertex may have;
    stride: grid spacing (pixels); max_edge: metres (inf: no limit);
    surface_tol: metres a ray's closest approach may lie off the surface to be moved onto it (farther: dropped;
    inf: all kept);
    bounds: optional (low (3,), high (3,)) camera-frame box (metres) every kept triangle lies in;
    long_in_bounds: with bounds, triangles longer than max_edge are kept too.
    Returns vertices (n, 3) camera-frame metres and triangles (m, 3) int64; every vertex has
    window[0] <= z <= window[1] and lies on the surface."""
    vs, us = np.nonzero(region)
    if len(us) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    u0, v0 = us.min() - us.min() % stride, vs.min() - vs.min() % stride
    gu = np.arange(u0, us.max() + stride, stride)
    gv = np.arange(v0, vs.max() + stride, stride)
    gu = np.concatenate([[gu[0] - stride], gu, [gu[-1] + stride]])
    gv = np.concatenate([[gv[0] - stride], gv, [gv[-1] + stride]])
    h, w = region.shape
    GU, GV = np.meshgrid(gu, gv, indexing="xy")
    ok = (GU >= 0) & (GU < w) & (GV >= 0) & (GV < h)
    inside = np.zeros(GU.shape, bool)
    inside[ok] = region[GV[ok], GU[ok]]
    # grid points one step outside the region: snapped onto its outline
    near = np.zeros(GU.shape, bool)
    near[:-1] |= inside[1:]
    near[1:] |= inside[:-1]
    near[:, :-1] |= inside[:, 1:]
    near[:, 1:] |= inside[:, :-1]
    near &= ~inside
    keep = inside | near
    idx = np.full(GU.shape, -1, np.int64)
    idx[keep] = np.arange(keep.sum())
    uv = np.stack([GU[keep], GV[keep]], 1).astype(float)
    out = ~inside[keep]
    if out.any():
        y0, x0 = max(0, gv[0]), max(0, gu[0])
        sub = ~region[y0 : gv[-1] + 1, x0 : gu[-1] + 1]
        _, (iy, ix) = distance_transform_edt(sub, return_indices=True)
        q = uv[out]
        qi = np.clip(np.rint(q[:, 1]).astype(int) - y0, 0, sub.shape[0] - 1)
        qj = np.clip(np.rint(q[:, 0]).astype(int) - x0, 0, sub.shape[1] - 1)
        nearest = np.stack([ix[qi, qj] + x0, iy[qi, qj] + y0], 1).astype(float)
        d = q - nearest
        uv[out] = nearest + 0.5 * d / np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    verts, good = lift_points(prim, sheet, uv, depth, K, window, surface_tol)
    if not good.all():
        idx[keep] = np.where(good, idx[keep], -1)
    a, b = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel()
    c, d = idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tris = []
    full = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    tris += [np.stack([a, b, c], 1)[full], np.stack([a, c, d], 1)[full]]
    for t0, t1, t2, miss in ((b, c, d, a), (a, c, d, b), (a, b, d, c), (a, b, c, d)):
        three = (t0 >= 0) & (t1 >= 0) & (t2 >= 0) & (miss < 0)
        tris.append(np.stack([t0, t1, t2], 1)[three])
    tri = np.concatenate(tris).astype(np.int64)
    if len(tri):  # a triangle with an outline corner (``out``) whose centre pixel lies off the region spans a gap of
        # it (a small hole, a narrow notch where another face cuts in) and would hide that face when rendered
        rim = out[tri].any(axis=1)
        c = np.clip(np.rint(uv[tri].mean(axis=1)).astype(int), 0, [w - 1, h - 1])
        tri = tri[~(rim & ~region[c[:, 1], c[:, 0]])]
    return finish_mesh(verts, tri, max_edge, bounds, long_in_bounds)


def lift_points(
    prim: Primitive,
    sheet: int,
    uv: np.ndarray,
    depth: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    surface_tol: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Image points uv (N, 2) back-projected onto the face's sheet: (N, 3) camera-frame metres and (N,) bool
    usable (finite, inside ``window``, on the surface: closest-approach points within ``surface_tol`` metres
    moved onto it, farther ones unusable)."""
    h, w = depth.shape[:2]
    pix = np.clip(np.rint(uv).astype(int), 0, [w - 1, h - 1])
    prior = depth[pix[:, 1], pix[:, 0]].astype(float)
    rays = pixel_rays(uv, K)
    z = sheet_depth(intersect(prim, rays, window), sheet, np.where(prior > 0, prior, np.nan))
    verts = rays * z[:, None]
    good = np.isfinite(z) & (z >= max(window[0], 1e-9)) & (z <= window[1])
    if good.any():  # closest-approach points of rays missing the sheet: onto the surface, or dropped
        p = as_primitive(prim)
        gi = np.flatnonzero(good)
        off = np.abs(p.signed_distance(verts[gi]))
        good[gi[off > surface_tol]] = False
        snap = gi[(off <= surface_tol) & (off > 1e-9)]
        if len(snap):
            for _ in range(_CLOSEST_STEPS):
                verts[snap] = p.closest_point(verts[snap])
            good[snap] &= (
                (np.abs(p.signed_distance(verts[snap])) <= 1e-7)
                & (verts[snap, 2] >= window[0])
                & (verts[snap, 2] <= window[1])
            )
    return verts, good


def finish_mesh(
    verts: np.ndarray,
    tri: np.ndarray,
    max_edge: float,
    bounds: tuple[np.ndarray, np.ndarray] | None,
    long_in_bounds: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """The kept triangles (see the module doc: ``max_edge``, ``bounds``, ``long_in_bounds``), wound to face the
    camera, and the vertices they use (compacted)."""
    if len(tri) == 0:
        return np.zeros((0, 3)), tri
    p0, p1, p2 = verts[tri[:, 0]], verts[tri[:, 1]], verts[tri[:, 2]]
    longest = np.max(
        np.stack([np.linalg.norm(p1 - p0, axis=1), np.linalg.norm(p2 - p1, axis=1), np.linalg.norm(p0 - p2, axis=1)]), 0
    )
    keep = np.isfinite(longest) & (longest <= max_edge)
    if bounds is not None:
        inside = np.all((verts >= bounds[0]) & (verts <= bounds[1]), axis=1)[tri].all(axis=1)
        keep = (keep | (np.isfinite(longest) & long_in_bounds)) & inside
    tri = tri[keep]
    p0, p1, p2 = verts[tri[:, 0]], verts[tri[:, 1]], verts[tri[:, 2]]
    facing_away = np.einsum("ij,ij->i", np.cross(p1 - p0, p2 - p0), p0) > 0
    tri[facing_away] = tri[facing_away][:, [0, 2, 1]]
    return _compacted(verts, tri)


def _compacted(verts: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The vertices the triangles use, in order, and the triangles renumbered onto them."""
    used = np.unique(tri)
    remap = np.full(len(verts), -1, np.int64)
    remap[used] = np.arange(len(used))
    return verts[used], remap[tri]


def triangle_areas(verts: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(M,) areas of the triangles ``tri`` (M, 3) of ``verts`` (square metres for metres)."""
    p0, p1, p2 = verts[tri[:, 0]], verts[tri[:, 1]], verts[tri[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)


def sample_surface(vertices: np.ndarray, triangles: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Draw n points area-uniformly on a triangle mesh (metres, same frame as the vertices)."""
    if len(triangles) == 0 or n <= 0:
        return np.zeros((0, 3))
    p0, p1, p2 = (vertices[triangles[:, k]] for k in range(3))
    area = triangle_areas(vertices, triangles)
    if area.sum() <= 0:
        return np.zeros((0, 3))
    t = rng.choice(len(triangles), n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    flip = r1 + r2 > 1
    r1, r2 = np.where(flip, 1 - r1, r1), np.where(flip, 1 - r2, r2)
    return p0[t] + r1[:, None] * (p1[t] - p0[t]) + r2[:, None] * (p2[t] - p0[t])


def curvature_radius(prim: Primitive, points: np.ndarray) -> np.ndarray:
    """(N,) the smaller principal radius of curvature (metres) of ``prim`` at surface points (N, 3): a
    cylinder's or sphere's radius, a torus's tube radius, a cone's circle radius over the cosine of its half
    angle; infinite on a plane."""
    n = len(points)
    if isinstance(prim, (Cylinder, Sphere)):
        return np.full(n, abs(prim.radius))
    if isinstance(prim, Torus):
        return np.full(n, abs(prim.minor_radius))
    if isinstance(prim, Cone):
        d = points - prim.origin
        rho = np.linalg.norm(d - np.outer(d @ prim.axis, prim.axis), axis=1)
        return rho / np.cos(prim.half_angle)
    return np.full(n, np.inf)


def refine_curved(
    prim: Primitive,
    verts: np.ndarray,
    tri: np.ndarray,
    chord_angle: float,
    levels: int,
    max_triangles: int,
) -> tuple[np.ndarray, np.ndarray]:
    """A face mesh on a curved surface with every edge that lies off the surface like a chord subtending more
    than ``chord_angle`` radians at its smaller curvature radius (by its sagitta) split at its midpoint, moved
    onto the surface (its closest point), up to
    ``levels`` times and while the mesh stays under ``max_triangles``. The splits are per edge, so neighbouring
    triangles still share their corners (each triangle becomes 2, 3 or 4 with its winding). A pixel-grid mesh of
    a small curved face is coarse across its curvature (a hole wall of 1.7 mm radius seen 4 pixels wide: 5 flat
    facets on a half cylinder, its area 6 % short of the surface's); its flat triangles now stay within
    ``chord_angle``^2 / 24 of the surface's area. A torus is left as it is: where its fitted tube is thinner
    than the face seen, its pixel mesh runs onto both sheets of the tube, and splitting the edges between them
    grows the mesh there (corpus validation, oracle: four torus blends read back at 0.74-0.95 of their refined
    meshes' area, against 0.99-1.00 unrefined)."""
    p = as_primitive(prim)
    if isinstance(p, Torus):
        return verts, tri
    for _ in range(levels):  # loop over refinement levels
        if len(tri) == 0 or 4 * len(tri) > max_triangles:
            break
        e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(e, axis=0, return_inverse=True)
        inv = inv.reshape(3, -1).T  # (M, 3) edge ids of each triangle: ab, bc, ca
        mid = verts[uniq].mean(axis=1)
        # the edge's sagitta (its midpoint's distance to the surface) against that of a chord of chord_angle
        # across the curvature: an edge along a straight line of the surface (a cylinder's axis) is never split
        split = np.abs(p.signed_distance(mid)) > (1 - np.cos(chord_angle / 2)) * curvature_radius(p, mid)
        if not split.any():
            break
        new = np.full(len(uniq), -1, np.int64)
        new[split] = len(verts) + np.arange(split.sum())
        q = mid[split]
        for _ in range(_CLOSEST_STEPS):
            q = p.closest_point(q)
        verts = np.concatenate([verts, q])
        tri = _split_triangles(tri, new[inv])
    return verts, tri


def drop_stray_islands(
    verts: np.ndarray,
    tri: np.ndarray,
    measured: cKDTree | None,
    max_share: float,
    max_dist: float,
) -> tuple[np.ndarray, np.ndarray]:
    """A face mesh without its stray islands: pieces (connected through shared corners) other than the largest
    whose area is at most ``max_share`` of the mesh's and whose vertices lie, at their median, farther than
    ``max_dist`` metres from every measured point of the part (``measured``: a KD-tree of them; None keeps all).
    A few pixels of a curved face whose rays pass its near sheet meet the far one: a cone of a corpus part
    (validation, learned) held a 0.3 mm² island 260 mm behind the part, which set the reconstruction's box
    (the STEP writer drops such specks, so the file's box came out 0.81 of the VB-Rep's). A piece of the face
    seen past an occluder lies on measured points and stays, however small."""
    if measured is None or len(tri) < 2:
        return verts, tri
    k, comp = _pieces(len(verts), tri)
    if k < 2:
        return verts, tri
    piece_area = np.bincount(comp[tri[:, 0]], weights=triangle_areas(verts, tri), minlength=k)
    main = int(np.argmax(piece_area))
    drop = np.zeros(k, bool)
    for c in np.flatnonzero(piece_area <= max_share * piece_area.sum()):  # loop over small pieces
        if c != main and float(np.median(measured.query(verts[comp == c], k=1)[0])) > max_dist:
            drop[c] = True
    if not drop.any():
        return verts, tri
    return _compacted(verts, tri[~drop[comp[tri[:, 0]]]])


def _pieces(n: int, tri: np.ndarray) -> tuple[int, np.ndarray]:
    """The pieces of a mesh of ``n`` vertices and triangles ``tri`` (M, 3) connected through shared corners: their
    count and each vertex's piece label (n,)."""
    rows = np.concatenate([tri[:, 0], tri[:, 1], tri[:, 2]])
    cols = np.concatenate([tri[:, 1], tri[:, 2], tri[:, 0]])
    return connected_components(coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)), directed=False)


def read_vertices(verts: np.ndarray, region: np.ndarray, depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N,) bool: which mesh vertices (N, 3) project next to a pixel of the face (``region``) that has a depth
    reading: the pixel nearest their image point or one of its 8 neighbours (a vertex of the outline lies half a
    pixel past the face's last pixels)."""
    seen = region & (np.asarray(depth) > 0)
    vs, us = np.nonzero(seen)
    if not len(verts) or not len(vs):
        return np.zeros(len(verts), bool)
    h, w = seen.shape
    # the dilation on the readings' box plus a pixel, not the whole image: this runs for every face
    v0, v1, u0, u1 = max(vs.min() - 1, 0), min(vs.max() + 2, h), max(us.min() - 1, 0), min(us.max() + 2, w)
    readable = binary_dilation(seen[v0:v1, u0:u1], structure=np.ones((3, 3), bool))
    pix = np.clip(np.rint(project(verts, K)).astype(int), 0, [w - 1, h - 1])
    inside = (pix[:, 0] >= u0) & (pix[:, 0] < u1) & (pix[:, 1] >= v0) & (pix[:, 1] < v1)
    out = np.zeros(len(verts), bool)
    out[inside] = readable[pix[inside, 1] - v0, pix[inside, 0] - u0]
    return out


def grazing(prim: Primitive, verts: np.ndarray, max_cos: float) -> np.ndarray:
    """(N,) bool: the mesh vertices (N, 3, camera frame) whose camera ray meets the surface within
    arccos(``max_cos``) of edge-on (|cos| of the angle between the ray and the surface normal at most
    ``max_cos``)."""
    if not len(verts):
        return np.zeros(0, bool)
    rays = verts / np.maximum(np.linalg.norm(verts, axis=1, keepdims=True), 1e-12)
    normals = as_primitive(prim).normal(verts)
    return np.abs(np.einsum("ij,ij->i", rays, normals)) <= max_cos


def clip_to_measured(
    verts: np.ndarray,
    tri: np.ndarray,
    read: np.ndarray,
    own: cKDTree | None,
    max_dist: float,
    min_share: float = 0.0,
    judged: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A face mesh kept to what its own pixels measured (``own``: a KD-tree of those points; None keeps all).

    The mesh lifts the face's pixels onto its surface along their rays. Where the surface is seen nearly edge-on
    a small error of its fit moves that crossing far along the ray: a plane 87-89 degrees from the view whose
    normal was 0.2-0.7 degrees off the points' own (a corpus part, oracle segmentation) reached 0.07-0.14 part
    sizes past the part, the points themselves lying within 0.6 mm of it. So (issue 16: a fitted surface never
    extends past its region's measured pixels by more than a stated tolerance):

    - a triangle with a vertex on (or next to) a pixel with a reading (``read``, (N,) bool) and, with
      ``judged`` ((N,) bool, e.g. `grazing`), among those, that lies farther than ``max_dist`` metres from every
      measured point of the face is dropped;
    - a piece of what is left (connected through shared corners) with no read vertex left (one within
      ``max_dist`` of the readings, or not judged) is dropped too.

    A vertex on a pixel without a reading (a dropout on a dark or grazing wall, which the face's other pixels
    and edges place) has nothing to contradict it and stays with its piece. When what is left holds less than
    ``min_share`` of the mesh's area, the readings contradict the surface over most of the face: no mesh is
    left."""
    if own is None or not len(tri):
        return verts, tri
    dist = np.full(len(verts), np.inf)
    if read.any():
        dist[read] = own.query(verts[read], k=1)[0]
    far = read & (dist > max_dist)
    if judged is not None:
        far &= judged
    near = read & ~far  # read and within max_dist, or not judged: no verdict against it
    total = triangle_areas(verts, tri).sum()
    tri = tri[~far[tri].any(axis=1)]
    if not len(tri):
        return _compacted(verts, tri)
    _, comp = _pieces(len(verts), tri)
    supported = np.zeros(comp.max() + 1, bool)
    used = np.unique(tri)
    supported[comp[used[near[used]]]] = True
    tri = tri[supported[comp[tri[:, 0]]]]
    if min_share > 0 and triangle_areas(verts, tri).sum() < min_share * total:
        tri = tri[:0]
    return _compacted(verts, tri)


def beyond_measured(verts: np.ndarray, read: np.ndarray, own: cKDTree | None, max_dist: float) -> bool:
    """Whether a face's mesh lies, at the median of its vertices on pixels with a reading (``read``), farther
    than ``max_dist`` metres from every point its own pixels measured (``own``; None: never). A face's loop mesh
    (its trimmed face) is not used then: its loops bound it where the sensor did not see it. A loop mesh only
    partly past its readings is kept whole: its edges place it."""
    if own is None or not read.any():
        return False
    return bool(np.median(own.query(verts[read], k=1)[0]) > max_dist)


def _split_triangles(tri: np.ndarray, mids: np.ndarray) -> np.ndarray:
    """Triangles (M, 3) a, b, c with the new vertex on each of their edges ab, bc, ca (M, 3; -1: not split)
    replaced by their parts, wound as they were."""
    out = [tri[(mids < 0).all(axis=1)]]
    k = (mids >= 0).sum(axis=1)
    for r in range(3):  # rotations: the single split edge, or the unsplit one of two, moved to a fixed place
        t = np.roll(tri, -r, axis=1)
        m = np.roll(mids, -r, axis=1)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        ab, bc, ca = m[:, 0], m[:, 1], m[:, 2]
        one = (k == 1) & (ab >= 0)
        out += [np.stack([a, ab, c], 1)[one], np.stack([ab, b, c], 1)[one]]
        two = (k == 2) & (ca < 0)
        out += [np.stack([a, ab, bc], 1)[two], np.stack([ab, b, bc], 1)[two], np.stack([a, bc, c], 1)[two]]
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, bc, ca = mids[:, 0], mids[:, 1], mids[:, 2]
    three = k == 3
    out += [np.stack(x, 1)[three] for x in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))]
    return np.concatenate(out).astype(np.int64)
