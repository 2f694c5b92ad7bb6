"""Geometric verification of the learned instances against depth-only surface regions (issue 15, item 4).

The network draws boundaries where the image shows them: it follows printed edges inside one surface (a label on
a box side) and misses edges the colour does not show (a step of a few millimetres, a small face of an unseen
part). The geometric segmenter (`v2c.segment.geometric`) sees only the depth: its plane regions are whole where
the depth says one surface, whatever is printed on it. This step uses those regions as evidence, in two tests:

- **split**: a learned instance that two or more plane regions each cover substantially (at least
  ``piece_min_px`` valid pixels and ``piece_min_share`` of the instance) and that one fit of its own label's type
  does not explain (robust residual sigma above ``one_surface_sigma`` sensor sigmas; a true cylinder or a true
  plane passes and is left alone) is cut along the regions: each covered part becomes its own instance, the rest
  stays the instance (or joins the nearest piece when it is smaller than a piece);
- **merge**: learned instances (not curved ones labelled with a score of at least ``merge_curved_score``) that
  lie inside one plane region (at least ``merge_inside_share`` of their valid
  pixels) and on its plane (median distance within ``merge_sigma`` sensor sigmas) become one instance: the depth
  says one surface, so a printed edge never splits it.

A region counts when it holds ``region_min_px`` valid pixels and is labelled a plane, or its own plane explains it
within the noise (robust residual sigma within ``region_sigma`` sensor sigmas). Sensor sigma =
``noise_sigma_coeff`` z^2 (z in metres), the refine step's noise law. The depth regions cost a run of the
geometric segmenter (about 1 s per scan on 2 cores), so the learned segmenter asks for them only when some
plane-labelled instance is not one plane (`needs_regions`: more than ``gate_far_share`` of its points beyond
``gate_far_sigma`` sensor sigmas of its own plane). A split-off piece is labelled a plane of undecided axis with
score 0, so the fit stage searches its type and axis (`v2c.fit.stage._label_of`); the largest piece of a
plane-labelled instance keeps the instance's label and score. Merged instances keep the largest plane-labelled
member's label (`refine._relabel`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from v2c.camera import backproject
from v2c.geometry.config import RansacConfig
from v2c.geometry.points import instance_points, mad_sigma
from v2c.geometry.ransac import ransac_fit
from v2c.groups import UnionFind
from v2c.labels import TYPE_NAMES, TYPE_OF_LABEL, label_of
from v2c.segment.refine import _is_plane, _relabel, scan_geometry
from v2c.segment.types import Segmentation


@dataclass(frozen=True)
class VerifyConfig:
    """Thresholds of the geometric verification (module docstring); pixels are valid-depth pixels."""

    enabled: bool = True
    region_min_px: int = 100  # plane regions of the depth with fewer valid pixels are not used (pixels)
    region_sigma: float = 1.5  # a region labelled curved counts as a plane when its own plane leaves at most this
    # robust residual sigma (sensor sigmas); plane-labelled regions count as they are (their noise can be larger
    # than the sensor law at a grazing angle; the split and merge tests check distances themselves)
    one_surface_sigma: float = 2.0  # an instance whose own-type fit leaves at most this robust residual sigma is
    # one surface and never split (sensor sigmas)
    piece_min_px: int = 60  # a region covers an instance substantially with at least this many of its pixels ...
    piece_min_share: float = 0.05  # ... and this share of them (fraction)
    merge_inside_share: float = 0.8  # instances with at least this share of their pixels inside one plane region ...
    merge_sigma: float = 1.5  # ... and their median distance to its plane within this many sensor sigmas merge
    merge_min_px: int = 8  # instances with fewer valid pixels take no part in the merge (pixels)
    merge_curved_score: float = 0.6  # ... nor curved-labelled ones whose label score is at least this: a curved
    # face the network is sure of that the depth cannot tell from a plane keeps its face (FitConfig.label_score_min)
    noise_sigma_coeff: float = 0.0015  # sensor depth sigma = this * z^2 (1/m, z in metres), as RefineConfig's
    trim_sigma: float = 3.0  # a plane is refitted on the points within this many robust sigmas of the first fit (ratio)
    seed: int = 0  # seeds the curved fits of the one-surface test
    gate_far_sigma: float = 3.0  # the depth regions are computed only when some plane-labelled instance has more
    gate_far_share: float = 0.1  # ... than this share of its points further than gate_far_sigma sensor sigmas from
    # its own plane (fraction): the geometric segmenter costs about 1 s per scan, and a scan whose plane instances
    # are each one plane has nothing to split; 0 always computes them


def _plane(x: np.ndarray, trim_sigma: float) -> tuple[np.ndarray, float]:
    """(unit normal, offset) of the least-squares plane n.x = d of ``x`` (n, 3), refitted once on the points
    within ``trim_sigma`` robust sigmas of the first fit."""
    for _ in range(2):  # fit, then refit on the trimmed points
        c = x.mean(axis=0)
        _, _, vt = np.linalg.svd(x - c, full_matrices=False)
        n = vt[2]
        r = (x - c) @ n
        keep = np.abs(r) <= trim_sigma * max(mad_sigma(r), 1e-9)
        if keep.sum() < 3 or keep.all():
            break
        x = x[keep]
    return n, float(n @ c)


@dataclass(frozen=True)
class _Region:
    mask: np.ndarray  # (H, W) bool pixels of the region
    normal: np.ndarray
    offset: float


def plane_regions(depth_seg: Segmentation, pts: np.ndarray, valid: np.ndarray, cfg: VerifyConfig) -> list[_Region]:
    """The plane regions of a depth-only segmentation, and its other regions that are planes within the noise
    (the geometric segmenter can label a flat region of its curved phase a cylinder) (module docstring)."""
    out: list[_Region] = []
    is_plane = _is_plane(depth_seg.labels)
    for g in depth_seg.instance_ids():  # loop over depth regions
        m = depth_seg.instances == g
        x = pts[m & valid]
        if len(x) < cfg.region_min_px:
            continue
        n, d = _plane(x, cfg.trim_sigma)
        sigma = cfg.noise_sigma_coeff * float(np.median(x[:, 2])) ** 2
        if is_plane[g] or mad_sigma(x @ n - d) <= cfg.region_sigma * sigma:
            out.append(_Region(m, n, d))
    return out


def _one_surface(
    i: int,
    pieces: list[np.ndarray],
    seg: Segmentation,
    pts: np.ndarray,
    valid: np.ndarray,
    size: float,
    cfg: VerifyConfig,
    ransac: RansacConfig,
    rng: np.random.Generator,
) -> bool:
    """True when one fit of instance ``i``'s label type lies within one_surface_sigma sensor sigmas (median
    distance) of each of its ``pieces`` (bool (H, W) pixel sets inside it): a minority surface shows as a piece
    far off the fit, which a robust residual over the whole instance would hide."""
    inst = seg.instances
    lab = int(seg.labels[i])
    ptype = TYPE_NAMES[int(TYPE_OF_LABEL[lab])] if 1 <= lab <= 17 else "plane"
    if ptype == "plane":
        n, d = _plane(pts[(inst == i) & valid], cfg.trim_sigma)

        def dist(x: np.ndarray) -> np.ndarray:
            return np.abs(x @ n - d)

    else:
        ip = instance_points(pts, valid, inst, np.array([i]), ransac).get(int(i))
        if ip is None or len(ip.points) < 6:
            return True
        got = ransac_fit(ptype, ip.points, ip.normals, size, ransac, rng)
        if got is None:
            return False
        prim = got.primitive

        def dist(x: np.ndarray) -> np.ndarray:
            return np.abs(prim.signed_distance(x))

    for piece in pieces:  # loop over the pieces the regions cover
        x = pts[piece & valid]
        sigma = cfg.noise_sigma_coeff * float(np.median(x[:, 2])) ** 2
        if float(np.median(dist(x))) > cfg.one_surface_sigma * sigma:
            return False
    return True


def split_by_regions(
    seg: Segmentation,
    regions: list[_Region],
    pts: np.ndarray,
    valid: np.ndarray,
    size: float,
    cfg: VerifyConfig,
    ransac: RansacConfig,
) -> Segmentation:
    """``seg`` with each instance that two or more plane regions cover and no one surface explains cut along the
    regions (module docstring)."""
    if len(regions) < 2:
        return seg
    rng = np.random.default_rng(cfg.seed)
    inst = np.array(seg.instances, np.int32)
    labels, scores = list(np.asarray(seg.labels)), list(np.asarray(seg.scores, np.float32))
    is_plane = _is_plane(seg.labels)
    undecided = label_of("plane", "U")
    for i in seg.instance_ids():  # loop over instances
        mi = inst == i
        n_valid = int((mi & valid).sum())
        need = max(cfg.piece_min_px, cfg.piece_min_share * n_valid)
        cover = [(int((mi & valid & r.mask).sum()), k) for k, r in enumerate(regions)]
        pieces = sorted(((c, k) for c, k in cover if c >= need), reverse=True)
        if len(pieces) < 2:
            continue
        masks = [mi & regions[k].mask for _, k in pieces]
        if _one_surface(int(i), masks, seg, pts, valid, size, cfg, ransac, rng):
            continue
        ids = []
        for rank, piece in enumerate(masks):  # loop over the covering regions (disjoint), largest first
            new = len(labels)
            keep = rank == 0 and bool(is_plane[i])
            labels.append(labels[i] if keep else undecided)
            scores.append(scores[i] if keep else np.float32(0.0))
            inst[piece] = new
            ids.append(new)
        rest = inst == i
        if int((rest & valid).sum()) < need:  # a small rest joins the nearest piece
            seeds = np.isin(inst, ids)
            _, near = cv2.distanceTransformWithLabels(
                (~seeds).astype(np.uint8), cv2.DIST_L2, 3, labelType=cv2.DIST_LABEL_PIXEL
            )
            lut = np.zeros(int(near.max()) + 1, np.int32)
            lut[near[seeds]] = inst[seeds]
            inst[rest] = lut[near[rest]]
    return _compact(Segmentation(inst, np.asarray(labels, np.uint8), np.asarray(scores, np.float32), seg.method))


def _compact(seg: Segmentation) -> Segmentation:
    """``seg`` with the ids that cover no pixel dropped and the rest renumbered 1..N in order."""
    keep = np.union1d([0], seg.instance_ids())
    if len(keep) == len(seg.labels):
        return seg
    lut = np.zeros(len(seg.labels), np.int32)
    lut[keep] = np.arange(len(keep), dtype=np.int32)
    return Segmentation(lut[seg.instances], np.asarray(seg.labels)[keep], np.asarray(seg.scores)[keep], seg.method)


def merge_by_regions(
    seg: Segmentation, regions: list[_Region], pts: np.ndarray, valid: np.ndarray, cfg: VerifyConfig
) -> Segmentation:
    """``seg`` with the instances that lie inside one plane region and on its plane merged (module docstring)."""
    inst = seg.instances
    ids = seg.instance_ids()
    sets = UnionFind([int(i) for i in ids])
    is_plane = _is_plane(seg.labels)
    sure_curved = ~is_plane & (np.asarray(seg.scores) >= cfg.merge_curved_score)
    merged = False
    for r in regions:  # loop over plane regions
        inside = np.unique(inst[r.mask])
        members = []
        for i in inside[inside > 0]:  # loop over the instances it touches
            m = (inst == i) & valid
            n_valid = int(m.sum())
            if sure_curved[i] or n_valid < cfg.merge_min_px or (m & r.mask).sum() < cfg.merge_inside_share * n_valid:
                continue
            x = pts[m]
            sigma = cfg.noise_sigma_coeff * float(np.median(x[:, 2])) ** 2
            if float(np.median(np.abs(x @ r.normal - r.offset))) <= cfg.merge_sigma * sigma:
                members.append(int(i))
        for a in members[1:]:
            sets.union(members[0], a)
            merged = True
    if not merged:
        return seg
    groups = [g for g in sets.groups() if len(g) > 1]
    return _relabel(seg, np.asarray(inst, np.int32), groups, is_plane, unkept_label=label_of("plane", "U"))


def needs_regions(seg: Segmentation, depth: np.ndarray, K: np.ndarray, cfg: VerifyConfig = VerifyConfig()) -> bool:
    """True when some plane-labelled instance of ``seg`` with at least 2 x piece_min_px valid pixels has more than
    gate_far_share of its points further than gate_far_sigma sensor sigmas from its own (trimmed) plane: the
    depth regions may split it. Always True with gate_far_share 0."""
    if not cfg.enabled:
        return False
    if cfg.gate_far_share <= 0:
        return True
    pts = backproject(np.asarray(depth, float), np.asarray(K, float))
    valid = np.asarray(depth) > 0
    is_plane = _is_plane(seg.labels)
    for i in seg.instance_ids():  # loop over instances
        if not is_plane[i]:
            continue
        x = pts[(seg.instances == i) & valid]
        if len(x) < 2 * cfg.piece_min_px:
            continue
        n, d = _plane(x, cfg.trim_sigma)
        sigma = cfg.noise_sigma_coeff * x[:, 2] ** 2
        if float(np.mean(np.abs(x @ n - d) > cfg.gate_far_sigma * sigma)) > cfg.gate_far_share:
            return True
    return False


def verify_instances(
    seg: Segmentation,
    depth_seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: VerifyConfig = VerifyConfig(),
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """`split_by_regions`, then `merge_by_regions`, of the learned instances ``seg`` with the plane regions of the
    depth-only segmentation ``depth_seg`` of the same scan (``depth`` metres, intrinsics ``K``)."""
    if not cfg.enabled:
        return seg
    ransac = ransac or RansacConfig()
    valid = (np.asarray(depth) > 0) & (seg.instances > 0)
    if not valid.any():
        return seg
    pts, size = scan_geometry(depth, K, seg.instances, ransac)
    regions = plane_regions(depth_seg, pts, valid, cfg)
    if not regions:
        return seg
    seg = split_by_regions(seg, regions, pts, valid, size, cfg, ransac)
    return merge_by_regions(seg, regions, pts, valid, cfg)
