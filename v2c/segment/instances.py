"""Per-pixel labels + face boundaries -> surface instances (the panoptic step of the learned segmenter).

0. Boundary evidence: the predicted boundary probability, raised (pixel-wise maximum) by optional extra evidence
   from the scan (``feature_evidence``: depth jumps and normal creases from the network's input features; off by
   default, they did not help on the tuning set).
1. Core pixels: part pixels (label != 0) with evidence <= ``boundary_threshold``; seed pixels: core pixels with
   evidence < ``seed_threshold`` (default: the same cut).
2. Markers: connected components (4-connected) of seed pixels sharing one label (a change of arg-max label always
   separates markers). With ``seed_split_px`` > 0 the seeds are eroded by that much first (conditional erosion:
   components that would vanish are kept whole), which cuts necks through gaps of the predicted boundary (off by
   default: it fragments faces more than it separates them).
2b. A face seen edge-on returns no depth and looks like a boundary all across, so the boundary band covers it and
   its markers are specks. Where the band, with one label, is thicker than 2 x ``band_core_px`` + 1 pixels and
   mostly unmeasured (``unmeasured``: no depth reading), its core becomes a marker if it has at least
   ``band_core_min_px`` pixels. A band's half beside its own face is thinner, and a boundary between measured
   faces has depth. On the tuning and validation sets this is neutral within 0.001; it recovers edge-on faces that
   the flooding split between their neighbours.
3. Markers under ``min_area_px`` are dissolved; the other part pixels are flooded from the markers in order of
   evidence (``flood_levels`` thresholds; within a level each pixel joins the nearest marker of its connected
   piece), so a region grows across low evidence first and two markers meet on the ridge of the predicted boundary
   band, not half-way between their cores (which handed thin faces to their neighbours); what is left joins the
   nearest instance within ``max_fill_px``; what is still left forms instances of its own (per label,
   4-connected, at least ``min_area_px``).
3b. A face the boundary band covers whole (a hole's wall under its rim, a narrow step or chamfer: no seed pixel) is
   kept as it is labelled: band pixels of one label that touch no marker of that label and are sure of it
   (``band_marker_px``, ``band_marker_prob``) form an instance that the flooding does not take (tuning set,
   stage-7 weights, 100 scans: face recall 0.808 -> 0.882, precision 0.906 -> 0.908; docs/segmentation.md).
4. Neighbouring instances whose contact is mostly open (core pixels on both sides, i.e. no boundary evidence
   between them) were split by label noise only: they are merged. Two faces separated by a partial boundary have
   a contact that is mostly closed, so they stay apart; so do two instances of different primitive types that are
   both sure of their labels (``merge_same_type``: a hole's wall meets its plane without a predicted boundary).
5. Each instance's label is the arg-max of its mean class probability (background excluded), its score that mean
   probability; without probabilities, the majority label and its share.
Pixel units throughout. Everything runs on the part's bounding box.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from v2c.labels import BACKGROUND, IGNORE, NUM_CLASSES, TYPE_OF_LABEL
from v2c.segment.types import Segmentation


@dataclass(frozen=True)
class InstanceConfig:
    """Thresholds of instance extraction from the network's boundary and label maps (units in the comments)."""

    boundary_threshold: float = 0.25  # boundary probability above which a pixel is on a face boundary
    core_erode_px: int = 0  # core pixels are eroded by this much before the components are taken (pixels)
    min_area_px: int = 50  # markers smaller than this are dissolved into their neighbours (pixels)
    max_fill_px: float = 6.0  # farthest a leftover part pixel is attached to an instance (pixels)
    merge_open_frac: float = 0.5  # merge two instances when this share of their contact is open (no boundary)
    merge_min_contact_px: int = 3  # ... and their contact is at least this long (pixel pairs)
    merge_same_type: bool = True  # ... and their majority labels are of one primitive type (a plane and a
    # cylinder that meet without a predicted boundary stay apart; label noise within a face rarely changes type)
    merge_sure_prob: float = 0.85  # with class probabilities: ... or one of them is unsure, its mean probability
    # of its majority label below this (a patch of label noise; 0 = type alone decides)
    seed_threshold: float = 0.25  # seed (marker) pixels have boundary evidence below this (probability)
    seed_split_px: int = 0  # conditional erosion of the seeds before the markers are taken (pixels)
    flood_levels: tuple[float, ...] = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.85, 0.9, 0.95, 0.98, 1.01)  # evidence
    # thresholds of the flooding from the markers, increasing (empty = the nearest marker only)
    depth_edge_gain: float = 0.0  # extra evidence = depth-edge feature (relative jump x 25) times this
    normal_gain: float = 0.0  # extra evidence = (1 - cos of the normal change over 2 px) times this
    band_marker_px: int = 35  # a face wholly inside the predicted boundary band (a thin wall or step) is an
    # instance of its own: connected band pixels of one label, at least this many, touching no marker of that label
    # (pixels; 0 = off)
    band_core_px: int = 3  # a part of the band thicker than 2 x this + 1 pixels, of one label, is a marker (a face
    # seen edge-on is boundary-like all across; a boundary band's half beside its face is thin) (pixels; 0 = off)
    band_core_min_px: int = 30  # ... when its core (the pixels this far inside it) has at least this many pixels
    band_core_unmeasured: float = 0.7  # ... of which at least this share have no depth reading (fraction; with a
    # depth map: a face seen edge-on returns none, a boundary between two measured faces does)
    band_marker_prob: float = 0.55  # ... and a mean probability of its label at least this (with class
    # probabilities; label noise along a boundary is less sure than a thin face)


