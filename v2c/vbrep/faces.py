"""The face step of VB-Rep extraction: each instance's surface and sheet (camera frame, metres).

A fitted primitive with valid parameters is taken as it is; one with invalid parameters (`valid_primitive`) is
rejected, and a curved one is replaced by a least-squares sphere through its depth points when that fits. An
instance left without a surface (at least ``fallback_min_px`` pixels) gets a fallback from its evidence (its own
depth points and its boundaries lifted onto fitted neighbours, `fallback_sources`): the plane or cylinder
its label's axis class gives (`labelled_fallback`), else a free plane when at least two sources fix it; where a
free plane would be drawn for a curved label, that type on an axis its fitted neighbours suggest takes its place
where it fits (`curved_fallback`: a small fillet, rounded rim, chamfer or ball end that had too few points for
RANSAC). Each
surface's sheet (boss or hole) is chosen from the depth points (`v2c.vbrep.ambiguity`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from v2c.camera import pixel_rays
from v2c.labels import TYPE_NAMES, TYPE_OF_LABEL, type_axis_of
from v2c.primitives import Cone, Cylinder, Plane, Sphere, Torus
from v2c.primitives.directions import unit
from v2c.segment.graph import EdgeGraph, build_edge_graph
from v2c.segment.refine import touching_pairs
from v2c.vbrep.ambiguity import SheetChoice, choose_sheet
from v2c.vbrep.classify import FaceGeom
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.mesh import lift_points
from v2c.vbrep.pointfit import (
    fit_axis_cylinder_points,
    fit_axis_line_cone_points,
    fit_axis_line_torus_points,
    fit_axis_plane_points,
    fit_plane_normal_across,
    fit_plane_points,
    fit_sphere_points,
    measured_points,
)
from v2c.vbrep.raycast import as_primitive, intersect, sheet_depth
from v2c.vbrep.topology import valid_primitive

if TYPE_CHECKING:
    from v2c.fit.result import FitResult
    from v2c.primitives.base import Primitive
    from v2c.segment.types import Segmentation

_FRAME_ROW = {"X": 0, "Y": 1, "Z": 2}


def labelled_fallback(
    inst: int, seg: Segmentation, fit: FitResult, X: np.ndarray, scale: float, cfg: VBRepConfig
) -> tuple[Cylinder | Plane, float, str | None] | None:
    """An unfitted instance labelled cylinder or plane with an aligned axis class (X / Y / Z): the cylinder on
    that axis of the shared frame (radius at most the part size: a tiny wall patch keeps its type instead of
    becoming a plane), or the plane normal to it, that fits its evidence X (N, 3) within fallback_rms; else None.
    A face seen at a grazing angle has hardly any depth; its label's axis fixes the plane that its edges alone
    cannot. When the fit found faces of one axis class only, the frame's other two axes are a guess about it: a
    plane labelled with another class is then fitted with its normal across the one found (it is parallel to it),
    and a cylinder is left to the rules for unlabelled faces. Returns (surface, RMS metres, axis label or None)."""
    labels = np.asarray(seg.labels)
    if inst >= len(labels) or not 1 <= int(labels[inst]) <= 16:
        return None
    ptype, ax = type_axis_of(int(labels[inst]))
    if ptype.value not in ("cylinder", "plane") or ax is None or ax.value == "U":
        return None
    frame = np.asarray(fit.frame, float)
    axis = frame[_FRAME_ROW[ax.value]]
    max_rms = cfg.fallback_rms * scale
    found = {v for v in fit.axis_labels.values() if v in _FRAME_ROW}
    if len(found) == 1 and ax.value not in found:
        if ptype.value != "plane":
            return None
        got = fit_plane_normal_across(X, frame[_FRAME_ROW[found.pop()]])
        if got is None or got[1] > max_rms:
            return None
        return got[0], got[1], None
    if ptype.value == "plane":
        got = fit_axis_plane_points(X, axis)
    else:
        got = fit_axis_cylinder_points(X, axis, cfg.fallback_fit_iters)
        if got is not None and got[0].radius > scale:
            return None
    if got is None or got[1] > max_rms:
        return None
    return got[0], got[1], ax.value


def _axis_candidates(
    nbs: list[FaceGeom], frame: np.ndarray, axis_class: str | None, min_cross_deg: float
) -> tuple[list[tuple[np.ndarray, str | None]], list[tuple[np.ndarray, np.ndarray]]]:
    """Axis directions a small curved face may have (unit vectors, each with its frame axis name or None): the
    part frame's axis its label names (X / Y / Z; none for U, which says the axis is none of them), each
    neighbouring plane's normal (a hole wall or boss through that plane), the cross product of two neighbouring
    planes' normals at least ``min_cross_deg`` apart (a fillet or chamfer between them), each curved neighbour's
    axis (a step on a shaft, the next flute of a knob); and the axis lines (point, direction) of the curved
    neighbours (a rounded rim or chamfer coaxial with its hole)."""
    dirs: list[tuple[np.ndarray, str | None]] = []
    if axis_class in _FRAME_ROW:
        dirs.append((np.asarray(frame[_FRAME_ROW[axis_class]], float), axis_class))
    planes = [np.asarray(f.prim.axis_vector, float) for f in nbs if isinstance(f.prim, Plane)]
    dirs += [(n, None) for n in planes]
    for i in range(len(planes)):  # loop over pairs of neighbouring planes
        for j in range(i + 1, len(planes)):
            c = np.cross(planes[i], planes[j])
            if np.linalg.norm(c) >= np.sin(np.deg2rad(min_cross_deg)):
                dirs.append((unit(c), None))
    lines = [
        (np.asarray(f.prim.origin, float), np.asarray(f.prim.axis_vector, float))
        for f in nbs
        if isinstance(f.prim, (Cylinder, Cone, Torus))
    ]
    dirs += [(a, None) for _, a in lines]
    return dirs, lines


def curved_fallback(
    inst: int,
    seg: Segmentation,
    fit: FitResult,
    faces: dict[int, FaceGeom],
    neighbours: list[int],
    X: np.ndarray,
    scale: float,
    cfg: VBRepConfig,
) -> tuple[Primitive, float, str | None] | None:
    """An unfitted instance labelled with a curved type (cylinder, cone, sphere, torus; any axis class), called
    where a free plane through its evidence would be drawn (``neighbours``: the ids of the instances touching it,
    ascending): that type through its evidence X (N, 3), the best
    (least RMS) over the axes its fitted neighbours and its label's axis class suggest (`_axis_candidates`) and,
    for a cylinder, its evidence's long direction (``fallback_strip_axis``: the principal axis of X, where X is at
    least ``fallback_strip_elongation`` times longer than wide; a fillet or rounded edge is a strip along its
    axis): a
    cylinder on any candidate direction, a cone or torus on a curved neighbour's axis line, a free sphere; its
    size at most the part size and its RMS within fallback_rms and within fallback_curved_sigma depth-noise
    sigmas (sigma_depth_coeff_per_m z^2 at the evidence's median depth: a 2 mm knob flute fitted on a
    neighbour's unrelated axis missed its evidence by 2.4 sigmas), else None. A small fillet, rounded rim,
    chamfer or ball end of a real part has too few points for RANSAC, and the free plane in its place has its
    normal across a fillet's axis, the worst axis there is; where several candidate axes fit alike (20-40 points
    of a small fillet rarely tell them apart), the least RMS is still the better guess. Returns (surface, RMS
    metres, frame axis name or None)."""
    labels = np.asarray(seg.labels)
    if not cfg.fallback_curved or inst >= len(labels) or not 1 <= int(labels[inst]) <= 17:
        return None
    ptype, ax = type_axis_of(int(labels[inst]))
    if ptype.value == "plane":
        return None
    nbs = [faces[j] for j in neighbours if j in faces]
    dirs, lines = _axis_candidates(
        nbs, np.asarray(fit.frame, float), None if ax is None else ax.value, cfg.fallback_axis_cross_deg
    )
    got: list[tuple[Primitive, float, str | None]] = []
    if ptype.value == "sphere":
        sp = fit_sphere_points(X, cfg.fallback_trim)
        if sp is not None:
            got.append((sp[0], sp[1], None))
    elif ptype.value == "cylinder":
        if cfg.fallback_strip_axis and len(X) >= 3:  # the evidence's long direction: a strip along its axis
            c = X - X.mean(axis=0)
            w, v = np.linalg.eigh(c.T @ c)
            if w[-1] >= cfg.fallback_strip_elongation**2 * max(float(w[-2]), 1e-30):
                dirs.append((v[:, -1], None))
        for a, name in dirs:  # loop over candidate axis directions
            cy = fit_axis_cylinder_points(X, a, cfg.fallback_fit_iters)
            if cy is not None:
                got.append((cy[0], cy[1], name))
    else:
        for c, a in lines:  # loop over the curved neighbours' axis lines
            if ptype.value == "cone":
                cu = fit_axis_line_cone_points(X, c, a)
            else:
                cu = fit_axis_line_torus_points(X, c, a, cfg.fallback_fit_iters)
            if cu is not None:
                got.append((cu[0], cu[1], None))
    sigma = cfg.sigma_depth_coeff_per_m * float(np.median(X[:, 2])) ** 2
    bound = min(cfg.fallback_rms * scale, cfg.fallback_curved_sigma * sigma)
    ok = [g for g in got if g[1] <= bound and _extent(g[0]) <= scale]
    return min(ok, key=lambda g: g[1]) if ok else None


def _extent(prim: Primitive) -> float:
    """A curved surface's size (metres): its radius (a torus: major plus minor; a cone: 0, bounded by its
    evidence)."""
    if isinstance(prim, Torus):
        return float(prim.radius + prim.minor_radius)
    if isinstance(prim, (Cylinder, Sphere)):
        return float(prim.radius)
    return 0.0


def fallback_sources(
    inst: int,
    inst_map: np.ndarray,
    depth: np.ndarray,
    K: np.ndarray,
    faces: dict[int, FaceGeom],
    window: tuple[float, float],
) -> tuple[np.ndarray, list[np.ndarray]]:
    """3D evidence (camera frame, metres) for an instance the geometry stage could not fit (e.g. a face seen at a
    grazing angle, where the sensor returns no depth): its own depth points, plus its boundary pixels next to each
    fitted neighbour lifted onto that neighbour's surface (where two faces meet, the edge lies on both), at the
    pixel sides they share (half a pixel from either pixel's centre: the face's own boundary pixels lifted onto a
    neighbour that meets it at an angle lie off it by up to a pixel's footprint times that angle's tangent,
    which on a face of a few pixels turned the fitted plane by tens of degrees). Returns its own points (N, 3;
    any number) and each lifted edge with at least 3 points."""
    m = inst_map == inst
    own = measured_points(m, depth, K)
    h, w = m.shape
    vs, us = np.nonzero(m)
    crossings: dict[int, list[np.ndarray]] = {}
    for dv, du in ((0, 1), (0, -1), (1, 0), (-1, 0)):  # loop over the 4 neighbours of the face's pixels
        v2, u2 = vs + dv, us + du
        ok = (v2 >= 0) & (v2 < h) & (u2 >= 0) & (u2 < w)
        other = np.zeros(len(vs), inst_map.dtype)
        other[ok] = inst_map[v2[ok], u2[ok]]
        for j in np.unique(other[ok & (other != inst)]):
            sel = ok & (other == j)
            # the shared pixel side: half a pixel from the face's pixel towards the neighbour's
            crossings.setdefault(int(j), []).append(np.stack([us[sel] + du / 2, vs[sel] + dv / 2], 1))
    edges = []
    for j in sorted(crossings):  # loop over the fitted neighbours
        if j not in faces:
            continue
        rays = pixel_rays(np.concatenate(crossings[j]).astype(float), K)
        edges.append(rays * sheet_depth(intersect(faces[j].prim, rays, window), faces[j].sheet)[:, None])
    return own, [e for e in edges if len(e) >= 3]


def _plane_label(seg: Segmentation, inst: int) -> bool:
    """Whether instance ``inst``'s label names a plane (any axis class)."""
    labels = np.asarray(seg.labels)
    return inst < len(labels) and int(TYPE_OF_LABEL[int(labels[inst])]) == TYPE_NAMES.index("plane")


