"""Geometric segmenter from the depth alone (no learning): the no-network baseline the learned model must beat.

1. Points, normals (``data.estimate_normals``) and the part region: mask.png & ROI & depth > 0, or without a mask,
   the pixels standing ``min_height_m`` above the RANSAC ground plane. Every threshold on a distance is in units of
   the sensor's depth noise, sigma(z) = ``noise_sigma_coeff`` z^2 (the `sensor` profile's D4xx model,
   `v2c.synth.noise.SensorNoise`), plus a floor for the slow warp of the depth.
2. Plane growing: seeds are the pixels whose local plane (PCA of a ``seed_window_px`` window) explains their
   neighbourhood within the noise, flattest first. A seed's plane takes the pixels within the distance and normal
   tolerances that are connected to the seed, is refitted to them and grows again until it stops changing. A grown
   region whose points a curved primitive (cylinder, cone, sphere; least-squares fits from points and normals)
   explains better (GRIC with the sensor's noise, `geometry.selection.select_type`) and whose patch supports that
   curvature (`geometry.selection.supported`) is grown again with that primitive: a seed on a wide cylinder gives a
   strip first, its cylinder then takes the whole wall.
3. Curved growing: what no plane took (its thin bands along creases opened away) falls into connected pieces;
   each piece's best primitive by GRIC is grown the same way, largest piece first.
4. Merging: touching regions that one primitive of their type explains within the noise (median distance of
   each) become one (pieces of one face cut by a seed order, a warp or an occluding boss).
5. Fragments under ``min_instance_px`` join the touching region whose surface fits them best; left-over part
   pixels (crease bands, pixels without depth inside mask.png) join the nearest region.
6. Labels: type of the region's primitive, axis class of its axis against a part frame estimated from the scene:
   Z = ground normal, X/Y = the dominant horizontal direction of plane normals and cylinder axes (modulo 90
   degrees), X being the one nearer the viewing direction.
Units: metres, camera frame, pixels for image sizes, degrees in the config. Deterministic: no random sampling
(seeds are ordered, fits are least squares, subsamples are strided).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from v2c.camera import backproject
from v2c.geometry.config import RansacConfig
from v2c.geometry.points import mad_sigma, median_depth_sigma
from v2c.geometry.selection import supported
from v2c.labels import AxisClass, PrimitiveType, axis_class, label_of
from v2c.pick import PickConfig, depth_pieces, flying_mask
from v2c.primitives import Cone, Cylinder, Plane, Primitive, Sphere
from v2c.scan import Scan
from v2c.segment.data import FeatureConfig, Ground, estimate_ground, estimate_normals, gravity_frame
from v2c.segment.instances import _fill, _relabel_raster
from v2c.segment.refine import RefineConfig, split_coaxial_steps
from v2c.segment.types import Segmentation


@dataclass(frozen=True)
class GeometricConfig:
    """Thresholds of the geometric segmenter (module docstring; units in the comments)."""

    features: FeatureConfig = field(default_factory=lambda: FeatureConfig(smooth_sigma_px=2.0, diff_step_px=2))
    min_height_m: float = 0.003  # without a mask: part = points this far above the ground plane (metres)
    roi_ground_margin: float = 0.5  # with a ROI and no mask, the ground plane is found in the band this wide around
    # the ROI (fraction of the ROI's smaller side): the support the part stands on, not the frame's largest
    # up-facing plane (a floor far below the real frames' tables); the whole frame where the band finds none
    roi_one_object: bool = True  # with a ROI and no mask, the part is the one object of what stands above the
    # ground in the ROI (`_one_object`: the largest depth-connected piece and the pieces that come near it, with the
    # pixels without depth it encloses): a ROI is a box, and neighbours reach into it
    depth_jump_rel: float = 0.015  # relative depth jump between 4-neighbours that marks a step edge
    noise_sigma_coeff: float = 0.0015  # depth noise sigma = this * z^2 (1/m, z in metres): the `sensor` profile
    dist_sigma: float = 2.5  # plane inlier distance: this many noise sigmas ... (ratio)
    dist_floor_m: float = 0.0005  # ... plus this (metres): the sensor's slow fBm warp bends a face by about this
    curved_dist_sigma: float = 2.5  # curved primitives' inlier distance: this many noise sigmas ... (ratio)
    curved_dist_floor_m: float = 0.0005  # ... plus this (metres)
    normal_deg: float = 20.0  # inlier normal deviation from a plane's normal (degrees)
    curved_normal_deg: float = 40.0  # ... from a curved primitive's (degrees; the smoothed normals of a small hole's
    # wall lean towards the plane around it)
    seed_window_px: int = 3  # half size of the window of a seed's local plane (pixels)
    seed_max_sigma: float = 1.5  # seeds: rms distance to their local plane at most this many noise sigmas (ratio)
    grow_iters: int = 5  # refits of a growing region (count)
    grow_window_px: int = 16  # a region's inliers are first sought this far around it (pixels; speed only)
    fit_points: int = 3000  # most points a region's primitive is fitted to (count; strided subsample)
    polish_points: int = 400  # most points of the robust least-squares polish of a curved fit (count)
    polish_iters: int = 6  # its Gauss-Newton steps (count)
    min_region_px: int = 40  # smallest grown region kept (pixels)
    max_seeds: int = 400  # most seeds tried per scan (count)
    open_px: int = 1  # curved pieces: the unassigned pixels are opened by this radius first (pixels)
    type_prior: tuple[tuple[str, float], ...] = (("cone", 2.0), ("sphere", 4.0))  # extra GRIC penalty of a type,
    # in parameters (a part has many more cylinders than cones and spheres; a sphere fits a short band of a
    # cylinder as well, with fewer parameters)
    axis_hint_px: int = 500  # planes this large lend their normal to the curved fits as a likely axis (pixels)
    axis_hint_deg: float = 10.0  # ... unless one within this angle is there already (degrees)
    axis_hints: int = 4  # ... at most this many, the ground normal included (count)
    plane_rms_sigma: float = 1.3  # a grown plane is tested for curvature only where its rms residual exceeds this
    # many noise sigmas (ratio; true planes of the tuning scans gave 0.35-1.03, the warp included)
    retype: bool = True  # the label's type: the best type by GRIC on the final instance's points
    claim_px: int = 6  # unassigned pixels join the nearest-fitting neighbouring region up to this far (pixels)
    min_instance_px: int = 40  # smaller instances join a neighbour (pixels)
    merge_median_sigma: float = 1.5  # merge: each piece's median |distance| to the joint primitive within this
    # many noise sigmas (ratio) ...
    merge_gric: bool = False  # merge only where the joint primitive also beats the two own ones by GRIC
    strip_kinds: tuple[str, ...] = ("cylinder",)  # curved types two touching planes that are not coplanar may
    # merge into (strips of a wide cylinder that plane seeds cut; cones and spheres also joined two true planes)
    merge_sigma_floor: float = 3.0  # merge: the noise level of the GRIC comparison at least this many sensor sigmas
    merge_floor_m: float = 0.0  # ... plus this (metres; the warp)
    merge_normal_deg: float = 10.0  # ... and planes' normals within this angle (degrees)
    max_fill_px: float = 12.0  # farthest a leftover pixel joins an instance (pixels)
    aligned_deg: float = 12.0  # axis class tolerance against the estimated part frame (degrees)
    coaxial_split: bool = False  # cylinder instances are cut where their radius steps (`refine.split_coaxial_steps`,
    # with ``refine``'s settings, the learned path's)
    refine: RefineConfig = field(default_factory=RefineConfig)
    crop_margin_px: int = 8  # work on the part's bounding box grown by this (pixels)
    ransac: RansacConfig = field(default_factory=RansacConfig)  # type selection (GRIC) and curvature support


# ---------------------------------------------------------------------------------------------------------------
# least-squares primitive fits from points and normals (camera frame, metres)


def _strided(n: int, m: int) -> np.ndarray:
    """Indices of a deterministic subsample of at most ``m`` of ``n`` items."""
    return np.arange(n) if n <= m else np.linspace(0, n - 1, m).astype(np.int64)


def fit_plane(x: np.ndarray) -> Plane:
    """Total least-squares plane through points ``x`` (N, 3), normal facing the camera."""
    c = x.mean(axis=0)
    nrm = np.linalg.eigh((x - c).T @ (x - c))[1][:, 0]
    return Plane(c, -nrm if nrm @ c > 0 else nrm)


def _circle_2d(q: np.ndarray) -> tuple[np.ndarray, float]:
    """Algebraic (Kasa) circle through 2D points ``q`` (N, 2): (centre, radius)."""
    a = np.column_stack([2 * q, np.ones(len(q))])
    sol = np.linalg.lstsq(a, np.sum(q * q, axis=1), rcond=None)[0]
    c = sol[:2]
    return c, float(np.sqrt(max(sol[2] + c @ c, 0.0)))


def fit_cylinder(x: np.ndarray, n: np.ndarray, axis: np.ndarray | None = None) -> Cylinder | None:
    """Cylinder from points and normals (N, 3) about ``axis`` (unit), by default the direction the normals are
    most orthogonal to: the circle is an algebraic fit of the points projected along the axis."""
    a = np.linalg.eigh(n.T @ n)[1][:, 0] if axis is None else axis
    b1, b2 = _basis(a)
    c2, r = _circle_2d(np.column_stack([x @ b1, x @ b2]))
    if not np.isfinite(r) or r <= 0:
        return None
    return Cylinder(c2[0] * b1 + c2[1] * b2, a, r)


def cone_about(x: np.ndarray, axis: np.ndarray) -> Cone | None:
    """Cone about the direction ``axis`` (unit) through points ``x``: the axis line through the algebraic circle
    centre of the points projected along it, the radius a linear function of the height (its slope the tangent
    of the half angle)."""
    b1, b2 = _basis(axis)
    c2, _ = _circle_2d(np.column_stack([x @ b1, x @ b2]))
    o = c2[0] * b1 + c2[1] * b2
    h = (x - o) @ axis
    rho = np.linalg.norm((x - o) - h[:, None] * axis, axis=1)
    if np.ptp(h) <= 0:
        return None
    k, b = np.polyfit(h, rho, 1)
    if abs(k) < 1e-3:
        return None
    a = axis if k > 0 else -axis
    return Cone(o - (b / k) * axis, a, float(np.arctan(abs(k))))


def fit_cone(x: np.ndarray, n: np.ndarray) -> Cone | None:
    """Cone from points and normals: the normals lie on a small circle around the axis (the centred normals'
    thinnest direction), every tangent plane passes through the apex (least squares)."""
    nc = n - n.mean(axis=0)
    a = np.linalg.eigh(nc.T @ nc)[1][:, 0]
    m = n.T @ n
    if np.linalg.cond(m) > 1e8:
        return None
    apex = np.linalg.solve(m, n.T @ np.sum(n * x, axis=1))
    d = x - apex
    if np.median(d @ a) < 0:
        a = -a
    cosang = (d @ a) / np.maximum(np.linalg.norm(d, axis=1), 1e-12)
    half = float(np.arccos(np.clip(np.median(cosang), -1, 1)))
    if not 0.02 < half < np.pi / 2 - 0.02:
        return None
    return Cone(apex, a, half)


def fit_sphere(x: np.ndarray) -> Sphere | None:
    """Algebraic sphere through points ``x`` (N, 3)."""
    a = np.column_stack([2 * x, np.ones(len(x))])
    sol = np.linalg.lstsq(a, np.sum(x * x, axis=1), rcond=None)[0]
    c = sol[:3]
    r2 = sol[3] + c @ c
    return Sphere(c, float(np.sqrt(r2))) if r2 > 0 else None


def _basis(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing the unit ``a`` to an orthonormal basis."""
    t = np.array([1.0, 0, 0]) if abs(a[0]) < 0.9 else np.array([0, 1.0, 0])
    b1 = t - (t @ a) * a
    b1 /= np.linalg.norm(b1)
    b2 = np.array([a[1] * b1[2] - a[2] * b1[1], a[2] * b1[0] - a[0] * b1[2], a[0] * b1[1] - a[1] * b1[0]])
    return b1, b2


