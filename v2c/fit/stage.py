"""`fit_scan`: the whole geometry optimisation stage on one scan (RANSAC per instance -> frame -> aligned joint
fit -> two rounds of intersection refinement), following the paper's "Geometry Optimization" section."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Set as AbstractSet
from dataclasses import dataclass, field, replace
from itertools import permutations
from time import perf_counter, process_time
from typing import TYPE_CHECKING

import numpy as np

from v2c.camera import backproject, pixel_rays_closed_form
from v2c.fit.align import AXIS_NAMES, align_fit, frame_from_axes, init_frame, orient_frame
from v2c.fit.config import FitConfig
from v2c.fit.constrained import fit_with_axis, start_with_axis
from v2c.fit.intersect import boundary_points, init_depths, refine_intersections
from v2c.fit.result import ABLATIONS, FitResult
from v2c.fit.tangency import adjacent_terms, constrain_blends, tangent_junctions
from v2c.geometry.points import InstancePoints, estimate_part_size, instance_points, mad_sigma
from v2c.geometry.ransac import RansacFit, cone_ok, inlier_mask, plausible, ransac_fit, refine_primitive, torus_ok
from v2c.geometry.residuals import Term
from v2c.geometry.selection import (
    NESTED_TYPES,
    fit_instance,
    noise_sigma,
    radius_supported,
    select_type,
    supported,
)
from v2c.labels import AxisClass, PrimitiveType, type_axis_of
from v2c.primitives import Cylinder, Plane, Primitive, Torus
from v2c.primitives.directions import unit
from v2c.segment.graph import build_edge_graph
from v2c.segment.types import Segmentation

if TYPE_CHECKING:
    from v2c.scan import Scan

log = logging.getLogger(__name__)


def _typed_label(seg: Segmentation, i: int) -> tuple[PrimitiveType, AxisClass | None] | None:
    """Instance ``i``'s label as (primitive type, axis class), or None for background or no label."""
    lab = int(seg.labels[i]) if i < len(seg.labels) else 0
    return type_axis_of(lab) if 1 <= lab <= 17 else None


def _label_of(seg: Segmentation, i: int, config: FitConfig) -> tuple[str | None, int | None | str]:
    """(type, or None for a type search; wanted axis: 0/1/2 frame axis, -1 unaligned, None sphere, "?" decide
    later). A weak label (score < label_score_min) still lends its axis class X/Y/Z: segmenters estimate the
    part frame from the scene (the ground), which names axes better than the fit alone can."""
    score = float(seg.scores[i]) if i < len(seg.scores) else 0.0
    typed = _typed_label(seg, i)
    if typed is None:
        return None, "?"
    ptype, ax = typed
    k = None if ax is None else {"X": 0, "Y": 1, "Z": 2, "U": -1}[ax.value]
    if score < config.label_score_min:
        return None, k if k is not None and k >= 0 else "?"
    return ptype.value, k


def _same_axis_meaning(seg: Segmentation, i: int, got_type: str) -> bool:
    """Whether instance ``i``'s label's axis class means the axis of ``got_type``, the type its type search found:
    a plane's class names its normal, a cylinder's, cone's or torus's its axis of revolution. A weak "plane X"
    label whose points a curved type fits better (a bowed box side, a printed band) says nothing of that curved
    type's axis, which lies across X; held on X, a near-flat torus of the real lying sugar box kept its inlier
    count on a loose band but came out 26-49 mm off its points."""
    typed = _typed_label(seg, i)
    return typed is not None and (typed[0].value == "plane") == (got_type == "plane")


def _inliers(prim: Primitive, ip: InstancePoints, scale: float, config: FitConfig) -> np.ndarray:
    """(n,) bool inliers of an instance: distance and normal test; where no point passes (tiny patches with
    poor normals), the distance test alone; where none passes that either, every point."""
    eps = config.d_inlier * scale
    m = inlier_mask(prim, ip.points, ip.normals, eps, float(np.cos(np.deg2rad(config.normal_angle_deg))))
    if not m.any():
        m = inlier_mask(prim, ip.points, ip.normals, eps, -1.0)
    return m if m.any() else np.ones(len(ip.points), bool)


def _canonical(prim: Primitive, x: np.ndarray) -> Primitive:
    """Same surface, origin moved next to the data (plane: centroid projected; cylinder: onto the axis) and plane
    normal facing the camera."""
    c = x.mean(axis=0)
    if isinstance(prim, Plane):
        n = prim.normal_vec if prim.normal_vec @ prim.origin <= 0 else -prim.normal_vec
        return Plane(c - ((c - prim.origin) @ n) * n, n)
    if isinstance(prim, Cylinder):
        return Cylinder(prim.origin + ((c - prim.origin) @ prim.axis) * prim.axis, prim.axis, prim.radius)
    return prim


