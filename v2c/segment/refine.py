"""Geometric check of learned instances: split off what a plane instance's own plane cannot explain, split a
cylinder instance at a step of its radius, and merge plane fragments that lie on one plane.

The network's commonest miss is a thin face (a hole's wall, a boss's side, a narrow step) painted with the label of
the plane around it, with no predicted boundary between them (docs/segmentation.md). Depth sees what colour and
label maps miss: the thin face lies off the plane. For every instance labelled plane, a plane is fitted to its
points (RANSAC, then least squares on the inliers); connected sets of valid pixels further from it than the
tolerance become instances of their own, labelled by the network's most probable class there, or join a
neighbouring instance of that label (the rest of the face they belong to). Pixels whose normal turns away from the
plane where the network's most probable class is another count as off the plane too (a narrow chamfer).

Coaxial shaft sections whose radii differ by a few thousandths of the part size meet at a shoulder one or two
pixels wide: no label, colour or predicted boundary separates them. Depth does: for every instance labelled
cylinder, the change point of the residuals of one cylinder fit (ordered along its axis; the peak of the
mean-shift cumulative sum of the residuals clipped at coax_clip_mad robust sigmas) splits the points in two,
one coaxial fit with a radius per side (shared axis line) measures the step, and a step both larger than
coax_step_part and coax_z noise standard errors splits the instance there; each side is tested again, to
coax_max_splits levels.

Real depth errs together over neighbouring pixels (a structured-light or stereo sensor's noise is spatially
correlated, docs/synth.md "Sensor model against real frames"), so n pixels do not hold n independent readings.
Tests that count pixels (the coaxial step's standard error, GRIC in the curvature tests) divide by the *design
effect* of the residuals (`design_effect`: noise_block_px^2 times the variance of their noise_block_px-square
block means over their variance, once their mean over noise_detrend_px squares is taken off; 1 for white noise):
the number of pixels per independent reading.

A real sensor also rounds every crease over its matching window, and the network labels the rounded band a
fillet. A curved-labelled strip between plane instances, wider than that band, whose depth outside it the planes
explain is cut between them along their crease (`split_crease_strips`). Those cuts and absorptions change which
instances touch, so the coplanar merge and the absorption run once more, the merge gated by the sensor's noise
(`remerge`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np
from scipy.optimize import least_squares

from v2c.camera import backproject
from v2c.geometry.config import RansacConfig
from v2c.geometry.points import estimate_part_size, instance_points, mad_sigma, median_depth_sigma
from v2c.geometry.ransac import RansacFit, ransac_fit, refine_primitive
from v2c.geometry.selection import select_type, supported
from v2c.groups import UnionFind
from v2c.labels import TYPE_NAMES, TYPE_OF_LABEL, label_of
from v2c.primitives import Cylinder, Plane
from v2c.primitives.directions import tangent_basis
from v2c.segment.types import Segmentation


@dataclass(frozen=True)
class RefineConfig:
    """Thresholds of the plane-outlier split (units in the comments)."""

    enabled: bool = True
    min_parent_px: int = 80  # plane instances with fewer valid pixels are left alone (pixels)
    tol_part: float = 0.015  # off-plane distance that counts as another surface (part-size units)
    tol_noise: float = 4.0  # ... and at least this many robust residual sigmas of the plane's inliers (ratio)
    min_split_px: int = 60  # smallest split-off set after the opening (pixels)
    open_px: int = 1  # opening radius applied to the outlier mask first (pixels; removes edge speckle)
    min_split_share: float = 0.02  # ... and at least this share of the parent instance (fraction)
    max_split_share: float = 0.5  # ... and at most this share (fraction; a larger set is more likely the face
    # itself, with the plane fitted to what it wrongly took in)
    normal_split_deg: float = 20.0  # with normals: pixels whose normal is this far from the plane's and whose most
    # probable class is not the instance's also count as off the plane (degrees): a narrow chamfer stays within
    # tol_part of the plane it leaves
    coax: bool = True  # split cylinder instances at a radius step (module docstring)
    coax_min_px: int = 300  # cylinder instances with fewer valid pixels are left alone (pixels)
    coax_min_side_px: int = 150  # each side of a split holds at least this many valid pixels (pixels)
    coax_min_side_share: float = 0.1  # ... and this share of the instance (fraction)
    coax_step_part: float = 0.0025  # smallest radius step that splits (part-size units)
    coax_z: float = 15.0  # ... and at least this many standard errors of the two radii's difference (ratio)
    coax_clip_mad: float = 3.0  # residuals clipped at this many robust sigmas before the mean-shift change point
    # (ratio; 0: the median-centred sum)
    coax_fit_points: int = 800  # points of the coaxial two-radius fit (count)
    coax_max_splits: int = 2  # levels of splitting: a split's sides are tested again until this depth (count)
    noise_block_px: int = 0  # side of the square blocks whose mean residual measures how far the depth noise is
    # correlated between neighbouring pixels (pixels; `design_effect`; 0: white noise, every pixel independent).
    # 5 px: the smallest patch of the sensor model's patch-size profile (docs/synth.md), about the correlation
    # length of the real frames' noise (the `structured_light` profile's 3-px blur; off by default: on the real
    # frames it cut the false coaxial splits but moved the cracker box's angle to 83.7 degrees and the tuna can's
    # radius to -7.4 % through the fit, docs/segmentation.md); on the tuning set (40 scans,
    # seed 9600) 9-px blocks also took in the misfit of true radius steps and cut their z below coax_z
    noise_detrend_px: int = 21  # ... after taking off the residuals' local mean over this square (pixels): what
    # varies more slowly (a second radius step, a warp) is misfit, not the pixel-scale correlation of the noise.
    # 21 px: the largest patch of the same profile; without it a shaft of three sections (44/47/50 mm) was not cut
    noise_block_gric: bool = True  # the curvature tests (`_flat`, `_curvature_earned`) weigh the sensor's noise by
    # the design effect of the curved fit's residuals too (GRIC's data term over independent readings)
    merge: bool = True  # merge adjacent plane instances that lie on one plane (fragments of a face)
    merge_angle_deg: float = 5.0  # ... normals within this angle (degrees)
    merge_tol_part: float = 0.01  # ... and each one's points within this median distance of the other's plane
    #                                (part-size units)
    merge_min_px: int = 8  # instances with fewer valid pixels take part with a plane through their points (pixels)
    merge_flat: bool = True  # instances of any label take part in the merge where one plane explains their points
    # within the sensor's noise (printed art cut a box side into pieces the network calls cylinders and cones)
    flat_sigma: float = 1.5  # ... robust residual sigma (1.4826 MAD) of their plane within this many sensor sigmas
    # (ratio) ...
    flat_min_px: int = 30  # ... and at least this many valid pixels (pixels)
    merge_joint: bool = True  # also merge touching flat pieces that one plane fitted to both explains, although
    # their own planes disagree by more than merge_angle_deg (a small piece's own plane is poorly determined on real
    # depth): each piece's points within merge_tol_part of the joint plane (median), joined greedily, best first,
    # the joint plane refitted to each grown group so a chain of pieces cannot bend round a curved surface
    merge_joint_angle_deg: float = 12.0  # ... and each piece's own plane within this angle of the joint plane
    # (degrees)
    merge_joint_excess_sigma: float = 0.0  # ... or, further off than that angle, its points' median distance to the
    # joint plane within this many sensor sigmas of that to their own plane (ratio; 0: the angle alone): the joint
    # plane explains the piece as well within the noise (`_explained_by_one_plane`)
    merge_joint_points: int = 4000  # points of a group its joint plane is fitted to (count; a seeded subsample)
    merge_coax: bool = True  # merge touching cylinder-labelled pieces that one cylinder fitted to both explains
    # (a hole wall or a shaft cut into several instances): each piece's points within merge_tol_part of the joint
    # cylinder (median), joined greedily, best first, refitted to every grown group; before the coaxial step split,
    # which cuts a true radius step apart again
    merge_coax_min_px: int = 30  # pieces with fewer valid pixels are left alone (pixels)
    merge_coax_max_radius: float = 2.0  # the joint radius at most this many times the largest piece's own (ratio;
    # a near-flat union would otherwise pass as a huge cylinder)
    merge_coax_refit: bool = True  # the joint cylinder may also be a member's own cylinder refined by least squares
    # on the union (a RANSAC fit of the union alone missed the real soup can's side: radius 35.4 mm, one piece
    # 1.5 mm off it, where the refined own cylinder gives 33.3 mm and 0.5 mm)
    merge_coax_curved_pairs: bool = True  # with merge_coax_curved: two touching plane- or cone-labelled pieces that
    # both earn a cylinder's curvature join too, measured against the cylinders that earned it (a can's side the
    # network calls a plane and the plane split cut in two); the group becomes a cylinder of no axis class
    merge_coax_any_label: bool = False  # pieces labelled plane or cone take part too, next to a cylinder-labelled one
    # (the network calls strips of narrow hole walls planes); the group keeps a cylinder label
    merge_coax_curved: bool = True  # ... only those that are curved: a cylinder fitted to them is supported by the
    # patch and beats their plane by GRIC with the sensor's noise model (`_curvature_earned`; a can's side the
    # network calls a plane in part; a true plane beside a cylinder stays out)
    absorb: bool = True  # fragments join the touching neighbour whose surface their depth fits (absorb_fragments)
    absorb_max_px: int = 400  # fragments: instances with at most this many valid pixels (pixels) ...
    absorb_max_share: float = 0.5  # ... and at most this share of the neighbour they join (fraction)
    absorb_sigma: float = 1.0  # ... whose points lie within this many sensor sigmas of the neighbour's surface
    # (median of |distance| / sigma(z) over the fragment's points; ratio; 0.674 for points on it with Gaussian noise)
    absorb_ring_px: int = 8  # a plane neighbour's surface is the plane through its pixels this close to the
    # fragment (pixels; local, so a warped or slightly bent side is judged where the fragment is)
    absorb_ring_min_px: int = 30  # fewer such pixels: the plane of the whole neighbour (pixels)
    absorb_min_px: int = 6  # fragments with fewer valid pixels are left alone (pixels)
    absorb_min_valid_share: float = 0.5  # ... and those with depth on less of their pixels (fraction; a face seen
    # edge-on returns little depth, and what it returns lies on its neighbour)
    absorb_island_curved: bool = True  # a curved-labelled fragment enclosed by one instance (touching no other and
    # not the background: an island inside one face) joins it where its depth fits, though it earns its curvature:
    # a blend runs between two faces (a printed spot on a box's top). One on the silhouette may be a blend whose
    # other face is unseen (a can's rim beyond its lid) and stays
    absorb_earned_min_score: float = 0.5  # a curved-labelled fragment keeps its curvature (the earned exemption
    # above) only where the network's score for it is at least this (probability); below, it is judged as any
    # fragment, by its depth against its neighbours' surfaces. 0: every earned fragment stays
    crease: bool = True  # a curved-labelled instance lying along the crease where two or more plane instances meet,
    # whose depth their planes explain outside the sensor's rounding band, is cut between them
    # (`split_crease_strips`): a real sensor's matching window rounds every crease, and the network labels the band
    # a fillet (the real boxes' edges); a fillet the sensor resolves departs from the planes beyond that band
    crease_band_px: float = 4.5  # half-width of the sensor's rounding band about a crease (pixels; half the 9 x 9
    # correlation window of a structured-light or active-stereo sensor; measured on the real frames' box creases:
    # depth off the two planes by more than half a sigma within 4-5 px of the crease line, docs/segmentation.md)
    crease_width_quantile: float = 0.95  # a strip is judged only where this quantile of its pixels' distance to its
    # outline (its half-width) exceeds crease_band_px (fraction): a strip no wider than the band is where depth
    # cannot tell a narrow fillet from the rounding (true fillets of the validation sets), and the label stands
    crease_sigma: float = 1.0  # ... the instance's points outside the band within this many sensor sigmas of the
    # planes' envelope (median of |distance along the ray| / sigma(z); ratio; absorb_sigma's)
    crease_planes: bool = True  # a plane-labelled strip is judged as a curved-labelled one: a plane through the
    # rounded band of a real crease leans halfway between its hosts (the lying sugar box's long edge, labelled an
    # unaligned plane), and a chamfer the sensor resolves departs from the hosts' envelope as a fillet does
    crease_flat_hosts: bool = True  # a curved-labelled instance that `_flat` finds flat hosts a strip too (the real
    # cracker box's printed front, labelled a cylinder, beside the strips along its creases)
    crease_after_verify: bool = True  # in segment_learned, the crease cut once more after the depth-region
    # verification, whose merges make the faces that host the strips
    crease_host_ratio: float = 1.0  # a host plane instance has at least this many times the strip's valid pixels
    # (ratio; 2 kept the real standing sugar box's strip of 1,800 px beside its end face of 3,000 on one seed of four
    # and changed nothing on the validation sets)
    crease_min_angle_deg: float = 20.0  # two hosts' planes meet at least at this angle (degrees; flatter pairs make
    # no crease)
    crease_silhouette: bool = False  # crease_sigma's test leaves out a strip's points within crease_band_px of the
    # silhouette too (pixels of no instance: the background, the mask's edge), where a real sensor's window mixes
    # in the background's depth. Off: it cut true fillets at the silhouette (in-family seed 0 recall 91.84 ->
    # 91.39 %) and on the real frames traded a face per box for a point of the cracker box's coverage
    # (docs/bench.md, session 19)
    remerge: bool = True  # the merge and the fragment absorption once more after the steps that change which
    # instances touch (`remerge`: after the crease cut, and in segment_learned after the depth-region verification)
    remerge_sigma: float = 3.0  # ... that merge only where each piece's points lie within this many sensor sigmas of
    # the other's plane or of the joint plane (median; ratio): merge_tol_part alone joins a step of a few millimetres
    absorb_rounds: int = 3  # absorption repeated on its own result while something joins, at most this many rounds
    # (count): fragments that joined each other are judged again as the larger piece they became
    noise_sigma_coeff: float = 0.0015  # sensor depth sigma = this * z^2 (1/m, z in metres): RansacConfig's, the
    # synthetic `sensor` profile's D4xx model
    hypotheses: int = 64  # RANSAC plane hypotheses per instance (count)
    sample_points: int = 800  # points scoring them (count)
    seed: int = 0


_PLANE = TYPE_NAMES.index("plane")
_CYLINDER = TYPE_NAMES.index("cylinder")


def _is_plane(labels: np.ndarray) -> np.ndarray:
    """(N,) bool: which 18-class labels are planes (any axis class)."""
    return TYPE_OF_LABEL[np.asarray(labels, np.int64)] == _PLANE


def scan_geometry(
    depth: np.ndarray, K: np.ndarray, inst: np.ndarray, ransac: RansacConfig | None = None
) -> tuple[np.ndarray, float]:
    """(H, W, 3) camera-frame points and the part size (metres; `estimate_part_size` with ``ransac.scale_trim``)
    from the valid pixels of the instances: what every step measures distances in. No step moves a pixel into or
    out of the part, so one computation serves them all."""
    ransac = ransac or RansacConfig()
    pts = backproject(np.asarray(depth, float), np.asarray(K, float))
    return pts, estimate_part_size(pts[(np.asarray(depth) > 0) & (np.asarray(inst) > 0)], ransac.scale_trim)


def _step_input(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    on: bool,
    geometry: tuple[np.ndarray, float] | None,
    ransac: RansacConfig | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float] | None:
    """What every step works on: (instance ids (H, W) int32, a copy the step may change; the part's valid pixels;
    the point map; the part size), or None when the step has nothing to do (``on`` is False, no valid pixel).
    geometry: `scan_geometry` when already computed (else computed here with ``ransac``)."""
    inst = np.asarray(seg.instances).astype(np.int32)
    valid = (np.asarray(depth) > 0) & (inst > 0)
    if not on or not valid.any():
        return None
    pts, size = geometry or scan_geometry(depth, K, inst, ransac)
    return inst, valid, pts, size


def refine_instances(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    probs: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    normals: np.ndarray | None = None,
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """`split_plane_outliers`, `merge_coaxial`, `split_coaxial_steps`, `merge_coplanar`, `absorb_fragments`,
    `split_crease_strips`, then `remerge`, on one point map
    (normals: see `split_plane_outliers`; ransac: the instance points, RANSAC and type-selection settings of the
    cylinder and curvature tests, default `RansacConfig()`; a `v2c.fit.FitConfig` is one)."""
    if not cfg.enabled:
        return seg
    ransac = ransac or RansacConfig()
    geometry = scan_geometry(depth, K, seg.instances, ransac)
    seg = split_plane_outliers(seg, depth, K, probs, cfg, geometry, normals)
    seg = merge_coaxial(seg, depth, K, cfg, geometry, ransac)
    seg = split_coaxial_steps(seg, depth, K, cfg, geometry, ransac)
    seg = merge_coplanar(seg, depth, K, cfg, geometry, ransac)
    seg = absorb_fragments(seg, depth, K, cfg, geometry, ransac)
    seg = split_crease_strips(seg, depth, K, cfg, geometry, ransac)
    return remerge(seg, depth, K, cfg, geometry, ransac)


def remerge(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    geometry: tuple[np.ndarray, float] | None = None,
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """`merge_coplanar` with pieces within remerge_sigma sensor sigmas of one plane, then `absorb_fragments`: the
    merge and the absorption once more after a step that changed which instances touch (with remerge; ``seg``
    itself without). A crease strip cut between its planes, a strip absorbed or a piece the depth regions cut off
    leaves two pieces of one face touching that the first merge never compared: a box side in two on real frames."""
    if not cfg.remerge:
        return seg
    seg = merge_coplanar(seg, depth, K, cfg, geometry, ransac, max_sigma=cfg.remerge_sigma)
    return absorb_fragments(seg, depth, K, cfg, geometry, ransac)


def design_effect(
    pixels: np.ndarray, residuals: np.ndarray, shape: tuple[int, int], block_px: int, detrend_px: int = 0
) -> float:
    """Pixels per independent reading of the residuals (metres) at flat pixel indices ``pixels`` of an image of
    ``shape``: block_px^2 times the mean square of their block_px x block_px block means (every block wholly
    inside the pixel set, overlapping) over their mean square, after centring on the median and, with detrend_px
    > block_px, taking off their mean over detrend_px x detrend_px squares (slow misfit); residuals beyond 3
    robust sigmas (flying pixels) leave the set. 1 for white noise, up to block_px^2 for noise constant over a
    block; at least 1, and 1 where block_px < 2 or fewer than 10 blocks fit."""
    if block_px < 2 or len(pixels) < block_px * block_px:
        return 1.0
    r = np.asarray(residuals, float) - float(np.median(residuals))
    spread = 3.0 * mad_sigma(r)
    if spread <= 0:
        return 1.0
    keep = np.abs(r) <= spread  # outliers (flying pixels at a silhouette) leave the blocks they touch out
    r, pixels = r[keep], np.asarray(pixels, np.int64)[keep]
    h, w = shape
    rows, cols = np.divmod(pixels, w)
    r0, c0 = int(rows.min()), int(cols.min())  # work on the pixel set's bounding box
    box = np.zeros((int(rows.max()) - r0 + 1, int(cols.max()) - c0 + 1), np.float64)
    inside = np.zeros(box.shape, np.float64)
    box[rows - r0, cols - c0] = r
    inside[rows - r0, cols - c0] = 1.0
    if detrend_px > block_px:  # the residuals less their local mean: what varies over more than detrend_px
        # pixels (a second radius step, a slow warp) is shape misfit for this count, not pixel-scale noise
        kd = (detrend_px, detrend_px)
        local = cv2.boxFilter(box, -1, kd, normalize=False, borderType=cv2.BORDER_CONSTANT)
        local /= np.maximum(cv2.boxFilter(inside, -1, kd, normalize=False, borderType=cv2.BORDER_CONSTANT), 1.0)
        box = np.where(inside > 0, box - local, 0.0)
        r = box[rows - r0, cols - c0]
    k = (block_px, block_px)
    sums = cv2.boxFilter(box, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    full = cv2.boxFilter(inside, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT) > block_px * block_px - 0.5
    if full.sum() < 10:
        return 1.0
    means = sums[full] / (block_px * block_px)
    return float(np.clip(block_px * block_px * np.mean(means**2) / max(float(np.mean(r**2)), 1e-30), 1.0, block_px**2))


def _plane_ransac(x: np.ndarray, tol: float, cfg: RefineConfig, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """(unit normal, offset) of the plane n.x = d that most points of x (n, 3) lie within tol of."""
    sub = x[rng.choice(len(x), min(len(x), cfg.sample_points), replace=False)]
    tri = sub[rng.integers(0, len(sub), (cfg.hypotheses, 3))]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    n = n[ok] / norm[ok, None]
    d = np.einsum("ij,ij->i", n, tri[ok, 0])
    score = (np.abs(sub @ n.T - d) < tol).sum(axis=0)
    k = int(np.argmax(score))
    return _lsq_plane(x[np.abs(x @ n[k] - d[k]) < tol])


def _lsq_plane(x: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit normal, offset) of the total least-squares plane n.x = d through the points x (n >= 3, 3)."""
    c = x.mean(axis=0)
    nrm = np.linalg.svd(x - c, full_matrices=False)[2][2]
    return nrm, float(nrm @ c)


