"""Geometric fallback segmenter from the depth alone (no learning): the baseline the learned model must beat.

1. Normals (``data.estimate_normals``) and the part region: mask.png & ROI & depth > 0, or without a mask, the pixels
   standing ``min_height_m`` above the RANSAC ground plane.
2. Step edges: a relative depth jump above ``depth_jump_rel``; regions = connected components of the other part
   pixels.
3. Inside each region, primitives are peeled off greedily (efficient-RANSAC style, locally sampled): plane (3
   points), cylinder and sphere (2 oriented points) hypotheses; the one with the most inliers (distance and normal
   tests) takes its largest connected inlier set; repeat on the rest. Creases and tangent-continuous joins (plane +
   fillet) are split by the normal test.
4. Leftover part pixels join the nearest instance; each instance gets a type test (plane / cylinder / cone / sphere
   by least-squares residuals on its points) and an axis class against a part frame estimated from the scene:
   Z = ground normal, X/Y = the dominant horizontal direction of plane normals and cylinder axes (modulo 90
   degrees), X being the one nearer the viewing direction.
Units: metres, camera frame, pixels for image sizes, degrees in the config.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from v2c.camera import backproject
from v2c.labels import AxisClass, PrimitiveType, axis_class, label_of
from v2c.scan import Scan
from v2c.segment.data import FeatureConfig, Ground, estimate_ground, estimate_normals, gravity_frame
from v2c.segment.instances import _fill, _relabel_raster
from v2c.segment.types import Segmentation


@dataclass(frozen=True)
class GeometricConfig:
    """Thresholds of the geometric segmenter (module docstring; units in the comments)."""

    features: FeatureConfig = field(default_factory=lambda: FeatureConfig(smooth_sigma_px=2.0, diff_step_px=2))
    min_height_m: float = 0.003  # without a mask: part = points this far above the ground plane (metres)
    depth_jump_rel: float = 0.015  # relative depth jump between 4-neighbours that marks a step edge
    min_region_px: int = 40  # smallest region / instance kept (pixels)
    max_fill_px: float = 12.0  # farthest a leftover pixel joins an instance (pixels)
    hypotheses: int = 48  # RANSAC hypotheses per primitive kind and round
    sample_px: int = 1500  # points of a region used to score hypotheses
    inlier_rel: float = 0.003  # inlier distance relative to the depth (metres per metre)
    inlier_min_m: float = 0.001  # floor of the inlier distance (metres)
    inlier_angle_deg: float = 20.0  # inlier normal deviation (degrees)
    sample_radius_px: int = 6  # hypothesis points are drawn within this image distance of a seed (pixels)
    max_rounds: int = 30  # RANSAC rounds per region (each peels off at most one primitive)
    plane_bonus: float = 1.03  # a plane wins unless a curved hypothesis has this factor more inliers
    min_radius_rel: float = 0.002  # curved hypotheses: radius bounds relative to the depth
    max_radius_rel: float = 0.15
    aligned_deg: float = 12.0  # axis class tolerance against the estimated part frame (degrees)
    cone_min_deg: float = 8.0  # a curved instance is a cone when its normals tilt this much from its axis (deg)
    plane_max_spread_deg: float = 6.0  # a curved instance whose normals spread less than this is a plane (deg)
    cone_min_spread: float = 0.005  # ... and they spread enough to tell (2nd eigenvalue of their covariance)
    seed: int = 0


# ---------------------------------------------------------------------------------------------------------------
# hypotheses (vectorised over K hypotheses x M points)


def _plane_hyp(p: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plane hypotheses through point triples ``idx`` (K, 3)."""
    n = np.cross(p[idx[:, 1]] - p[idx[:, 0]], p[idx[:, 2]] - p[idx[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return p[idx[:, 0]], n


def _two_point_axis_hyp(p: np.ndarray, n: np.ndarray, i: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Cylinder hypotheses from oriented point pairs ``i`` (K, 2): axis = n1 x n2, centre from the normal lines."""
    p1, p2, n1, n2 = p[i[:, 0]], p[i[:, 1]], n[i[:, 0]], n[i[:, 1]]
    a = np.cross(n1, n2)
    a /= np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-12)
    # closest points of the lines p1 + t n1, p2 + s n2
    w = p1 - p2
    b = np.sum(n1 * n2, axis=1)
    d, e = np.sum(n1 * w, axis=1), np.sum(n2 * w, axis=1)
    den = np.maximum(1 - b * b, 1e-9)
    t = (b * e - d) / den
    s = (e - b * d) / den
    c = 0.5 * ((p1 + t[:, None] * n1) + (p2 + s[:, None] * n2))
    r = 0.5 * (np.abs(t) + np.abs(s))
    return c, a, r


def _sphere_hyp(p: np.ndarray, n: np.ndarray, i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c, _, r = _two_point_axis_hyp(p, n, i)
    return c, r


def _score(p: np.ndarray, n: np.ndarray, kind: str, hyp: tuple, tol: np.ndarray, cos_t: float) -> np.ndarray:
    """(K, M) bool inlier matrix of hypotheses of one kind."""
    if kind == "plane":
        o, nrm = hyp
        d = np.abs(np.einsum("kc,mc->km", nrm, p) - np.sum(nrm * o, axis=1)[:, None])
        ang = np.abs(np.einsum("kc,mc->km", nrm, n))
        return (d < tol[None]) & (ang > cos_t)
    if kind == "cylinder":
        c, a, r = hyp
        q = p[None] - c[:, None]
        h = np.einsum("kmc,kc->km", q, a)
        radial = q - h[..., None] * a[:, None]
        rho = np.linalg.norm(radial, axis=2)
        d = np.abs(rho - r[:, None])
        ang = np.abs(np.einsum("kmc,mc->km", radial, n)) / np.maximum(rho, 1e-12)
        return (d < tol[None]) & (ang > cos_t)
    c, r = hyp
    q = p[None] - c[:, None]
    rho = np.linalg.norm(q, axis=2)
    d = np.abs(rho - r[:, None])
    ang = np.abs(np.einsum("kmc,mc->km", q, n)) / np.maximum(rho, 1e-12)
    return (d < tol[None]) & (ang > cos_t)


def _local_samples(
    vv: np.ndarray, uu: np.ndarray, rest: np.ndarray, k: int, m: int, radius: int, rng: np.random.Generator
) -> np.ndarray:
    """(K', m) indices into the pixel list (vv, uu): a random seed pixel and m - 1 pixels within ``radius`` pixels
    of it that are still in ``rest`` (efficient-RANSAC style local sampling). Rows with a miss are dropped."""
    h, w = rest.shape
    lut = np.full(rest.shape, -1, np.int64)
    lut[vv, uu] = np.arange(len(vv))
    seed = rng.integers(0, len(vv), k)
    out = [seed]
    for _ in range(m - 1):
        dv = rng.integers(-radius, radius + 1, k)
        du = rng.integers(-radius, radius + 1, k)
        v = np.clip(vv[seed] + dv, 0, h - 1)
        u = np.clip(uu[seed] + du, 0, w - 1)
        out.append(lut[v, u])
    idx = np.stack(out, axis=1)
    ok = (idx >= 0).all(axis=1) & (idx[:, 1:] != idx[:, :1]).all(axis=1)
    return idx[ok]


def _best_hypothesis(
    vv: np.ndarray,
    uu: np.ndarray,
    rest: np.ndarray,
    P: np.ndarray,
    N: np.ndarray,
    tol_img: np.ndarray,
    sample: np.ndarray,
    cfg: GeometricConfig,
    rng: np.random.Generator,
) -> tuple[str, tuple, int]:
    """Best (kind, params, inlier count on the sample) among plane, cylinder and sphere hypotheses."""
    cos_t = np.cos(np.deg2rad(cfg.inlier_angle_deg))
    allp, alln = P[vv, uu], N[vv, uu]
    p, n, tol = allp[sample], alln[sample], tol_img[vv[sample], uu[sample]]
    z = float(np.median(p[:, 2]))
    rmin, rmax = cfg.min_radius_rel * z, cfg.max_radius_rel * z
    best: tuple[str, tuple, float, int] = ("plane", (), -1.0, 0)
    k, rad = cfg.hypotheses, cfg.sample_radius_px
    cands = []
    i3 = _local_samples(vv, uu, rest, k, 3, rad, rng)
    if len(i3):
        cands.append(("plane", _plane_hyp(allp, i3)))
    i2 = _local_samples(vv, uu, rest, 2 * k, 2, 2 * rad, rng)
    if len(i2):
        c, a, r = _two_point_axis_hyp(allp, alln, i2[:k])
        ok = (r > rmin) & (r < rmax)
        if ok.any():
            cands.append(("cylinder", (c[ok], a[ok], r[ok])))
        if len(i2) > k:
            c, r = _sphere_hyp(allp, alln, i2[k:])
            ok = (r > rmin) & (r < rmax)
            if ok.any():
                cands.append(("sphere", (c[ok], r[ok])))
    for kind, hyp in cands:
        cnt = _score(p, n, kind, hyp, tol, cos_t).sum(axis=1)
        j = int(np.argmax(cnt))
        val = cnt[j] * (cfg.plane_bonus if kind == "plane" else 1.0)
        if val > best[2]:
            best = (kind, tuple(h[j : j + 1] for h in hyp), val, int(cnt[j]))
    return best[0], best[1], best[3]


def _largest_component(mask: np.ndarray) -> np.ndarray:
    n, cc, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=4)
    if n <= 1:
        return np.zeros_like(mask)
    j = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return cc == j


def _peel_region(
    region: np.ndarray,
    P: np.ndarray,
    N: np.ndarray,
    tol_img: np.ndarray,
    cfg: GeometricConfig,
    rng: np.random.Generator,
) -> list[tuple[np.ndarray, str]]:
    """(mask, kind) of the primitives peeled off one region (image-sized bool masks), largest inlier sets first."""
    out = []
    rest = region & (np.linalg.norm(N, axis=2) > 0.5)
    cos_t = np.cos(np.deg2rad(cfg.inlier_angle_deg))
    misses = 0
    for _ in range(cfg.max_rounds):
        vv, uu = np.nonzero(rest)
        if len(vv) < cfg.min_region_px:
            break
        sample = rng.choice(len(vv), size=min(cfg.sample_px, len(vv)), replace=False)
        kind, hyp, cnt = _best_hypothesis(vv, uu, rest, P, N, tol_img, sample, cfg, rng)
        if not hyp or cnt * len(vv) / len(sample) < cfg.min_region_px:
            break
        inl = _score(P[vv, uu], N[vv, uu], kind, hyp, tol_img[vv, uu], cos_t)[0]
        m = np.zeros_like(rest)
        m[vv[inl], uu[inl]] = True
        m = _largest_component(m)
        if m.sum() < cfg.min_region_px:
            misses += 1  # scattered inliers: try other hypotheses, give up after a few
            if misses >= 3:
                break
            continue
        out.append((m, kind))
        rest &= ~m
    return out


# ---------------------------------------------------------------------------------------------------------------
# type tests and the part frame


@dataclass
class _Fit:
    kind: PrimitiveType
    axis: np.ndarray | None  # plane normal / cylinder, cone axis (camera frame, unit); None for spheres
    area: int


def _fit_plane(p: np.ndarray) -> tuple[np.ndarray, float]:
    c = p.mean(axis=0)
    _, s, vt = np.linalg.svd(p - c, full_matrices=False)
    return vt[2], float(s[2] / np.sqrt(len(p)))


def classify_instance(p: np.ndarray, n: np.ndarray, kind: str, cfg: GeometricConfig) -> _Fit:
    """Type and axis of one instance from its RANSAC kind and its points ``p`` / normals ``n`` (M, 3).

    plane: the least-squares normal. cylinder: the axis is the thinnest direction of the normals' spread; when the
    normals tilt from it by more than ``cone_min_deg`` on average, a cone.
    """
    valid = np.linalg.norm(n, axis=1) > 0.5
    nn = n[valid]
    if kind == "sphere":
        return _Fit(PrimitiveType.SPHERE, None, len(p))
    if kind == "plane" or len(nn) < 10:
        normal, _ = _fit_plane(p)
        return _Fit(PrimitiveType.PLANE, normal, len(p))
    _, vecs = np.linalg.eigh(nn.T @ nn)
    a_cyl = vecs[:, 0]
    # normals of a cylinder lie on a great circle of the unit sphere, a cone's on a small one: the centred spread's
    # thinnest direction is the axis of both, and the circle's offset along it is the cone's tilt. A narrow arc of
    # normals gives no reliable offset: then a cylinder.
    w, vecs_c = np.linalg.eigh(np.cov(nn.T))
    if w[2] < np.sin(np.deg2rad(cfg.plane_max_spread_deg)) ** 2:  # normals hardly vary: a plane after all
        normal, _ = _fit_plane(p)
        return _Fit(PrimitiveType.PLANE, normal, len(p))
    a_c = vecs_c[:, 0]
    tilt = np.degrees(np.arcsin(min(abs(float(np.mean(nn @ a_c))), 1.0)))
    if w[1] > cfg.cone_min_spread and tilt > cfg.cone_min_deg:
        return _Fit(PrimitiveType.CONE, a_c, len(p))
    return _Fit(PrimitiveType.CYLINDER, a_cyl if w[1] <= cfg.cone_min_spread else a_c, len(p))


def part_frame(fits: list[_Fit], view_frame: np.ndarray) -> np.ndarray:
    """(3, 3) rows X, Y, Z of the estimated part frame (camera frame).

    view_frame: rows (forward, left, up) of ``data.gravity_frame``. Z = up; the horizontal axes are the area-weighted
    dominant direction (modulo 90 degrees) of the horizontal parts of plane normals and cylinder/cone axes; X is the
    one nearer the forward (viewing) direction, signed to point away from the camera.
    """
    fwd, left, up = view_frame
    acc = 0j
    for f in fits:
        if f.axis is None:
            continue
        h = f.axis - (f.axis @ up) * up
        hn = np.linalg.norm(h)
        if hn < 0.5:  # mostly vertical: says nothing about the horizontal axes
            continue
        ang = np.arctan2(h @ left, h @ fwd)
        acc += f.area * hn * np.exp(4j * ang)
    theta = np.angle(acc) / 4 if abs(acc) > 0 else 0.0
    a1 = np.cos(theta) * fwd + np.sin(theta) * left
    a2 = np.cross(up, a1)
    x = a1 if abs(a1 @ fwd) >= abs(a2 @ fwd) else a2
    if x @ fwd < 0:
        x = -x
    y = np.cross(up, x)
    return np.stack([x, y, up])


# ---------------------------------------------------------------------------------------------------------------


def part_region(scan: Scan, cfg: GeometricConfig) -> tuple[np.ndarray, Ground | None]:
    """(part pixels (H, W) bool, ground plane or None)."""
    ground = estimate_ground(scan.depth, scan.K, scan.mask, cfg.features)
    valid = scan.depth > 0
    if scan.mask is not None:
        part = valid & scan.mask
    elif ground is not None:
        pts = backproject(scan.depth, scan.K)
        part = valid & (pts @ ground.up + ground.offset > cfg.min_height_m)
    else:
        part = valid.copy()
    if scan.roi is not None:
        part &= scan.roi_mask()
    return part, ground


def smooth_regions(depth: np.ndarray, part: np.ndarray, cfg: GeometricConfig) -> tuple[np.ndarray, int]:
    """Connected components (int32 ids, count) of part pixels not on a depth step."""
    edge = np.zeros(depth.shape, bool)
    dp = np.pad(depth, 1, mode="edge")
    for nb in (dp[1:-1, 2:], dp[1:-1, :-2], dp[2:, 1:-1], dp[:-2, 1:-1]):
        edge |= (nb > 0) & (np.abs(nb - depth) > cfg.depth_jump_rel * np.maximum(depth, 1e-3))
    n, cc = cv2.connectedComponents((part & ~edge).astype(np.uint8), connectivity=4)
    return cc.astype(np.int32), n - 1


def segment_geometric(scan: Scan, config: GeometricConfig | None = None) -> Segmentation:
    """Segment a scan from its depth alone (see the module docstring)."""
    cfg = config or GeometricConfig()
    rng = np.random.default_rng(cfg.seed)
    P = backproject(scan.depth, scan.K)
    N = estimate_normals(scan.depth, scan.K, cfg.features).astype(np.float64)
    part, ground = part_region(scan, cfg)
    regions, nreg = smooth_regions(scan.depth, part, cfg)
    tol_img = np.maximum(cfg.inlier_rel * scan.depth, cfg.inlier_min_m)
    inst = np.zeros(part.shape, np.int32)
    kinds: dict[int, str] = {}
    nxt = 0
    areas = np.bincount(regions.ravel(), minlength=nreg + 1)
    for rid in np.nonzero(areas >= cfg.min_region_px)[0]:
        if rid == 0:
            continue
        for m, kind in _peel_region(regions == rid, P, N, tol_img, cfg, rng):
            nxt += 1
            inst[m] = nxt
            kinds[nxt] = kind
    # pixels of the part without a depth reading (mask.png given) still belong to the nearest instance
    fill_region = part if scan.mask is None else scan.mask & (scan.roi_mask() if scan.roi is not None else True)
    inst = _fill(inst, fill_region, cfg.max_fill_px)
    order = _relabel_raster(inst)
    kinds = {int(order[inst == i][0]): k for i, k in kinds.items() if (inst == i).any()}
    inst = order
    n = int(inst.max())
    fits: list[_Fit] = []
    for i in range(1, n + 1):
        vv, uu = np.nonzero((inst == i) & (scan.depth > 0))
        if len(vv) < 3:
            vv, uu = np.nonzero(inst == i)
        if len(vv) > 4000:
            sel = rng.choice(len(vv), 4000, replace=False)
            vv, uu = vv[sel], uu[sel]
        fits.append(classify_instance(P[vv, uu], N[vv, uu], kinds.get(i, "plane"), cfg))
    frame = part_frame(fits, gravity_frame(ground, scan.K, part if part.any() else None, part.shape))
    labels = np.zeros(n + 1, np.uint8)
    scores = np.zeros(n + 1, np.float32)
    for i, f in enumerate(fits, start=1):
        if f.kind is PrimitiveType.SPHERE:
            labels[i] = label_of(PrimitiveType.SPHERE, None)
        else:
            ax = axis_class(f.axis, frame, tol_deg=cfg.aligned_deg)
            labels[i] = label_of(f.kind, ax if isinstance(ax, AxisClass) else AxisClass.U)
        scores[i] = 0.5
    return Segmentation(instances=inst, labels=labels, scores=scores, method="geometric")
