"""Checking a fixture against a known part: how far its mating faces are from what they reference, and how much
of it would cut into the part. Output frame, millimetres (move the true part there with
`fixtures_design.assembly.true_part`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from build123d import Face, Shape, Vertex
from OCP.BRepExtrema import BRepExtrema_DistShapeShape

from fixtures_design.model import Fixture, common_volume, sample_face, sample_triangles
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
    pts = sample_triangles(np.concatenate(tris), n_points, seed)
    if not len(pts):
        return 0.0
    cls = BRepClass3d_SolidClassifier(fixture.solid.wrapped)
    inside = 0
    for p in pts:
        cls.Perform(gp_Pnt(*map(float, p)), 1e-6)
        inside += cls.State() == TopAbs_IN
    return inside / n_points


@dataclass(frozen=True)
class EvidenceConfig:
    """When the scan's own points say a design would cut into the part (`observed_inside`)."""

    noise_coeff_per_m: float = 0.0015  # the depth noise law sigma = coeff * z^2 (z in metres; the sensor's)
    n_sigma: float = 3.0  # a point counts when it lies deeper inside the fixture than this many noise sigmas
    max_points: int = 10  # designs with more such points are refused (flying pixels, speckle tolerated)


def observed_inside(
    fixture: Fixture, points: np.ndarray, config: EvidenceConfig = EvidenceConfig(), limit: int = 400
) -> tuple[int, float]:
    """How many of the scan's observed points (camera frame, metres, (N, 3)) lie inside the fixture's solid by more
    than ``config.n_sigma`` depth-noise sigmas (``noise_coeff_per_m`` z^2), and the deepest such depth (mm).

    The depth map shows material there: a fixture holding it would cut into the part (a hole fitted too wide or off
    its axis, a pin deeper than a counterbore's step, a block over a feature the segmentation merged away). The
    depth of at most ``limit`` inside points (a seeded subset) is measured; the count is scaled up to all of them.
    """
    from OCP.BRepClass3d import BRepClass3d_SolidClassifier
    from OCP.gp import gp_Pnt
    from OCP.TopAbs import TopAbs_IN

    p_cam = np.asarray(points, float).reshape(-1, 3)
    p_cam = p_cam[p_cam[:, 2] > 0]
    if not len(p_cam):
        return 0, 0.0
    pts = fixture.fmap.points(p_cam)
    bb = fixture.solid.bounding_box()
    lo, hi = np.array(tuple(bb.min)), np.array(tuple(bb.max))
    near = np.all((pts >= lo) & (pts <= hi), axis=1)
    pts, z = pts[near], p_cam[near, 2]
    cls = BRepClass3d_SolidClassifier(fixture.solid.wrapped)
    inside = np.zeros(len(pts), bool)
    for i, p in enumerate(pts):
        cls.Perform(gp_Pnt(*map(float, p)), 1e-6)
        inside[i] = cls.State() == TopAbs_IN
    idx = np.flatnonzero(inside)
    if not len(idx):
        return 0, 0.0
    sub = np.random.default_rng(0).choice(idx, min(limit, len(idx)), replace=False)
    shell = Shape.cast(fixture.solid.shells()[0].wrapped) if fixture.solid.shells() else fixture.solid
    depth = distances_mm(pts[sub], shell)
    margin = config.n_sigma * config.noise_coeff_per_m * z[sub] ** 2 * fixture.fmap.scale
    deep = depth > margin
    return int(round(deep.sum() * len(idx) / len(sub))), float(depth[deep].max()) if deep.any() else 0.0