def _components_per_label(labels: np.ndarray, core: np.ndarray) -> np.ndarray:
    """(H, W) int32 ids 1..N of 4-connected components of ``core`` pixels with equal labels (raster order)."""
    inst = np.zeros(labels.shape, np.int32)
    nxt = 0
    for lab in np.unique(labels[core]):
        m = (core & (labels == lab)).astype(np.uint8)
        n, cc = cv2.connectedComponents(m, connectivity=4)
        if n > 1:
            sel = cc > 0
            inst[sel] = cc[sel] + nxt
            nxt += n - 1
    return inst


def _relabel_raster(inst: np.ndarray) -> np.ndarray:
    """Ids renumbered 1..N in raster order of first appearance (0 stays 0)."""
    flat = inst.ravel()
    ids, first = np.unique(flat, return_index=True)
    keep = ids > 0
    ids, first = ids[keep], first[keep]
    order = ids[np.argsort(first)]
    lut = np.zeros(int(inst.max()) + 1, np.int32)
    lut[order] = np.arange(1, len(order) + 1, dtype=np.int32)
    return lut[inst]


def _drop_small(inst: np.ndarray, min_area: int) -> np.ndarray:
    area = np.bincount(inst.ravel())
    small = area < min_area
    small[0] = False
    out = inst.copy()
    out[small[inst]] = 0
    return out


def _fill(inst: np.ndarray, part: np.ndarray, max_dist: float) -> np.ndarray:
    """Attach unassigned part pixels to the nearest instance pixel within ``max_dist`` pixels."""
    hole = part & (inst == 0)
    if not hole.any() or not (inst > 0).any():
        return inst
    dist, (iv, iu) = ndimage.distance_transform_edt(inst == 0, return_indices=True)
    out = inst.copy()
    take = hole & (dist <= max_dist)
    out[take] = inst[iv[take], iu[take]]
    return out


