"""A hand-built VB-Rep that exercises every analytic surface type of the STEP export.

`revolved_all_types()`: a part of revolution about its Z axis (dimensions in millimetres, part frame):

- a cylinder (radius 30, z 0..40), a cone (from radius 30 at z 40 to radius 15 at z 55, apex at z 70, half
  angle 45 degrees), a torus ring (centre z 60, ring radius 15, tube radius 5) sitting on the cone's rim, a
  sphere (centre z 60, radius 12) rising out of the ring, and the flat top disc (z 70) that cuts the sphere;
- seen from above and in front (camera on the +X side, 35 degrees up); each surface of revolution is shown
  over the 140-degree sector facing the camera, bounded left and right by visibility edges (its meridians);
- the four circles where neighbouring surfaces meet are intersection edges (analytic circles), the cylinder's
  bottom arc an occluded edge, the top disc's far arc a silhouette.

The torus face runs over its outer equator, the seam of OCCT's torus parametrisation. Camera frame, metres,
like `scenes.vbrep`.
"""

from __future__ import annotations

import numpy as np

from v2c.vbrep.model import EdgeType, VBRep, VEdge, VertexKind, VFace, VVertex

from scenes.vbrep import IMAGE_SIZE, K_DEFAULT, grid_triangles, look_at, project

_MM = 1e-3


def _profiles() -> list[tuple[str, callable]]:
    """(type, profile(t) -> (rho, z) in millimetres for t in [0, 1]) of the four faces of revolution."""
    rho3 = (12.0**2 - 5.0**2 + 15.0**2) / (2 * 15.0)  # sphere radius 12 meets the tube (15, 60; 5)
    z3 = 60.0 + np.sqrt(12.0**2 - rho3**2)
    th3 = np.arctan2(z3 - 60.0, rho3 - 15.0)
    lat0, lat1 = np.arcsin((z3 - 60.0) / 12.0), np.arcsin(10.0 / 12.0)
    return [
        ("cylinder", lambda t: (np.full_like(t, 30.0), 40.0 * t)),
        ("cone", lambda t: (30.0 - 15.0 * t, 40.0 + 15.0 * t)),
        (
            "torus",
            lambda t: (
                15.0 + 5.0 * np.cos(-np.pi / 2 + t * (th3 + np.pi / 2)),
                60.0 + 5.0 * np.sin(-np.pi / 2 + t * (th3 + np.pi / 2)),
            ),
        ),
        (
            "sphere",
            lambda t: (
                12.0 * np.cos(lat0 + t * (lat1 - lat0)),
                60.0 + 12.0 * np.sin(lat0 + t * (lat1 - lat0)),
            ),
        ),
    ]