def _residuals(kind: str, q: list, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Signed distances of ``x`` (N, 3) to the primitive with parameters ``q`` and their Jacobian (N, k) over the
    local parameters of `_update` (axis tilts along the axis' tangent basis, origin shifts, radius or angle)."""
    if kind == "sphere":
        c, rad = q
        d = x - c
        rho = np.sqrt(np.einsum("ij,ij->i", d, d))
        e = d / np.maximum(rho, 1e-12)[:, None]
        return rho - rad, np.column_stack([-e, -np.ones(len(x))])
    o, a, v = q
    b1, b2 = _basis(a)
    d = x - o
    h = d @ a
    radial = d - h[:, None] * a
    rho = np.sqrt(np.einsum("ij,ij->i", radial, radial))
    e = radial / np.maximum(rho, 1e-12)[:, None]
    e1, e2 = e @ b1, e @ b2
    if kind == "cylinder":
        return rho - v, np.column_stack([-h * e1, -h * e2, -e1, -e2, -np.ones(len(x))])
    sa, ca = np.sin(v), np.cos(v)
    r = -h * sa + rho * ca
    jt1 = -sa * (d @ b1) - ca * h * e1
    jt2 = -sa * (d @ b2) - ca * h * e2
    return r, np.column_stack([jt1, jt2, -ca * e1, -ca * e2, np.full(len(x), sa), -h * ca - rho * sa])


def _update(kind: str, q: list, dv: np.ndarray) -> list:
    """Parameters ``q`` moved by the local step ``dv`` (`_residuals`)."""
    if kind == "sphere":
        return [q[0] + dv[:3], q[1] + dv[3]]
    o, a, v = q
    b1, b2 = _basis(a)
    a2 = a + dv[0] * b1 + dv[1] * b2
    a2 /= np.linalg.norm(a2)
    o2 = o + dv[2] * b1 + dv[3] * b2 + (dv[4] * a if kind == "cone" else 0.0)
    return [o2, a2, v + dv[-1]]


def _polish(p0: Primitive, x: np.ndarray, noise: float, iters: int) -> Primitive:
    """Robust Gauss-Newton on the point-to-surface distances of ``x`` (N, 3): ``iters`` slightly damped steps with
    the analytic Jacobian of `_residuals` and Huber weights (knee at 2 ``noise`` metres). Returns ``p0`` where a
    step degenerates."""
    kind = p0.type
    if isinstance(p0, Sphere):
        q: list = [p0.origin.copy(), float(p0.radius)]
    elif isinstance(p0, Cylinder):
        q = [p0.origin.copy(), p0.axis.copy(), float(p0.radius)]
    else:
        q = [p0.origin.copy(), p0.axis.copy(), float(p0.half_angle)]  # type: ignore[attr-defined]
    for _ in range(iters):
        r, J = _residuals(kind, q, x)
        w = 1.0 / np.maximum(np.abs(r) / (2.0 * noise), 1.0)
        Jw = J * w[:, None]
        A = Jw.T @ J
        A[np.diag_indices(len(A))] *= 1.0 + 1e-3
        try:
            dv = -np.linalg.solve(A + 1e-15 * np.eye(len(A)), Jw.T @ r)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(dv)):
            break
        q = _update(kind, q, dv)
        if np.max(np.abs(dv)) < 1e-7:
            break
    out = Sphere(*q) if kind == "sphere" else Cylinder(*q) if kind == "cylinder" else Cone(*q)
    return out if out.is_finite(axis_tol=0.5) else p0


def fit_of_type(
    kind: str,
    x: np.ndarray,
    n: np.ndarray,
    cfg: GeometricConfig,
    start: Primitive | None = None,
    axes: tuple[np.ndarray, ...] = (),
) -> Primitive | None:
    """The primitive of type ``kind`` ("plane", "cylinder", "cone", "sphere") for points and normals (N, 3): planes
    by total least squares; curved types from ``start`` (one of that type), else from closed-form fits from the
    points and normals and, for cylinders and cones, about each direction of ``axes`` too (the part's frame
    directions: most axes of a part are one of them), each polished by robust Gauss-Newton on the points'
    distances alone (`_polish`: the smoothed normals of a small or narrow patch are poor); the one closest to the
    points (median distance) wins."""
    if kind == "plane":
        return fit_plane(x)
    sub = x[_strided(len(x), cfg.polish_points)]
    noise = median_depth_sigma(sub, cfg.noise_sigma_coeff)
    if start is not None and start.type == kind:
        starts: list[Primitive | None] = [start]
    elif kind == "cylinder":
        starts = [fit_cylinder(x, n)] + [fit_cylinder(x, n, a) for a in axes]
    elif kind == "cone":
        starts = [fit_cone(x, n)] + [cone_about(x, a) for a in axes]
    else:
        starts = [fit_sphere(x)]
    best, best_d = None, np.inf
    for p0 in starts:
        if p0 is None or not p0.is_finite(axis_tol=0.5):
            continue
        p = _polish(p0, sub, noise, cfg.polish_iters) if len(x) >= 12 else p0
        if p.type == "cone" and not 0.01 < p.half_angle < np.pi / 2 - 0.01:  # type: ignore[attr-defined]
            p = p0
        if p.type in ("cylinder", "sphere") and not 0 < p.radius < 10.0:  # type: ignore[attr-defined]
            p = p0
        d = float(np.median(np.abs(p.signed_distance(sub))))
        if d < best_d:
            best, best_d = p, d
    return best


CURVED = ("cylinder", "cone", "sphere")


def gric(prim: Primitive, x: np.ndarray, sigma: np.ndarray, cfg: GeometricConfig) -> float:
    """Torr's GRIC of ``prim`` on points ``x`` (N, 3) with per-point noise ``sigma`` (metres), as
    `geometry.selection.select_type` scores it, plus the type's prior (``type_prior``, in units of one parameter's
    penalty log(3N))."""
    lam = float(np.log(3 * max(len(x), 1)))
    r2 = np.minimum((prim.signed_distance(x) / sigma) ** 2, cfg.ransac.gric_trunc)
    return float(np.sum(r2)) + lam * (_DOF[prim.type] + dict(cfg.type_prior).get(prim.type, 0.0))


def ranked_primitives(
    x: np.ndarray, n: np.ndarray, kinds: tuple[str, ...], cfg: GeometricConfig, axes: tuple[np.ndarray, ...] = ()
) -> list[Primitive]:
    """Primitives of ``kinds`` fitted to points ``x`` and normals ``n`` (N, 3), best (lowest `gric`) first; curved
    ones only where the patch supports their curvature (`geometry.selection.supported`). The noise level is
    the sensor's sigma at each point, at least the best candidate's robust residual level (as
    `geometry.selection.select_type`)."""
    cands: list[Primitive] = []
    for k in kinds:
        if k != "plane" and len(x) < 12:
            continue
        p = fit_of_type(k, x, n, cfg, axes=axes)
        if p is not None and p.is_finite(axis_tol=0.5) and (k == "plane" or supported(p, x, cfg.ransac)):
            cands.append(p)
    if len(cands) <= 1:
        return cands
    level = min(mad_sigma(p.signed_distance(x)) for p in cands)
    sigma = np.maximum(level, cfg.noise_sigma_coeff * x[:, 2] ** 2)
    return sorted(cands, key=lambda p: (gric(p, x, sigma, cfg), _DOF[p.type]))


# ---------------------------------------------------------------------------------------------------------------
# region growing on a cropped pixel grid


@dataclass
class _Grid:
    """The part's bounding box: points P, normals N (h, w, 3), noise-based inlier distance tol (h, w), the pixels
    a region may take (avail) and the part (part)."""

    P: np.ndarray
    N: np.ndarray
    tol: np.ndarray
    tol_curved: np.ndarray
    sigma: np.ndarray
    avail: np.ndarray
    cos_plane: float
    cos_curved: float
    axes: tuple[np.ndarray, ...] = ()  # the part's frame directions as far as known (ground normal, large planes)


def _component_at(mask: np.ndarray, anchor: np.ndarray) -> np.ndarray:
    """The 4-connected component of ``mask`` that shares the most pixels with ``anchor`` (empty if none does)."""
    n, cc = cv2.connectedComponents(mask.astype(np.uint8), connectivity=4)
    if n <= 1:
        return np.zeros_like(mask)
    hits = np.bincount(cc[anchor & mask], minlength=n)
    hits[0] = 0
    if hits.max() == 0:
        return np.zeros_like(mask)
    return cc == int(np.argmax(hits))


def _inliers(prim: Primitive, g: _Grid, free: np.ndarray, win: tuple[slice, slice]) -> np.ndarray:
    """Bool mask of the window ``win``: free pixels within the distance and normal tolerances of ``prim``."""
    fw = free[win]
    vv, uu = np.nonzero(fw)
    P, N = g.P[win], g.N[win]
    x = P[vv, uu]
    tol = (g.tol if prim.type == "plane" else g.tol_curved)[win][vv, uu]
    ok = np.abs(prim.signed_distance(x)) < tol
    cos_t = g.cos_plane if prim.type == "plane" else g.cos_curved
    ok &= np.abs(np.sum(prim.normal(x) * N[vv, uu], axis=1)) > cos_t
    out = np.zeros(fw.shape, bool)
    out[vv[ok], uu[ok]] = True
    return out


def _bbox(m: np.ndarray) -> tuple[int, int, int, int]:
    rows, cols = np.nonzero(m.any(axis=1))[0], np.nonzero(m.any(axis=0))[0]
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _connected_inliers(
    prim: Primitive, g: _Grid, free: np.ndarray, anchor: np.ndarray, cfg: GeometricConfig
) -> np.ndarray:
    """(h, w) bool: the connected set of ``prim``'s free inliers that overlaps ``anchor`` most. Evaluated in a
    window around the anchor (``grow_window_px``), widened while the set reaches the window's edge, so a small
    region costs what its neighbourhood costs, not the part."""
    h, w = free.shape
    out = np.zeros_like(free)
    if not anchor.any():
        return out
    r0, r1, c0, c1 = _bbox(anchor)
    m = cfg.grow_window_px
    while True:
        win = (slice(max(r0 - m, 0), min(r1 + m, h)), slice(max(c0 - m, 0), min(c1 + m, w)))
        comp = _component_at(_inliers(prim, g, free, win), anchor[win])
        if not comp.any():
            return out
        edge = (
            (win[0].start > 0 and comp[0].any())
            or (win[0].stop < h and comp[-1].any())
            or (win[1].start > 0 and comp[:, 0].any())
            or (win[1].stop < w and comp[:, -1].any())
        )
        if not edge:
            out[win] = comp
            return out
        b = _bbox(comp)
        r0, r1 = win[0].start + b[0], win[0].start + b[1]
        c0, c1 = win[1].start + b[2], win[1].start + b[3]
        m *= 2


def _refit(
    kind: str,
    region: np.ndarray,
    g: _Grid,
    cfg: GeometricConfig,
    start: Primitive | None = None,
    axes: tuple[np.ndarray, ...] = (),
) -> Primitive | None:
    """``fit_of_type`` on the pixels ``region`` (a strided subsample)."""
    vv, uu = np.nonzero(region)
    s = _strided(len(vv), cfg.fit_points)
    return fit_of_type(kind, g.P[vv[s], uu[s]], g.N[vv[s], uu[s]], cfg, start, axes)


def grow(
    prim: Primitive, anchor: np.ndarray, free: np.ndarray, g: _Grid, cfg: GeometricConfig
) -> tuple[np.ndarray, Primitive]:
    """Grow ``prim`` from the pixels ``anchor`` over ``free``: its inliers connected to the anchor, refitted and
    grown again until the region stops changing (at most ``grow_iters`` times). Returns (region, primitive)."""
    region = np.zeros_like(free)
    for _ in range(cfg.grow_iters):
        new = _connected_inliers(prim, g, free, anchor | region, cfg)
        if new.sum() < 12:
            return new, prim
        same = np.count_nonzero(new ^ region) <= 0.01 * np.count_nonzero(new)
        region = new
        fitted = _refit(prim.type, region, g, cfg, prim)
        if fitted is None or not fitted.is_finite(axis_tol=0.5):
            break
        prim = fitted
        if same:
            break
    return region, prim


# ---------------------------------------------------------------------------------------------------------------


def _local_planes(P: np.ndarray, valid: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel: (rms distance of the window's points to their PCA plane (metres), the plane's unit normal)
    over the (2r+1)^2 window of valid pixels (box filters of the moments, one batched eigen-decomposition)."""
    k = (2 * r + 1, 2 * r + 1)
    v = valid.astype(np.float64)
    cnt = cv2.boxFilter(v, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    Pv = P * v[..., None]
    s1 = np.stack(
        [cv2.boxFilter(Pv[..., i], -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT) for i in range(3)], -1
    )
    s2 = np.empty(P.shape[:2] + (3, 3))
    for i in range(3):
        for j in range(i, 3):
            s2[..., i, j] = s2[..., j, i] = cv2.boxFilter(
                Pv[..., i] * P[..., j], -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT
            )
    c = np.maximum(cnt, 1.0)[..., None, None]
    mu = s1 / c[..., 0]
    cov = s2 / c - mu[..., :, None] * mu[..., None, :]
    rms = np.full(valid.shape, np.inf)
    nrm = np.zeros(P.shape)
    ok = valid & (cnt >= 0.6 * k[0] * k[1])
    w, vec = np.linalg.eigh(cov[ok])
    rms[ok] = np.sqrt(np.maximum(w[:, 0], 0.0))
    nrm[ok] = vec[:, :, 0]
    return rms, nrm


def _plane_phase(g: _Grid, cfg: GeometricConfig) -> list[tuple[np.ndarray, Primitive]]:
    """Plane growing from the flattest seeds (module docstring, step 2); a region a curved primitive explains
    better is grown again with it."""
    rms, lnrm = _local_planes(g.P, g.avail, cfg.seed_window_px)
    ratio = rms / np.maximum(g.sigma, 1e-9)
    sv, su = np.nonzero(g.avail & (ratio <= cfg.seed_max_sigma))
    order = np.argsort(ratio[sv, su], kind="stable")
    free = g.avail.copy()
    visited = np.zeros_like(free)
    out: list[tuple[np.ndarray, Primitive]] = []
    tried = 0
    r = cfg.seed_window_px
    for k in order:
        v, u = int(sv[k]), int(su[k])
        if not free[v, u] or visited[v, u]:
            continue
        tried += 1
        if tried > cfg.max_seeds:
            break
        anchor = np.zeros_like(free)
        anchor[max(v - r, 0) : v + r + 1, max(u - r, 0) : u + r + 1] = True
        anchor &= free
        nrm = lnrm[v, u]
        prim: Primitive = Plane(g.P[v, u], -nrm if nrm @ g.P[v, u] > 0 else nrm)
        region, prim = grow(prim, anchor, free, g, cfg)
        if region.sum() < cfg.min_region_px:
            visited |= region | anchor
            continue
        prim, region = _curved_instead(prim, region, free, g, cfg)
        out.append((region, prim))
        free &= ~region
        if prim.type == "plane" and region.sum() >= cfg.axis_hint_px:
            _add_axis(g, prim.axis_vector, cfg)
    return out


def _add_axis(g: _Grid, a: np.ndarray, cfg: GeometricConfig) -> None:
    """Add the direction ``a`` to the grid's frame directions unless one lies within ``axis_hint_deg`` of it."""
    if len(g.axes) < cfg.axis_hints and all(abs(float(a @ b)) < np.cos(np.deg2rad(cfg.axis_hint_deg)) for b in g.axes):
        g.axes = (*g.axes, np.asarray(a, float))


def _curved_instead(
    prim: Primitive, region: np.ndarray, free: np.ndarray, g: _Grid, cfg: GeometricConfig
) -> tuple[Primitive, np.ndarray]:
    """A grown plane region's primitive and pixels, or, where the plane leaves residuals above the noise
    (``plane_rms_sigma``) and a curved primitive beats it on the region's points (`ranked_primitives`), that
    primitive grown from the region, when it takes at least as many pixels."""
    vv, uu = np.nonzero(region)
    s = _strided(len(vv), cfg.fit_points)
    x, n = g.P[vv[s], uu[s]], g.N[vv[s], uu[s]]
    rms = float(np.sqrt(np.mean(prim.signed_distance(x) ** 2)))
    if rms <= cfg.plane_rms_sigma * float(np.median(g.sigma[vv[s], uu[s]])):
        return prim, region
    best = ranked_primitives(x, n, ("plane",) + CURVED, cfg, g.axes)[0]
    if best.type == "plane":
        return prim, region
    reg2, prim2 = grow(best, region, free, g, cfg)
    if reg2.sum() >= region.sum():
        return prim2, reg2
    return prim, region


_DOF = {"plane": 3, "sphere": 4, "cylinder": 5, "cone": 6, "torus": 7}


def _curved_phase(g: _Grid, free: np.ndarray, cfg: GeometricConfig) -> list[tuple[np.ndarray, Primitive]]:
    """Pieces no plane took, largest first: their primitives ranked by GRIC (`ranked_primitives`), the first that
    grows to ``min_region_px`` kept (module docstring, step 3)."""
    out: list[tuple[np.ndarray, Primitive]] = []
    free = free.copy()
    tried = np.zeros_like(free)
    ker = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * cfg.open_px + 1, 2 * cfg.open_px + 1))
    for _ in range(cfg.max_seeds):
        cand = cv2.morphologyEx((free & ~tried).astype(np.uint8), cv2.MORPH_OPEN, ker).astype(bool)
        n, cc, stats, _ = cv2.connectedComponentsWithStats(cand.astype(np.uint8), connectivity=4)
        if n <= 1:
            break
        j = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
        if stats[j, cv2.CC_STAT_AREA] < cfg.min_region_px:
            break
        piece = cc == j
        vv, uu = np.nonzero(piece)
        s = _strided(len(vv), cfg.fit_points)
        region = np.zeros_like(piece)
        for prim in ranked_primitives(g.P[vv[s], uu[s]], g.N[vv[s], uu[s]], ("plane",) + CURVED, cfg, g.axes):
            region, prim = grow(prim, piece, free, g, cfg)
            if region.sum() >= cfg.min_region_px:
                break
        if region.sum() < cfg.min_region_px:
            tried |= piece
            continue
        out.append((region, prim))
        free &= ~region
        tried |= piece & ~region
    return out