def own_first_plane(
    own: np.ndarray | None, edges: list[np.ndarray], trim: float, max_rms: float, min_flat: float
) -> tuple[Plane, float, float] | None:
    """A free plane for a face the geometry stage left without one, from its own depth points ``own`` (N, 3, or
    None) first: where they lie on a patch, not a line (flatness at least ``min_flat``), a neighbour's lifted edge
    (each of ``edges``) joins them only when it lies within ``max_rms`` metres (RMS) of their plane; else every
    source together (`pointfit.fit_plane_points`, refitted on the ``trim`` share). A face's boundary lifted onto a
    neighbour lies on the face only where the two meet at an edge; where the face is seen beside the neighbour
    (past it, or behind it) the lifted points lie on the neighbour, and a 16-pixel chamfer whose own points fixed
    its normal within 7 degrees came out 87 degrees off with them (a corpus part, training split, oracle)."""
    got = fit_plane_points(own, trim) if own is not None else None
    if got is None or got[2] < min_flat:
        return fit_plane_points(np.concatenate(([own] if own is not None else []) + edges), trim)
    plane = got[0]
    kept = [own] + [e for e in edges if float(np.sqrt(np.mean(plane.signed_distance(e) ** 2))) <= max_rms]
    return fit_plane_points(np.concatenate(kept), trim) if len(kept) > 1 else got


