"""Small analytic test scenes ray-cast in numpy (no OCCT): a box from a corner, an upright cylinder, a plate
with a round hole or a round boss of the same outline.

A scene is a list of bounded faces (a primitive in the part frame plus a predicate on part-frame points saying
which part of the surface is material boundary); a pixel sees the nearest crossing that satisfies its face's
predicate. Everything is then posed in the camera frame (OpenCV), metres. `scene_inputs` turns a render into the
stage inputs of VB-Rep extraction (Scan-like object with ground truth, oracle Segmentation, FitResult-like object
with the true or perturbed primitives and the 2D edge graph), for the tests.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from v2c.camera import pixel_rays
from v2c.vbrep.raycast import intersect

from scenes.vbrep import K_DEFAULT, look_at

Bound = Callable[[np.ndarray], np.ndarray]


@dataclass
class BoundedFace:
    """primitive: to_dict form in the PART frame; bound: (N, 3) part-frame points -> (N,) bool; label: 18-class."""

    primitive: dict
    bound: Bound
    label: int
    axis_label: str | None = None


@dataclass
class Scene:
    faces: list[BoundedFace]
    eye: np.ndarray  # part frame, metres
    target: np.ndarray
    size: float  # part size (metres)
    K: np.ndarray = field(default_factory=lambda: K_DEFAULT.copy())
    image_size: tuple[int, int] = (640, 480)


def _to_cam(prim: dict, R: np.ndarray, eye: np.ndarray) -> dict:
    p = dict(prim["params"])
    out = {}
    for k, v in p.items():
        if k == "origin":
            out[k] = (R @ (np.asarray(v, float) - eye)).tolist()
        elif k in ("normal", "axis"):
            out[k] = (R @ np.asarray(v, float)).tolist()
        else:
            out[k] = v
    return {"type": prim["type"], "params": out}


def render_scene(scene: Scene) -> SimpleNamespace:
    """Ray-cast the scene: faces (H, W) uint16 (1 + face index, 0 = none), depth (H, W) float32 metres,
    primitives in the camera frame, rotation R (camera <- part) and the part axes in the camera frame."""
    w, h = scene.image_size
    R = look_at(scene.eye, scene.target)
    uu, vv = np.meshgrid(np.arange(w), np.arange(h))
    rays = pixel_rays(np.stack([uu.ravel(), vv.ravel()], 1).astype(float), scene.K)
    best = np.full(len(rays), np.inf)
    fid = np.zeros(len(rays), np.uint16)
    prims_cam = [_to_cam(f.primitive, R, scene.eye) for f in scene.faces]
    for k, (f, pc) in enumerate(zip(scene.faces, prims_cam)):
        hits = intersect(pc, rays, (0.05, 3.0), samples=400)
        for s in range(hits.depths.shape[1]):
            z = hits.depths[:, s]
            ok = np.isfinite(z) & (z < best)
            if not ok.any():
                continue
            idx = np.flatnonzero(ok)
            pts_cam = rays[idx] * z[idx, None]
            part = pts_cam @ R + scene.eye  # camera -> part
            inb = f.bound(part)
            idx = idx[inb]
            best[idx] = z[idx]
            fid[idx] = k + 1
    depth = np.where(np.isfinite(best), best, 0.0).reshape(h, w).astype(np.float32)
    return SimpleNamespace(faces=fid.reshape(h, w), depth=depth, primitives=prims_cam, R=R, axes_cam=R.T.copy())


def scene_inputs(
    scene: Scene,
    noise_m: float = 0.0,
    seed: int = 0,
    perturb: Callable[[dict, np.random.Generator], dict] | None = None,
) -> SimpleNamespace:
    """Stage inputs from a scene: ``scan`` (a `Scan`: color, depth with Gaussian noise of ``noise_m`` metres, K,
    mask, ground truth without a STEP file), ``seg`` (oracle `Segmentation`), ``fit`` (a `FitResult`: primitives =
    the true ones, or ``perturb(dict, rng)`` of them; graph = build_edge_graph of the instance map; residuals =
    noise_m; scale = part size) and ``render`` (the noise-free render)."""
    from v2c.fit import FitResult
    from v2c.primitives import from_dict
    from v2c.scan import GroundTruth, Scan
    from v2c.segment.graph import build_edge_graph
    from v2c.segment.types import Segmentation

    rng = np.random.default_rng(seed)
    r = render_scene(scene)
    ids = np.unique(r.faces)
    ids = ids[ids > 0]
    inst = np.zeros(r.faces.shape, np.int32)
    for k, f in enumerate(ids, 1):
        inst[r.faces == f] = k
    labels = np.zeros(len(ids) + 1, np.uint8)
    prim_of = {}
    axis_of = {}
    for k, f in enumerate(ids, 1):
        labels[k] = scene.faces[f - 1].label
        p = r.primitives[f - 1]
        prim_of[k] = perturb(p, rng) if perturb else p
        axis_of[k] = scene.faces[f - 1].axis_label
    depth = r.depth.copy()
    if noise_m > 0:
        depth = np.where(depth > 0, depth + rng.normal(0, noise_m, depth.shape), 0).astype(np.float32)
    mask = r.faces > 0
    color = np.full((*r.faces.shape, 3), 40, np.uint8)
    shade = (80 + 150 * (r.faces.astype(float) / max(1, r.faces.max()))).astype(np.uint8)
    color[mask] = np.stack([shade, shade, shade], -1)[mask]
    gt_prims = [
        {
            "id": k,
            "pixel_value": k + 1,
            "type": p["type"],
            "axis_label": scene.faces[k].axis_label,
            "params": p["params"],
        }
        for k, p in enumerate(r.primitives)
    ]
    gt = GroundTruth(
        faces=r.faces,
        labels=_labels_image(r.faces, scene),
        primitives=gt_prims,
        depth_clean=r.depth,
        meta={"part_size_m": scene.size, "axes_cam": r.axes_cam.tolist()},
        step_path=None,
    )  # type: ignore[arg-type]  (no STEP for numpy scenes)
    scan = Scan(
        path=None,
        color=color,
        depth=depth,
        K=scene.K.copy(),
        mask=mask,
        roi=None,  # type: ignore[arg-type]
        gt=gt,
    )
    seg = Segmentation(inst, labels, np.ones(len(labels), np.float32), "oracle")
    graph = build_edge_graph(inst)
    fit = FitResult(
        primitives={k: from_dict(p) for k, p in prim_of.items()},
        frame=r.R.T.copy(),
        axis_labels=axis_of,
        inliers={},
        residuals={k: noise_m for k in prim_of},
        vertex_depths=np.zeros(len(graph.vertices)),
        graph=graph,
        scale=scene.size,
        timings={},
    )
    return SimpleNamespace(scan=scan, seg=seg, fit=fit, render=r)


def planes_depth(inst: np.ndarray, K: np.ndarray, planes: dict) -> np.ndarray:
    """The depth (metres) of each instance's plane (``planes``: instance id -> `v2c.primitives.Plane`, camera
    frame) along its pixels' rays; 0 on pixels of no listed instance."""
    vs, us = np.nonzero(inst > 0)
    rays = pixel_rays(np.stack([us, vs], 1).astype(float), K)
    depth = np.zeros(inst.shape)
    for k, p in planes.items():  # loop over instances
        sel = inst[vs, us] == k
        n = np.asarray(p.axis_vector, float)
        depth[vs[sel], us[sel]] = float(n @ np.asarray(p.origin, float)) / (rays[sel] @ n)
    return depth