# ---------------------------------------------------------------------------------------------------------------
# merging, fragments, labels


def _touching(inst: np.ndarray) -> set[tuple[int, int]]:
    """Pairs (a < b) of ids that are 4-neighbours somewhere (0 excluded)."""
    pairs: set[tuple[int, int]] = set()
    for a, b in ((inst[:, :-1], inst[:, 1:]), (inst[:-1, :], inst[1:, :])):
        m = (a != b) & (a > 0) & (b > 0)
        lo, hi = np.minimum(a[m], b[m]), np.maximum(a[m], b[m])
        pairs |= set(zip(lo.tolist(), hi.tolist(), strict=True))
    return pairs


def _explains(prim: Primitive | None, parts: list[np.ndarray], g: _Grid, cfg: GeometricConfig) -> float | None:
    """The largest median |distance| / noise sigma of ``prim`` over the parts when it is within
    merge_median_sigma for every part, a plane's normal within merge_normal_deg of each part's own and a curved
    primitive supported by their union (`geometry.selection.supported`); else None."""
    if prim is None or not prim.is_finite(axis_tol=0.5):
        return None
    worst = 0.0
    xs = []
    for m in parts:
        vv, uu = np.nonzero(m & g.avail)
        if len(vv) < 3:
            continue
        s = _strided(len(vv), cfg.fit_points)
        x = g.P[vv[s], uu[s]]
        xs.append(x)
        d = float(np.median(np.abs(prim.signed_distance(x)) / (g.sigma[vv[s], uu[s]] + cfg.merge_floor_m / 1.5)))
        if d > cfg.merge_median_sigma:
            return None
        worst = max(worst, d)
        if isinstance(prim, Plane) and len(x) >= 3 and not _coplanar(fit_plane(x), prim, cfg):
            return None
    if not xs:
        return None
    if prim.type != "plane" and not supported(prim, np.concatenate(xs), cfg.ransac):
        return None
    return worst