class _FaceSet:
    """Faces and sheets being collected; the sheet choice's sampling draws from one seeded generator, in order."""

    def __init__(
        self, inst_map: np.ndarray, depth: np.ndarray, K: np.ndarray, window: tuple[float, float], cfg: VBRepConfig
    ) -> None:
        self.inst_map, self.depth, self.K, self.window, self.cfg = inst_map, depth, K, window, cfg
        self.rng = np.random.default_rng(cfg.seed)
        self.faces: dict[int, FaceGeom] = {}
        self.sheets: dict[int, SheetChoice] = {}

    def add(self, inst: int, prim: Primitive, res: float, axl: str | None, extra: dict[str, Any]) -> None:
        """Take ``prim`` (RMS residual ``res`` metres) as instance ``inst``'s surface, on its best sheet."""
        vs, us = np.nonzero(self.inst_map == inst)
        if len(us) == 0:
            return
        ch = choose_sheet(
            prim,
            np.stack([us, vs], 1).astype(float),
            self.depth[vs, us],
            self.K,
            self.window,
            self.rng,
            self.cfg.sheet_max_pixels,
        )
        if not np.isfinite(ch.errors).any() and self.cfg.sheet_ring_px > 0:
            ch = SheetChoice(self._ring_sheet(inst, prim), ch.errors)
        self.faces[inst] = FaceGeom(inst, prim, ch.sheet, res, axl, extra)
        self.sheets[inst] = ch

    def _ring_sheet(self, inst: int, prim: Primitive) -> int:
        """The sheet of ``prim`` that best meets the readings within ``sheet_ring_px`` of instance ``inst``'s
        outline (other instances' pixels and the background's; `choose_sheet` on them); 0 (the nearest) when
        none is there either. For a face whose own pixels have no reading: the errors that score its
        confidence stay its own (none)."""
        r = self.cfg.sheet_ring_px
        region = (self.inst_map == inst).astype(np.uint8)
        ring = (cv2.dilate(region, np.ones((2 * r + 1, 2 * r + 1), np.uint8)) > 0) & (region == 0) & (self.depth > 0)
        vs, us = np.nonzero(ring)
        if len(us) == 0:
            return 0
        pix = np.stack([us, vs], 1).astype(float)
        return choose_sheet(
            prim, pix, self.depth[vs, us], self.K, self.window, self.rng, self.cfg.sheet_max_pixels
        ).sheet

    def coincides(self, plane: Plane, scale: float) -> bool:
        """Whether ``plane`` is a fitted plane again (within fallback_min_angle_deg and fallback_rms)."""
        cfg = self.cfg
        return any(
            f.prim.type == "plane"
            and abs(float(f.prim.axis_vector @ plane.axis_vector)) > np.cos(np.deg2rad(cfg.fallback_min_angle_deg))
            and abs(float(f.prim.axis_vector @ (plane.origin - f.prim.origin))) < cfg.fallback_rms * scale
            for f in self.faces.values()
        )