def _assign_axes(
    fits: dict[int, Primitive],
    want: dict[int, int | None | str],
    weights: dict[int, float],
    ipts: dict[int, InstancePoints],
    view_dir: np.ndarray,
    scale: float,
    config: FitConfig,
    consensus: bool = False,
) -> tuple[np.ndarray, dict[int, int | None], dict[int, Primitive]]:
    """Initial frame from the labelled axes, then each instance's final axis index (0/1/2, -1 free, None none).

    A label is tested, not trusted blindly: the instance is refitted with its axis held on the frame axis
    (`constrained.fit_with_axis`); the label stands if that fit keeps label_keep_ratio of the free fit's inliers
    (a small patch's free RANSAC axis can be far off while the labelled axis fits it just as well). Otherwise the
    other frame axes are tried the same way, else the axis stays free. Type-searched (weak label) instances try
    the frame axis nearest their own when it is within snap_deg. Returns (frame, axis indices, primitives, with
    the constrained refits in place).

    consensus: the frame may instead be the consensus of every instance's axis, labelled or not (`frame_from_axes`
    within frame_outlier_deg, its axes named by the labels, `_named_by_labels`): it is taken where it holds more
    of the instances than the labels' frame does (`_frame_support`: the total weight of the instances whose axis
    lies within frame_outlier_deg of one of its axes; the labels' frame on a tie)."""
    lab_ids = [i for i in fits if isinstance(want[i], int) and want[i] >= 0]
    frame = init_frame(
        [fits[i].axis_vector for i in lab_ids],
        [want[i] for i in lab_ids],
        [weights[i] for i in lab_ids],
        view_dir,
        config.frame_outlier_deg,
    )
    if consensus or not lab_ids:  # (no confident axis label: a frame from the type-searched axes themselves)
        ids = [i for i in fits if (consensus or want[i] == "?") and fits[i].axis_vector is not None]
        found = frame_from_axes(
            [fits[i].axis_vector for i in ids],
            [weights[i] for i in ids],
            view_dir,
            config.frame_outlier_deg if consensus else config.snap_deg,
        )
        if found is not None and consensus and lab_ids:  # the labels name the consensus axes
            found = _named_by_labels(found, [(fits[i].axis_vector, want[i], weights[i]) for i in lab_ids], view_dir)
            if _frame_support(found, fits, weights, config) <= _frame_support(frame, fits, weights, config):
                found = frame
        frame = frame if found is None else found
    eps = config.d_inlier * scale
    out: dict[int, int | None] = {}
    prims = dict(fits)
    for i, p in fits.items():  # loop over instances
        a = p.axis_vector
        w = want[i]
        if a is None:
            out[i] = None
            continue
        out[i] = -1
        cos = np.abs(frame @ a)
        if w == "?":
            k = int(np.argmax(cos))
            tries = [k] if cos[k] > np.cos(np.deg2rad(config.snap_deg)) else []
        elif w is None or w < 0:
            tries = []
        else:
            tries = [w] + [k for k in np.argsort(-cos) if k != w]
        ip = ipts[i]
        x, n = ip.points, ip.normals
        if len(x) > config.refine_points:
            sel = np.random.default_rng([config.seed, i, 2]).choice(len(x), config.refine_points, replace=False)
            x, n = x[sel], n[sel]
        # distance-only inliers: on small patches the depth-gradient normals are too poor to judge a label
        free = np.count_nonzero(inlier_mask(p, x, n, eps, -1.0))
        for k in tries:
            ax = frame[k] * (np.sign(a @ frame[k]) or 1.0)
            q = fit_with_axis(p, x, n, ax, scale, config)
            if np.count_nonzero(inlier_mask(q, x, n, eps, -1.0)) >= config.label_keep_ratio * free:
                out[i], prims[i] = int(k), _canonical(q, x)
                break
    return frame, out, prims


def _frame_support(
    frame: np.ndarray, fits: dict[int, Primitive], weights: dict[int, float], config: FitConfig
) -> float:
    """The total weight of the instances whose axis lies within frame_outlier_deg of one of ``frame``'s axes."""
    cos = np.cos(np.deg2rad(config.frame_outlier_deg))
    return float(
        sum(
            weights[i]
            for i, p in fits.items()
            if p.axis_vector is not None and np.max(np.abs(frame @ unit(p.axis_vector))) >= cos
        )
    )


def _named_by_labels(frame: np.ndarray, labelled: list, view_dir: np.ndarray) -> np.ndarray:
    """``frame``'s rows reordered so that each labelled axis class (X, Y, Z) names the row its instances' axes
    lie along, by the largest total weight over the six orderings (``labelled``: (axis, class 0/1/2, weight)),
    then oriented as SCAN_FORMAT.md says (`orient_frame`)."""

    def support(order: tuple[int, ...]) -> float:
        return sum(w * abs(float(frame[order[k]] @ a)) for a, k, w in labelled)

    best = max(permutations(range(3)), key=support)
    r = frame[list(best)].copy()
    if np.linalg.det(r) < 0:
        r[0] *= -1
    return orient_frame(r, view_dir)


@dataclass
class _Fits:
    """RANSAC results per instance: primitive, wanted axis (see `_label_of`), inlier count weight, inlier mask."""

    prims: dict[int, Primitive] = field(default_factory=dict)
    want: dict[int, int | None | str] = field(default_factory=dict)
    weights: dict[int, float] = field(default_factory=dict)
    inliers: dict[int, np.ndarray] = field(default_factory=dict)
    searched: list[int] = field(default_factory=list)
    scores: dict[int, float] = field(default_factory=dict)  # label confidence of each instance ([0, 1])


def _rays_hit_share(prim: Primitive, rays: np.ndarray, x: np.ndarray, config: FitConfig) -> float:
    """The share of the camera ``rays`` (N, 3; z = 1) that meet ``prim`` within the depth range of its points
    ``x`` (widened by half that range): the smallest |signed distance| over ray_hit_samples depths along each ray
    within ray_hit_sigma depth-noise sigmas, or within half a sample step along the ray."""
    if not len(rays) or len(x) < 3:
        return 1.0
    zlo, zhi = float(x[:, 2].min()), float(x[:, 2].max())
    pad = 0.5 * max(zhi - zlo, 1e-3)
    z = np.linspace(max(zlo - pad, 1e-3), zhi + pad, config.ray_hit_samples)
    step = float(z[1] - z[0])
    sigma = float(np.median(noise_sigma(x, config)))
    pts = rays[:, None, :] * z[None, :, None]
    d = np.abs(prim.signed_distance(pts.reshape(-1, 3))).reshape(len(rays), len(z))
    tol = max(config.ray_hit_sigma * sigma, 0.5 * step * float(np.median(np.linalg.norm(rays, axis=1))))
    return float(np.mean(np.nanmin(d, axis=1) <= tol))


def _seen_by_its_pixels(
    prim: Primitive, inst: np.ndarray, i: int, ip: InstancePoints, K: np.ndarray | None, config: FitConfig
) -> bool:
    """Whether the camera rays of instance ``i``'s pixels (of the instance map ``inst``; at most ray_hit_max_px,
    a seeded sample) hit ``prim`` in at least ray_hit_min_share of cases (`_rays_hit_share`); True when the test is
    off (ray_hit_min_share 0) or without intrinsics ``K``."""
    if K is None or config.ray_hit_min_share <= 0:
        return True
    vv, uu = np.nonzero(inst == i)
    if len(vv) > config.ray_hit_max_px:
        pick = np.random.default_rng([config.seed, i, 4]).choice(len(vv), config.ray_hit_max_px, replace=False)
        vv, uu = vv[pick], uu[pick]
    rays = pixel_rays_closed_form(np.stack([uu, vv], axis=1).astype(float), K)
    return _rays_hit_share(prim, rays, ip.points, config) >= config.ray_hit_min_share