def _joint(
    a: int, b: int, inst: np.ndarray, prims: dict[int, Primitive], g: _Grid, cfg: GeometricConfig
) -> tuple[float, Primitive] | None:
    """(GRIC gain per point, joint primitive) of the best primitive that explains both regions ``a`` and ``b``
    (`_explains`) and beats their own two primitives by GRIC on their union (truncated squared residuals at the
    pooled robust noise level of the two own fits, at least ``merge_sigma_floor`` sensor sigmas, plus log(3N) per
    parameter and the type priors); None if none does. Candidates: either one's type, and the curved types for two
    planes that are not coplanar (strips of a wide cylinder that plane seeds cut)."""
    ma, mb = inst == a, inst == b
    vv, uu = np.nonzero((ma | mb) & g.avail)
    s = _strided(len(vv), cfg.fit_points)
    vv, uu = vv[s], uu[s]
    if len(vv) < 6:
        return None
    x, in_a = g.P[vv, uu], ma[vv, uu]
    r_own = np.where(in_a, prims[a].signed_distance(x), prims[b].signed_distance(x))
    level = mad_sigma(r_own)
    sigma = np.maximum(level, cfg.merge_sigma_floor * g.sigma[vv, uu])
    lam = float(np.log(3 * len(x)))
    prior = dict(cfg.type_prior)

    def cost(r: np.ndarray, kinds: list[str]) -> float:
        pen = sum(_DOF[k] + prior.get(k, 0.0) for k in kinds)
        return float(np.sum(np.minimum((r / sigma) ** 2, cfg.ransac.gric_trunc))) + lam * pen

    separate = cost(r_own, [prims[a].type, prims[b].type])
    kinds = {prims[a].type, prims[b].type}
    if kinds == {"plane"} and not _coplanar(prims[a], prims[b], cfg):
        kinds |= set(cfg.strip_kinds)
    best = None
    for k in sorted(kinds, key=lambda t: _DOF[t]):
        start = prims[a] if prims[a].type == k else prims[b] if prims[b].type == k else None
        joint = _refit(k, ma | mb, g, cfg, start, g.axes)
        fit = _explains(joint, [ma, mb], g, cfg)
        if fit is None:
            continue
        gain = (cost(joint.signed_distance(x), [k]) - separate) / len(x)  # type: ignore[union-attr]
        key = gain if cfg.merge_gric else fit
        if (gain < 0 or not cfg.merge_gric) and (best is None or key < best[0]):
            best = (key, joint)
    return best


