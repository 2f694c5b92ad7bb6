"""Hand-built analytic VB-Reps for the tests of later stages (STEP export, fixtures, figures).

`box_corner()`: a 0.10 x 0.08 x 0.06 m box seen from a corner: 3 planar faces, 3 intersection edges meeting in
one corner vertex, 6 silhouette edges around.
`cylinder_upright()`: a cylinder (radius 0.04 m, height 0.08 m) standing on its base, seen from above and to the
side: the cylinder face bounded by 2 visibility edges, the top disc, the front arc of the top circle as an
intersection edge (analytic circle), the back arc of the top circle and the bottom arc as silhouettes.

Both are in the camera frame (OpenCV), metres, with a 640 x 480 camera of focal length 615 px.
"""

from __future__ import annotations

import numpy as np

from v2c.vbrep.model import EdgeType, VBRep, VEdge, VertexKind, VFace, VVertex

IMAGE_SIZE = (640, 480)
K_DEFAULT = np.array([[615.0, 0.0, 320.0], [0.0, 615.0, 240.0], [0.0, 0.0, 1.0]])


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray | None = None) -> np.ndarray:
    """(3, 3) rotation R with rows = the camera's x (right), y (down), z (forward) axes in world coordinates,
    so that camera coordinates are ``R @ (p - eye)``; ``up`` (default world +Z) points up in the image."""
    up = np.array([0.0, 0.0, 1.0]) if up is None else np.asarray(up, float)
    z = np.asarray(target, float) - np.asarray(eye, float)
    z /= np.linalg.norm(z)
    y = -(up - (up @ z) * z)
    y /= np.linalg.norm(y)
    x = np.cross(y, z)
    return np.stack([x, y, z])


def project(points: np.ndarray, K: np.ndarray = K_DEFAULT) -> np.ndarray:
    """(N, 3) camera-frame points -> (N, 2) pixel (u, v)."""
    p = np.atleast_2d(points) @ K.T
    return p[:, :2] / p[:, 2:3]


def _segment(a: np.ndarray, b: np.ndarray, n: int = 16) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return a[None] * (1 - t) + b[None] * t