def _add_fitted(fs: _FaceSet, fit: FitResult, scale: float) -> list[int]:
    """The fitted primitives, in instance order; returns the ids of those rejected for invalid parameters."""
    rejected = []
    for inst in sorted(fit.primitives):
        if not valid_primitive(as_primitive(fit.primitives[inst])):
            rejected.append(int(inst))
            # a curved face with invalid parameters (e.g. a torus with a negative major radius): the nearest
            # valid surface, a least-squares sphere through its depth points, if it fits them; else it is left
            # to the unfitted-face rule
            got = fit_sphere_points(measured_points(fs.inst_map == inst, fs.depth, fs.K), fs.cfg.fallback_trim)
            if got is not None and got[1] <= fs.cfg.fallback_rms * scale:
                fs.add(int(inst), got[0], got[1], None, {"refit": "sphere"})
            continue
        fs.add(
            int(inst),
            as_primitive(fit.primitives[inst]),
            float(fit.residuals.get(inst, 0.0) or 0.0),
            fit.axis_labels.get(inst),
            {},
        )
    return rejected


def _facing_view(plane: Plane, evidence: np.ndarray, min_deg: float) -> bool:
    """Whether the camera sees ``plane`` at least ``min_deg`` degrees from edge-on along the ray through the
    centroid of its evidence (N, 3): a free plane whose evidence puts it (nearly) edge-on cannot be what
    its pixels show; its few pixels lie on neighbouring surfaces or the background behind."""
    ray = evidence.mean(axis=0)
    ray = ray / max(float(np.linalg.norm(ray)), 1e-12)
    return abs(float(np.asarray(plane.axis_vector, float) @ ray)) >= np.sin(np.deg2rad(min_deg))