def merge_regions(
    inst: np.ndarray, prims: dict[int, Primitive], g: _Grid, cfg: GeometricConfig, reach: np.ndarray | None = None
) -> tuple[np.ndarray, dict[int, Primitive]]:
    """Merge touching regions that one primitive explains (module docstring, step 4; `_joint`), the pair whose
    joint primitive fits closest first, repeated until no pair merges. reach: (h, w) bool part pixels through
    which regions touch when each takes the nearest of them (`instances._fill`, ``max_fill_px``): two pieces of
    one face parted by a line of pixels without depth or a crease band are neighbours."""
    near = inst.copy() if reach is None else _fill(inst, reach, cfg.max_fill_px)
    cache: dict[tuple[int, int], tuple[float, Primitive] | None] = {}
    while True:
        best = None
        for a, b in sorted(_touching(near)):
            if a not in prims or b not in prims:
                continue
            if (a, b) not in cache:
                cache[(a, b)] = _joint(a, b, inst, prims, g, cfg)
            r = cache[(a, b)]
            if r is not None and (best is None or r[0] < best[0]):
                best = (r[0], a, b, r[1])
        if best is None:
            return inst, prims
        _, a, b, joint = best
        inst[inst == b] = a
        near[near == b] = a
        prims[a] = joint
        del prims[b]
        cache = {k: v for k, v in cache.items() if a not in k and b not in k}