def _ransac_instances(
    ipts: dict[int, InstancePoints],
    seg: Segmentation,
    scale: float,
    config: FitConfig,
    K: np.ndarray | None = None,
) -> _Fits:
    """Step 1: RANSAC per instance, typed by its label (or by the type search for weak labels, whose curved
    result must be hit by the rays of ray_hit_min_share of the instance's pixels, `_rays_hit_share`, given the
    intrinsics ``K``)."""
    out = _Fits()
    inst = np.asarray(seg.instances)
    for i, ip in ipts.items():  # loop over instances
        ptype, ax = _label_of(seg, i, config)
        rng = np.random.default_rng([config.seed, i])
        got_type, f = fit_instance(ip.points, ip.normals, ptype, scale, config, rng)
        if f is None:
            continue
        if ptype is None and got_type != "plane" and not _seen_by_its_pixels(f.primitive, inst, i, ip, K, config):
            g = ransac_fit("plane", ip.points, ip.normals, scale, config, np.random.default_rng([config.seed, i, 5]))
            if g is not None:
                got_type, f = "plane", g
        if not f.inliers.any():
            f.inliers = _inliers(f.primitive, ip, scale, config)
        if ptype is None:
            out.searched.append(i)
            ax = None if got_type == "sphere" else ax if _same_axis_meaning(seg, i, got_type) else "?"
        out.prims[i] = _canonical(f.primitive, ip.points[f.inliers])
        out.scores[i] = float(seg.scores[i]) if i < len(seg.scores) else 0.0
        out.want[i], out.weights[i], out.inliers[i] = ax, float(np.count_nonzero(f.inliers)), f.inliers
    return out


def _planes_where_unsupported(
    fits: _Fits,
    ipts: dict[int, InstancePoints],
    axis_idx: dict[int, int | None],
    frame: np.ndarray,
    use_frame: bool,
    scale: float,
    config: FitConfig,
) -> list[int]:
    """Curved labels their patch does not support (`geometry.selection.supported`: a radius beyond
    support_extent_ratio patch extents, or a sagitta under the sensor noise), or whose fit does not beat a plane's
    by GRIC with the sensor's noise model (`geometry.selection.select_type`: a loose RANSAC inlier band lets a bent
    fit through), become planes, in place. Checked after the axis test, so a true cylinder whose free RANSAC axis
    was off is judged with the part frame's axis. The plane joins the frame only when its normal lies within
    snap_deg of a frame axis (the label's axis class named the cylinder's axis, not a plane normal). Certain
    labels (score >= support_label_certain: the oracle's) stay, unless (unsupported_labels, scores under
    unsupported_label_certain) their radius is beyond what the patch's extent supports (`radius_supported`) and
    the plane wins GRIC. A curved label under unsupported_label_certain on at least flat_label_min_px points
    becomes a plane, certain or not, where its own plane explains its points within the sensor's noise and its
    curved fit explains them flat_label_worse times worse or more (`_plane_explains`). Returns the instances that
    became planes."""
    demoted = []
    for i in sorted(fits.prims):  # loop over instances
        p, ip = fits.prims[i], ipts[i]
        if isinstance(p, Plane) or i in fits.searched:
            continue
        x = ip.points[fits.inliers[i]]
        score = fits.scores.get(i, 0.0)
        certain = score >= config.support_label_certain
        kept = certain and not (
            config.unsupported_labels
            and score < config.unsupported_label_certain
            and not radius_supported(p, x, config)
        )  # a certain label, unless its radius is more than its patch's extent supports
        may_be_flat = (
            config.flat_label_sigma > 0
            and score < config.unsupported_label_certain
            and len(ip.points) >= config.flat_label_min_px
        )
        if kept and not may_be_flat:
            continue
        f = ransac_fit("plane", ip.points, ip.normals, scale, config, np.random.default_rng([config.seed, i, 3]))
        if f is None:
            continue
        flat = may_be_flat and _plane_explains(f.primitive, p, ip.points, config)
        cands = {"plane": f, p.type: RansacFit(p, fits.inliers[i], 0.0)}
        if not flat and (
            kept or ((certain or supported(p, x, config)) and select_type(cands, ip.points, scale, config) != "plane")
        ):
            continue  # the label stands: certain, or not beaten by its plane
        demoted.append(i)
        q = _canonical(f.primitive, ip.points[f.inliers] if f.inliers.any() else ip.points)
        axis_idx[i] = -1
        cos = np.abs(frame @ q.axis_vector)
        k = int(np.argmax(cos))
        if cos[k] > np.cos(np.deg2rad(config.snap_deg)):
            axis_idx[i] = k
            if use_frame:
                q = _canonical(
                    fit_with_axis(
                        q, ip.points, ip.normals, frame[k] * (np.sign(q.axis_vector @ frame[k]) or 1.0), scale, config
                    ),
                    ip.points,
                )
        fits.prims[i] = q
        fits.inliers[i] = _inliers(q, ip, scale, config)
        fits.want[i] = "?"
        fits.searched.append(i)
    return demoted


def _plane_explains(plane: Primitive, curved: Primitive, x: np.ndarray, config: FitConfig) -> bool:
    """True when ``plane`` explains the instance points ``x`` (N, 3, metres) within the sensor's noise (their
    robust residual sigma, `mad_sigma`, at most flat_label_sigma times the sensor's depth sigma at their median
    point, `noise_sigma`) and the ``curved`` fit explains them flat_label_worse times worse or more: a curved
    label the depth contradicts."""
    sigma = float(np.median(noise_sigma(x, config)))
    s_plane = mad_sigma(plane.signed_distance(x))
    return s_plane <= config.flat_label_sigma * sigma and mad_sigma(curved.signed_distance(x)) >= (
        config.flat_label_worse * s_plane
    )


def _label_trusted(fits: _Fits, i: int, config: FitConfig) -> bool:
    """Whether instance ``i`` keeps its labelled type untested against the nested simpler one: its type came from
    its label, not the type search, and the label is at least ``nested_label_certain`` probable."""
    return i not in fits.searched and fits.scores.get(i, 0.0) >= config.nested_label_certain