def _add_fallbacks(fs: _FaceSet, seg: Segmentation, fit: FitResult, scale: float) -> None:
    """A surface for each instance of at least fallback_min_px pixels still without one, where its evidence
    fixes one (module docstring)."""
    cfg = fs.cfg
    counts = np.bincount(fs.inst_map.ravel())
    pairs: np.ndarray | None = None  # the touching instances (`touching_pairs`), found once when first needed
    for inst in np.flatnonzero(counts >= cfg.fallback_min_px):
        if inst == 0 or int(inst) in fs.faces:
            continue
        own_pts, edges = fallback_sources(int(inst), fs.inst_map, fs.depth, fs.K, fs.faces, fs.window)
        own = own_pts if len(own_pts) >= 3 else None
        sources = edges if own is None else [own, *edges]
        if not sources:
            continue
        evidence = np.concatenate(sources)
        # one source (one neighbour's edge, no depth of its own) places a surface whose axis the label gives
        lab = labelled_fallback(int(inst), seg, fit, evidence, scale, cfg)
        if lab is not None and not (lab[0].type == "plane" and fs.coincides(lab[0], scale)):
            fs.add(int(inst), lab[0], lab[1], lab[2], {"fallback": True})
            continue
        if len(sources) < 2:  # one neighbour's edge alone does not fix a free plane (it may lie in that neighbour)
            continue
        got = (
            own_first_plane(own, edges, cfg.fallback_trim, cfg.fallback_rms * scale, cfg.fallback_flatness)
            if cfg.fallback_own_first and _plane_label(seg, int(inst))
            else fit_plane_points(evidence, cfg.fallback_trim)
        )
        if got is None:
            continue
        plane, rms, flat = got
        if (
            rms <= cfg.fallback_rms * scale
            and flat >= cfg.fallback_flatness
            and not fs.coincides(plane, scale)
            and _facing_view(plane, evidence, cfg.fallback_min_view_deg)
        ):  # the evidence fixes a surface here; a curved label's own type replaces the plane where it fits
            if pairs is None:
                pairs = touching_pairs(fs.inst_map)
            nbs = np.unique(pairs[(pairs == inst).any(axis=1)])
            nbs = [int(j) for j in nbs if j != inst]
            cur = curved_fallback(int(inst), seg, fit, fs.faces, nbs, evidence, scale, cfg)
            if cur is not None:
                fs.add(int(inst), cur[0], cur[1], cur[2], {"fallback": True})
            else:
                fs.add(int(inst), plane, rms, None, {"fallback": True})