def _quad_mesh(corners: np.ndarray, n: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Grid mesh of a planar quad with corners p00, p10, p11, p01 (n x n vertices)."""
    s, t = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="xy")
    s = s.ravel()[:, None]
    t = t.ravel()[:, None]
    p00, p10, p11, p01 = corners
    verts = (1 - s) * (1 - t) * p00 + s * (1 - t) * p10 + s * t * p11 + (1 - s) * t * p01
    return verts, grid_triangles(n, n)


def grid_triangles(nu: int, nv: int) -> np.ndarray:
    """Triangles of a row-major grid of nv rows x nu columns of vertices."""
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="xy")
    a = (j * nu + i).ravel()
    b, c, d = a + 1, a + nu + 1, a + nu
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def _plane(origin: np.ndarray, normal: np.ndarray) -> dict:
    return {"type": "plane", "params": {"origin": origin.tolist(), "normal": normal.tolist()}}


def box_corner(size: tuple[float, float, float] = (0.10, 0.08, 0.06), distance: float = 0.5) -> VBRep:
    """A box seen from its (+X, +Y, +Z) corner: see the module docstring. Part frame = box axes, centred."""
    h = np.asarray(size, float) / 2
    eye = np.array([1.0, 0.75, 0.85])
    eye = eye / np.linalg.norm(eye) * distance
    R = look_at(eye, np.zeros(3))

    def cam(p: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(p) - eye) @ R.T

    def corner(sx: int, sy: int, sz: int) -> np.ndarray:
        return cam(np.array([sx, sy, sz]) * h)[0]

    pts = {
        "V0": corner(1, 1, 1),
        "A": corner(1, 1, -1),
        "B": corner(1, -1, 1),
        "C": corner(-1, 1, 1),
        "D": corner(1, -1, -1),
        "E": corner(-1, 1, -1),
        "F": corner(-1, -1, 1),
    }
    names = list(pts)
    vid = {n: i for i, n in enumerate(names)}
    vertices = [
        VVertex(
            id=i,
            kind=VertexKind.CORNER if n == "V0" else VertexKind.OTHER,
            position=pts[n],
            pixel=project(pts[n])[0],
        )
        for i, n in enumerate(names)
    ]
    axes_cam = R.T.copy()  # rows: part X, Y, Z in the camera frame
    nx, ny, nz = axes_cam
    faces_def = [  # (instance, normal, quad corners, axis label)
        (1, nx, ["V0", "A", "D", "B"], "X"),
        (2, ny, ["V0", "C", "E", "A"], "Y"),
        (3, nz, ["V0", "B", "F", "C"], "Z"),
    ]
    edge_def = [  # (a, b, type, faces)
        ("V0", "A", EdgeType.INTERSECTION, (0, 1)),
        ("V0", "B", EdgeType.INTERSECTION, (0, 2)),
        ("V0", "C", EdgeType.INTERSECTION, (1, 2)),
        ("A", "D", EdgeType.SILHOUETTE, (0,)),
        ("D", "B", EdgeType.SILHOUETTE, (0,)),
        ("C", "E", EdgeType.SILHOUETTE, (1,)),
        ("E", "A", EdgeType.SILHOUETTE, (1,)),
        ("B", "F", EdgeType.SILHOUETTE, (2,)),
        ("F", "C", EdgeType.SILHOUETTE, (2,)),
    ]
    edges = []
    for i, (a, b, t, fs) in enumerate(edge_def):
        pa, pb = pts[a], pts[b]
        curve = None
        if t is EdgeType.INTERSECTION:
            d = (pb - pa) / np.linalg.norm(pb - pa)
            curve = {"kind": "line", "origin": pa.copy(), "direction": d}
        edges.append(
            VEdge(i, t, 0.95 if t is EdgeType.INTERSECTION else 0.9, fs, _segment(pa, pb), vid[a], vid[b], curve)
        )
    loops = [
        [(0, False), (3, False), (4, False), (1, True)],
        [(2, False), (5, False), (6, False), (0, True)],
        [(1, False), (7, False), (8, False), (2, True)],
    ]
    faces = []
    for k, (inst, n, quad, lab) in enumerate(faces_def):
        c = np.stack([pts[q] for q in quad])
        mv, mt = _quad_mesh(c)
        faces.append(VFace(k, inst, _plane(c[0], n), lab, [loops[k]], mv, mt, 0.95))
    return VBRep(
        faces,
        edges,
        vertices,
        frame=axes_cam,
        K=K_DEFAULT.copy(),
        image_size=IMAGE_SIZE,
        scale=float(max(size)),
        meta={"example": "box_corner"},
    )


def cylinder_upright(
    radius: float = 0.04, height: float = 0.08, distance: float = 0.45, elevation_deg: float = 35.0
) -> VBRep:
    """An upright cylinder standing on its base (part frame: base centre at origin, axis +Z), seen from above
    and to the side; see the module docstring."""
    el = np.deg2rad(elevation_deg)
    target = np.array([0.0, 0.0, height / 2])
    eye = target + distance * np.array([np.cos(el), 0.0, np.sin(el)])
    R = look_at(eye, target)

    def cam(p: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(p) - eye) @ R.T

    # Visibility (contour) lines: points where the normal is orthogonal to the ray from the eye; in the
    # horizontal plane the tangent points from the eye's projection, at angles +-acos(r / d) around it.
    d_h = np.hypot(eye[0], eye[1])
    phi0 = np.arctan2(eye[1], eye[0])
    half = np.arccos(radius / d_h)
    phis = np.array([phi0 - half, phi0 + half])

    def ring(phi: np.ndarray, z: float) -> np.ndarray:
        return cam(np.stack([radius * np.cos(phi), radius * np.sin(phi), np.full_like(phi, z)], 1))

    top_l, top_r = ring(phis, height)
    bot_l, bot_r = ring(phis, 0.0)
    pts = [top_l, top_r, bot_l, bot_r]
    kinds = [VertexKind.INTERSECTION_VISIBILITY] * 2 + [VertexKind.OTHER] * 2
    vertices = [VVertex(i, k, p, project(p)[0]) for i, (k, p) in enumerate(zip(kinds, pts))]

    n_arc = 33
    front = np.linspace(phis[0], phis[1], n_arc)
    back = np.linspace(phis[1], phis[0] + 2 * np.pi, n_arc)
    axis_cam = R @ np.array([0.0, 0.0, 1.0])
    center_top = cam(np.array([0.0, 0.0, height]))[0]
    edges = [
        VEdge(
            0,
            EdgeType.INTERSECTION,
            0.95,
            (0, 1),
            ring(front, height),
            0,
            1,
            {"kind": "circle", "center": center_top, "axis": axis_cam, "radius": radius},
        ),
        VEdge(1, EdgeType.SILHOUETTE, 0.9, (1,), ring(back, height), 1, 0),
        VEdge(2, EdgeType.VISIBILITY, 0.85, (0,), _segment(top_l, bot_l), 0, 2),
        VEdge(3, EdgeType.VISIBILITY, 0.85, (0,), _segment(top_r, bot_r), 1, 3),
        VEdge(4, EdgeType.SILHOUETTE, 0.9, (0,), ring(front, 0.0), 2, 3),
    ]
    # Cylinder face mesh: the visible half between the contour lines, full height.
    nu, nv = 33, 9
    pu, zv = np.meshgrid(front, np.linspace(0.0, height, nv), indexing="xy")
    side_v = cam(np.stack([radius * np.cos(pu.ravel()), radius * np.sin(pu.ravel()), zv.ravel()], 1))
    side_t = grid_triangles(nu, nv)
    # Top disc: polar grid, centre vertex first.
    nr, na = 6, 48
    rr, aa = np.meshgrid(np.linspace(0, radius, nr)[1:], np.linspace(0, 2 * np.pi, na, endpoint=False))
    disc = np.concatenate(
        [
            [[0.0, 0.0, height]],
            np.stack(
                [rr.T.ravel() * np.cos(aa.T.ravel()), rr.T.ravel() * np.sin(aa.T.ravel()), np.full(rr.size, height)], 1
            ),
        ]
    )
    top_v = cam(disc)
    tris = [[0, 1 + a, 1 + (a + 1) % na] for a in range(na)]
    for r in range(nr - 2):
        for a in range(na):
            i0, i1 = 1 + r * na + a, 1 + r * na + (a + 1) % na
            tris += [[i0, i0 + na, i1 + na], [i0, i1 + na, i1]]
    top_t = np.asarray(tris, np.int64)
    faces = [
        VFace(
            0,
            1,
            {
                "type": "cylinder",
                "params": {"origin": cam(np.zeros(3))[0].tolist(), "axis": axis_cam.tolist(), "radius": radius},
            },
            "Z",
            [[(0, False), (3, False), (4, True), (2, True)]],
            side_v,
            side_t,
            0.9,
        ),
        # The top disc's outward normal is the part's +Z (facing the camera, which looks down on it).
        VFace(1, 2, _plane(center_top, axis_cam), "Z", [[(0, False), (1, False)]], top_v, top_t, 0.95),
    ]
    return VBRep(
        faces,
        edges,
        vertices,
        frame=R.T.copy(),
        K=K_DEFAULT.copy(),
        image_size=IMAGE_SIZE,
        scale=float(max(2 * radius, height)),
        meta={"example": "cylinder_upright"},
    )