def _nested_cylinder(
    cone: Primitive, ip: InstancePoints, inliers: np.ndarray, scale: float, config: FitConfig
) -> RansacFit | None:
    """The cylinder nested in ``cone`` (its half angle taken to 0, its axis direction kept): through the circle
    of the cone's inlier points, its axis line and radius refined on them with the direction held. A free
    cylinder, RANSAC's or one whose axis may turn, tilts by about the half angle to lie along the seen side of a
    partly seen cone (or across a narrow chamfer strip) and wins GRIC for want of points while explaining
    nothing of the cone's shape (corpus validation split, learned: type 91.5 -> 92.7 %, alignment 0.064 ->
    0.058 with the direction held; 0.061 with it free to turn)."""
    use = inliers if np.count_nonzero(inliers) >= 10 else np.ones(len(ip.points), bool)
    a = np.asarray(cone.axis_vector, float)
    start = start_with_axis("cylinder", ip.points[use], ip.normals[use], a, by_points=True)
    if start is None or not start.is_finite():
        return None
    q = refine_primitive(start, ip.points[use], scale, config, axis=a)
    if not (q.is_finite() and plausible(q, scale, config)):
        return None
    m = _inliers(q, ip, scale, config)
    return RansacFit(q, m, float(np.count_nonzero(m)) / max(len(ip.points), 1))


def _nested_after_joint(
    fits: _Fits,
    ipts: dict[int, InstancePoints],
    order: list[int],
    prims: list[Primitive],
    scale: float,
    config: FitConfig,
) -> bool:
    """The nested test again on the cones of the joint fit (``prims``, in ``order``), whose axes the shared
    frame has now set: the seen side of a cylinder (a can labelled cone) fits a cone whose axis is tilted by
    about its half angle, and the cylinder held on that tilted axis loses to it before the joint fit; held on
    the axis the frame gives it, it explains the points as well. Every instance takes its joint-fit primitive
    in ``fits`` (the next joint fit's start), a cone that loses GRIC to its nested cylinder that cylinder.
    Returns whether any cone changed."""
    changed = False
    for i, p in zip(order, prims, strict=True):
        fits.prims[i] = p
        if p.type != "cone" or _label_trusted(fits, i, config):
            continue
        ip = ipts[i]
        inl = _inliers(p, ip, scale, config)
        f = _nested_cylinder(p, ip, inl, scale, config)
        if f is None or not supported(f.primitive, ip.points, config):
            continue
        cands = {p.type: RansacFit(p, inl, 0.0), "cylinder": f}
        if select_type(cands, ip.points, scale, config) == "cylinder":
            fits.prims[i] = _canonical(f.primitive, ip.points)
            fits.inliers[i] = f.inliers
            changed = True
    return changed


def _simpler_where_nested(
    fits: _Fits,
    ipts: dict[int, InstancePoints],
    axis_idx: dict[int, int | None],
    frame: np.ndarray,
    scale: float,
    config: FitConfig,
) -> None:
    """Cones and tori (labelled or type-searched) whose simpler nested type (`NESTED_TYPES`: the cylinder) explains
    their points as well by GRIC with the sensor's noise model (`geometry.selection.select_type`: the extra
    parameters must buy more than their log(3N) each; a cone of half angle within noise of 0 buys nothing) take
    that type, in place. A cone's cylinder is the nested one with ``nested_from_axis`` (`_nested_cylinder`: on
    the cone's axis direction; tested again after the joint fit, `_nested_after_joint`); a torus's, and with it
    off a cone's, a free RANSAC fit; a type-searched cone meets a free RANSAC cylinder too with
    ``nested_free_searched`` (`_select_among`). Either way the simpler fit's axis ends free (the frame's axis
    came in part from this instance's own poor fit); it joins the frame axis within snap_deg of it, else it
    stays unaligned.
    A cone or torus whose label is at least ``nested_label_certain`` probable keeps its type: on a narrow
    chamfer strip the cylinder wins GRIC for want of points, not because the surface is one."""
    if not config.nested_selection:
        return
    for i in sorted(fits.prims):  # loop over instances
        p, ip = fits.prims[i], ipts[i]
        if p.type not in NESTED_TYPES:
            continue
        if _label_trusted(fits, i, config):
            continue
        cands = {p.type: RansacFit(p, fits.inliers[i], 0.0)}
        for k, t in enumerate(NESTED_TYPES[p.type]):  # loop over the simpler types
            tries = []
            if config.nested_from_axis and p.type == "cone":
                tries.append(_nested_cylinder(p, ip, fits.inliers[i], scale, config))
            free_searched = config.nested_free_searched and i in fits.searched and p.type == "cone"
            if not (config.nested_from_axis and p.type == "cone") or free_searched:
                rng = np.random.default_rng([config.seed, i, 5, k])
                tries.append(ransac_fit(t, ip.points, ip.normals, scale, config, rng))
            for f in tries:
                if f is None or not supported(f.primitive, ip.points, config):
                    continue
                key = t if t not in cands else f"{t}_free"
                cands[key] = RansacFit(f.primitive, f.inliers, f.score)
        best = _select_among(cands, ip.points, scale, config)
        if best == p.type:
            continue
        q = _canonical(cands[best].primitive, ip.points)
        fits.prims[i] = q
        fits.inliers[i] = _inliers(q, ip, scale, config)
        cos = np.abs(frame @ q.axis_vector)
        k = int(np.argmax(cos))
        axis_idx[i] = k if cos[k] > np.cos(np.deg2rad(config.snap_deg)) else -1


def _select_among(cands: dict[str, RansacFit], x: np.ndarray, scale: float, config: FitConfig) -> str:
    """`select_type` over candidates that may hold two fits of one type (keys "cylinder" and "cylinder_free"),
    each against the best so far: two of one type by their median absolute residual, two types by GRIC. Returns
    the key of the winner."""
    types = {k: k.split("_")[0] for k in cands}
    best: str | None = None
    for k in cands:  # loop over the candidates
        if best is None:
            best = k
            continue
        pair = {types[best]: cands[best], types[k]: cands[k]} if types[best] != types[k] else None
        if pair is None:  # two fits of one type: the one nearer its points
            a, b = (np.abs(cands[q].primitive.signed_distance(x)) for q in (best, k))
            best = k if float(np.median(b)) < float(np.median(a)) else best
        elif select_type(pair, x, scale, config) == types[k]:
            best = k
    assert best is not None
    return best