def face_geoms(
    fit: FitResult,
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    scale: float,
    cfg: VBRepConfig,
    stats: dict[str, Any],
) -> tuple[dict[int, FaceGeom], dict[int, SheetChoice]]:
    """Each face's geometry and sheet (instance id -> `FaceGeom`, `SheetChoice`); depth: (H, W) metres, 0 = none;
    window: depth range of the ray casts (metres); scale: part size (metres). Fitted primitives with invalid
    parameters are rejected (``stats["rejected_primitives"]``, instance ids) and treated like instances without a
    fit."""
    fs = _FaceSet(np.asarray(seg.instances), depth, K, window, cfg)
    rejected = _add_fitted(fs, fit, scale)
    _add_fallbacks(fs, seg, fit, scale)
    stats["rejected_primitives"] = rejected
    return fs.faces, fs.sheets


def _ray_miss(fs: _FaceSet, inst: int, prim: Primitive, sheet: int, scale: float) -> float:
    """Median distance (metres) from ``prim`` (on ``sheet``) lifted along the rays of instance ``inst``'s pixels
    with a reading to the nearest point those pixels measured (inf where no ray meets it; `v2c.vbrep.mesh.
    beyond_measured`'s measure, per pixel); 0 for an instance with fewer than 3 readings."""
    vs, us = np.nonzero((fs.inst_map == inst) & (fs.depth > 0))
    if len(us) < 3:
        return 0.0
    uv = np.stack([us, vs], 1).astype(float)
    own = pixel_rays(uv, fs.K) * fs.depth[vs, us, None]
    lifted, good = lift_points(prim, sheet, uv, fs.depth, fs.K, fs.window, fs.cfg.mesh_surface_tol * scale)
    if not good.any():
        return float("inf")
    return float(np.median(cKDTree(own).query(lifted[good], k=1)[0]))


def planes_for_unseen_surfaces(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    scale: float,
    cfg: VBRepConfig,
    faces: dict[int, FaceGeom],
    sheets: dict[int, SheetChoice],
    insts: list[int],
) -> list[int]:
    """The curved surfaces of instances ``insts`` whose meshes missed their own readings (the extraction left
    those faces without a mesh, and so without a face in the STEP, though the sensor saw them: a real tuna can's
    lid piece fitted as a torus its pixels' rays meet 4 mm off their depth) replaced, in ``faces`` and ``sheets``,
    by the plane through those readings where that plane's rays meet them within mesh_evidence_tol (the mesh
    test's own bound). Returns the instance ids replaced."""
    fs = _FaceSet(np.asarray(seg.instances), depth, K, window, cfg)
    fs.faces, fs.sheets = dict(faces), dict(sheets)
    out = []
    for inst in sorted(insts):
        fg = faces.get(inst)
        if fg is None or isinstance(fg.prim, Plane):
            continue
        got = fit_plane_points(measured_points(fs.inst_map == inst, depth, K), cfg.fallback_trim)
        if got is None or _ray_miss(fs, inst, got[0], 0, scale) > cfg.mesh_evidence_tol * scale:
            continue
        fs.add(inst, got[0], got[1], None, {**fg.extra, "refit": "plane"})
        faces[inst], sheets[inst] = fs.faces[inst], fs.sheets[inst]
        out.append(int(inst))
    return out


