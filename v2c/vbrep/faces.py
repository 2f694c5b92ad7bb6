"""The face step of VB-Rep extraction: each instance's surface and sheet (camera frame, metres).

A fitted primitive with valid parameters is taken as it is; one with invalid parameters (`valid_primitive`) is
rejected, and a curved one is replaced by a least-squares sphere through its depth points when that fits. An
instance left without a surface (at least ``fallback_min_px`` pixels) gets a fallback from its evidence (its own
depth points and its boundaries lifted onto fitted neighbours, `fallback_plane_points`): the plane or cylinder
its label's axis class gives (`labelled_fallback`), else a free plane when at least two sources fix it. Each
surface's sheet (boss or hole) is chosen from the depth points (`v2c.vbrep.ambiguity`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.ndimage import distance_transform_edt

from v2c.camera import pixel_rays
from v2c.labels import type_axis_of
from v2c.primitives import Cylinder, Plane
from v2c.segment.graph import EdgeGraph, build_edge_graph
from v2c.vbrep.ambiguity import SheetChoice, choose_sheet
from v2c.vbrep.classify import FaceGeom
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.pointfit import (
    fit_axis_cylinder_points,
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


def fallback_plane_points(
    inst: int,
    inst_map: np.ndarray,
    depth: np.ndarray,
    K: np.ndarray,
    faces: dict[int, FaceGeom],
    window: tuple[float, float],
) -> list[np.ndarray]:
    """3D evidence (camera frame, metres) for an instance the geometry stage could not fit (e.g. a face seen at a
    grazing angle, where the sensor returns no depth): its own depth points, plus its boundary pixels next to each
    fitted neighbour lifted onto that neighbour's surface (where two faces meet, the edge lies on both), at the
    pixel sides they share (half a pixel from either pixel's centre: the face's own boundary pixels lifted onto a
    neighbour that meets it at an angle lie off it by up to a pixel's footprint times that angle's tangent,
    which on a face of a few pixels turned the fitted plane by tens of degrees). Returns the point sets of each
    source with at least 3 points."""
    m = inst_map == inst
    pts = [measured_points(m, depth, K)]
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
    for j in sorted(crossings):  # loop over the fitted neighbours
        if j not in faces:
            continue
        rays = pixel_rays(np.concatenate(crossings[j]).astype(float), K)
        pts.append(rays * sheet_depth(intersect(faces[j].prim, rays, window), faces[j].sheet)[:, None])
    return [p for p in pts if len(p) >= 3]


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
        self.faces[inst] = FaceGeom(inst, prim, ch.sheet, res, axl, extra)
        self.sheets[inst] = ch

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
    for inst in np.flatnonzero(counts >= cfg.fallback_min_px):
        if inst == 0 or int(inst) in fs.faces:
            continue
        sources = fallback_plane_points(int(inst), fs.inst_map, fs.depth, fs.K, fs.faces, fs.window)
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
        got = fit_plane_points(evidence, cfg.fallback_trim)
        if got is None:
            continue
        plane, rms, flat = got
        if (
            rms <= cfg.fallback_rms * scale
            and flat >= cfg.fallback_flatness
            and not fs.coincides(plane, scale)
            and _facing_view(plane, evidence, cfg.fallback_min_view_deg)
        ):
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