def _holds_patch(prim: Primitive, x: np.ndarray, config: FitConfig) -> bool:
    """False for a cylinder too thin to hold its patch ``x`` (N, 3): the points' trimmed (support_trim_pct)
    extent across its axis exceeds its diameter by more than small_chord_sigma depth-noise sigmas
    (`geometry.selection.noise_sigma`); True for every other primitive. On a strip a few pixels wide the
    radius is barely constrained, and the rays of a thin cylinder miss most of the strip."""
    if not isinstance(prim, Cylinder) or len(x) < 3:
        return True
    y = x - np.outer(x @ prim.axis, prim.axis)
    y = y - y.mean(axis=0)
    u = np.linalg.eigh(y.T @ y)[1][:, -1]
    lo, hi = np.percentile(y @ u, [config.support_trim_pct, 100.0 - config.support_trim_pct])
    sigma = float(np.median(noise_sigma(x, config)))
    return float(hi - lo) <= 2.0 * prim.radius + config.small_chord_sigma * sigma


def _adjacency(inst: np.ndarray) -> dict[int, set[int]]:
    """Instance id -> the ids whose pixels touch its own (`segment.refine.touching_pairs`: 4-neighbourhood of the
    instance map; 0 is no instance)."""
    from v2c.segment.refine import touching_pairs

    out: dict[int, set[int]] = {}
    for a, b in touching_pairs(inst).tolist():  # loop over touching instance pairs
        out.setdefault(a, set()).add(b)
        out.setdefault(b, set()).add(a)
    return out


def _planes_along_crossings(
    prims: list[Primitive],
    order: list[int],
    ipts: dict[int, InstancePoints],
    axis_idx: dict[int, int | None],
    inst: np.ndarray,
    scale: float,
    config: FitConfig,
) -> list[Primitive]:
    """``prims`` (in ``order``'s instances) with each unaligned plane (axis class U or none, at least
    crossing_min_points inlier points) refitted parallel to the line where two of its touching planes meet (at
    least crossing_min_deg apart): the total-least-squares plane through its inlier points whose normal is
    perpendicular to that line, for the line that fits best, when its RMS distance is at most
    crossing_max_rms_ratio times the free plane's and it turns the plane by at most crossing_max_turn_deg.

    A chamfer between two faces is parallel to the line where they meet. The sensor's correlated depth error
    (the `sensor` profile's 2 mm fBm warp) tilts a patch of a few dozen pixels by degrees, and the shared frame
    that holds the aligned planes does not reach an unaligned one: on a corpus part of the training split
    (`brepnet__53589` view 1, oracle) 45-degree chamfers of 30-110 px were fitted 2-13 degrees off; along their
    crossing, 0.2-2. A plane that does not lie along a crossing leaves its points far off the constrained fit and
    is kept; so is a thin strip whose points fit any plane through its long axis, where the turn is large."""
    from itertools import combinations

    from v2c.primitives.directions import tangent_basis

    at = {i: k for k, i in enumerate(order)}
    planes = {i for i in order if isinstance(prims[at[i]], Plane)}
    free = [i for i in planes if axis_idx.get(i) is None or axis_idx[i] < 0]
    if not free:
        return prims
    near = _adjacency(inst)
    touching = {i: near.get(i, set()) & planes for i in planes}
    min_sin = float(np.sin(np.deg2rad(config.crossing_min_deg)))
    out = list(prims)
    for i in sorted(free):  # loop over unaligned planes
        p = prims[at[i]]
        x = ipts[i].points[_inliers(p, ipts[i], scale, config)]
        if len(x) < max(config.crossing_min_points, 3) or len(touching[i]) < 2:
            continue
        c = x - x.mean(axis=0)
        rms_free = float(np.linalg.svd(c, compute_uv=False)[-1]) / np.sqrt(len(x))
        best = None
        for a, b in combinations(sorted(touching[i]), 2):  # loop over pairs of touching planes
            d = np.cross(prims[at[a]].axis_vector, prims[at[b]].axis_vector)
            if np.linalg.norm(d) < min_sin:
                continue
            t1, t2 = tangent_basis(unit(d))
            q = c @ np.stack([t1, t2], axis=1)
            w, v = np.linalg.eigh(q.T @ q)  # the normal: the least-spread direction across the line
            rms = float(np.sqrt(max(w[0], 0.0) / len(x)))
            if best is None or rms < best[0]:
                best = (rms, v[0, 0] * t1 + v[1, 0] * t2)
        if best is not None and best[0] <= config.crossing_max_rms_ratio * rms_free:
            n = unit(best[1])
            n = n if n @ p.axis_vector >= 0 else -n
            if n @ p.axis_vector >= np.cos(np.deg2rad(config.crossing_max_turn_deg)):
                out[at[i]] = Plane(x.mean(axis=0), n)
    return out


def _planes_toward_their_depth(
    prims: list[Primitive],
    order: list[int],
    ipts: dict[int, InstancePoints],
    axis_idx: dict[int, int | None],
    scale: float,
    config: FitConfig,
) -> list[Primitive]:
    """``prims`` (in ``order``'s instances) with each aligned plane of at least frame_tilt_min_points points whose
    robust free plane (`refine_primitive` on every point of its instance: the joint fit's loss) leaves it by at
    least frame_tilt_min_lift over those points (5th to 95th percentile of the height between the two) turned
    toward that free plane by at most frame_tilt_max_deg, through the median of its points.

    The shared frame holds a part's faces square, as a CAD model has them; a real sensor's depth of a real box
    does not: the YCB-Video cracker box's sides lie 83.5-87.4 degrees apart in its depth, the top 5.3 degrees off
    the frame, and held on the frame a tenth of a side's readings lie beyond 3 mm of it. The bound keeps two faces
    within twice it of the frame's angle; the generated scans' aligned planes lie within a fraction of a degree of
    their axes and are left on the frame."""
    from scipy.spatial.transform import Rotation

    max_turn = float(np.deg2rad(config.frame_tilt_max_deg))
    if max_turn <= 0.0:
        return prims
    out = list(prims)
    for k, i in enumerate(order):  # loop over the fitted instances
        p = prims[k]
        k_axis = axis_idx.get(i)
        x = ipts[i].points
        if not isinstance(p, Plane) or k_axis is None or k_axis < 0 or len(x) < max(config.frame_tilt_min_points, 3):
            continue
        n0 = p.normal_vec
        free = refine_primitive(p, x, scale, config)
        lo, hi = np.percentile(free.signed_distance(x) - p.signed_distance(x), [5.0, 95.0])
        n_free = free.normal_vec
        axis = np.cross(n0, n_free)
        turn = float(np.arctan2(np.linalg.norm(axis), n0 @ n_free))
        if not (np.isfinite(turn) and np.isfinite(hi - lo)) or hi - lo < config.frame_tilt_min_lift:
            continue
        n = Rotation.from_rotvec(unit(axis) * min(turn, max_turn)).apply(n0)
        # the offset along the turned normal: the median of the points (a robust centre)
        s = (x - p.origin) @ n
        out[k] = Plane(p.origin + float(np.median(s)) * n, n)
    return out