def _labels_image(faces: np.ndarray, scene: Scene) -> np.ndarray:
    lut = np.zeros(len(scene.faces) + 1, np.uint8)
    for k, f in enumerate(scene.faces):
        lut[k + 1] = f.label
    return lut[faces]


# ------------------------------------------------------------------------------------------------ the scenes


def _plane(o: tuple, n: tuple) -> dict:
    return {"type": "plane", "params": {"origin": list(map(float, o)), "normal": list(map(float, n))}}


def _cyl(o: tuple, a: tuple, r: float) -> dict:
    return {
        "type": "cylinder",
        "params": {"origin": list(map(float, o)), "axis": list(map(float, a)), "radius": float(r)},
    }


def _box_bound(lo: np.ndarray, hi: np.ndarray, tol: float = 1e-7) -> Bound:
    return lambda p: np.all((p >= lo - tol) & (p <= hi + tol), axis=1)


def box_scene(
    size: tuple[float, float, float] = (0.10, 0.08, 0.06),
    distance: float = 0.45,
    view: tuple[float, float, float] = (1.0, 0.75, 0.85),
) -> Scene:
    """A box on the ground (part frame: centred in x, y; bottom at z = 0) seen from its (+X, +Y, +Z) corner."""
    sx, sy, sz = size
    lo, hi = np.array([-sx / 2, -sy / 2, 0.0]), np.array([sx / 2, sy / 2, sz])
    b = _box_bound(lo, hi)
    faces = [
        BoundedFace(_plane((sx / 2, 0, 0), (1, 0, 0)), b, 1, "X"),
        BoundedFace(_plane((0, sy / 2, 0), (0, 1, 0)), b, 2, "Y"),
        BoundedFace(_plane((0, 0, sz), (0, 0, 1)), b, 3, "Z"),
    ]
    target = np.array([0.0, 0.0, sz / 2])
    v = np.asarray(view, float)
    return Scene(faces, target + v / np.linalg.norm(v) * distance, target, float(max(size)))