def revolved_all_types(distance: float = 0.35, elevation_deg: float = 35.0, sector_deg: float = 140.0) -> VBRep:
    """The part of the module docstring as a VB-Rep (camera frame, metres)."""
    el = np.deg2rad(elevation_deg)
    target = np.array([0.0, 0.0, 0.035])
    eye = target + distance * np.array([np.cos(el), 0.0, np.sin(el)])
    R = look_at(eye, target)

    def cam(p: np.ndarray) -> np.ndarray:
        return (np.atleast_2d(p) * _MM - eye) @ R.T

    def rev(rho: np.ndarray, z: np.ndarray, phi: np.ndarray) -> np.ndarray:
        return cam(np.stack([rho * np.cos(phi), rho * np.sin(phi), z], -1).reshape(-1, 3))

    half = np.deg2rad(sector_deg) / 2
    phi_a, phi_b = -half, half
    profiles = _profiles()
    levels = [profiles[0][1](np.array([0.0]))] + [p(np.array([1.0])) for _, p in profiles]
    levels = [(float(r[0]), float(z[0])) for r, z in levels]  # (rho, z) of the 5 circles

    vertices = []
    for k, (rho, z) in enumerate(levels):
        for side, phi in (("L", phi_a), ("R", phi_b)):
            pos = rev(np.array(rho), np.array(z), np.array(phi))[0]
            kind = VertexKind.INTERSECTION_VISIBILITY if 1 <= k <= 4 else VertexKind.OTHER
            vertices.append(VVertex(2 * k + (side == "R"), kind, pos, project(pos)[0]))

    front = np.linspace(phi_a, phi_b, 33)
    back = np.linspace(phi_b, phi_a + 2 * np.pi, 33)
    axis = R @ np.array([0.0, 0.0, 1.0])
    arc_types = [EdgeType.OCCLUDED] + [EdgeType.INTERSECTION] * 4
    arc_faces = [(0,), (0, 1), (1, 2), (2, 3), (3, 4)]
    edges = []
    for k, (rho, z) in enumerate(levels):
        curve = None
        if arc_types[k] is EdgeType.INTERSECTION:
            curve = {
                "kind": "circle",
                "center": cam(np.array([0.0, 0.0, z]))[0],
                "axis": axis,
                "radius": rho * _MM,
            }
        edges.append(
            VEdge(
                k,
                arc_types[k],
                0.9 - 0.05 * k,
                arc_faces[k],
                rev(np.full_like(front, rho), np.full_like(front, z), front),
                2 * k,
                2 * k + 1,
                curve,
            )
        )
    rho4, z4 = levels[4]
    edges.append(
        VEdge(
            5,
            EdgeType.SILHOUETTE,
            0.8,
            (4,),
            rev(np.full_like(back, rho4), np.full_like(back, z4), back),
            9,
            8,
        )
    )
    t = np.linspace(0.0, 1.0, 17)
    for k, (_, prof) in enumerate(profiles):
        rho, z = prof(t)
        edges.append(
            VEdge(
                6 + 2 * k,
                EdgeType.VISIBILITY,
                0.7,
                (k,),
                rev(rho, z, np.full_like(t, phi_a)),
                2 * k,
                2 * k + 2,
            )
        )
        edges.append(
            VEdge(
                7 + 2 * k,
                EdgeType.VISIBILITY,
                0.7,
                (k,),
                rev(rho, z, np.full_like(t, phi_b)),
                2 * k + 1,
                2 * k + 3,
            )
        )

    prims = [
        {"type": "cylinder", "params": {"origin": cam(np.zeros(3))[0], "axis": axis, "radius": 30 * _MM}},
        {
            "type": "cone",
            "params": {"origin": cam(np.array([0.0, 0, 70]))[0], "axis": -axis, "half_angle": np.pi / 4},
        },
        {
            "type": "torus",
            "params": {
                "origin": cam(np.array([0.0, 0, 60]))[0],
                "axis": axis,
                "radius": 15 * _MM,
                "minor_radius": 5 * _MM,
            },
        },
        {"type": "sphere", "params": {"origin": cam(np.array([0.0, 0, 60]))[0], "radius": 12 * _MM}},
        {"type": "plane", "params": {"origin": cam(np.array([0.0, 0, 70]))[0], "normal": axis}},
    ]
    prims = [
        {
            "type": p["type"],
            "params": {k: (np.asarray(v).tolist() if np.ndim(v) else float(v)) for k, v in p["params"].items()},
        }
        for p in prims
    ]
    faces = []
    tt = np.linspace(0.0, 1.0, 9)
    for k, (_, prof) in enumerate(profiles):
        rho, z = prof(tt)
        pu, ti = np.meshgrid(front, np.arange(len(tt)), indexing="xy")
        mv = rev(rho[ti.ravel()], z[ti.ravel()], pu.ravel())
        loop = [(k, False), (7 + 2 * k, False), (k + 1, True), (6 + 2 * k, True)]
        faces.append(
            VFace(
                k,
                k + 1,
                prims[k],
                None if k == 3 else "Z",
                [loop],
                mv,
                grid_triangles(len(front), len(tt)),
                0.9,
            )
        )
    na, nr = 48, 4
    rr, aa = np.meshgrid(np.linspace(0, rho4, nr + 1)[1:], np.linspace(0, 2 * np.pi, na, endpoint=False))
    disc = np.concatenate(
        [
            [[0.0, 0.0, z4]],
            np.stack([(rr.T * np.cos(aa.T)).ravel(), (rr.T * np.sin(aa.T)).ravel(), np.full(rr.size, z4)], 1),
        ]
    )
    tris = [[0, 1 + a, 1 + (a + 1) % na] for a in range(na)]
    for r in range(nr - 1):
        for a in range(na):
            i0, i1 = 1 + r * na + a, 1 + r * na + (a + 1) % na
            tris += [[i0, i0 + na, i1 + na], [i0, i1 + na, i1]]
    faces.append(VFace(4, 5, prims[4], "Z", [[(4, False), (5, False)]], cam(disc), np.asarray(tris, np.int64), 0.95))
    return VBRep(
        faces,
        edges,
        vertices,
        frame=R.T.copy(),
        K=K_DEFAULT.copy(),
        image_size=IMAGE_SIZE,
        scale=0.07,
        meta={"example": "revolved_all_types"},
    )