def _small_instances(
    fits: _Fits,
    ipts: dict[int, InstancePoints],
    seg: Segmentation,
    axis_idx: dict[int, int | None],
    frame: np.ndarray,
    scale: float,
    config: FitConfig,
) -> None:
    """Instances too small for RANSAC (``ipts``: small_instance_px to min_instance_px pixels) whose label names
    their type and a frame axis (X / Y / Z), fitted in place with that type on that axis of the shared frame
    (`constrained.fit_with_axis` from its closed-form starts): a few pixels cannot fix an axis, but the label and
    the frame do, and they join the joint fit and the intersection refinement like any aligned instance. A fit
    that is not plausible (`_keep_plausible`'s tests) or whose median distance to the points exceeds d_inlier
    part sizes is left out (the VB-Rep's fallbacks then see the instance)."""
    for i in sorted(ipts):  # loop over instances
        ptype, k = _label_of(seg, i, config)
        if ptype is None or ptype == "sphere" or not isinstance(k, int) or k < 0:
            continue
        ip = ipts[i]
        a = frame[k]
        start = start_with_axis(ptype, ip.points, ip.normals, a, by_points=ptype != "plane")
        if start is None or not start.is_finite():
            continue
        q = fit_with_axis(start, ip.points, ip.normals, a, scale, config)
        if not (
            q.is_finite()
            and plausible(q, scale, config)
            and torus_ok(q, ip.points, config)
            and cone_ok(q, ip.points, scale, config)
            and float(np.median(np.abs(q.signed_distance(ip.points)))) <= config.d_inlier * scale
            and _holds_patch(q, ip.points, config)
        ):
            continue
        fits.prims[i] = _canonical(q, ip.points)
        # distance-only inliers: a few pixels' depth-gradient normals are too poor to judge (as in `_assign_axes`)
        m = inlier_mask(fits.prims[i], ip.points, ip.normals, config.d_inlier * scale, -1.0)
        fits.inliers[i] = m if m.any() else np.ones(len(ip.points), bool)
        fits.want[i] = k
        fits.weights[i] = float(np.count_nonzero(fits.inliers[i]))
        fits.scores[i] = float(seg.scores[i]) if i < len(seg.scores) else 0.0
        axis_idx[i] = k


def _neighbour_directions(
    nb: list[int], fits: _Fits, axis_idx: dict[int, int | None], config: FitConfig
) -> list[np.ndarray]:
    """The directions the anchors ``nb`` (instance ids touching an instance) give it: their unaligned axes, then the
    lines where two of them that are planes, aligned or not, cross at least ``crossing_min_deg`` apart."""
    dirs = [unit(fits.prims[j].axis_vector) for j in nb if axis_idx.get(j) == -1]
    planes = [unit(fits.prims[j].axis_vector) for j in nb if isinstance(fits.prims[j], Plane)]
    sin_min = np.sin(np.deg2rad(config.crossing_min_deg))
    for a_i, u in enumerate(planes):
        for v in planes[a_i + 1 :]:
            c = np.cross(u, v)
            if np.linalg.norm(c) >= sin_min:
                dirs.append(unit(c))
    return dirs


def _related_axes(
    fits: _Fits,
    ipts: dict[int, InstancePoints],
    axis_idx: dict[int, int | None],
    inst: np.ndarray,
    scale: float,
    config: FitConfig,
) -> set[int]:
    """Unaligned instances whose axis their own points hardly fix, held on a direction their neighbours give: the
    ids so held.

    An instance with at least ``related_anchor_points`` inliers is an anchor: its axis (a plane's normal, a curved
    face's axis, or its frame axis) is its own. The directions an unaligned instance may take from the anchors whose
    pixels touch its own are their unaligned axes (parallel faces, a hole square to its face, coaxial sections) and
    the lines where two of those neighbours that are planes, aligned or not, cross at least ``crossing_min_deg``
    apart (a blend along their edge). Every other unaligned instance is refitted with its axis on each such
    direction within ``related_max_deg`` of its free axis and takes the one of lowest GRIC
    (`geometry.selection.select_type`'s criterion: truncated squared residuals in units of the sensor's noise,
    log(3 N) per degree of freedom) when that is no higher than its free fit's: two degrees of freedom fewer must
    cost less than they explain."""
    free = [i for i, p in fits.prims.items() if axis_idx.get(i) == -1 and p.axis_vector is not None]
    anchor = {
        i
        for i, p in fits.prims.items()
        if p.axis_vector is not None and np.count_nonzero(fits.inliers[i]) >= config.related_anchor_points
    }
    held: set[int] = set()
    if not anchor or not free:
        return held
    near = _adjacency(inst)
    cos_max = np.cos(np.deg2rad(config.related_max_deg))
    for i in free:
        if i in anchor:
            continue
        dirs = _neighbour_directions(sorted(near.get(i, set()) & anchor), fits, axis_idx, config)
        if not dirs:
            continue
        cand = np.array(dirs)
        p = fits.prims[i]
        a = unit(p.axis_vector)
        cos = np.abs(cand @ a)
        if not np.any(cos >= cos_max):
            continue
        ip = ipts[i]
        x, n = ip.points[fits.inliers[i]], ip.normals[fits.inliers[i]]
        if len(x) > config.refine_points:
            sel = np.random.default_rng([config.seed, i, 5]).choice(len(x), config.refine_points, replace=False)
            x, n = x[sel], n[sel]
        if len(x) < p.local_size + 2:
            continue
        d_free = np.abs(p.signed_distance(x))
        sigma = np.maximum(max(mad_sigma(d_free), config.gric_min_sigma * scale), noise_sigma(x, config))
        lam = np.log(3 * len(x))

        def cost(d: np.ndarray, sigma: np.ndarray = sigma) -> float:
            return float(np.sum(np.minimum((d / sigma) ** 2, config.gric_trunc)))

        best, best_cost = None, cost(d_free) + 2 * lam  # the free axis: two more degrees of freedom
        for k in np.flatnonzero(cos >= cos_max):
            q = fit_with_axis(p, x, n, cand[k] * (np.sign(a @ cand[k]) or 1.0), scale, config)
            if not q.is_finite():
                continue
            c = cost(np.abs(q.signed_distance(x)))
            if c <= best_cost:
                best, best_cost = q, c
        if best is not None:
            fits.prims[i] = _canonical(best, x)
            fits.inliers[i] = _inliers(fits.prims[i], ip, scale, config)
            held.add(i)
    return held