def _settled_plane(
    x: np.ndarray, nrm: np.ndarray, off: float, tol: float, iterations: int = 5
) -> tuple[np.ndarray, float]:
    """The plane (unit normal, offset) refitted by least squares to the points of x (n, 3) within tol of it, then
    to those within tol of the refit, up to ``iterations`` times: it settles where its inliers stop changing."""
    for _ in range(iterations):  # loop over refits
        inl = np.abs(x @ nrm - off) < tol
        if inl.sum() < 3:
            break
        nrm, off = _lsq_plane(x[inl])
    return nrm, off


def _same_label_neighbour(
    inst: np.ndarray, sel: np.ndarray, parent: int, label: int, labels: list, kernel: np.ndarray
) -> int | None:
    """The instance other than ``parent`` with label ``label`` that shares the longest contact with the pixel set
    ``sel`` (the rest of a face the network cut elsewhere), or None."""
    ring = cv2.dilate(sel.astype(np.uint8), kernel).astype(bool) & ~sel
    ids, counts = np.unique(inst[ring], return_counts=True)
    best, best_n = None, 0
    for j, k in zip(ids.tolist(), counts.tolist(), strict=True):
        if j not in (0, parent) and j < len(labels) and int(labels[j]) == label and k > best_n:
            best, best_n = j, k
    return best