def cylinder_scene(
    radius: float = 0.035, height: float = 0.08, distance: float = 0.4, elevation_deg: float = 35.0
) -> Scene:
    """An upright cylinder standing on its base (axis +Z), seen from above and to the side."""
    el = np.deg2rad(elevation_deg)
    target = np.array([0.0, 0.0, height / 2])

    def side(p: np.ndarray) -> np.ndarray:
        return (p[:, 2] >= -1e-7) & (p[:, 2] <= height + 1e-7)

    def top(p: np.ndarray) -> np.ndarray:
        return np.hypot(p[:, 0], p[:, 1]) <= radius + 1e-7

    faces = [
        BoundedFace(_cyl((0, 0, 0), (0, 0, 1), radius), side, 7, "Z"),
        BoundedFace(_plane((0, 0, height), (0, 0, 1)), top, 3, "Z"),
    ]
    eye = target + distance * np.array([np.cos(el) * 0.8, np.cos(el) * 0.6, np.sin(el)])
    return Scene(faces, eye, target, float(max(2 * radius, height)))


def plate_feature_scene(
    kind: str,
    radius: float = 0.02,
    depth: float = 0.015,
    plate: float = 0.12,
    thickness: float = 0.02,
    distance: float = 0.35,
    elevation_deg: float = 50.0,
) -> Scene:
    """A square plate (top at z = 0) with a round ``kind`` = "hole" (blind, ``depth`` deep) or "boss" (``depth``
    high) of the same radius at its centre, seen obliquely from above. The cylinder face has the same image
    outline family either way; only the depth tells a hole (far wall seen from inside) from a boss."""
    el = np.deg2rad(elevation_deg)
    half = plate / 2

    def in_plate(p: np.ndarray) -> np.ndarray:
        return (np.abs(p[:, 0]) <= half + 1e-7) & (np.abs(p[:, 1]) <= half + 1e-7)

    def rho(p: np.ndarray) -> np.ndarray:
        return np.hypot(p[:, 0], p[:, 1])

    faces = [
        BoundedFace(_plane((0, 0, 0), (0, 0, 1)), lambda p: in_plate(p) & (rho(p) >= radius - 1e-7), 3, "Z"),
        BoundedFace(
            _plane((half, 0, 0), (1, 0, 0)), lambda p: in_plate(p) & (p[:, 2] <= 1e-7) & (p[:, 2] >= -thickness), 1, "X"
        ),
        BoundedFace(
            _plane((0, half, 0), (0, 1, 0)), lambda p: in_plate(p) & (p[:, 2] <= 1e-7) & (p[:, 2] >= -thickness), 2, "Y"
        ),
    ]
    if kind == "hole":
        faces += [
            BoundedFace(_cyl((0, 0, 0), (0, 0, 1), radius), lambda p: (p[:, 2] <= 1e-7) & (p[:, 2] >= -depth), 7, "Z"),
            BoundedFace(_plane((0, 0, -depth), (0, 0, 1)), lambda p: rho(p) <= radius + 1e-7, 3, "Z"),
        ]
    elif kind == "boss":
        faces += [
            BoundedFace(_cyl((0, 0, 0), (0, 0, 1), radius), lambda p: (p[:, 2] >= -1e-7) & (p[:, 2] <= depth), 7, "Z"),
            BoundedFace(_plane((0, 0, depth), (0, 0, 1)), lambda p: rho(p) <= radius + 1e-7, 3, "Z"),
        ]
    else:
        raise ValueError(f"kind must be 'hole' or 'boss', not {kind!r}")
    target = np.zeros(3)
    eye = distance * np.array([np.cos(el) * 0.8, np.cos(el) * 0.6, np.sin(el)])
    return Scene(faces, eye, target, float(plate))


