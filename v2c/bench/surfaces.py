"""The two surfaces the Chamfer distance and the face metrics of BENCHMARK.md compare, and the ray casts behind
them: G, the ground-truth surface of a synthetic scan (`gt_points`, clean depth back-projected on the part's pixels),
and R, the reconstructed VB-Rep's face meshes (`reconstruction_points`, drawn area-uniformly, optionally only where
the camera sees them); the VB-Rep rendered from the scan's camera (`render_vbrep`); `chamfer_distance` of two point
sets.

Below `v2c.bench.metrics` (every metric of one scan) and `v2c.bench.vbrep` (the per-stage VB-Rep metrics), which
both use it. Units: metres; frame: the scan's camera (OpenCV: x right, y down, z forward), rays from its centre.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from v2c.camera import pixel_rays
from v2c.vbrep.mesh import sample_surface
from v2c.vbrep.model import VBRep

if TYPE_CHECKING:
    from v2c.scan import Scan


# ------------------------------------------------------------------------------------------ ground truth G


def part_size(scan: Scan) -> float:
    """Ground-truth part size (metres): meta.json part_size_m, else the clean point cloud's largest extent."""
    size = scan.gt.meta.get("part_size_m")
    if size:
        return float(size)
    pts = gt_points(scan, None, 0)
    return float(np.max(pts.max(0) - pts.min(0)))


def gt_points(scan: Scan, n: int | None = 20000, seed: int = 0) -> np.ndarray:
    """Ground truth surface G: clean depth back-projected on the part's pixels (gt faces > 0), n drawn at random
    (seeded; all if n is None). Camera frame, metres."""
    gt = scan.gt
    depth = np.asarray(gt.depth_clean, float)
    vs, us = np.nonzero((np.asarray(gt.faces) > 0) & (depth > 0))
    if n is not None and len(us) > n:
        idx = np.random.default_rng(seed).choice(len(us), n, replace=False)
        vs, us = vs[idx], us[idx]
    z = depth[vs, us]
    Kinv = np.linalg.inv(np.asarray(scan.K, float))
    rays = np.stack([us, vs, np.ones_like(us)], 1).astype(float) @ Kinv.T
    return rays / rays[:, 2:3] * z[:, None]


# ----------------------------------------------------------------------------------------------- rendering


def vbrep_mesh(vbrep: VBRep) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """All face meshes in one: vertices (n, 3) camera metres, triangles (m, 3) int64, face index (m,) int64 (the
    position in ``vbrep.faces``)."""
    verts, tris, owner, off = [], [], [], 0
    for k, f in enumerate(vbrep.faces):
        t = np.asarray(f.mesh_triangles, np.int64).reshape(-1, 3)
        if len(t) == 0:
            continue
        v = np.asarray(f.mesh_vertices, float).reshape(-1, 3)
        verts.append(v)
        tris.append(t + off)
        owner.append(np.full(len(t), k, np.int64))
        off += len(v)
    if not verts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    return np.concatenate(verts), np.concatenate(tris), np.concatenate(owner)