def split_plane_outliers(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    probs: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    geometry: tuple[np.ndarray, float] | None = None,
    normals: np.ndarray | None = None,
) -> Segmentation:
    """``seg`` with the off-plane parts of its plane instances split off (module docstring). depth: (H, W) metres
    (0 = no reading); probs: the network's (18, H, W) class probabilities, which label the new instances;
    geometry: `scan_geometry` of the scan when already computed; normals: (3, H, W) unit surface normals in any
    one frame (the network's input features), for the normal test (normal_split_deg; None: distance only)."""
    prepared = _step_input(seg, depth, K, cfg.enabled, geometry, None)
    if prepared is None:
        return seg
    inst, valid, pts, size = prepared
    labels, scores = list(np.asarray(seg.labels)), list(np.asarray(seg.scores))
    is_plane = _is_plane(seg.labels)
    rng = np.random.default_rng(cfg.seed)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * cfg.open_px + 1,) * 2)
    n0 = len(labels)
    changed = False
    for i in range(1, n0):  # loop over instances
        if not is_plane[i]:
            continue
        m = valid & (inst == i)
        parent_px = int(m.sum())
        if parent_px < cfg.min_parent_px:
            continue
        x = pts[m]
        tol = cfg.tol_part * size
        nrm, off = _plane_ransac(x, 0.5 * tol, cfg, rng)
        r = x @ nrm - off
        inl = np.abs(r) < 0.5 * tol
        sigma = mad_sigma(r[inl]) if inl.any() else 0.0
        off_plane = np.abs(r) > max(tol, cfg.tol_noise * sigma)
        if normals is not None:
            nm = normals[:, m].T
            ref = np.median(nm[inl], axis=0) if inl.any() else np.zeros(3)
            ref /= max(float(np.linalg.norm(ref)), 1e-12)
            off_plane |= (np.abs(nm @ ref) < np.cos(np.deg2rad(cfg.normal_split_deg))) & (
                probs[:, m].argmax(axis=0) != labels[i]
            )
        far = np.zeros(m.shape, np.uint8)
        far[m] = off_plane
        if cfg.open_px > 0:
            far = cv2.morphologyEx(far, cv2.MORPH_OPEN, kernel)
        n_cc, cc, stats, _ = cv2.connectedComponentsWithStats(far, connectivity=8)
        min_px = max(cfg.min_split_px, cfg.min_split_share * parent_px)
        for c in range(1, n_cc):  # loop over outlier components
            if not min_px <= stats[c, cv2.CC_STAT_AREA] <= cfg.max_split_share * parent_px:
                continue
            sel = cc == c
            p = probs[:, sel].mean(axis=1)
            p[0] = 0.0
            new = int(np.argmax(p))
            target = _same_label_neighbour(inst, sel, i, new, labels, kernel)
            if target is None:
                target = len(labels)
                labels.append(new)
                scores.append(float(p[new] / max(p.sum(), 1e-9)))
            inst[sel] = target
            changed = True
    if not changed:
        return seg
    return Segmentation(inst, np.asarray(labels, np.uint8), np.asarray(scores, np.float32), seg.method)