def _joint_terms(
    fits: _Fits,
    ipts: dict[int, InstancePoints],
    axis_idx: dict[int, int | None],
    frame: np.ndarray,
    use_frame: bool,
    config: FitConfig,
    held: AbstractSet[int] = frozenset(),
) -> tuple[list[int], list[Term]]:
    """Step 2 set-up: one Term per fitted instance (subsampled inliers; frame axis, free axis, or the axis it is
    held on, ``held``: `_related_axes`)."""
    order = []
    terms: list[Term] = []
    for i in sorted(fits.prims):
        if not fits.prims[i].is_finite() or not np.all(np.isfinite(ipts[i].points)):
            # a degenerate fit (zero-length normal, NaN) would poison the joint solve for every face: drop it
            log.warning(
                "instance %d: its %s fit is degenerate (%r); the face is dropped", i, fits.prims[i].type, fits.prims[i]
            )
            continue
        order.append(i)
        x = ipts[i].points[fits.inliers[i]]
        rng = np.random.default_rng([config.seed, i, 1])
        if len(x) > config.align_points:
            x = x[rng.choice(len(x), config.align_points, replace=False)]
        k = axis_idx[i]
        if k is not None and (k < 0 or not use_frame):
            k = -2 if i in held else -1
        p = fits.prims[i]
        sign = 1.0 if k is None or k < 0 else float(np.sign(p.axis_vector @ frame[k]) or 1.0)
        n_in = int(np.count_nonzero(fits.inliers[i]))
        weight = float(np.sqrt(n_in / max(len(x), 1))) if config.recon_weighting == "all" else 1.0
        terms.append(Term(p, x, k, sign, weight))
    return order, terms


def _keep_plausible(
    new: list[Primitive], old: list[Primitive], terms: list[Term], frame: np.ndarray, scale: float, config: FitConfig
) -> list[Primitive]:
    """A joint solve has no bounds: a primitive it drove out of range (cone half angle beyond 90 degrees or a cone
    wider than max_radius at its points, negative radius, a torus outside its data-derived radius bounds
    `geometry.ransac.torus_limits`, a curvature its points no longer support, `geometry.selection.supported`, a
    cylinder too thin to hold its points, `_holds_patch`) goes
    back to its value before the solve, its axis re-set from the current frame when aligned."""
    out = []
    for p, q, tm in zip(new, old, terms, strict=True):
        if (
            p.is_finite()
            and plausible(p, scale, config)
            and torus_ok(p, tm.points, config, 1.2)
            and cone_ok(p, tm.points, scale, config)
            and (supported(p, tm.points, config) or not supported(q, tm.points, config))
            and (_holds_patch(p, tm.points, config) or not _holds_patch(q, tm.points, config))
        ):
            out.append(p)
        elif tm.axis_index is not None and tm.axis_index >= 0:
            out.append(q.from_local(np.zeros(q.local_size), tm.axis_sign * frame[tm.axis_index]))
        else:
            out.append(q)
    return out


def _joint_fit(
    terms: list[Term], frame: np.ndarray, scale: float, config: FitConfig
) -> tuple[np.ndarray, list[Primitive]]:
    """Step 2's aligned joint least squares (`align.align_fit` with the config's solver settings), each result
    kept only where plausible (`_keep_plausible`); returns the frame and the primitives in ``terms``' order."""
    frame, prims = align_fit(
        terms,
        frame,
        scale,
        config.loss,
        config.loss_scale,
        config.max_nfev,
        config.ftol,
        config.jacobian,
        config.lsmr_tol,
    )
    return frame, _keep_plausible(prims, [tm.prim for tm in terms], terms, frame, scale, config)