def inlay_scene(
    radius: float = 0.03,
    tilt_deg: float = 1.0,
    plate: float = 0.12,
    thickness: float = 0.02,
    distance: float = 0.3,
    elevation_deg: float = 60.0,
) -> Scene:
    """A square plate (top at z = 0) with a round inlay of ``radius`` at its centre whose top is a plane through
    the centre tilted by ``tilt_deg`` about the part's y axis (so it stands at most radius * tan(tilt) proud of
    or below the plate, under the depth-gap threshold), seen obliquely from above. In the image the inlay is a
    plane face enclosed by one neighbour, the plate's top, along one closed edge; the two planes meet only on a
    line through the centre."""
    el = np.deg2rad(elevation_deg)
    half = plate / 2
    t = np.deg2rad(tilt_deg)

    def in_plate(p: np.ndarray) -> np.ndarray:
        return (np.abs(p[:, 0]) <= half + 1e-7) & (np.abs(p[:, 1]) <= half + 1e-7)

    def rho(p: np.ndarray) -> np.ndarray:
        return np.hypot(p[:, 0], p[:, 1])

    # the two bounds overlap by ``seam`` so that no pixel on the seam sees through both (the nearer face wins)
    seam = 1e-4
    faces = [
        BoundedFace(_plane((0, 0, 0), (0, 0, 1)), lambda p: in_plate(p) & (rho(p) >= radius - seam), 3, "Z"),
        BoundedFace(
            _plane((half, 0, 0), (1, 0, 0)), lambda p: in_plate(p) & (p[:, 2] <= 1e-7) & (p[:, 2] >= -thickness), 1, "X"
        ),
        BoundedFace(
            _plane((0, half, 0), (0, 1, 0)), lambda p: in_plate(p) & (p[:, 2] <= 1e-7) & (p[:, 2] >= -thickness), 2, "Y"
        ),
        BoundedFace(_plane((0, 0, 0), (-np.sin(t), 0, np.cos(t))), lambda p: rho(p) < radius + seam, 3, None),
    ]
    target = np.zeros(3)
    eye = distance * np.array([np.cos(el) * 0.8, np.cos(el) * 0.6, np.sin(el)])
    return Scene(faces, eye, target, float(plate))