def _coaxial_step(
    x: np.ndarray, side: np.ndarray, cyl: Cylinder, size: float, cfg: RefineConfig, rng: np.random.Generator
) -> tuple[float, float]:
    """(radius step r_side - r_other in part sizes, its size in standard errors) of one coaxial fit of points x
    (n, 3) with a radius per side (bool (n,)): shared axis line (two tilt and two shift parameters about
    ``cyl``'s), soft-l1 distances in part sizes."""
    if len(x) > cfg.coax_fit_points:
        sel = rng.choice(len(x), cfg.coax_fit_points, replace=False)
        x, side = x[sel], side[sel]
    t1, t2 = tangent_basis(cyl.axis)

    def residuals(p: np.ndarray) -> np.ndarray:
        a = cyl.axis + p[0] * t1 + p[1] * t2
        a = a / np.linalg.norm(a)
        v = x - (cyl.origin + size * (p[2] * t1 + p[3] * t2))
        rho = np.linalg.norm(v - np.outer(v @ a, a), axis=1)
        return rho / size - np.where(side, p[5], p[4])

    r0 = cyl.radius / size
    sol = least_squares(residuals, [0.0, 0.0, 0.0, 0.0, r0, r0], loss="soft_l1", f_scale=cfg.coax_step_part)
    sigma = mad_sigma(sol.fun)
    n_small = min(int(side.sum()), int((~side).sum()))
    step = float(sol.x[5] - sol.x[4])
    return step, abs(step) / max(sigma * np.sqrt(2.0 / max(n_small, 1)), 1e-12)