def _majority_label(inst: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(max id + 1,) most frequent label of each instance id (index 0 and empty ids: 0)."""
    n = int(inst.max()) + 1
    sel = inst > 0
    lab = np.where(labels[sel] == IGNORE, BACKGROUND, labels[sel]).astype(np.int64)
    votes = np.bincount(inst[sel].astype(np.int64) * NUM_CLASSES + lab, minlength=n * NUM_CLASSES)
    return votes.reshape(n, NUM_CLASSES).argmax(axis=1)


def _mean_prob_of(ids: np.ndarray, label_of_id: np.ndarray, probs: np.ndarray) -> np.ndarray:
    """(len(label_of_id),) mean probability, over each id's pixels of an id map, of that id's label (0 where empty)."""
    sel = ids > 0
    flat = ids[sel].astype(np.int64)
    own = probs.reshape(probs.shape[0], -1)[label_of_id[flat], np.flatnonzero(sel)]
    n = len(label_of_id)
    return np.bincount(flat, weights=own, minlength=n) / np.maximum(np.bincount(flat, minlength=n), 1)


def _merge_open(
    inst: np.ndarray, core: np.ndarray, labels: np.ndarray, probs: np.ndarray | None, cfg: InstanceConfig
) -> np.ndarray:
    """Union instances whose shared border is mostly open (both sides core pixels); with ``merge_same_type``,
    only instances whose majority labels are of one primitive type or of which one is unsure (``merge_sure_prob``,
    probs: (18, H, W) or None)."""
    n = int(inst.max())
    if n < 2:
        return inst
    keys, opens = [], []
    for a, b, ca, cb in (
        (inst[:, :-1], inst[:, 1:], core[:, :-1], core[:, 1:]),
        (inst[:-1, :], inst[1:, :], core[:-1, :], core[1:, :]),
    ):
        m = (a > 0) & (b > 0) & (a != b)
        lo, hi = np.minimum(a[m], b[m]).astype(np.int64), np.maximum(a[m], b[m]).astype(np.int64)
        keys.append(lo * (n + 1) + hi)
        opens.append((ca[m] & cb[m]).astype(np.int64))
    key, op = np.concatenate(keys), np.concatenate(opens)
    if not len(key):
        return inst
    uk, inv = np.unique(key, return_inverse=True)
    contact = np.bincount(inv)
    open_n = np.bincount(inv, weights=op)
    merge = (contact >= cfg.merge_min_contact_px) & (open_n >= cfg.merge_open_frac * contact)
    if cfg.merge_same_type:
        major = _majority_label(inst, labels)
        kind = TYPE_OF_LABEL[major]
        a, b = uk // (n + 1), uk % (n + 1)
        ok = kind[a] == kind[b]
        if probs is not None and cfg.merge_sure_prob > 0:
            sure = _mean_prob_of(inst, major, probs) >= cfg.merge_sure_prob
            ok |= ~(sure[a] & sure[b])
        merge &= ok
    if not merge.any():
        return inst
    parent = np.arange(n + 1)

    def find(x: int) -> int:
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    for k in uk[merge]:
        ra, rb = find(int(k // (n + 1))), find(int(k % (n + 1)))
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([find(i) for i in range(n + 1)])
    return roots[inst].astype(np.int32)


def feature_evidence(feat: np.ndarray, cfg: InstanceConfig) -> np.ndarray | None:
    """(H, W) float32 boundary evidence in [0, 1] from the network input features (``data.compute_features``):
    depth-edge channel x ``depth_edge_gain`` and normal crease x ``normal_gain`` (pixel-wise maximum); None when
    both gains are 0."""
    if cfg.depth_edge_gain <= 0 and cfg.normal_gain <= 0:
        return None
    ev = np.zeros(feat.shape[1:], np.float32)
    if cfg.depth_edge_gain > 0:
        ev = np.maximum(ev, np.asarray(feat[7], np.float32) * cfg.depth_edge_gain)
    if cfg.normal_gain > 0:
        n = np.asarray(feat[3:6], np.float32)
        crease = np.zeros_like(ev)
        # 1 - cos of the angle between the normals one pixel either side, along rows and columns
        crease[:, 1:-1] = 1.0 - (n[:, :, :-2] * n[:, :, 2:]).sum(axis=0)
        crease[1:-1, :] = np.maximum(crease[1:-1, :], 1.0 - (n[:, :-2, :] * n[:, 2:, :]).sum(axis=0))
        crease[np.asarray(feat[8]) > 0.5] = 0.0  # no depth: no normal
        ev = np.maximum(ev, crease * cfg.normal_gain)
    return np.clip(ev, 0.0, 1.0)


def _markers(labels: np.ndarray, seeds: np.ndarray, split_px: int) -> np.ndarray:
    """Per-label 4-connected components of ``seeds``; with ``split_px`` > 0, of the seeds eroded by that much,
    plus every component that the erosion removes entirely (so small faces keep their marker)."""
    whole = _components_per_label(labels, seeds)
    if split_px <= 0:
        return whole
    er = cv2.erode(seeds.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=split_px) > 0
    inst = _components_per_label(labels, er)
    covered = np.zeros(int(whole.max()) + 1, bool)
    covered[whole[er]] = True
    lost = (whole > 0) & ~covered[whole]
    if lost.any():
        inst = np.where(lost, whole + inst.max(), inst)
    return inst.astype(np.int32)


def _band_markers(
    inst: np.ndarray, labels: np.ndarray, part: np.ndarray, probs: np.ndarray | None, cfg: InstanceConfig
) -> np.ndarray:
    """(H, W) int32 instances, numbered above ``inst``'s markers (0 elsewhere), of the faces the boundary band
    covers whole, which the flooding would hand to their neighbours: 4-connected components of one label among
    the part pixels no marker holds, of at least ``band_marker_px`` pixels, that touch no marker of their own label
    (a band half beside its face's marker touches that marker; a thin face between two faces of other labels does
    not), with a mean probability of their label of at least ``band_marker_prob`` (probs: (18, H, W) or None)."""
    band = _components_per_label(labels, part & (inst == 0))
    n = int(band.max())
    if n == 0:
        return band
    area = np.bincount(band.ravel(), minlength=n + 1)
    lab_band, lab_inst = _majority_label(band, labels), _majority_label(inst, labels)  # one label per region
    same = np.zeros(n + 1, bool)  # band component touches a marker of its own label
    for a, b in (
        (band[:, :-1], inst[:, 1:]),
        (band[:, 1:], inst[:, :-1]),
        (band[:-1, :], inst[1:, :]),
        (band[1:, :], inst[:-1, :]),
    ):
        m = (a > 0) & (b > 0)
        ids = a[m]
        same[ids[lab_band[ids] == lab_inst[b[m]]]] = True
    keep = (area >= cfg.band_marker_px) & ~same
    if probs is not None and cfg.band_marker_prob > 0:
        keep &= _mean_prob_of(band, lab_band, probs) >= cfg.band_marker_prob
    keep[0] = False
    return np.where(keep[band], band + int(inst.max()), 0).astype(np.int32)


def _band_cores(
    inst: np.ndarray,
    labels: np.ndarray,
    part: np.ndarray,
    probs: np.ndarray | None,
    unmeasured: np.ndarray,
    cfg: InstanceConfig,
) -> np.ndarray:
    """``inst`` with new markers (numbered above its own) where the part pixels no marker holds are, with one label,
    thicker than 2 x ``band_core_px`` + 1 pixels: the cores (pixels whose disk of that radius holds one band
    component) of at least ``band_core_min_px`` pixels, a mean probability of their label of at least
    ``band_marker_prob`` and at least ``band_core_unmeasured`` of their pixels ``unmeasured`` (no depth reading)."""
    band = _components_per_label(labels, part & (inst == 0)).astype(np.float32)
    if not band.any():
        return inst
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * cfg.band_core_px + 1,) * 2)
    core = (band > 0) & (cv2.erode(band, k, borderValue=0) == band) & (cv2.dilate(band, k) == band)
    cores = _drop_small(_components_per_label(labels, core), cfg.band_core_min_px)
    n = int(cores.max())
    if n == 0:
        return inst
    ok = np.ones(n + 1, bool)
    if probs is not None and cfg.band_marker_prob > 0:
        ok &= _mean_prob_of(cores, _majority_label(cores, labels), probs) >= cfg.band_marker_prob
    ok &= np.bincount(
        cores.ravel(), weights=unmeasured.ravel(), minlength=n + 1
    ) >= cfg.band_core_unmeasured * np.bincount(cores.ravel(), minlength=n + 1)
    ok[0] = False
    cores = np.where(ok[cores], cores, 0)
    return np.where(cores > 0, cores + int(inst.max()), inst).astype(np.int32)


def _flood(inst: np.ndarray, part: np.ndarray, ev: np.ndarray, levels: tuple[float, ...]) -> np.ndarray:
    """Grow the instances over part pixels in order of evidence: for each level, every unassigned part pixel with
    evidence below it joins the nearest instance pixel of its connected piece of (assigned | allowed) pixels."""
    out = inst.copy()
    for t in levels:
        allowed = part & ((out > 0) | (ev < t))
        hole = allowed & (out == 0)
        if not hole.any() or not (out > 0).any():
            continue
        _, cc = cv2.connectedComponents(allowed.astype(np.uint8), connectivity=4)
        _, (iv, iu) = ndimage.distance_transform_edt(out == 0, return_indices=True)
        take = hole & (cc == cc[iv, iu])
        out[take] = out[iv[take], iu[take]]
    return out


def label_instances(inst: np.ndarray, labels: np.ndarray, probs: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """(labels (N+1,) uint8, scores (N+1,) float32) of instances 1..N (index 0 = background: label 0, score 0).

    probs: (18, H, W) class probabilities or None (then majority label and its pixel share).
    """
    n = int(inst.max())
    flat = inst.ravel()
    sel = flat > 0
    idx = flat[sel]
    area = np.bincount(idx, minlength=n + 1).astype(np.float64)
    if probs is not None:
        p = probs.reshape(probs.shape[0], -1)[:, sel].astype(np.float64)
        mean = np.stack([np.bincount(idx, weights=p[c], minlength=n + 1) for c in range(NUM_CLASSES)]).astype(
            np.float64
        )
        mean /= np.maximum(area, 1)[None]
        mean[BACKGROUND] = 0.0
        mean /= np.maximum(mean.sum(axis=0, keepdims=True), 1e-12)
        lab = mean.argmax(axis=0)
        score = mean[lab, np.arange(n + 1)]
    else:
        lv = labels.ravel()[sel].astype(np.int64)
        lv = np.where(lv == IGNORE, 0, lv)
        votes = np.zeros((NUM_CLASSES, n + 1))
        np.add.at(votes, (lv, idx), 1.0)
        votes[BACKGROUND] = 0.0
        lab = votes.argmax(axis=0)
        score = votes[lab, np.arange(n + 1)] / np.maximum(area, 1)
    lab[0], score[0] = 0, 0.0
    return lab.astype(np.uint8), score.astype(np.float32)


def _instances(
    labels: np.ndarray,
    part: np.ndarray,
    ev: np.ndarray,
    probs: np.ndarray | None,
    cfg: InstanceConfig,
    unmeasured: np.ndarray | None = None,
) -> np.ndarray:
    """Steps 1-4 of the module docstring: (H, W) int32 instance ids (not yet renumbered)."""
    core = part & (ev <= cfg.boundary_threshold)
    seeds = core & (ev < cfg.seed_threshold) if cfg.seed_threshold < cfg.boundary_threshold else core
    if cfg.core_erode_px > 0:  # break thin bridges through gaps of the predicted boundary
        seeds = cv2.erode(seeds.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=cfg.core_erode_px) > 0
    inst = _markers(labels, seeds, cfg.seed_split_px)
    inst = _drop_small(inst, cfg.min_area_px)
    if cfg.band_core_px > 0 and unmeasured is not None:
        inst = _band_cores(inst, labels, part, probs, unmeasured, cfg)
    band = _band_markers(inst, labels, part, probs, cfg) if cfg.band_marker_px > 0 else None
    if cfg.flood_levels:
        inst = _flood(inst, part, ev, cfg.flood_levels)
    inst = _fill(inst, part, cfg.max_fill_px)
    if band is not None:
        inst = np.where(band > 0, band, inst)
    # part pixels still unassigned (e.g. a face wholly inside a thick predicted boundary) form their own instances
    left = _drop_small(_components_per_label(labels, part & (inst == 0)), cfg.min_area_px)
    inst = np.where(left > 0, left + inst.max(), inst).astype(np.int32)
    return _merge_open(inst, core, labels, probs, cfg)


def extract_instances(
    labels: np.ndarray,
    boundary: np.ndarray,
    region: np.ndarray | None = None,
    probs: np.ndarray | None = None,
    cfg: InstanceConfig = InstanceConfig(),
    method: str = "learned",
    evidence: np.ndarray | None = None,
    unmeasured: np.ndarray | None = None,
) -> Segmentation:
    """Instances from a per-pixel label map and a face-boundary map.

    labels: (H, W) int 18-class labels (0 = background; 255 treated as background). boundary: (H, W) bool, or
    float probabilities (thresholded at ``boundary_threshold``). region: optional (H, W) bool, pixels allowed to
    be part (mask/ROI). probs: optional (18, H, W) class probabilities for the instance labels and scores.
    evidence: optional (H, W) extra boundary evidence in [0, 1] (``feature_evidence``), combined by maximum.
    unmeasured: optional (H, W) bool pixels without a depth reading (``band_core_unmeasured``).
    """
    labels = np.asarray(labels)
    bnd = np.asarray(boundary)
    ev = bnd.astype(np.float32)  # a bool map is evidence 0 / 1
    if evidence is not None:
        ev = np.maximum(ev, evidence)
    part = (labels != BACKGROUND) & (labels != IGNORE)
    if region is not None:
        part &= region
    inst = np.zeros(labels.shape, np.int32)
    rows, cols = np.nonzero(part.any(axis=1))[0], np.nonzero(part.any(axis=0))[0]
    if len(rows):  # work on the part's bounding box (same result, less image to flood)
        box = (slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1))
        inst[box] = _instances(
            labels[box],
            part[box],
            ev[box],
            None if probs is None else probs[(slice(None), *box)],
            cfg,
            None if unmeasured is None else np.asarray(unmeasured, bool)[box],
        )
    inst = _relabel_raster(inst)
    lab, score = label_instances(inst, labels, probs)
    return Segmentation(instances=inst, labels=lab, scores=score, method=method)
