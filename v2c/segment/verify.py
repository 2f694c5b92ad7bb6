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
  says one surface, so a printed edge never splits it. ``merge_sigma`` is 2.5: a real structured-light sensor
  reads printed art a millimetre or two off the board it is printed on (the sugar box's printed pieces lie 1.6-2.2
  sensor sigmas off its side's plane, median), which 1.5 kept apart;
- **printed art labelled curved** (``merge_flat_curved``): a curved-labelled instance the network is fairly sure of
  (score from ``merge_curved_score`` up to ``merge_certain_score``) still joins the region's largest plane-labelled
  member when it is the smaller of the two and the region's plane explains it within the noise: median distance within
  ``merge_sigma`` and robust residual sigma about that median within ``region_sigma`` sensor sigmas (flat, not only
  near), and it holds at least ``flat_min_px`` valid pixels. On the real frames the network calls printed bands on box
  sides cylinders and cones at 0.6-0.7; a true shallow cylinder or fillet has a side that bends away from the plane,
  and a label as certain as ``merge_certain_score`` (the fit stage's ``nested_label_certain``) is not overruled;
- **merge along cylinders** (``merge_cylinders``): the same for the depth's cylinder regions (regions the
  geometric segmenter labels cylinder or cone, not flat within the noise, that one fitted cylinder explains
  within ``region_sigma`` sensor sigmas): instances inside one and on its cylinder become one cylinder-labelled
  instance of score at least ``cylinder_label_score``, so the fit stage fits the cylinder the depth showed (a can's
  side the network cut at its label's bands into cones and tori: the tuna can's side came back as a 5.7 mm
  cylinder beside a cone and four tori). Instances labelled another type at a score of at least
  ``merge_curved_score`` stay out (a knob's torus blend beside its cylinder), and a region holding two cylinders
  the network is sure of merges nothing (a shaft's coaxial sections a small radius step apart).

- **instances no one primitive explains** (``explain_split``, `split_unexplained`, after the rest): an instance
  that no one primitive holds within the noise is cut into the best primitive's inliers and the rest (the curved
  instances the plane regions cannot split: a watering can's body, a boss and the flange it stands on); where
  another type holds more than the label's, around the label's surface (``explain_core_label``: the real tuna can's
  side, which a sphere held together with its rim's inner wall).

A region counts when it holds ``region_min_px`` valid pixels and is labelled a plane, or its own plane explains it
within the noise (robust residual sigma within ``region_sigma`` sensor sigmas). Sensor sigma =
``noise_sigma_coeff`` z^2 (z in metres), the refine step's noise law. The depth regions cost a run of the
geometric segmenter (about 0.5-1 s per scan on 2 cores). `needs_regions` can ask for them only when some
plane-labelled instance is not one plane (more than ``gate_far_share`` of its points beyond ``gate_far_sigma``
sensor sigmas of its own plane); that gate is off by default (``gate_far_share`` 0) since the merges need the
regions too: the upright sugar box's side in 8 pieces, each one plane, never opened it. A split-off piece is
labelled a plane of undecided axis with score 0, so the fit stage searches its type and axis
(`v2c.fit.stage._label_of`); the largest piece of a plane-labelled instance keeps the instance's label and score.
Merged instances keep the largest plane-labelled member's label (`refine._relabel`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import cv2
import numpy as np

from v2c.camera import backproject
from v2c.geometry.config import RansacConfig
from v2c.geometry.points import InstancePoints, instance_points, mad_sigma, median_depth_sigma
from v2c.geometry.ransac import ransac_fit, refine_primitive
from v2c.geometry.selection import NESTED_TYPES, supported
from v2c.groups import UnionFind
from v2c.labels import TYPE_NAMES, TYPE_OF_LABEL, label_of
from v2c.primitives import Cylinder, Primitive
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
    merge_sigma: float = 2.5  # ... and their median distance to its plane within this many sensor sigmas merge
    merge_min_px: int = 8  # instances with fewer valid pixels take no part in the merge (pixels)
    merge_curved_score: float = 0.6  # ... nor curved-labelled ones whose label score is at least this: a curved
    # face the network is sure of that the depth cannot tell from a plane keeps its face (FitConfig.label_score_min)
    noise_sigma_coeff: float = 0.0015  # sensor depth sigma = this * z^2 (1/m, z in metres), as RefineConfig's
    trim_sigma: float = 3.0  # a plane is refitted on the points within this many robust sigmas of the first fit (ratio)
    seed: int = 0  # seeds the curved fits of the one-surface test and of the cylinder regions
    merge_cylinders: bool = True  # also merge the instances inside one cylinder region of the depth and on its
    # cylinder (`merge_by_cylinder_regions`): printed bands cut a can's side into pieces the network calls cones
    # and tori
    merge_flat_curved: bool = True  # an instance labelled curved at merge_curved_score or more still joins a
    # plane region's largest plane-labelled member when the region's plane explains it within the noise (robust
    # sigma about its median within region_sigma, median within merge_sigma) and it is the smaller one
    # (`_flat_curved_pairs`)
    merge_certain_score: float = 0.9  # ... unless its label is at least this probable ([0, 1]; as
    # FitConfig.nested_label_certain: a label that certain is not tested against the simpler type either)
    flat_min_px: int = 150  # ... or it holds fewer valid pixels than this: on a small patch the depth's flatness
    # is no evidence against the label (pixels). Chosen on validation (learned, full; 8 -> 150): in-family seed
    # 9000 lost two true curved strips of 22 and 122 px (a fillet tangent to its plane) and gained a torus of
    # 296 px; the corpus-val split changes on one scan either way
    cylinder_label_score: float = 0.6  # ... and the merged instance, a cylinder label, scores at least this
    # ([0, 1]; FitConfig.label_score_min: a label the fit stage keeps)
    explain_split: bool = True  # split an instance that no one primitive explains (`split_unexplained`)
    explain_min_px: int = 300  # ... instances with fewer valid pixels are left alone (pixels)
    explain_share: float = 0.85  # ... one primitive (its label's type, else the best of every type) that holds
    # this share of its valid points within explain_sigma sensor sigmas + explain_floor_m explains it (fraction)
    explain_sigma: float = 2.5  # ... (sensor sigmas)
    explain_floor_m: float = 0.0005  # ... (metres; the sensor's slow warp bends a face by about this)
    explain_piece_px: int = 60  # a piece the split leaves with fewer valid pixels joins the largest piece (pixels)
    explain_min_part: float = 0.25  # the best primitive must explain at least this share of the instance, so the
    # split is a surface and the rest (fraction)
    explain_depth: int = 2  # pieces are tested again down to this many splits (count)
    explain_core_label: bool = True  # an instance no one primitive explains is cut around its label's surface (the
    # label's type, else the simpler type nested in it: a cone's or a torus's cylinder) where that holds at least
    # explain_min_part of it, not around whichever type holds most: the network names the surface, the depth
    # says it holds more than one
    explain_curved_pieces: bool = True  # in an instance that a curved primitive explains (its patch supporting the
    # curvature), a piece of its outliers that one primitive of its own explains is split off too (`_outlier_pieces`):
    # the curved instances' analogue of the plane instances' off-plane split (`refine`), e.g. the real tuna can's
    # top band, 3-11 mm off its side's cylinder and 15 % of the instance. Validation (learned): in-family seed 9000
    # identical, corpus-val precision / recall identical (one view's alignment 0.0143 -> 0.0135); without the
    # support test a near-flat cylinder over a real box's front gave up printed pieces, and a corpus face was cut
    # in two (74.93 / 55.66 -> 74.69 / 55.54 %); docs/segmentation.md
    gate_far_sigma: float = 3.0  # the depth regions are computed only when some plane-labelled instance has more
    gate_far_share: float = 0.0  # ... than this share of its points further than gate_far_sigma sensor sigmas from
    # its own plane (fraction): the geometric segmenter costs about 0.5-1 s per scan, and a scan whose plane
    # instances are each one plane has nothing to split, but may have pieces to merge; 0 always computes them.
    # Chosen on validation (0.1 -> 0, with merge_sigma 1.5 -> 2.5; learned, full): corpus-val precision / recall
    # 72.7 / 54.4 -> 74.6 / 55.6 %, in-family seed 9000 93.9 / 88.7 -> 94.7 / 89.1 %, segmentation +0.5 s


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


@dataclass(frozen=True)
class _CylinderRegion:
    mask: np.ndarray  # (H, W) bool pixels of the region
    cylinder: Cylinder  # its fitted cylinder (metres)


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
        if is_plane[g] or _within_noise(x, x @ n - d, cfg):
            out.append(_Region(m, n, d))
    return out


def _within_noise(x: np.ndarray, residuals: np.ndarray, cfg: VerifyConfig) -> bool:
    """Whether the robust sigma of ``residuals`` (metres) of points ``x`` is within region_sigma sensor sigmas."""
    return mad_sigma(residuals) <= cfg.region_sigma * median_depth_sigma(x, cfg.noise_sigma_coeff)


def _inside_points(
    inst: np.ndarray, i: int, mask: np.ndarray, pts: np.ndarray, valid: np.ndarray, cfg: VerifyConfig
) -> np.ndarray | None:
    """The valid points of instance ``i`` when it holds at least merge_min_px of them and merge_inside_share lie
    in ``mask`` (a region), else None."""
    m = (inst == i) & valid
    n_valid = int(m.sum())
    if n_valid < cfg.merge_min_px or (m & mask).sum() < cfg.merge_inside_share * n_valid:
        return None
    return pts[m]


def cylinder_regions(
    depth_seg: Segmentation,
    pts: np.ndarray,
    valid: np.ndarray,
    size: float,
    cfg: VerifyConfig,
    ransac: RansacConfig,
) -> list[_CylinderRegion]:
    """The regions of a depth-only segmentation labelled cylinder or cone that are not planes within the noise
    (`plane_regions` takes those), each with a cylinder fitted to its points (RANSAC, then least squares on the
    inliers), where that fit lies within region_sigma sensor sigmas of them (robust residual sigma): a can's
    side, a shaft, a hole's wall, seen by the depth as one curved surface (module docstring)."""
    out: list[_CylinderRegion] = []
    types = TYPE_OF_LABEL[np.asarray(depth_seg.labels, np.int64)]
    curved = {TYPE_NAMES.index("cylinder"), TYPE_NAMES.index("cone")}
    rng = np.random.default_rng(cfg.seed)
    inst = np.asarray(depth_seg.instances)
    for g in depth_seg.instance_ids():  # loop over depth regions
        if int(types[g]) not in curved:
            continue
        m = inst == g
        ip = instance_points(pts, valid, inst, np.array([g]), ransac).get(int(g))
        if ip is None or len(ip.points) < cfg.region_min_px:
            continue
        x = ip.points
        n, d = _plane(x, cfg.trim_sigma)
        if _within_noise(x, x @ n - d, cfg):
            continue  # flat: a plane region
        got = ransac_fit("cylinder", x, ip.normals, size, ransac, rng)
        if got is None or not isinstance(got.primitive, Cylinder):
            continue
        cyl = refine_primitive(got.primitive, x[got.inliers], size, ransac) if got.inliers.sum() >= 6 else got.primitive
        if _within_noise(x, cyl.signed_distance(x), cfg):
            out.append(_CylinderRegion(m, cyl))
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
        if float(np.median(dist(x))) > cfg.one_surface_sigma * median_depth_sigma(x, cfg.noise_sigma_coeff):
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
            _join_nearest(inst, np.isin(inst, ids), rest)
    return _compact(Segmentation(inst, np.asarray(labels, np.uint8), np.asarray(scores, np.float32), seg.method))


def _compact(seg: Segmentation) -> Segmentation:
    """``seg`` with the ids that cover no pixel dropped and the rest renumbered 1..N in order."""
    keep = np.union1d([0], seg.instance_ids())
    if len(keep) == len(seg.labels):
        return seg
    lut = np.zeros(len(seg.labels), np.int32)
    lut[keep] = np.arange(len(keep), dtype=np.int32)
    return Segmentation(lut[seg.instances], np.asarray(seg.labels)[keep], np.asarray(seg.scores)[keep], seg.method)


def _groups_inside(
    seg: Segmentation,
    regions: list[tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]],
    excluded: np.ndarray,
    pts: np.ndarray,
    valid: np.ndarray,
    cfg: VerifyConfig,
    anchors: np.ndarray | None = None,
) -> list[list[int]]:
    """The groups (two or more instance ids) that lie inside one region (``regions``: (pixel mask, |distance| of
    points to its surface)), each member with at least merge_inside_share of its valid pixels inside and its
    median distance within merge_sigma sensor sigmas, ``excluded`` (bool per id) and those under merge_min_px
    valid pixels left out; regions sharing an instance join. ``anchors`` (bool per id): a region whose members
    hold two or more merges none (two faces the network is sure of, which the region spans)."""
    inst = seg.instances
    sets = UnionFind([int(i) for i in seg.instance_ids()])
    for mask, dist in regions:  # loop over regions
        inside = np.unique(inst[mask])
        members = []
        for i in inside[inside > 0]:  # loop over the instances it touches
            x = None if excluded[i] else _inside_points(inst, int(i), mask, pts, valid, cfg)
            if x is None:
                continue
            if float(np.median(dist(x))) <= cfg.merge_sigma * median_depth_sigma(x, cfg.noise_sigma_coeff):
                members.append(int(i))
        if anchors is not None and int(anchors[members].sum()) >= 2:
            continue
        for other in members[1:]:
            sets.union(members[0], other)
    return [g for g in sets.groups() if len(g) > 1]


def _flat_curved_pairs(
    seg: Segmentation,
    regions: list[_Region],
    sure_curved: np.ndarray,
    is_plane: np.ndarray,
    pts: np.ndarray,
    valid: np.ndarray,
    cfg: VerifyConfig,
) -> list[list[int]]:
    """[anchor, curved] pairs: an instance labelled curved at a score of at least merge_curved_score (and under
    merge_certain_score) with at least flat_min_px valid pixels that lies inside a plane region (merge_inside_share
    of its valid pixels) whose plane explains it within the noise (robust residual sigma about their median within
    region_sigma and median distance within merge_sigma sensor sigmas: flat, and off the plane by no more than
    printed art reads off its board), paired with the region's largest plane-labelled member (inside and on the
    plane as in `_groups_inside`) when that member has more valid pixels than it (module docstring: printed art the
    network calls a cylinder)."""
    inst = seg.instances
    scores = np.asarray(seg.scores)
    pairs: list[list[int]] = []
    for r in regions:  # loop over plane regions
        inside = np.unique(inst[r.mask])
        anchor, anchor_px, curved = -1, 0, []
        for i in inside[inside > 0]:  # loop over the instances it touches
            x = _inside_points(inst, int(i), r.mask, pts, valid, cfg)
            if x is None:
                continue
            res = x @ r.normal - r.offset
            if float(np.median(np.abs(res))) > cfg.merge_sigma * median_depth_sigma(x, cfg.noise_sigma_coeff):
                continue
            n_valid = len(x)
            if is_plane[i] and n_valid > anchor_px:
                anchor, anchor_px = int(i), n_valid
            elif (
                sure_curved[i]
                and scores[i] < cfg.merge_certain_score
                and n_valid >= cfg.flat_min_px
                and _within_noise(x, res - np.median(res), cfg)
            ):
                curved.append((int(i), n_valid))
        pairs += [[anchor, i] for i, n in curved if anchor > 0 and n < anchor_px]
    return pairs


def merge_by_regions(
    seg: Segmentation, regions: list[_Region], pts: np.ndarray, valid: np.ndarray, cfg: VerifyConfig
) -> Segmentation:
    """``seg`` with the instances that lie inside one plane region and on its plane merged (module docstring)."""
    is_plane = _is_plane(seg.labels)
    sure_curved = ~is_plane & (np.asarray(seg.scores) >= cfg.merge_curved_score)
    planes = [(r.mask, lambda x, r=r: np.abs(x @ r.normal - r.offset)) for r in regions]
    groups = _groups_inside(seg, planes, sure_curved, pts, valid, cfg)
    if cfg.merge_flat_curved:
        pairs = _flat_curved_pairs(seg, regions, sure_curved, is_plane, pts, valid, cfg)
        if pairs:
            sets = UnionFind([int(i) for i in seg.instance_ids()])
            for g in groups + pairs:  # loop over the groups and pairs: one partition
                for other in g[1:]:
                    sets.union(g[0], other)
            groups = [g for g in sets.groups() if len(g) > 1]
    if not groups:
        return seg
    return _relabel(seg, np.asarray(seg.instances, np.int32), groups, is_plane, unkept_label=label_of("plane", "U"))


def merge_by_cylinder_regions(
    seg: Segmentation, regions: list[_CylinderRegion], pts: np.ndarray, valid: np.ndarray, cfg: VerifyConfig
) -> Segmentation:
    """``seg`` with the instances that lie inside one cylinder region (at least merge_inside_share of their valid
    pixels) and on its cylinder (median distance within merge_sigma sensor sigmas) merged, but for those labelled
    another type at a score of at least merge_curved_score (a plane, a torus blend or a sphere the network is sure
    of keeps its face), and but for regions holding two or more cylinders it is sure of (coaxial sections a small
    radius step apart, which one region spans and `refine.split_coaxial_steps` cut apart); the group keeps its
    largest cylinder-labelled member's label, or becomes a cylinder of undecided axis, at a score of at least
    cylinder_label_score (module docstring)."""
    is_cyl = TYPE_OF_LABEL[np.asarray(seg.labels, np.int64)] == TYPE_NAMES.index("cylinder")
    sure = np.asarray(seg.scores) >= cfg.merge_curved_score
    cylinders = [(r.mask, lambda x, c=r.cylinder: np.abs(c.signed_distance(x))) for r in regions]
    groups = _groups_inside(seg, cylinders, sure & ~is_cyl, pts, valid, cfg, anchors=sure & is_cyl)
    if not groups:
        return seg
    # the depth showed one cylinder that explains every member within the noise: the merged instance is a
    # cylinder at least at cylinder_label_score (the fit stage then fits that type instead of searching for one
    # that also fits the sensor's correlated error, a cone or a torus); the member it merges into keeps its score
    scores = np.array(seg.scores, np.float32)
    members = [i for g in groups for i in g]
    scores[members] = np.maximum(scores[members], cfg.cylinder_label_score)
    seg = Segmentation(seg.instances, seg.labels, scores, seg.method)
    return _relabel(seg, np.asarray(seg.instances, np.int32), groups, is_cyl, unkept_label=label_of("cylinder", "U"))


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
    if regions:
        seg = split_by_regions(seg, regions, pts, valid, size, cfg, ransac)
        seg = merge_by_regions(seg, regions, pts, valid, cfg)
    if cfg.merge_cylinders:
        cylinders = cylinder_regions(depth_seg, pts, valid, size, cfg, ransac)
        if cylinders:
            seg = merge_by_cylinder_regions(seg, cylinders, pts, valid, cfg)
    return seg


def _join_nearest(inst: np.ndarray, seeds: np.ndarray, rest: np.ndarray) -> None:
    """The pixels of ``rest`` take the id (``inst``, (H, W), changed in place) of the nearest pixel of ``seeds``
    ((H, W) bool, not empty)."""
    _, near = cv2.distanceTransformWithLabels((~seeds).astype(np.uint8), cv2.DIST_L2, 3, labelType=cv2.DIST_LABEL_PIXEL)
    lut = np.zeros(int(near.max()) + 1, np.int32)
    lut[near[seeds]] = inst[seeds]
    inst[rest] = lut[near[rest]]


#: The types `split_unexplained` tries, in this order after an instance's own label's.
_TYPES = ("plane", "cylinder", "cone", "sphere", "torus")


def _explaining_fit(
    types: list[str] | tuple[str, ...],
    x: np.ndarray,
    normals: np.ndarray,
    tol: np.ndarray,
    size: float,
    tight: RansacConfig,
    rng: np.random.Generator,
    share: float,
) -> tuple[str | None, np.ndarray, Primitive | None]:
    """(type, inliers, primitive) of the fit that holds most of the points ``x`` within their tolerance ``tol``: a
    RANSAC (band ``tight``) of each of ``types`` in turn, stopping at the first that holds ``share`` of them;
    (None, no inliers, None) when no type fits."""
    best_type, best_in, best_prim = None, np.zeros(len(x), bool), None
    for t in types:
        got = ransac_fit(t, x, normals, size, tight, rng)
        if got is None:
            continue
        inl = np.abs(got.primitive.signed_distance(x)) < tol
        if inl.sum() > best_in.sum():
            best_type, best_in, best_prim = t, inl, got.primitive
        if best_in.mean() >= share:
            break
    return best_type, best_in, best_prim


def _outlier_pieces(
    shape: tuple[int, int],
    ip: InstancePoints,
    x: np.ndarray,
    outliers: np.ndarray,
    tol: np.ndarray,
    size: float,
    tight: RansacConfig,
    cfg: VerifyConfig,
    rng: np.random.Generator,
) -> list[np.ndarray]:
    """(H, W) bool masks of the pieces of an instance's ``outliers`` (of its points ``x``, pixels ``ip.pixels``)
    that are surfaces of their own: each 4-connected piece after a 3 x 3 opening, with at least
    ``explain_piece_px`` valid pixels, that one primitive (plane, cylinder, cone, sphere or torus; `_explaining_fit`)
    holds in ``explain_share`` of its points within their tolerance ``tol``."""
    h, w = shape
    out = np.zeros(h * w, np.uint8)
    out[ip.pixels[outliers]] = 1
    out = cv2.morphologyEx(out.reshape(h, w), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, comp = cv2.connectedComponents(out, connectivity=4)
    where = np.full(h * w, -1, np.int64)
    where[ip.pixels] = np.arange(len(ip.pixels))
    pieces = []
    for k in range(1, n):  # loop over the outliers' pieces
        piece = comp == k
        idx = where[piece.ravel()]
        idx = idx[idx >= 0]
        if len(idx) < cfg.explain_piece_px:
            continue
        inl = _explaining_fit(_TYPES, x[idx], ip.normals[idx], tol[idx], size, tight, rng, cfg.explain_share)[1]
        if inl.mean() >= cfg.explain_share:
            pieces.append(piece)
    return pieces


def split_unexplained(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: VerifyConfig = VerifyConfig(),
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """Instances that no one primitive explains are split (issue 15 item 4, "an instance whose residuals show two
    surfaces is split"). An instance of at least ``explain_min_px`` valid pixels is explained when one primitive
    holds ``explain_share`` of its points within ``explain_sigma`` sensor sigmas + ``explain_floor_m``: first its
    label's type, else the best of every type, each a RANSAC whose inlier band is that tolerance (the fit stage's
    band, 3 % of the part, holds two surfaces a few millimetres apart). Otherwise the best primitive's inliers
    (their largest 4-connected piece after a 1-px opening) become one instance and what is left another (each
    4-connected piece of at least ``explain_piece_px`` valid pixels its own; smaller ones and the pixels without
    depth join the nearest piece); with ``explain_core_label``, where the best type is not the label's, the inliers
    of the label's type (or of the type nested in it) instead, when they hold at least ``explain_min_part``: the
    network names the surface. The pieces left are tested again, down to ``explain_depth`` splits. The first
    piece keeps the label when its type is the label's (and the cut was not made along the label's surface for
    that reason); the others are undecided planes of score 0, so the fit stage searches their type. With
    ``explain_curved_pieces``, an instance that a curved primitive explains, whose patch supports that curvature
    (`geometry.selection.supported`: not a near-flat cylinder over a box's side), gives up each piece of its
    outliers that one primitive of its own explains (`_outlier_pieces`), as such a piece too (plane instances have
    the off-plane split of `refine` for that)."""
    if not cfg.explain_split:
        return seg
    ransac = ransac or RansacConfig()
    inst = np.asarray(seg.instances).astype(np.int32).copy()
    valid = (np.asarray(depth) > 0) & (inst > 0)
    if not valid.any():
        return seg
    pts, size = scan_geometry(depth, K, inst, ransac)
    if not size > 0:
        return seg
    labels, scores = list(np.asarray(seg.labels)), list(np.asarray(seg.scores, np.float32))
    undecided = label_of("plane", "U")
    todo = [(int(i), 0) for i in seg.instance_ids()]
    changed = False
    while todo:
        i, level = todo.pop(0)
        m = (inst == i) & valid
        if int(m.sum()) < cfg.explain_min_px or level >= cfg.explain_depth:
            continue
        ip = instance_points(pts, m, inst, np.array([i]), ransac).get(i)
        if ip is None:
            continue
        x = ip.points
        tol = cfg.explain_sigma * cfg.noise_sigma_coeff * x[:, 2] ** 2 + cfg.explain_floor_m
        tight = replace(ransac, d_inlier=float(np.median(tol)) / size)
        lab = int(labels[i])  # every id here is one of labels' (the pieces' are appended as they are made)
        own = TYPE_NAMES[int(TYPE_OF_LABEL[lab])] if 1 <= lab <= 17 else None
        rng = np.random.default_rng([cfg.seed, i, level])
        types = ([own] if own else []) + [u for u in _TYPES if u != own]
        best_type, best_in, best_prim = _explaining_fit(types, x, ip.normals, tol, size, tight, rng, cfg.explain_share)
        explained = best_in.mean() >= cfg.explain_share
        by_label = False  # the cut follows the label's surface, not the type holding most (explain_core_label)
        if not explained and cfg.explain_core_label and own is not None and best_type not in (own, None):
            family = [own, *NESTED_TYPES.get(own, ())]
            rng_label = np.random.default_rng([cfg.seed, i, level, 1])
            got = _explaining_fit(family, x, ip.normals, tol, size, tight, rng_label, cfg.explain_share)
            if got[0] is not None and got[1].mean() >= cfg.explain_min_part:
                best_type, best_in, best_prim = got
                by_label = True
        if (
            explained
            and cfg.explain_curved_pieces
            and best_type not in (None, "plane")
            and supported(best_prim, x[best_in], ransac)
        ):
            for piece in _outlier_pieces(inst.shape, ip, x, ~best_in, tol, size, tight, cfg, rng):
                changed = True
                inst[piece] = len(labels)
                labels.append(undecided)
                scores.append(np.float32(0.0))
            continue
        if best_type is None or explained or best_in.mean() < cfg.explain_min_part:
            continue
        h, w = inst.shape
        core = np.zeros(h * w, np.uint8)
        core[ip.pixels[best_in]] = 1
        core = cv2.morphologyEx(core.reshape(h, w), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
        n, comp = cv2.connectedComponents(core, connectivity=4)
        if n <= 1:
            continue
        sizes = np.bincount(comp[m], minlength=n)
        sizes[0] = 0
        first = (comp == int(np.argmax(sizes))) & m
        rest = m & ~first
        n2, comp2 = cv2.connectedComponents(rest.astype(np.uint8), connectivity=4)
        pieces = [comp2 == k for k in range(1, n2) if int(np.count_nonzero(comp2 == k)) >= cfg.explain_piece_px]
        if not pieces:
            continue
        changed = True
        keep = best_type == own and not by_label  # a cut along the label's surface still leaves its type to the fit
        whole = inst == i  # every pixel of the instance, with or without depth
        inst[whole] = 0
        inst[first] = i
        if not keep:
            labels[i], scores[i] = undecided, np.float32(0.0)
        for piece in pieces:
            inst[piece] = len(labels)
            labels.append(undecided)
            scores.append(np.float32(0.0))
            todo.append((len(labels) - 1, level + 1))
        # the small pieces and the pixels without depth join the nearest of the instance's pieces
        left = whole & (inst == 0)
        if left.any():
            _join_nearest(inst, whole & (inst > 0), left)
    if not changed:
        return seg
    return Segmentation(inst, np.asarray(labels, np.uint8), np.asarray(scores, np.float32), seg.method)