def _coplanar(p: Primitive, q: Primitive, cfg: GeometricConfig) -> bool:
    return abs(float(p.axis_vector @ q.axis_vector)) >= np.cos(np.deg2rad(cfg.merge_normal_deg))


def claim_boundaries(inst: np.ndarray, prims: dict[int, Primitive], g: _Grid, cfg: GeometricConfig) -> np.ndarray:
    """Part pixels with depth that no region took (the bands along creases where the smoothed normals turn, the
    rims of small faces) join, one pixel ring at a time (``claim_px`` rings), the 4-neighbouring region whose
    primitive lies closest to them, where it lies within the inlier distance: the cut falls on the crease, where
    the two surfaces meet, instead of half-way across the band."""
    cand_ok = g.avail.copy()
    h, w = inst.shape
    for _ in range(cfg.claim_px):
        todo = cand_ok & (inst == 0)
        if not todo.any():
            break
        pad = np.pad(inst, 1)
        nb = np.stack([pad[:-2, 1:-1], pad[2:, 1:-1], pad[1:-1, :-2], pad[1:-1, 2:]])[:, todo]  # (4, M)
        has = (nb > 0).any(axis=0)
        if not has.any():
            break
        vv, uu = np.nonzero(todo)
        vv, uu, nb = vv[has], uu[has], nb[:, has]
        x = g.P[vv, uu]
        best = np.full(len(vv), np.inf)
        lab = np.zeros(len(vv), np.int32)
        for k in np.unique(nb[nb > 0]):
            sel = (nb == k).any(axis=0)
            p = prims.get(int(k))
            if p is None:
                continue
            tol = g.tol if p.type == "plane" else g.tol_curved
            d = np.abs(p.signed_distance(x[sel])) / tol[vv[sel], uu[sel]]
            better = d < best[sel]
            idx = np.nonzero(sel)[0][better]
            best[idx] = d[better]
            lab[idx] = k
        ok = best < 1.0
        if not ok.any():
            break
        inst[vv[ok], uu[ok]] = lab[ok]
    return inst