def split_coaxial_steps(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    geometry: tuple[np.ndarray, float] | None = None,
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """``seg`` with each cylinder instance split where its radius steps (module docstring); the new instance keeps
    the label and score. depth: (H, W) metres (0 = no reading); geometry: `scan_geometry` when already computed;
    ransac: the instance points and cylinder RANSAC settings (default `RansacConfig()`)."""
    ransac = ransac or RansacConfig()
    prepared = _step_input(seg, depth, K, cfg.enabled and cfg.coax, geometry, ransac)
    if prepared is None:
        return seg
    inst, valid, pts, size = prepared
    labels, scores = list(np.asarray(seg.labels)), list(np.asarray(seg.scores))
    rng = np.random.default_rng(cfg.seed)
    todo = [(i, 0) for i in range(1, len(labels)) if TYPE_OF_LABEL[int(labels[i])] == _CYLINDER]
    changed = False
    while todo:  # loop over instances (a split's two sides are queued again)
        i, depth_level = todo.pop(0)
        if depth_level >= cfg.coax_max_splits:
            continue
        ip = instance_points(pts, valid, inst, np.array([i]), ransac).get(i)
        if ip is None or len(ip.points) < cfg.coax_min_px:
            continue
        got = ransac_fit("cylinder", ip.points, ip.normals, size, ransac, rng)
        if got is None:
            continue
        cyl = got.primitive
        x = ip.points
        order = np.argsort((x - cyl.origin) @ cyl.axis)
        n = len(x)
        lo = max(cfg.coax_min_side_px, int(np.ceil(cfg.coax_min_side_share * n)))
        if n - 2 * lo < 1:
            continue
        e = cyl.signed_distance(x[order])
        if cfg.coax_clip_mad > 0:  # mean-shift CUSUM of clipped residuals: zero at both ends, peaks at the step
            med = np.median(e)
            spread = cfg.coax_clip_mad * mad_sigma(e - med)
            e = np.clip(e, med - spread, med + spread)
            cusum = np.cumsum(e - e.mean())
        else:
            cusum = np.cumsum(e - np.median(e))
        k = lo + int(np.argmax(np.abs(cusum[lo : n - lo])))  # the change point of the residuals along the axis
        side = np.zeros(n, bool)
        side[order[k:]] = True
        step, z = _coaxial_step(x, side, cyl, size, cfg, rng)
        if abs(step) < cfg.coax_step_part or z < cfg.coax_z:
            continue
        # the standard error counted every pixel as an independent reading: divide by the residuals' design effect
        # (the noise left after a radius per side; real depth errs together over neighbouring pixels)
        r = cyl.signed_distance(x)
        r = r - np.where(side, np.median(r[side]), np.median(r[~side]))
        deff = design_effect(ip.pixels, r, inst.shape, cfg.noise_block_px, cfg.noise_detrend_px)
        if z / np.sqrt(deff) < cfg.coax_z:
            continue
        new = len(labels)
        labels.append(labels[i])
        scores.append(scores[i])
        inst.ravel()[ip.pixels[side]] = new
        todo += [(i, depth_level + 1), (new, depth_level + 1)]
        changed = True
    if not changed:
        return seg
    return Segmentation(inst, np.asarray(labels, np.uint8), np.asarray(scores, np.float32), seg.method)


def _flat(
    i: int,
    x: np.ndarray,
    nrm: np.ndarray,
    off: float,
    labels: np.ndarray,
    size: float,
    cfg: RefineConfig,
    rng: np.random.Generator,
    normals: np.ndarray,
    ransac: RansacConfig,
    where: tuple[np.ndarray, tuple[int, int]] | None = None,
) -> bool:
    """True when instance ``i`` (points ``x``, metres; its plane n.x = off), whose label is not a plane, is flat:
    its plane explains it within flat_sigma sensor sigmas (robust residual sigma), and a fit of its label's type
    does not earn its curvature (`geometry.selection.supported` and GRIC against the plane, with the sensor's
    noise model cfg.noise_sigma_coeff and the other settings of ``ransac``; ``normals`` (N, 3) the points'
    depth-gradient normals; ``where``: the points' flat pixel indices and the image shape, for the design effect
    of the curved fit's residuals, `_gric_config`): a true shallow cone or a wide fillet keeps its own face."""
    sigma = median_depth_sigma(x, cfg.noise_sigma_coeff)
    if mad_sigma(x @ nrm - off) > cfg.flat_sigma * sigma:
        return False
    ptype = TYPE_NAMES[int(TYPE_OF_LABEL[int(labels[i])])]
    if ptype not in ("cylinder", "cone", "sphere", "torus") or len(x) < 6:
        return True
    fit_cfg = replace(ransac, noise_sigma_coeff=cfg.noise_sigma_coeff)
    got = ransac_fit(ptype, x, normals, size, fit_cfg, rng)
    if got is None:
        return True
    if not supported(got.primitive, x[got.inliers] if got.inliers.sum() >= 3 else x, fit_cfg):
        return True
    plane = RansacFit(Plane(off * nrm, nrm), np.ones(len(x), bool), 1.0)
    return select_type({"plane": plane, ptype: got}, x, size, _gric_config(fit_cfg, got.primitive, x, where, cfg)) == (
        "plane"
    )


def _gric_config(
    fit_cfg: RansacConfig,
    prim: object,
    x: np.ndarray,
    where: tuple[np.ndarray, tuple[int, int]] | None,
    cfg: RefineConfig,
) -> RansacConfig:
    """``fit_cfg`` for GRIC (`select_type`) with its sensor sigma (noise_sigma_coeff) times the square root of the
    design effect of the residuals of ``prim`` on points ``x`` (`design_effect`; ``where``: their flat pixel
    indices and the image shape): GRIC's data term then counts independent readings, not pixels. The sagitta test
    (`supported`) keeps the plain sigma: it compares one depth deviation with the noise of a reading, which
    correlation does not change. Unchanged without ``where``, with noise_block_gric off or noise_block_px < 2."""
    if where is None or not cfg.noise_block_gric or cfg.noise_block_px < 2:
        return fit_cfg
    deff = design_effect(where[0], prim.signed_distance(x), where[1], cfg.noise_block_px, cfg.noise_detrend_px)
    return replace(fit_cfg, noise_sigma_coeff=fit_cfg.noise_sigma_coeff * float(np.sqrt(deff)))


def _coplanar_pairs(
    pairs: np.ndarray,
    planes: dict[int, tuple[np.ndarray, float, np.ndarray]],
    tol: float,
    cfg: RefineConfig,
    max_sigma: float = float("inf"),
) -> tuple[list[tuple[int, int]], list[tuple[float, int, int]]]:
    """The touching pairs whose own planes agree (normals within merge_angle_deg, each one's points within ``tol``
    metres of the other's plane, median), and, with merge_joint, the other flat pairs as joint-plane candidates:
    (score, a, b), score = the pair's larger median distance to the other's plane (metres), best first. A pair
    with a piece further than ``max_sigma`` sensor sigmas from the other's plane (median) is neither."""
    cos_min = np.cos(np.deg2rad(cfg.merge_angle_deg))
    agree: list[tuple[int, int]] = []
    joint: list[tuple[float, int, int]] = []
    for a, b in pairs.tolist():  # loop over touching pairs
        if a not in planes or b not in planes:
            continue
        (na, da, xa), (nb, db, xb) = planes[a], planes[b]
        dab, dba = float(np.median(np.abs(xb @ na - da))), float(np.median(np.abs(xa @ nb - db)))
        if np.isfinite(max_sigma) and (
            dab > max_sigma * median_depth_sigma(xb, cfg.noise_sigma_coeff)
            or dba > max_sigma * median_depth_sigma(xa, cfg.noise_sigma_coeff)
        ):
            continue
        if abs(float(na @ nb)) >= cos_min and dab < tol and dba < tol:
            agree.append((a, b))
        elif cfg.merge_joint:
            joint.append((min(dab, dba), a, b))
    return agree, sorted(joint)


def _explained_by_one_plane(
    xs: list[np.ndarray],
    own: list[tuple[np.ndarray, float]],
    tol: float,
    cfg: RefineConfig,
    rng: np.random.Generator,
    max_sigma: float = float("inf"),
) -> bool:
    """True when one plane fitted to the point sets ``xs`` (metres) lies within ``tol`` of each (median distance)
    and within merge_joint_angle_deg of each set's own plane (``own``: (unit normal, offset) per set), or, with
    merge_joint_excess_sigma, explains the set nearly as well as its own plane: its median distance exceeds that
    to the own plane by at most merge_joint_excess_sigma sensor sigmas (noise_sigma_coeff z^2 at the set's median
    depth). A small piece's own plane can tilt far on real depth while the joint plane fits it as well, within the
    noise; a narrow chamfer strip, which the angle test is there for, lies further off the joint plane. Never when
    a set's median distance to the joint plane exceeds ``max_sigma`` sensor sigmas."""
    x = np.concatenate(xs)
    if len(x) > cfg.merge_joint_points:
        x = x[rng.choice(len(x), cfg.merge_joint_points, replace=False)]
    n, d = _plane_ransac(x, 0.5 * tol, cfg, rng)
    cos_min = np.cos(np.deg2rad(cfg.merge_joint_angle_deg))
    for xi, (ni, di) in zip(xs, own, strict=True):  # loop over the pieces
        joint = float(np.median(np.abs(xi @ n - d)))
        if joint >= tol:
            return False
        sigma = median_depth_sigma(xi, cfg.noise_sigma_coeff)
        if joint > max_sigma * sigma:
            return False
        if abs(float(n @ ni)) >= cos_min:
            continue
        if joint - float(np.median(np.abs(xi @ ni - di))) > cfg.merge_joint_excess_sigma * sigma:
            return False
    return True


def _merge_groups(
    pairs: np.ndarray,
    planes: dict[int, tuple[np.ndarray, float, np.ndarray]],
    tol: float,
    cfg: RefineConfig,
    rng: np.random.Generator,
    max_sigma: float = float("inf"),
) -> list[list[int]]:
    """Groups (instance ids, two or more) to merge: the pairs whose own planes agree, joined transitively (as
    always), then with merge_joint the remaining flat pairs best first, each joining two groups only when one
    plane explains every piece of both (`_explained_by_one_plane`); ``max_sigma``: their sensor-sigma gate."""
    agree, joint = _coplanar_pairs(pairs, planes, tol, cfg, max_sigma)
    sets = UnionFind(sorted(planes))
    for a, b in agree:
        sets.union(a, b)
    for _, a, b in joint:  # loop over candidate pairs, best first
        ra, rb = sets.find(a), sets.find(b)
        if ra == rb:
            continue
        members = sets.members((ra, rb))
        if _explained_by_one_plane(
            [planes[i][2] for i in members],
            [(planes[i][0], planes[i][1]) for i in members],
            tol,
            cfg,
            rng,
            max_sigma,
        ):
            sets.union(ra, rb)
    return sets.groups()


def touching_pairs(inst: np.ndarray) -> np.ndarray:
    """(P, 2) int: the pairs (a < b) of instances (ids > 0) that touch (4-neighbour pixel pairs)."""
    pairs = _contacts(inst)
    return pairs[pairs[:, 0] > 0]


def _contacts(inst: np.ndarray) -> np.ndarray:
    """(P, 2) int: the pairs (a < b) of ids, the background's 0 among them, that touch (4-neighbour pixel pairs)."""
    pairs = np.concatenate(
        [np.stack([inst[:, :-1].ravel(), inst[:, 1:].ravel()], 1), np.stack([inst[:-1].ravel(), inst[1:].ravel()], 1)]
    )
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    return np.unique(np.sort(pairs, axis=1), axis=0).reshape(-1, 2)


def _relabel(
    seg: Segmentation,
    inst: np.ndarray,
    groups: list[list[int]],
    keep: np.ndarray,
    unkept_label: int | None = None,
) -> Segmentation:
    """``seg`` with each group of instance ids merged into its largest member among ``keep`` (bool per id; any
    member where none is kept, taking ``unkept_label`` when given), ids renumbered 1..N in order (labels[k] stays
    instance k's); the member's score stands."""
    labels = np.array(seg.labels)
    lut = np.arange(len(labels), dtype=np.int32)
    area = np.bincount(inst.ravel(), minlength=len(labels))
    for ids in groups:
        pool = [j for j in ids if keep[j]] or ids
        root = max(pool, key=lambda j: (area[j], -j))
        if not keep[root] and unkept_label is not None:
            labels[root] = unkept_label
        lut[ids] = root
    roots = np.unique(lut)  # ids 0..N renumbered without the merged ones
    compact = np.zeros(len(labels), np.int32)
    compact[roots] = np.arange(len(roots), dtype=np.int32)
    return Segmentation(compact[lut[inst]], labels[roots], np.asarray(seg.scores)[roots], seg.method)


def _curvature_earned(
    ptype: str,
    x: np.ndarray,
    n: np.ndarray,
    size: float,
    cfg: RefineConfig,
    ransac: RansacConfig,
    rng: np.random.Generator,
    where: tuple[np.ndarray, tuple[int, int]] | None = None,
) -> bool:
    """True when a fit of the curved type ``ptype`` to points ``x`` (metres; normals ``n``) is supported by the
    patch and beats its plane (`_earned_fit`)."""
    return _earned_fit(ptype, x, n, size, cfg, ransac, rng, where) is not None


def _earned_fit(
    ptype: str,
    x: np.ndarray,
    n: np.ndarray,
    size: float,
    cfg: RefineConfig,
    ransac: RansacConfig,
    rng: np.random.Generator,
    where: tuple[np.ndarray, tuple[int, int]] | None = None,
) -> object | None:
    """The fit (primitive) of the curved type ``ptype`` to points ``x`` (metres; normals ``n``) when it is
    supported by the patch (`geometry.selection.supported`: radius against extent, turn, sagitta against the
    sensor's noise) and beats the patch's plane by GRIC with the sensor's noise model
    (`geometry.selection.select_type`, noise_sigma_coeff, weighed by the design effect of the fit's residuals
    where ``where`` gives the points' flat pixel indices and the image shape, `_gric_config`); None for a plane,
    where there are too few points or where the curvature is not earned."""
    if ptype not in ("cylinder", "cone", "sphere", "torus") or len(x) < 6:
        return None
    fit_cfg = replace(ransac, noise_sigma_coeff=cfg.noise_sigma_coeff)
    got = ransac_fit(ptype, x, n, size, fit_cfg, rng)
    if got is None:
        return None
    if not supported(got.primitive, x[got.inliers] if got.inliers.sum() >= 3 else x, fit_cfg):
        return None
    nrm, off = _plane_ransac(x, 0.5 * cfg.tol_part * size, cfg, rng)
    plane = RansacFit(Plane(off * nrm, nrm), np.ones(len(x), bool), 1.0)
    chosen = select_type({"plane": plane, ptype: got}, x, size, _gric_config(fit_cfg, got.primitive, x, where, cfg))
    return got.primitive if chosen == ptype else None


def merge_coaxial(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    geometry: tuple[np.ndarray, float] | None = None,
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """``seg`` with touching cylinder-labelled instances merged where one cylinder explains them (merge_coax): the
    network cut one hole wall or shaft at a highlight, a shadow or a change of axis class. Each piece needs its
    own cylinder fit (`geometry.ransac.ransac_fit` with the settings of ``ransac``); pairs are joined best first
    (the smaller median distance of one piece's points to the other's cylinder), each join only when a cylinder
    fitted to both groups lies within merge_tol_part part sizes of every piece (median) with a radius at most
    merge_coax_max_radius times the largest piece's own. The merged instance keeps its largest piece's label."""
    ransac = ransac or RansacConfig()
    prepared = _step_input(seg, depth, K, cfg.enabled and cfg.merge_coax, geometry, ransac)
    if prepared is None:
        return seg
    inst, valid, pts, size = prepared
    tol = cfg.merge_tol_part * size
    types = TYPE_OF_LABEL[np.asarray(seg.labels, np.int64)]
    is_cyl = types == _CYLINDER
    is_cone = types == TYPE_NAMES.index("cone")
    other = (types == _PLANE) | is_cone
    joins = is_cyl | (other if cfg.merge_coax_any_label or cfg.merge_coax_curved else is_cyl)
    pairs = touching_pairs(inst)
    near_cyl = is_cyl[pairs[:, 0]] | is_cyl[pairs[:, 1]]
    if cfg.merge_coax_curved and cfg.merge_coax_curved_pairs:  # two curved pieces without a cylinder label
        near_cyl |= other[pairs[:, 0]] & other[pairs[:, 1]]
    pairs = pairs[near_cyl & joins[pairs[:, 0]] & joins[pairs[:, 1]]]
    if not len(pairs):
        return seg
    rng = np.random.default_rng(cfg.seed)
    ids = np.unique(pairs)
    got = instance_points(pts, valid, inst, ids, ransac)
    own: dict[int, tuple[np.ndarray, np.ndarray, Cylinder | None]] = {}
    earned: dict[int, Cylinder] = {}  # plane- or cone-labelled pieces: the cylinder that earned their curvature
    for i in ids.tolist():  # loop over candidate instances
        ip = got.get(int(i))
        if ip is None or len(ip.points) < cfg.merge_coax_min_px:
            continue
        if not is_cyl[i]:  # a plane or cone piece: measured against its cylinder neighbours' cylinders only
            if cfg.merge_coax_any_label:
                own[int(i)] = (ip.points, ip.normals, None)
                continue
            curve = _earned_fit(
                "cylinder",
                ip.points,
                ip.normals,
                size,
                cfg,
                ransac,
                np.random.default_rng([cfg.seed, int(i)]),
                (ip.pixels, inst.shape),
            )
            if isinstance(curve, Cylinder):
                own[int(i)] = (ip.points, ip.normals, None)
                earned[int(i)] = curve
            continue
        fit = ransac_fit("cylinder", ip.points, ip.normals, size, ransac, rng)
        if fit is not None and isinstance(fit.primitive, Cylinder):
            own[int(i)] = (ip.points, ip.normals, fit.primitive)

    def references(members: list[int]) -> list[Cylinder]:
        """The cylinders a group is measured against: its cylinder-labelled pieces' own, else (two curved pieces
        without a cylinder label) the ones that earned its pieces' curvature."""
        cyls = [own[i][2] for i in members if own[i][2] is not None]
        return cyls or [earned[i] for i in members if i in earned]

    scored = []
    for a, b in pairs.tolist():  # loop over touching pairs
        if a in own and b in own:
            ref = {p: references([p]) for p in (a, b)}
            d = [float(np.median(np.abs(ref[p][0].signed_distance(own[q][0])))) for p, q in ((a, b), (b, a)) if ref[p]]
            if d:
                scored.append((min(d), a, b))
    sets = UnionFind(sorted(own))
    for _, a, b in sorted(scored):  # loop over candidate pairs, best first
        ra, rb = sets.find(a), sets.find(b)
        if ra == rb:
            continue
        members = sets.members((ra, rb))
        refs = references(members)
        x = np.concatenate([own[i][0] for i in members])
        n = np.concatenate([own[i][1] for i in members])
        if len(x) > cfg.merge_joint_points:
            pick = rng.choice(len(x), cfg.merge_joint_points, replace=False)
            x, n = x[pick], n[pick]
        fit = ransac_fit("cylinder", x, n, size, ransac, rng)
        candidates = [fit.primitive] if fit is not None and isinstance(fit.primitive, Cylinder) else []
        if cfg.merge_coax_refit and not is_cone[members].any():  # the members' own cylinders refined on the
            # union: RANSAC's inlier band (d_inlier part sizes) is too wide to tell a 33-mm from a 35-mm radius on
            # real depth. Not beside a cone-labelled piece: a short true cone (a chamfer, a taper) lies within
            # merge_tol_part of a refined cylinder (tuning set, seed 9600: 4 such merges, 4 true cones)
            candidates += [refine_primitive(c, x, size, ransac) for c in refs]
        r_max = cfg.merge_coax_max_radius * max(c.radius for c in refs)
        if any(
            isinstance(cyl, Cylinder)
            and cyl.radius <= r_max
            and all(float(np.median(np.abs(cyl.signed_distance(own[i][0])))) < tol for i in members)
            for cyl in candidates
        ):
            sets.union(ra, rb)
    merged = sets.groups()
    if not merged:
        return seg
    # a group of curved pieces none of which the network called a cylinder keeps its largest cone-labelled piece's
    # label, else (plane-labelled pieces only) becomes a cylinder of no axis class
    keep = is_cyl.copy()
    for group in merged:
        if not keep[group].any():
            keep[group] = types[group] == TYPE_NAMES.index("cone")
    return _relabel(seg, inst, merged, keep, unkept_label=label_of("cylinder", "U"))


def merge_coplanar(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    geometry: tuple[np.ndarray, float] | None = None,
    ransac: RansacConfig | None = None,
    max_sigma: float = float("inf"),
) -> Segmentation:
    """``seg`` with adjacent plane instances merged where they lie on one plane (normals within merge_angle_deg,
    each one's points within merge_tol_part part sizes of the other's plane, median): the network cut a face where
    it saw a print edge, a shadow or noise, sometimes with two axis classes. With merge_flat, instances of other
    labels take part too where they are flat (`_flat`: their own plane explains them within flat_sigma sensor
    sigmas and their label's type does not earn its curvature; printed art: on real frames the network calls
    pieces of a box side cylinders and cones). The merged instance keeps the
    largest plane-labelled piece's label and score. Only touching instances (4-neighbour pixel pairs). ransac:
    the instance points, RANSAC and type-selection settings of `_flat` (default `RansacConfig()`); max_sigma: no
    piece merges further than this many sensor sigmas (median) from the other's plane or the joint plane (ratio;
    `remerge`'s gate, off by default)."""
    ransac = ransac or RansacConfig()
    prepared = _step_input(seg, depth, K, cfg.enabled and cfg.merge, geometry, ransac)
    if prepared is None:
        return seg
    inst, valid, pts, size = prepared
    tol = cfg.merge_tol_part * size
    labels = np.asarray(seg.labels)
    is_plane = _is_plane(labels)
    pairs = touching_pairs(inst)
    if not cfg.merge_flat:
        pairs = pairs[is_plane[pairs[:, 0]] & is_plane[pairs[:, 1]]]
    if not len(pairs):
        return seg
    rng = np.random.default_rng(cfg.seed)
    planes: dict[int, tuple[np.ndarray, float, np.ndarray]] = {}
    for i in np.unique(pairs):  # loop over candidate instances
        x = pts[valid & (inst == i)]
        if len(x) >= max(cfg.merge_min_px, 3) and (is_plane[i] or len(x) >= cfg.flat_min_px):
            nrm, off = _plane_ransac(x, 0.5 * cfg.tol_part * size, cfg, rng)
            if not is_plane[i]:
                ip = instance_points(pts, valid, inst, np.array([i]), ransac)[int(i)]
                if not _flat(
                    i, ip.points, nrm, off, labels, size, cfg, rng, ip.normals, ransac, (ip.pixels, inst.shape)
                ):
                    continue
            planes[int(i)] = (nrm, off, x)
    groups = _merge_groups(pairs, planes, tol, cfg, rng, max_sigma)
    if not groups:
        return seg
    # the largest plane-labelled piece's label and score stand (the largest piece's where none is a plane: then a
    # merged group of flat pieces is a plane of no axis class, at that piece's score)
    return _relabel(seg, inst, groups, is_plane, unkept_label=label_of("plane", "U"))


def _neighbour_distance(
    frag: np.ndarray,
    g: int,
    inst: np.ndarray,
    valid: np.ndarray,
    pts: np.ndarray,
    size: float,
    labels: np.ndarray,
    cfg: RefineConfig,
    ransac: RansacConfig,
    rng: np.random.Generator,
    surfaces: dict[int, object],
) -> float:
    """Median over the fragment's points (pixels ``frag``, bool (H, W)) of |distance to instance ``g``'s surface|
    in sensor sigmas (noise_sigma_coeff z^2), or inf when ``g`` has no surface. A plane-labelled ``g``: the plane
    through its valid pixels within absorb_ring_px of the fragment (its whole plane below absorb_ring_min_px); a
    curved one: a fit of its label's type to all its points (`geometry.ransac.ransac_fit`, cached in
    ``surfaces``)."""
    x = pts[frag & valid]
    sigma = cfg.noise_sigma_coeff * x[:, 2] ** 2
    ptype = TYPE_NAMES[int(TYPE_OF_LABEL[int(labels[g])])]
    tol = 0.5 * cfg.tol_part * size
    if ptype == "plane":
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * cfg.absorb_ring_px + 1,) * 2)
        ring = cv2.dilate(frag.astype(np.uint8), kernel).astype(bool) & (inst == g) & valid
        if ring.sum() < max(cfg.absorb_ring_min_px, 3):
            ring = (inst == g) & valid
        if ring.sum() < 3:
            return float("inf")
        nrm, off = _plane_ransac(pts[ring], tol, cfg, rng)
        d = np.abs(x @ nrm - off)
    else:
        if g not in surfaces:
            ip = instance_points(pts, valid, inst, np.array([g]), ransac).get(g)
            got = None if ip is None else ransac_fit(ptype, ip.points, ip.normals, size, ransac, rng)
            surfaces[g] = None if got is None else got.primitive
        prim = surfaces[g]
        if prim is None:
            return float("inf")
        d = np.abs(prim.signed_distance(x))
    return float(np.median(d / np.maximum(sigma, 1e-12)))


