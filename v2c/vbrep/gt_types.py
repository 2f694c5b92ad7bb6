"""The ground-truth edge type of every image boundary of a synthetic scan (the rule of docs/vbrep.md).

Input: gt/faces.png (which true face each pixel sees), primitives.json (each face's exact surface) and
depth_clean (noise-free depth). Every crack between two 4-neighbouring pixels with different face values is one
boundary sample, at the crack's midpoint in the image; the face on either side gets a typed record:

- **intersection** (both sides): the two faces' true surfaces meet at the boundary, i.e. along the rays through
  points within ``band_px`` of the crack their depths cross or come within ``gap_m`` (faces that share a B-rep edge
  of the true part meet exactly there; faces that merely overlap in the image are separated in depth);
- otherwise the nearer surface at the crack is the near face (background is infinitely far); its record is
  **visibility** when the face is curved and its contour generator (where its normal is orthogonal to the view
  ray) lies within ``vis_px`` pixels of the crack on the face's own pixels (the surface turns away from the
  camera there), else
  **silhouette**; the far face, if it is part of the part, gets **occluded**.

Each face's sheet of its surface (which crossing along the rays it is: outside of a boss, inside of a hole) is
read from the clean depth. Faces labelled non-analytic (255) are left out, with every crack touching them.
This is the same rule `v2c.vbrep.classify` applies to fitted surfaces, with tight tolerances on exact data.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from v2c.labels import IGNORE
from v2c.primitives import PRIMITIVE_CLASSES
from v2c.vbrep.ambiguity import choose_sheet
from v2c.vbrep.classify import KIND_INT, KIND_NEAR_A, FaceGeom, SurfaceView, TypingRule, classify_samples
from v2c.vbrep.model import EdgeType
from v2c.vbrep.raycast import as_primitive

if TYPE_CHECKING:
    from v2c.scan import GroundTruth, Scan


@dataclass(frozen=True)
class GTTypeConfig:
    """Tolerances of the ground-truth rule on exact data (the extraction's own are in `VBRepConfig`)."""

    band_px: float = 1.5  # pixels: surfaces meeting within this of the crack make an intersection
    band_step_px: float = 0.5  # pixels: spacing of the rays across that band
    gap_m: float = 0.0003  # metres: ... or coming closer than this in depth (tangent-continuous faces)
    vis_px: float = 2.0  # pixels: a contour generator within this of the crack makes a visibility edge
    vis_angle_deg: float = 90.0  # degrees: no tangent test (a crack's own normal is axis-aligned, not the
    #                              boundary's; the 2 px band and the face-pixel test are enough on exact data)
    vis_step_px: float = 0.5  # pixels: step of the contour search
    vis_bisect: int = 5  # bisection steps refining a contour crossing
    vis_face_px: int = 1  # pixels: a contour point must project within this of its face's own pixels
    curve_iters: int = 8  # Gauss-Newton iterations onto the intersection curve
    curve_slack_px: float = 1.0  # pixels: a point projected onto that curve may move band_px plus this
    sheet_max_pixels: int = 4000  # pixels: at most this many (seeded sample) per face to choose its sheet
    window_near: float = 0.5  # ratio: ray casts start at this times the nearest clean depth ...
    window_far: float = 1.5  # ratio: ... and end at this times the farthest
    window_min_m: float = 0.01  # metres: the near end is at least this
    window_empty_m: tuple[float, float] = (0.05, 5.0)  # metres: the window of a scan without clean depth
    seed: int = 0  # seeds the per-face pixel samples of the sheet choice

    def rule(self) -> TypingRule:
        """These tolerances as the edge-type rule's (`v2c.vbrep.classify`); ``gap_m`` is the depth-gap threshold."""
        return TypingRule(
            band_px=self.band_px,
            band_step_px=self.band_step_px,
            gap_m=self.gap_m,
            vis_px=self.vis_px,
            vis_step_px=self.vis_step_px,
            vis_bisect=self.vis_bisect,
            vis_angle_deg=self.vis_angle_deg,
            vis_face_px=self.vis_face_px,
            curve_iters=self.curve_iters,
            curve_slack_px=self.curve_slack_px,
        )


@dataclass
class GTEdgeSamples:
    """uv: (N, 2) pixels; face: (N,) faces.png value (1 + face index) of the face the record bounds; other: (N,)
    the value across the boundary (0 = background); type: (N,) EdgeType values as str."""

    uv: np.ndarray
    face: np.ndarray
    other: np.ndarray
    type: np.ndarray

    def share(self, t: EdgeType | str) -> float:
        """The share of the records of type ``t`` (0 without records)."""
        return float(np.mean(self.type == EdgeType(t).value)) if len(self.type) else 0.0


def _cracks(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Crack midpoints (N, 2), unit normals from side a to side b (N, 2), values a (N,), b (N,)."""
    _h, _w = faces.shape
    vv, uu = np.nonzero(faces[:, :-1] != faces[:, 1:])
    uv_h = np.stack([uu + 0.5, vv], 1).astype(float)
    a_h, b_h = faces[vv, uu], faces[vv, uu + 1]
    vv2, uu2 = np.nonzero(faces[:-1, :] != faces[1:, :])
    uv_v = np.stack([uu2, vv2 + 0.5], 1).astype(float)
    a_v, b_v = faces[vv2, uu2], faces[vv2 + 1, uu2]
    uv = np.concatenate([uv_h, uv_v])
    nrm = np.concatenate([np.tile([1.0, 0.0], (len(uv_h), 1)), np.tile([0.0, 1.0], (len(uv_v), 1))])
    return uv, nrm, np.concatenate([a_h, a_v]).astype(np.int64), np.concatenate([b_h, b_v]).astype(np.int64)


def _ground_truth(scan: Scan) -> GroundTruth:
    if scan.gt is None:
        raise ValueError(f"{scan.path}: no ground truth (gt/) to type the boundaries by")
    return scan.gt


def gt_face_geoms(scan: Scan, cfg: GTTypeConfig | None = None) -> dict[int, FaceGeom]:
    """faces.png value -> FaceGeom (true primitive, sheet from the clean depth) for the analytic faces in view."""
    cfg = cfg or GTTypeConfig()
    gt = _ground_truth(scan)
    faces = np.asarray(gt.faces).astype(np.int64)
    labels = np.asarray(gt.labels)
    depth = np.asarray(gt.depth_clean, float)
    window = _window(depth, cfg)
    rng = np.random.default_rng(cfg.seed)
    out = {}
    by_value = {int(p.get("pixel_value", int(p["id"]) + 1)): p for p in gt.primitives}
    for val in np.unique(faces[faces > 0]):
        p = by_value.get(int(val))
        if p is None or p.get("type") not in PRIMITIVE_CLASSES:
            continue
        sel = faces == val
        if np.all(labels[sel] == IGNORE):
            continue
        prim = as_primitive({"type": p["type"], "params": p["params"]})
        vs, us = np.nonzero(sel)
        ch = choose_sheet(
            prim, np.stack([us, vs], 1).astype(float), depth[vs, us], scan.K, window, rng, cfg.sheet_max_pixels
        )
        out[int(val)] = FaceGeom(int(val), prim, ch.sheet, 0.0, p.get("axis_label"))
    return out


def _window(depth: np.ndarray, cfg: GTTypeConfig) -> tuple[float, float]:
    """Depth range (metres) of the ray casts: around the clean depths (all of them: exact data)."""
    z = depth[depth > 0]
    if len(z) == 0:
        return cfg.window_empty_m
    return float(max(cfg.window_min_m, cfg.window_near * z.min())), float(cfg.window_far * z.max())


def gt_edge_samples(scan: Scan, cfg: GTTypeConfig | None = None) -> GTEdgeSamples:
    """Typed ground-truth boundary records of a synthetic scan (see the module docstring)."""
    cfg = cfg or GTTypeConfig()
    gt = _ground_truth(scan)
    faces = np.asarray(gt.faces).astype(np.int64)
    geoms = gt_face_geoms(scan, cfg)
    known = np.zeros(int(faces.max()) + 1, bool)
    known[0] = True
    for v in geoms:
        known[v] = True
    uv, nrm, a, b = _cracks(faces)
    keep = known[a] & known[b]
    uv, nrm, a, b = uv[keep], nrm[keep], a[keep], b[keep]
    view = SurfaceView(geoms, scan.K, _window(np.asarray(gt.depth_clean, float), cfg), faces)
    rule = cfg.rule()
    out_uv, out_face, out_other, out_type = [], [], [], []
    pairs = np.unique(np.stack([a, b], 1), axis=0)
    for pa, pb in pairs:
        sel = (a == pa) & (b == pb)
        st = classify_samples(uv[sel], nrm[sel], int(pa), int(pb), view, rule)
        near_type = np.where(st.vis, EdgeType.VISIBILITY.value, EdgeType.SILHOUETTE.value)
        is_int = st.kind == KIND_INT
        near_is_a = st.kind == KIND_NEAR_A
        for side, other, mine_near in ((pa, pb, near_is_a), (pb, pa, ~near_is_a & ~is_int)):
            if side == 0:
                continue
            t = np.where(is_int, EdgeType.INTERSECTION.value, np.where(mine_near, near_type, EdgeType.OCCLUDED.value))
            out_uv.append(uv[sel])
            out_face.append(np.full(sel.sum(), side))
            out_other.append(np.full(sel.sum(), other))
            out_type.append(t)
    if not out_uv:
        return GTEdgeSamples(np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, int), np.zeros(0, str))
    return GTEdgeSamples(
        np.concatenate(out_uv), np.concatenate(out_face), np.concatenate(out_other), np.concatenate(out_type)
    )