def _one_blas_thread() -> contextlib.AbstractContextManager:
    """Every matrix here is small: multi-threaded BLAS only adds overhead, and on a loaded machine
    oversubscription made one fit 6x slower. threadpoolctl limits it where installed."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(1, user_api="blas")


def fit_scan(scan: Scan, seg: Segmentation, config: FitConfig | None = None, ablation: str = "full") -> FitResult:
    """Fit one primitive per segmented instance of ``scan`` (camera frame, metres).

    ablation: "full" (shared frame + intersections), "no-axis" (free axes), "no-int" (no intersection term),
    "fit-only" (RANSAC with its local refinement only).
    """
    if ablation not in ABLATIONS:
        raise ValueError(f"unknown ablation {ablation!r}; choose from {', '.join(ABLATIONS)}")
    with _one_blas_thread():
        return _fit_scan(scan, seg, config or FitConfig(), ablation)


def _take_fixed(
    fits: _Fits,
    fixed: dict[int, Primitive],
    ipts: dict[int, InstancePoints],
    use_frame: bool,
    scale: float,
    config: FitConfig,
) -> None:
    """With the shared frame (use_frame), aligned instances start from their axis-constrained refit ``fixed``
    (`_assign_axes`), in place."""
    if not use_frame:
        return
    for i, p in fixed.items():
        if p is not fits.prims[i]:
            fits.prims[i] = p
            fits.inliers[i] = _inliers(p, ipts[i], scale, config)


def _fit_scan(scan: Scan, seg: Segmentation, config: FitConfig, ablation: str) -> FitResult:
    t_start, cpu_start = perf_counter(), process_time()
    timings: dict[str, float] = {}
    depth = np.asarray(scan.depth, float)
    K = np.asarray(scan.K, float)
    inst = np.asarray(seg.instances)
    valid = np.asarray(scan.valid, bool) & (inst > 0)
    pts = backproject(depth, K)
    scale = estimate_part_size(pts[valid], config.scale_trim)
    counts = np.bincount(inst[valid], minlength=int(inst.max()) + 1)
    ids = np.flatnonzero(counts >= config.min_instance_px)
    ipts = instance_points(pts, valid, inst, ids[ids > 0], config)
    small = np.flatnonzero((counts >= config.small_instance_px) & (counts < config.min_instance_px))
    small_pts = instance_points(pts, valid, inst, small[small > 0], config)
    t = perf_counter()
    timings["normals"] = t - t_start

    # 1. RANSAC per instance
    fits = _ransac_instances(ipts, seg, scale, config, K)
    timings["ransac"] = perf_counter() - t
    t = perf_counter()

    # 2. shared frame, label test and the aligned joint fit
    use_frame = ablation in ("full", "no-int")
    view_dir = unit(pts[valid].mean(axis=0)) if valid.any() else np.array([0.0, 0.0, 1.0])
    free = (dict(fits.prims), dict(fits.inliers))  # RANSAC's, before any axis is held on the frame
    frame, axis_idx, fixed = _assign_axes(fits.prims, fits.want, fits.weights, ipts, view_dir, scale, config)
    _take_fixed(fits, fixed, ipts, use_frame, scale, config)
    named = {i for i, w in fits.want.items() if isinstance(w, int) and w >= 0}  # labels that named a frame axis
    demoted = _planes_where_unsupported(fits, ipts, axis_idx, frame, use_frame, scale, config)
    if named.intersection(demoted):  # a label that named a frame axis was wrong: the frame again, by the
        # consensus of every instance's axis (the demoted ones' plane normals among them), every instance but the
        # demoted ones from RANSAC's fit
        for i in fits.prims:
            if i not in demoted:
                fits.prims[i], fits.inliers[i] = free[0][i], free[1][i]
        frame, axis_idx, fixed = _assign_axes(
            fits.prims, fits.want, fits.weights, ipts, view_dir, scale, config, consensus=True
        )
        _take_fixed(fits, fixed, ipts, use_frame, scale, config)
    _simpler_where_nested(fits, ipts, axis_idx, frame, scale, config)
    if use_frame:  # the frame gives small instances the axis their points cannot
        _small_instances(fits, small_pts, seg, axis_idx, frame, scale, config)
        ipts.update({i: small_pts[i] for i in small_pts if i in fits.prims})
    held = set()
    if use_frame and config.related_axes:  # unaligned instances on their neighbours' directions
        held = _related_axes(fits, ipts, axis_idx, inst, scale, config)
    order, terms = _joint_terms(fits, ipts, axis_idx, frame, use_frame, config, held)
    prims = [tm.prim for tm in terms]
    if ablation != "fit-only":
        frame, prims = _joint_fit(terms, frame, scale, config)
        if (
            config.nested_selection
            and config.nested_from_axis
            and _nested_after_joint(fits, ipts, order, prims, scale, config)
        ):
            order, terms = _joint_terms(fits, ipts, axis_idx, frame, use_frame, config, held)
            frame, prims = _joint_fit(terms, frame, scale, config)
    timings["align"] = perf_counter() - t
    t = perf_counter()

    # 3. edge graph and the iterative intersection refinement (two rounds: d_int, then d_int / 5)
    graph = build_edge_graph(inst, config.simplify_px)
    lifted = boundary_points(graph, {i: k for k, i in enumerate(order)}, K, config.edge_sample_px)
    timings["graph"] = perf_counter() - t
    t = perf_counter()
    lifted.s = init_depths(lifted, prims, depth, valid, scale, config)
    n_int = 0
    if ablation in ("full", "no-axis") and prims:
        fitted = list(prims)
        for rnd, thr in enumerate((config.d_int, config.d_int * config.d_int_second_factor)):
            terms = [replace(tm, prim=p) for p, tm in zip(prims, terms, strict=True)]
            member = fitted if (rnd > 0 and config.membership == "fitted") else None
            frame, prims, lifted.s, n_int = refine_intersections(terms, frame, lifted, scale, config, thr, member)
            prims = _keep_plausible(prims, [tm.prim for tm in terms], terms, frame, scale, config)
    timings["intersect"] = perf_counter() - t
    t = perf_counter()

    # 3b. tangent (G1) junctions: blends refitted tangent to their neighbours where the evidence says so
    if ablation == "full" and config.tangent_fit and prims:
        junctions = tangent_junctions(prims, lifted.rays, lifted.s, lifted.candidates, lifted.vertex, config)
        adjacent = (
            adjacent_terms(graph, {i: k for k, i in enumerate(order)}, config.torus_blend_min_contact_px)
            if config.torus_blend_fit and any(isinstance(p, Torus) for p in prims)
            else None
        )
        if junctions or adjacent:

            def inlier_points(k: int) -> np.ndarray:
                ip = ipts[order[k]]
                return ip.points[_inliers(prims[k], ip, scale, config)]

            def all_points(k: int) -> np.ndarray:
                return ipts[order[k]].points

            prims, taken = constrain_blends(prims, junctions, inlier_points, scale, config, adjacent, all_points)
            if taken:
                log.debug("tangent refits: %s", {order[k]: m for k, m in taken.items()})
    timings["tangent"] = perf_counter() - t
    if ablation == "full" and config.crossing_planes and prims:
        prims = _planes_along_crossings(prims, order, ipts, axis_idx, inst, scale, config)
    if ablation in ("full", "no-int") and prims:
        prims = _planes_toward_their_depth(prims, order, ipts, axis_idx, scale, config)

    # 4. final inliers and residuals on all points of each instance
    out_prims: dict[int, Primitive] = {}
    inliers: dict[int, np.ndarray] = {}
    resid: dict[int, float] = {}
    labels: dict[int, str | None] = {}
    for i, p in zip(order, prims, strict=True):
        ip = ipts[i]
        m = _inliers(p, ip, scale, config)
        out_prims[i] = _canonical(p, ip.points[m])
        inliers[i] = ip.pixels[m]
        resid[i] = float(np.sqrt(np.mean(p.signed_distance(ip.points[m]) ** 2)))
        k = axis_idx[i]
        labels[i] = None if k is None else ("U" if k < 0 else AXIS_NAMES[k])
    vd = np.zeros(len(graph.vertices))
    vsel = lifted.vertex >= 0
    vd[lifted.vertex[vsel]] = lifted.s[vsel]
    timings["total"] = perf_counter() - t_start
    timings["total_cpu"] = process_time() - cpu_start  # CPU seconds of this process (all its threads)
    return FitResult(
        primitives=out_prims,
        frame=frame,
        axis_labels=labels,
        inliers=inliers,
        residuals=resid,
        vertex_depths=vd,
        graph=graph,
        scale=scale,
        timings=timings,
        types_searched=fits.searched,
        n_intersections=n_int,
        ablation=ablation,
    )