def absorb_fragments(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    geometry: tuple[np.ndarray, float] | None = None,
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """``seg`` with its fragments (at most absorb_max_px valid pixels, depth on at least absorb_min_valid_share
    of them) joined to the touching, larger instance whose surface their depth fits best, where it fits within
    absorb_sigma sensor sigmas (`_neighbour_distance`): islands of printed art, strips along a box edge, pieces
    of noise that the network gave a label of their own. A fragment off every neighbour's surface (a hole's wall,
    a chamfer, a step: another surface) stays, and so does one whose curved label, at least absorb_earned_min_score
    probable, earns its curvature (`_curvature_earned`: a fillet strip leaves its plane tangentially, within the
    noise at first) unless one instance encloses it (absorb_island_curved: a blend runs between faces, an island
    inside one is not one). Smallest fragments first; the merged instance keeps the largest member's label and
    score; repeated on the result while something joins, at most absorb_rounds times. ransac: the settings of the
    curved neighbours' fits (default `RansacConfig()`)."""
    ransac = ransac or RansacConfig()
    for _ in range(max(cfg.absorb_rounds, 1)):  # loop over rounds, until nothing joins
        out = _absorb_round(seg, depth, K, cfg, geometry, ransac)
        if out is seg:
            break
        seg = out
    return seg


def _absorb_round(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig,
    geometry: tuple[np.ndarray, float] | None,
    ransac: RansacConfig,
) -> Segmentation:
    """One round of `absorb_fragments`: ``seg`` itself when nothing joins."""
    prepared = _step_input(seg, depth, K, cfg.enabled and cfg.absorb, geometry, ransac)
    if prepared is None:
        return seg
    inst, valid, pts, size = prepared
    labels = np.asarray(seg.labels)
    scores = np.asarray(seg.scores)
    n_px = np.bincount(inst[valid].ravel(), minlength=len(labels))
    area = np.bincount(inst.ravel(), minlength=len(labels))
    contacts = _contacts(inst)
    pairs = contacts[contacts[:, 0] > 0]  # `touching_pairs`
    frags = [
        i
        for i in range(1, len(labels))
        if cfg.absorb_min_px <= n_px[i] <= cfg.absorb_max_px and n_px[i] >= cfg.absorb_min_valid_share * area[i]
    ]
    if not frags or not len(pairs):
        return seg
    rng = np.random.default_rng(cfg.seed)
    types = [TYPE_NAMES[int(TYPE_OF_LABEL[int(k)])] for k in labels]
    n_touch = np.bincount(pairs.ravel(), minlength=len(labels))
    on_background = np.zeros(len(labels), bool)  # a pixel 4-adjacent to the background: the silhouette, the mask's
    on_background[contacts[contacts[:, 0] == 0, 1]] = True  # edge or a pixel no instance holds
    curved = {
        i
        for i in frags
        if types[i] != "plane"
        and float(scores[i]) >= cfg.absorb_earned_min_score
        and not (cfg.absorb_island_curved and n_touch[i] <= 1 and not on_background[i])
        and (ip := instance_points(pts, valid, inst, np.array([i]), ransac).get(i)) is not None
        and _curvature_earned(
            types[i],
            ip.points,
            ip.normals,
            size,
            cfg,
            ransac,
            np.random.default_rng([cfg.seed, int(i)]),
            (ip.pixels, inst.shape),
        )
    }
    surfaces: dict[int, object] = {}
    sets = UnionFind(range(1, len(labels)))
    for i in sorted((j for j in frags if j not in curved), key=lambda j: (n_px[j], j)):  # fragments, smallest first
        frag = inst == i
        best, best_d = None, cfg.absorb_sigma
        for g in _hosts(i, pairs, n_px, cfg):  # loop over its neighbours
            d = _neighbour_distance(frag, g, inst, valid, pts, size, labels, cfg, ransac, rng, surfaces)
            if d <= best_d:
                best, best_d = g, d
        if best is not None:
            sets.union(i, best)
    groups = sets.groups()
    if not groups:
        return seg
    return _relabel(seg, inst, groups, np.ones(len(labels), bool))


def _flat_instances(
    inst: np.ndarray,
    valid: np.ndarray,
    pts: np.ndarray,
    size: float,
    labels: np.ndarray,
    n_px: np.ndarray,
    cfg: RefineConfig,
    ransac: RansacConfig,
) -> np.ndarray:
    """(N,) bool: the curved-labelled instances of at least flat_min_px valid pixels that `_flat` finds flat."""
    out = np.zeros(len(labels), bool)
    plane = _is_plane(labels)
    for i in range(1, len(labels)):  # loop over instances
        if plane[i] or n_px[i] < max(cfg.flat_min_px, 3):
            continue
        x = pts[valid & (inst == i)]
        rng = np.random.default_rng([cfg.seed, i, 7])
        nrm, off = _plane_ransac(x, 0.5 * cfg.tol_part * size, cfg, rng)
        ip = instance_points(pts, valid, inst, np.array([i]), ransac)[int(i)]
        out[i] = _flat(i, ip.points, nrm, off, labels, size, cfg, rng, ip.normals, ransac, (ip.pixels, inst.shape))
    return out


def split_crease_strips(
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig = RefineConfig(),
    geometry: tuple[np.ndarray, float] | None = None,
    ransac: RansacConfig | None = None,
) -> Segmentation:
    """``seg`` with each crease strip cut between its host planes: a curved-labelled instance (with crease_planes a
    plane-labelled one too) touching two or more plane-labelled instances (with crease_flat_hosts and ``ransac``,
    the fit settings `_flat` needs, also curved-labelled ones `_flat` finds flat; each with at least
    crease_host_ratio times its valid pixels, their planes meeting at
    crease_min_angle_deg or more) whose depth the hosts' envelope explains (`_crease_hosts`). Each of its pixels
    joins the host whose plane the envelope shows there (with depth or without), so the cut follows the crease.
    Each host's plane is fitted once to all its valid pixels (RANSAC seeded by the seed and the host's id, then
    settled by least-squares refits to its inliers, `_settled_plane`, so a verdict does not hang on the draw)."""
    prepared = _step_input(seg, depth, K, cfg.enabled and cfg.crease, geometry, None)
    if prepared is None:
        return seg
    inst, valid, pts, size = prepared
    labels = np.asarray(seg.labels)
    n_px = np.bincount(inst[valid].ravel(), minlength=len(labels))
    pairs = touching_pairs(inst)
    if not len(pairs):
        return seg
    plane = _is_plane(labels)
    if cfg.crease_flat_hosts and ransac is not None:
        plane = plane | _flat_instances(inst, valid, pts, size, labels, n_px, cfg, ransac)
    tol = 0.5 * cfg.tol_part * size  # the hosts' RANSAC inlier band (metres)
    planes: dict[int, tuple[np.ndarray, float]] = {}
    groups = []
    for i in range(1, len(labels)):  # loop over the curved-labelled instances (and with crease_planes the planes)
        if (plane[i] and not cfg.crease_planes) or n_px[i] < 3:
            continue
        hosts = [
            int(g)
            for g in _neighbours(i, pairs)
            if plane[g] and n_px[g] >= cfg.crease_host_ratio * n_px[i] and n_px[g] >= 3
        ]
        if len(hosts) < 2:
            continue
        for g in hosts:  # loop over the hosts, each plane fitted once
            if g not in planes:
                x = pts[(inst == g) & valid]
                planes[g] = _settled_plane(x, *_plane_ransac(x, tol, cfg, np.random.default_rng([cfg.seed, g])), tol)
        sel = inst == i
        cut = _crease_hosts(sel, hosts, planes, inst, valid, pts, K, cfg)
        if cut is None:
            continue
        inst[sel] = cut
        groups.append([i, int(np.bincount(cut).argmax())])  # the emptied id goes
        n_px = np.bincount(inst[valid].ravel(), minlength=len(labels))  # an emptied strip hosts nothing after
        for g in hosts:  # a host that grew is fitted anew when it hosts again
            planes.pop(g, None)
    if not groups:
        return seg
    return _relabel(seg, inst, groups, np.ones(len(labels), bool))


def _crease_hosts(
    sel: np.ndarray,
    hosts: list[int],
    planes: dict[int, tuple[np.ndarray, float]],
    inst: np.ndarray,
    valid: np.ndarray,
    pts: np.ndarray,
    K: np.ndarray,
    cfg: RefineConfig,
) -> np.ndarray | None:
    """The host of each pixel of the strip ``sel`` ((H, W) bool, one instance; row-major order) where it is a crease
    strip, else None.

    The hosts' planes, seen along each pixel's ray, form an envelope: where they make a convex edge the nearest
    surface is the plane met farthest along the ray, where a concave one the nearest met (the choice that agrees
    with more of the hosts' own pixels). Its switching lines are the creases. The strip is a crease strip when it
    is wider than the band (crease_width_quantile of its pixels farther than crease_band_px from its outline),
    the hosts meet pairwise at crease_min_angle_deg or more somewhere, and its points farther than crease_band_px from
    every crease lie within crease_sigma sensor sigmas of the envelope (median; points within the band are the
    sensor's rounding and are not judged, nor with crease_silhouette those within the band of a pixel of no
    instance, where the window mixes in the background's depth; a strip whose depth lies wholly within the band
    is one)."""
    nrm = np.array([planes[g][0] for g in hosts])
    off = np.array([planes[g][1] for g in hosts])
    if max(np.degrees(np.arccos(min(abs(float(a @ b)), 1.0))) for k, a in enumerate(nrm) for b in nrm[k + 1 :]) < (
        cfg.crease_min_angle_deg
    ):
        return None
    inside = cv2.distanceTransform(np.pad(sel, 1).astype(np.uint8), cv2.DIST_L2, 5)[1:-1, 1:-1][sel]
    if float(np.percentile(inside, cfg.crease_width_quantile * 100.0)) <= cfg.crease_band_px:
        return None  # no wider than the band: the depth cannot tell a fillet from the rounding; the label stands
    ring = cv2.dilate(sel.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=int(4 * cfg.crease_band_px) + 1) > 0
    near = ring & np.isin(inst, hosts) & valid
    ys, xs = np.nonzero(ring)
    y0, y1, x0, x1 = ys.min(), ys.max() + 1, xs.min(), xs.max() + 1
    v, u = np.mgrid[y0:y1, x0:x1]
    rays = np.stack([u, v, np.ones_like(u)], -1).astype(float) @ np.linalg.inv(K).T  # z component 1
    along = rays @ nrm.T  # (h, w, hosts): n . ray
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(np.abs(along) > 1e-9, off / along, np.nan)
    z = np.where(z > 0, z, np.nan)  # a plane behind the camera or parallel to the ray shows nothing there
    if np.isnan(z).all(axis=-1).any():
        return None
    far_z = np.where(np.isnan(z), -np.inf, z).argmax(-1)
    near_z = np.where(np.isnan(z), np.inf, z).argmin(-1)
    own_idx = np.full(far_z.shape, -1)  # the host index of each host pixel
    for k, g in enumerate(hosts):  # loop over the hosts
        own_idx[inst[y0:y1, x0:x1] == g] = k
    box_near = near[y0:y1, x0:x1]
    convex = (far_z == own_idx)[box_near].sum() >= (near_z == own_idx)[box_near].sum()
    side = far_z if convex else near_z  # (h, w): the visible host index
    env = np.take_along_axis(z, side[..., None], -1)[..., 0]
    change = np.zeros(side.shape, bool)
    change[:, 1:] |= side[:, 1:] != side[:, :-1]
    change[1:] |= side[1:] != side[:-1]
    if not change.any():
        return None
    dist = cv2.distanceTransform((~change).astype(np.uint8), cv2.DIST_L2, 5)  # pixels to the nearest crease
    box_sel = sel[y0:y1, x0:x1]
    judged = box_sel & valid[y0:y1, x0:x1] & (dist > cfg.crease_band_px)
    if cfg.crease_silhouette:  # the matching window mixes the part's depth with the background's there too
        judged &= cv2.distanceTransform((inst[y0:y1, x0:x1] != 0).astype(np.uint8), cv2.DIST_L2, 5) > (
            cfg.crease_band_px
        )
    if judged.any():  # (a strip with depth only within the band is all rounding)
        zz = pts[y0:y1, x0:x1, 2][judged]
        sigma = cfg.noise_sigma_coeff * zz**2
        if float(np.median(np.abs(zz - env[judged]) / np.maximum(sigma, 1e-12))) > cfg.crease_sigma:
            return None
    return np.asarray(hosts)[side[box_sel]].astype(np.int32)


def _neighbours(i: int, pairs: np.ndarray) -> np.ndarray:
    """The ids that instance ``i`` touches, sorted, given the touching pairs (P, 2) of `touching_pairs`."""
    return np.unique(np.concatenate([pairs[pairs[:, 0] == i, 1], pairs[pairs[:, 1] == i, 0]]))


def _hosts(i: int, pairs: np.ndarray, n_px: np.ndarray, cfg: RefineConfig) -> list[int]:
    """The touching instances fragment ``i`` may join: larger than it, by at least 1 / absorb_max_share."""
    return [
        g for g in _neighbours(i, pairs).tolist() if n_px[g] > n_px[i] and n_px[i] <= cfg.absorb_max_share * n_px[g]
    ]