def absorb_islands(
    instances: np.ndarray, faced: set[int], cfg: VBRepConfig, stats: dict, scores: np.ndarray | None = None
) -> np.ndarray:
    """The instance map with every island of a faced instance (a connected piece, 8-connected, other than its
    largest, of fewer than ``island_max_px`` pixels and than ``island_max_share`` of the instance's) given to the
    other faced instances nearest its pixels (within ``speck_reach_px``); pieces out of that reach stay. Such
    islands are stray pixels of the segmentation (a few pixels of a box's top left among its side's); as a face's
    they become mesh islands, and in the STEP faces of their own beside it. ``stats["islands_absorbed"]``: how many
    pieces moved (one nearest its own instance's other pixels stays, uncounted). An instance whose score
    (``scores``, per id) is at least ``island_keep_score`` keeps its pieces: the oracle's ground truth, whose pieces
    are the true face's."""
    inst = np.asarray(instances)
    stats["islands_absorbed"] = 0
    if cfg.island_max_px <= 0 or len(faced) < 2:
        return inst
    piece = np.zeros(inst.shape, np.int64)  # 1.. per island, 0 elsewhere
    count = 0
    for i in sorted(faced):  # loop over faced instances
        if scores is not None and i < len(scores) and float(scores[i]) >= cfg.island_keep_score:
            continue  # a segmentation certain of it (the ground truth's): a face seen in pieces
        n, lab, st, _ = cv2.connectedComponentsWithStats((inst == i).astype(np.uint8), connectivity=8)
        area = st[1:, cv2.CC_STAT_AREA]
        cap = min(cfg.island_max_px, cfg.island_max_share * float(area.sum()))
        for k in np.flatnonzero(area < cap):  # loop over its small pieces but the largest
            if k != int(np.argmax(area)):
                count += 1
                piece[lab == k + 1] = count
    is_island = piece > 0
    if not is_island.any():
        return inst
    owner = np.isin(inst, sorted(faced)) & ~is_island
    dist, (iy, ix) = distance_transform_edt(~owner, return_indices=True)
    take = is_island & (dist <= cfg.speck_reach_px)
    out = inst.copy()
    out[take] = inst[iy[take], ix[take]]
    moved = np.unique(piece[out != inst])
    stats["islands_absorbed"] = len(moved)
    return out if len(moved) else inst


def absorb_specks(
    instances: np.ndarray, graph: EdgeGraph, faced: set[int], cfg: VBRepConfig, stats: dict
) -> tuple[np.ndarray, EdgeGraph]:
    """The instance map with every speck (an instance without a face, smaller than ``fallback_min_px`` pixels,
    which is never given one) given to the faced instances nearest its pixels (within ``speck_reach_px``), and its
    edge graph rebuilt (the same construction and simplification as the fit's, `v2c.segment.graph`); unchanged
    when there is no speck. A speck would otherwise count as background: its few-pixel boundaries cut its
    neighbours' edges into runs shorter than ``min_edge_px`` whose contraction merges vertices several pixels
    apart (edges that run out and back, loops of one or two edges). ``stats["specks_absorbed"]``: their ids."""
    inst = np.asarray(instances)
    sizes = np.bincount(inst.ravel().clip(0))
    specks = [i for i in np.flatnonzero(sizes) if i > 0 and i not in faced and sizes[i] < cfg.fallback_min_px]
    stats["specks_absorbed"] = [int(i) for i in specks]
    if not specks or not faced:
        return inst, graph
    is_speck = np.isin(inst, specks)
    owner = np.isin(inst, sorted(faced))
    dist, (iy, ix) = distance_transform_edt(~owner, return_indices=True)
    take = is_speck & (dist <= cfg.speck_reach_px)
    if not take.any():
        return inst, graph
    out = inst.copy()
    out[take] = inst[iy[take], ix[take]]
    return out, build_edge_graph(out, cfg.graph_simplify_px)
