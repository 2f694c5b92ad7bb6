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
from fixtures_design.references import plane_coords
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
    opening_tol_mm: float = 0.95  # mm: a pin may be at most this much wider than the opening its hole's plane shows
    opening_tol_rel: float = 0.015  # ... plus this share of the hole's radius (`hole_opening`; the rim's pixels reach
    # further into a large hole's opening). From the training and validation pins (fixture bench seeds 7100 and
    # 7200, corpus train and validation splits; docs/fixtures.md, "Pins that the scan contradicts"): the pins
    # that seated were at most 0.68 mm wider than the opening on holes under 20 mm radius and 0.9-1.3 mm on holes
    # of 54-94 mm; the pins fitted 2-2.6 mm too wide were 1.03-1.98 mm wider (the 1.03 mm one stays)
    opening_level_sigmas: float = 2.0  # the opening is bounded by the points within this many depth-noise sigmas of
    # the hole's plane, along its axis (the plane round the rim, the wall's top)
    opening_step_m: float = 0.00025  # metres: grid step of the largest-empty-circle search ...
    opening_max_steps: int = 400  # ... at least the radius over this many steps (count; a hole fitted huge)
    wall_skip_m: float = 0.001  # metres below the rim where a hole's wall points start (`wall_inside`; the rim's
    # mixed pixels above)
    wall_band_rel: float = 0.5  # wall points lie within this share of the hole's radius inside it ...
    wall_band_m: float = 0.003  # ... and this many metres outside it
    wall_min_sigma_m: float = 5e-5  # metres: the least radial noise sigma of a wall point
    max_wall_share: float = 0.10  # a pin whose hole's wall points lie deeper inside it than n_sigma of their
    # radial noise in more than this share (and at least min_wall_points of them) is refused. Training and
    # validation pins (as opening_tol_mm): the pins that seated had at most 7.4 % of their wall points there (27
    # points), the pins too wide for a narrower section (a counterbore's step the fit merged, a hole fitted
    # 0.5-3.4 mm too wide) 9-13 %
    min_wall_points: int = 4  # (count)
    wall_max_narrowing: float = 0.3  # a pin whose hole's wall points narrow towards the axis, going down it, faster
    # than this (mm of radius per mm of depth, tan 17 degrees: a chamfer or countersink the fit took for the hole)
    # at wall_narrowing_z standard errors of the slope is refused (`wall_narrowing`). Corpus training split (63
    # pins, docs/fixtures.md "A hole that narrows"): the one pin fitted to a 45-degree countersink (its wall 13.8 mm
    # fitted, 8.2 mm true) narrows at 0.87 +- 0.17 and cut 3.4 %; every other pin's lies under 0.4 (at most 0.15 at
    # 3 standard errors)
    wall_narrowing_z: float = 3.0  # standard errors of the fitted slope
    wall_narrowing_min_points: int = 12  # (count) fewer wall points say nothing of the slope


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


