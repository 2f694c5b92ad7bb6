"""Checking a fixture against a known part: how far its mating faces are from what they reference, and how much
of it would cut into the part. Output frame, millimetres (move the true part there with
`fixtures_design.assembly.true_part`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from build123d import Face, Shape, Vertex
from OCP.BRepExtrema import BRepExtrema_DistShapeShape

from fixtures_design.model import Fixture, common_volume, sample_face
from v2c.vbrep.model import VBRep


def distances_mm(points: np.ndarray, shape: Shape) -> np.ndarray:
    """(N,) distance (mm) from each point (N, 3) to ``shape`` (a face, a solid, ...), by OCCT."""
    out = np.empty(len(points))
    for i, p in enumerate(np.asarray(points, float)):
        d = BRepExtrema_DistShapeShape(Vertex(*p).wrapped, shape.wrapped)
        out[i] = d.Value()
    return out


@dataclass(frozen=True)
class MatingCheck:
    """Distances (mm) from points sampled on each mating face to the true face (or part) it references."""

    per_face_max: list[float]
    max: float
    median: float
    n_points: int


def check_mating(
    fixture: Fixture, true_part: Shape, true_faces: dict[int, Face] | None = None, max_points_per_face: int = 60
) -> MatingCheck:
    """Distance from each mating face to what it references on the true part (output frame, mm).

    true_faces: VB-Rep face id -> the true part's face it is (moved into the output frame); a mating face whose
    reference is -1 or missing there is measured against the whole ``true_part``.
    """
    maxima, all_d = [], []
    for face, ref in zip(fixture.mating_faces, fixture.mating_refs or [-1] * len(fixture.mating_faces)):
        pts = sample_face(face)
        pts = pts[:: max(1, len(pts) // max_points_per_face)]
        target = true_faces.get(ref) if true_faces and ref >= 0 else None
        d = distances_mm(pts, target if target is not None else true_part)
        maxima.append(float(d.max()))
        all_d.append(d)
    d = np.concatenate(all_d)
    return MatingCheck(maxima, float(d.max()), float(np.median(d)), len(d))


def interference(fixture: Fixture, true_part: Shape) -> tuple[float, float]:
    """(common volume mm^3, its fraction of the fixture's volume) of fixture and true part, by an OCCT boolean."""
    v = common_volume(fixture.solid, true_part)
    return v, v / fixture.volume_mm3


def part_inside_share(fixture: Fixture, vbrep: VBRep, n_points: int = 3000, seed: int = 0) -> float:
    """Share of points sampled on the VB-Rep's face meshes (area-weighted, seeded; moved into the output frame)
    that lie inside the fixture's solid: a fixture placed on its reference leaves the reconstructed part outside.
    0 for a VB-Rep without face meshes."""
    from OCP.BRepClass3d import BRepClass3d_SolidClassifier
    from OCP.gp import gp_Pnt
    from OCP.TopAbs import TopAbs_IN

    tris = []
    for f in vbrep.faces:
        v = np.asarray(f.mesh_vertices, float).reshape(-1, 3)
        t = np.asarray(f.mesh_triangles, int).reshape(-1, 3)
        if len(v) and len(t):
            tris.append(fixture.fmap.points(v)[t])
    if not tris:
        return 0.0
    tri = np.concatenate(tris)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not area.sum() > 0:
        return 0.0
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tri), n_points, p=area / area.sum())
    a, b = rng.random((2, n_points, 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    t = tri[pick]
    pts = t[:, 0] + a * (t[:, 1] - t[:, 0]) + b * (t[:, 2] - t[:, 0])
    cls = BRepClass3d_SolidClassifier(fixture.solid.wrapped)
    inside = 0
    for p in pts:
        cls.Perform(gp_Pnt(*map(float, p)), 1e-6)
        inside += cls.State() == TopAbs_IN
    return inside / n_points