def absorb_small(inst: np.ndarray, prims: dict[int, Primitive], g: _Grid, cfg: GeometricConfig) -> np.ndarray:
    """Instances under min_instance_px join the touching instance whose primitive fits their points best (median
    distance); without one they are dropped (their pixels are filled later)."""
    area = np.bincount(inst.ravel(), minlength=int(inst.max()) + 1)
    small = [i for i in np.argsort(area) if 0 < area[i] < cfg.min_instance_px]
    pairs = _touching(inst)
    for i in small:
        m = inst == i
        nbrs = [b if a == i else a for a, b in pairs if i in (a, b)]
        nbrs = [j for j in nbrs if j in prims and area[j] >= cfg.min_instance_px]
        vv, uu = np.nonzero(m & g.avail)
        if nbrs and len(vv):
            x = g.P[vv, uu]
            j = min(nbrs, key=lambda j: float(np.median(np.abs(prims[j].signed_distance(x)))))
            inst[m] = j
            area[j] += area[i]
        else:
            inst[m] = 0
        area[i] = 0
    return inst


@dataclass
class _Fit:
    kind: PrimitiveType
    axis: np.ndarray | None  # plane normal / cylinder, cone axis (camera frame, unit); None for spheres
    area: int


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
    """(part pixels (H, W) bool, ground plane or None): the mask's valid pixels, else those standing min_height_m
    above the ground plane (all valid pixels without one), within the ROI; with a ROI and no mask only the one
    object among them (roi_one_object, `_one_object`) and the pixels without depth it encloses."""
    ground = None
    if scan.mask is None and scan.roi is not None and cfg.roi_ground_margin > 0:
        x0, y0, x1, y1 = scan.roi
        m = int(round(cfg.roi_ground_margin * min(x1 - x0, y1 - y0)))
        h, w = scan.depth.shape
        band = np.zeros((h, w), bool)
        band[max(y0 - m, 0) : min(y1 + m, h), max(x0 - m, 0) : min(x1 + m, w)] = True
        band &= ~scan.roi_mask()
        ground = estimate_ground(scan.depth, scan.K, ~band, cfg.features)  # (its mask = pixels left out)
    if ground is None:
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
        if scan.mask is None and cfg.roi_one_object and part.any():
            from scipy.ndimage import binary_fill_holes

            obj = _one_object(part, scan)
            # pixels without depth that the object encloses (a shiny lid) are the object's, as in a drawn mask
            part = obj | (binary_fill_holes(obj) & ~valid & scan.roi_mask())
    return part, ground


def _one_object(part: np.ndarray, scan: Scan, pick: PickConfig | None = None) -> np.ndarray:
    """The object among ``part``'s pixels (H, W) bool: its largest depth-connected piece (`v2c.pick.depth_pieces`)
    and every piece whose points come within the pick's join step (connect_step_mm + connect_step_rel x depth) of
    it in space, repeated while one joins: pieces of one object that holes without depth part (a shiny lid), not
    the neighbours that stand apart from it (a bottle in front of a box). Flying pixels (`v2c.pick.flying_mask`)
    are left out of that nearness: a ramp of them across a depth step would bring the object behind within reach."""
    from scipy.spatial import cKDTree

    pick = pick or PickConfig()
    depth = np.asarray(scan.depth, np.float64)
    fly = flying_mask(depth, scan.K, pick)
    _, pieces = depth_pieces(part, depth, scan.K, pick, fly)
    flat = np.flatnonzero(part)
    piece = pieces.ravel()[flat]  # each part pixel's piece
    x = backproject(depth, scan.K).reshape(-1, 3)[flat]
    step = pick.connect_step_mm / 1000.0 + pick.connect_step_rel * x[:, 2]
    solid = ~fly.ravel()[flat]  # the pixels whose nearness counts
    ids, sizes = np.unique(piece, return_counts=True)
    inside = np.isin(piece, ids[np.argmax(sizes)])  # the largest piece (the first of equal ones)
    while not inside.all():  # loop while some piece joins: every piece with a point near the object joins at once
        ask, have = ~inside & solid, inside & solid
        if not ask.any() or not have.any():
            break
        near = cKDTree(x[have]).query(x[ask], k=1)[0] < step[ask]
        if not near.any():
            break
        inside |= np.isin(piece, piece[ask][near])
    keep = np.zeros(part.shape, bool)
    keep.flat[flat[inside]] = True
    return keep