def _along_axis(
    center: np.ndarray, axis: np.ndarray, points: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(unit axis, the points in front of the camera (N, 3), their offsets from ``center`` (N, 3), their heights
    along the axis (N,)); camera frame, metres."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    p = np.asarray(points, float).reshape(-1, 3)
    p = p[p[:, 2] > 0]
    v = p - np.asarray(center, float)
    return a, p, v, v @ a


def _wall_points(
    center: np.ndarray, axis: np.ndarray, radius: float, depth: float, points: np.ndarray, config: EvidenceConfig
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A hole's wall points (`wall_inside`): (points (M, 3), their depths along the axis (M,), distances from it
    (M,), offsets from it (M, 3)); camera frame, metres."""
    a, p, v, t = _along_axis(center, axis, points)
    radial = v - np.outer(t, a)
    rad = np.linalg.norm(radial, axis=1)
    wall = (
        (t > config.wall_skip_m)
        & (t < depth)
        & (rad > (1.0 - config.wall_band_rel) * radius)
        & (rad < radius + config.wall_band_m)
    )
    return p[wall], t[wall], rad[wall], radial[wall]


def wall_narrowing(
    center: np.ndarray,
    axis: np.ndarray,
    radius: float,
    depth: float,
    points: np.ndarray,
    config: EvidenceConfig = EvidenceConfig(),
) -> tuple[float, float, int]:
    """(slope, its standard error, wall points): how fast a hole's wall points come nearer the axis per unit of
    depth along it (positive: the hole narrows going in; a least-squares line of their distance from the axis over
    their depth), over the wall points of `wall_inside` (camera frame, metres). NaN slope with fewer than three
    points or no spread in depth.
    """
    _, t, rad, _ = _wall_points(center, axis, radius, depth, points, config)
    n = len(t)
    if n < 3 or np.ptp(t) <= 0:
        return float("nan"), float("nan"), n
    from scipy.stats import linregress

    line = linregress(t, rad)
    return -float(line.slope), float(line.stderr), n


def hole_opening(
    center: np.ndarray, axis: np.ndarray, radius: float, points: np.ndarray, config: EvidenceConfig = EvidenceConfig()
) -> float | None:
    """Radius (metres) of the largest circle on a hole's plane that holds none of the scan's points lying at the
    plane's level, its centre within ``radius`` of the hole's axis: how wide the opening is as the depth shows it.

    center: (3,) the rim's centre on the plane; axis: (3,) unit, into the hole; radius: the fitted hole's radius
    (metres); points: the scan's observed points of the part (camera frame, metres, (N, 3)). A point counts when it
    lies within ``config.opening_level_sigmas`` depth-noise sigmas of the plane along the axis: the plane round the
    rim and the wall's top edge bound the opening, and a hole fitted too wide (a short arc of its wall seen) has
    them inside its rim. The rim's own pixels reach up to about a pixel into the opening, so the value errs small
    by that much; where the plane round the hole is not seen it errs large. None: no point at the plane's level
    within three radii of the axis.
    """
    from scipy.spatial import cKDTree

    a, p, _, t = _along_axis(center, axis, points)
    sigma = config.noise_coeff_per_m * p[:, 2] ** 2
    q = plane_coords(p, center, a)[np.abs(t) <= config.opening_level_sigmas * sigma]
    q = q[np.linalg.norm(q, axis=1) <= 3.0 * radius]
    if not len(q):
        return None
    step = max(config.opening_step_m, radius / config.opening_max_steps)
    g = np.arange(-radius, radius + 0.5 * step, step)
    grid = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    grid = grid[np.linalg.norm(grid, axis=1) <= radius]
    dist, _ = cKDTree(q).query(grid)
    return float(dist.max())


def wall_inside(
    center: np.ndarray,
    axis: np.ndarray,
    radius: float,
    pin_radius: float,
    depth: float,
    points: np.ndarray,
    config: EvidenceConfig = EvidenceConfig(),
) -> tuple[int, int]:
    """(inside, wall): how many of a hole's wall points lie inside a pin of ``pin_radius`` on its axis by more
    than ``config.n_sigma`` sigmas of their radial noise, of how many wall points (camera frame, metres).

    Wall points: the scan's points from ``wall_skip_m`` below the rim (``center``, on the plane) to ``depth`` along
    ``axis``, between (1 - ``wall_band_rel``) x ``radius`` and ``radius`` + ``wall_band_m`` from the axis. A point's
    radial noise is its depth noise (``noise_coeff_per_m`` z^2) along its camera ray, projected on the direction
    away from the axis (at least ``wall_min_sigma_m``): a wall seen along the axis is measured across it far better
    than along the ray. A fitted cylinder that merged a counterbore with the narrower hole below, or a hole fitted
    too wide from a short arc of its wall, leaves the wall's own points inside the pin.
    """
    p, _, rad, radial = _wall_points(center, axis, radius, depth, points, config)
    if not len(p):
        return 0, 0
    ray = p / np.linalg.norm(p, axis=1, keepdims=True)
    along = np.abs(np.sum(ray * radial, axis=1)) / np.maximum(rad, 1e-12)
    sigma = np.maximum(config.noise_coeff_per_m * p[:, 2] ** 2 * along, config.wall_min_sigma_m)
    return int(np.sum(rad < pin_radius - config.n_sigma * sigma)), int(len(p))