class MeshCaster:
    """First-hit ray casts against a triangle mesh (trimesh + Embree), rays from the camera centre.

    ``cast(directions)`` returns, per ray ``x(t) = t * d``, the hit triangle (-1 = none) and the ray parameter t
    of the hit (inf = none): with ``d`` = a pixel ray of z component 1, t is the depth z (metres); with ``d`` =
    a point p, t < 1 means something lies in front of p.
    """

    def __init__(self, vertices: np.ndarray, triangles: np.ndarray) -> None:
        self.vertices = np.asarray(vertices, float)
        self.triangles = np.asarray(triangles, np.int64)
        self._intersector = None
        if len(self.triangles):
            import trimesh

            mesh = trimesh.Trimesh(self.vertices, self.triangles, process=False, validate=False)
            try:
                from trimesh.ray.ray_pyembree import RayMeshIntersector
            except ImportError:  # pure-numpy fallback (slow, same answers)
                from trimesh.ray.ray_triangle import RayMeshIntersector
            self._intersector = RayMeshIntersector(mesh)
            p0, p1, p2 = (self.vertices[self.triangles[:, k]] for k in range(3))
            self._normal = np.cross(p1 - p0, p2 - p0)
            self._offset = np.einsum("ij,ij->i", self._normal, p0)

    def cast(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """First hits of the rays ``t * d`` from the camera centre, one per row of ``directions`` (N, 3), camera
        frame: the hit triangle (N,) int64 (-1 = none) and the ray parameter t (N,) of the hit (inf = none); a hit
        behind the centre or parallel to its triangle counts as none."""
        d = np.asarray(directions, float).reshape(-1, 3)
        tri = np.full(len(d), -1, np.int64)
        t = np.full(len(d), np.inf)
        if self._intersector is None or len(d) == 0:
            return tri, t
        tri = np.asarray(self._intersector.intersects_first(np.zeros_like(d), d), np.int64)
        hit = tri >= 0
        nd = np.einsum("ij,ij->i", self._normal[tri[hit]], d[hit])
        with np.errstate(divide="ignore", invalid="ignore"):
            th = self._offset[tri[hit]] / nd
        th = np.where(np.isfinite(th) & (th > 0), th, np.inf)
        t[hit] = th
        tri[np.flatnonzero(hit)[~np.isfinite(th)]] = -1
        return tri, t


@dataclass
class Rendering:
    """The reconstruction seen from the scan's camera: face (H, W) int64 index into ``vbrep.faces`` of the nearest
    triangle at each pixel centre (-1 = none); depth (H, W) float64 z depth in metres (0 = none)."""

    face: np.ndarray
    depth: np.ndarray

    def pixel_counts(self, n_faces: int) -> np.ndarray:
        """(n_faces,) pixels each face covers."""
        f = self.face[self.face >= 0]
        return np.bincount(f, minlength=n_faces)[:n_faces]


def render_vbrep(vbrep: VBRep, caster: MeshCaster | None = None) -> Rendering:
    """Render the VB-Rep's face meshes from its camera (``vbrep.K``, ``vbrep.image_size``) with a z-buffer: one
    ray per pixel centre (u, v integers), the nearest triangle wins, whatever its orientation."""
    w, h = (int(x) for x in vbrep.image_size)
    if caster is None:
        V, T, _ = vbrep_mesh(vbrep)
        caster = MeshCaster(V, T)
    owner = vbrep_mesh(vbrep)[2]
    uu, vv = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays = pixel_rays(np.stack([uu.ravel(), vv.ravel()], 1), vbrep.K)
    tri, t = caster.cast(rays)
    face = np.where(tri >= 0, owner[np.maximum(tri, 0)] if len(owner) else -1, -1)
    depth = np.where(tri >= 0, t, 0.0)
    return Rendering(face.reshape(h, w), depth.reshape(h, w))


def visible_points(points: np.ndarray, caster: MeshCaster, eps: float) -> np.ndarray:
    """(N,) bool: the camera sees each camera-frame point, i.e. no triangle crosses its ray more than ``eps``
    metres before it."""
    p = np.asarray(points, float).reshape(-1, 3)
    _, t = caster.cast(p)
    dist = np.linalg.norm(p, axis=1)
    return ~((t < 1.0) & ((1.0 - t) * dist > eps))


# ------------------------------------------------------------------------------------------------- chamfer


def reconstruction_points(
    vbrep: VBRep,
    n: int,
    rng: np.random.Generator,
    caster: MeshCaster | None = None,
    visible_only: bool = True,
    eps: float = 0.0,
    max_rounds: int = 8,
) -> np.ndarray:
    """R: ``n`` points (camera metres) drawn area-uniformly on the face meshes; with ``visible_only`` only those
    the camera sees (draws again until ``n`` are found or ``max_rounds`` rounds are spent)."""
    V, T, _ = vbrep_mesh(vbrep)
    if len(T) == 0:
        return np.zeros((0, 3))
    if not visible_only:
        return sample_surface(V, T, n, rng)
    caster = caster or MeshCaster(V, T)
    found: list[np.ndarray] = []
    have, share = 0, 1.0
    for _ in range(max_rounds):
        m = int(min(20 * n, max(256, 1.2 * (n - have) / max(share, 0.05))))
        cand = sample_surface(V, T, m, rng)
        vis = visible_points(cand, caster, eps)
        share = max(float(vis.mean()), 1e-3)
        found.append(cand[vis])
        have += int(vis.sum())
        if have >= n:
            break
    return np.concatenate(found)[:n]


def chamfer_distance(R: np.ndarray, G: np.ndarray, size: float) -> float:
    """0.5 * (mean over R of the distance to the nearest point of G + mean over G of the distance to R) / size;
    inf when either set is empty."""
    if len(R) == 0 or len(G) == 0:
        return float("inf")
    d_rg = cKDTree(G).query(R)[0]
    d_gr = cKDTree(R).query(G)[0]
    return float(0.5 * (d_rg.mean() + d_gr.mean()) / size)