def step_edges(depth: np.ndarray, cfg: GeometricConfig) -> np.ndarray:
    """(H, W) bool: pixels with a relative depth jump above ``depth_jump_rel`` to a 4-neighbour."""
    edge = np.zeros(depth.shape, bool)
    dp = np.pad(depth, 1, mode="edge")
    for nb in (dp[1:-1, 2:], dp[1:-1, :-2], dp[2:, 1:-1], dp[:-2, 1:-1]):
        edge |= (nb > 0) & (np.abs(nb - depth) > cfg.depth_jump_rel * np.maximum(depth, 1e-3))
    return edge


def _final_primitive(p: Primitive, m: np.ndarray, g: _Grid, cfg: GeometricConfig) -> Primitive:
    """The primitive that labels an instance: with ``retype``, the best by `gric` of every type fitted to its valid
    pixels ``m`` (a region grown as a flexible type, a cone say, is often a cylinder once its pixels are all
    known); else its own type refitted. The grown primitive where too few pixels or a fit degenerates."""
    if np.count_nonzero(m) < 12:
        return p
    vv, uu = np.nonzero(m)
    s = _strided(len(vv), cfg.fit_points)
    x, n = g.P[vv[s], uu[s]], g.N[vv[s], uu[s]]
    if cfg.retype:
        ranked = ranked_primitives(x, n, ("plane",) + CURVED, cfg, g.axes)
        return ranked[0] if ranked else p
    fitted = fit_of_type(p.type, x, n, cfg, p)
    return fitted if fitted is not None and fitted.is_finite(axis_tol=0.5) else p


def _crop_box(m: np.ndarray, margin: int) -> tuple[slice, slice]:
    rows, cols = np.nonzero(m.any(axis=1))[0], np.nonzero(m.any(axis=0))[0]
    h, w = m.shape
    return (
        slice(max(rows[0] - margin, 0), min(rows[-1] + margin + 1, h)),
        slice(max(cols[0] - margin, 0), min(cols[-1] + margin + 1, w)),
    )


def _labels(
    inst: np.ndarray, prims: dict[int, Primitive], frame: np.ndarray, cfg: GeometricConfig
) -> tuple[np.ndarray, np.ndarray]:
    n = int(inst.max())
    labels = np.zeros(n + 1, np.uint8)
    scores = np.zeros(n + 1, np.float32)
    for i in range(1, n + 1):
        p = prims.get(i)
        if p is None:
            continue
        if p.type == "sphere":
            labels[i] = label_of(PrimitiveType.SPHERE, None)
        else:
            ax = axis_class(p.axis_vector, frame, tol_deg=cfg.aligned_deg)
            labels[i] = label_of(PrimitiveType(p.type), ax if isinstance(ax, AxisClass) else AxisClass.U)
        scores[i] = 0.5
    return labels, scores


def segment_geometric(scan: Scan, config: GeometricConfig | None = None) -> Segmentation:
    """Segment a scan from its depth alone (see the module docstring)."""
    cfg = config or GeometricConfig()
    part, ground = part_region(scan, cfg)
    h, w = part.shape
    inst_full = np.zeros((h, w), np.int32)
    if part.sum() < cfg.min_region_px:
        return Segmentation(
            instances=inst_full, labels=np.zeros(1, np.uint8), scores=np.zeros(1, np.float32), method="geometric"
        )
    sl = _crop_box(part, cfg.crop_margin_px)
    depth = scan.depth[sl]
    K = scan.K.copy()
    K[0, 2] -= sl[1].start
    K[1, 2] -= sl[0].start
    P = backproject(depth, K)
    N = estimate_normals(depth, K, cfg.features).astype(np.float64)
    sigma = cfg.noise_sigma_coeff * depth * depth
    avail = part[sl] & ~step_edges(depth, cfg) & (np.linalg.norm(N, axis=2) > 0.5)
    g = _Grid(
        P,
        N,
        cfg.dist_sigma * sigma + cfg.dist_floor_m,
        cfg.curved_dist_sigma * sigma + cfg.curved_dist_floor_m,
        sigma,
        avail,
        float(np.cos(np.deg2rad(cfg.normal_deg))),
        float(np.cos(np.deg2rad(cfg.curved_normal_deg))),
        () if ground is None else (np.asarray(ground.up, float),),
    )

    regions = _plane_phase(g, cfg)
    free = avail.copy()
    for m, _ in regions:
        free &= ~m
    regions += _curved_phase(g, free, cfg)
    inst = np.zeros(depth.shape, np.int32)
    prims: dict[int, Primitive] = {}
    for i, (m, p) in enumerate(regions, start=1):
        inst[m & (inst == 0)] = i
        prims[i] = p
    fill_region = part if scan.mask is None else scan.mask & (scan.roi_mask() if scan.roi is not None else True)
    inst = claim_boundaries(inst, prims, g, cfg)
    inst, prims = merge_regions(inst, prims, g, cfg, fill_region[sl])
    inst = absorb_small(inst, prims, g, cfg)
    # pixels of the part without a region (crease bands, no depth inside mask.png) join the nearest instance
    inst = _fill(inst, fill_region[sl], cfg.max_fill_px)
    # final primitive of each instance on all its points; ids renumbered in raster order
    order = _relabel_raster(inst)
    final: dict[int, Primitive] = {}
    for old, p in prims.items():
        m = inst == old
        if not m.any():
            continue
        new = int(order[m][0])
        final[new] = _final_primitive(p, m & avail, g, cfg)
    inst = order
    fits = [
        _Fit(PrimitiveType(p.type), p.axis_vector if p.type != "sphere" else None, int((inst == i).sum()))
        for i, p in final.items()
    ]
    part_c = np.zeros_like(part)
    part_c[sl] = inst > 0
    frame = part_frame(fits, gravity_frame(ground, scan.K, part if part.any() else None, part.shape))
    labels, scores = _labels(inst, final, frame, cfg)
    inst_full[sl] = inst
    seg = Segmentation(instances=inst_full, labels=labels, scores=scores, method="geometric")
    if cfg.coaxial_split:  # shaft sections whose radii differ by less than the inlier distance grow as one
        seg = split_coaxial_steps(seg, scan.depth, scan.K, cfg.refine)
    return seg
