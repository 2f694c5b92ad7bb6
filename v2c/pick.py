"""Pick the part in a cluttered real frame: drop the supporting plane, keep the depth-connected object under a point.

A real frame without ``mask.png`` or a ROI shows a table and several objects; reconstructing all of it is slow and
not what a user wants. `pick_object` finds the support plane (RANSAC on the back-projected depth: the plane with
the most points among those whose normal lies within `PickConfig.max_plane_tilt_deg` of the camera's viewing axis),
drops every point within `PickConfig.plane_drop_mm` of it or behind it (and of up to two more planes parallel to it
and well above it, a table seen standing on a floor), splits what is left into depth-connected
pieces (4-neighbours whose depths differ by less than `PickConfig.connect_step_mm` plus
`PickConfig.connect_step_rel` of the depth) and returns the piece under the pixel asked for (the image centre by
default), or the nearest one within `PickConfig.search_radius_px`.

When it applies (`v2c.scan.load_scan` decides, with `should_pick`): ``mode="centre"`` or a ``point`` always picks;
``mode="auto"`` (the commands' default) picks only a *scene*: a frame with no mask.png, no ROI and no ground truth
(``gt/``), more than `PickConfig.large_frame_px` valid pixels, and a support plane holding at least
`PickConfig.scene_plane_share` of them; ``mode="none"`` (the library's default) never picks. The commands set the
request with `pick_request` (a context, as `v2c.scan_checks.scan_limits`).

Units: metres and pixels (u = column, v = row); thresholds in millimetres where they say so. Deterministic: RANSAC
draws from `PickConfig.seed`.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from v2c.camera import backproject
from v2c.contexts import scoped
from v2c.depth_clean import DepthCleanConfig, flying_pixels

__all__ = [
    "PICK_MODES",
    "PickConfig",
    "PickError",
    "PickRequest",
    "PickResult",
    "current_pick",
    "depth_pieces",
    "flying_mask",
    "fit_support_plane",
    "large_frame_warning",
    "parse_point",
    "pick_object",
    "pick_request",
    "should_pick",
]

#: ``--pick`` values: auto = pick only a scene (see the module doc), centre = always the object under the image
#: centre (or under --point), none = never (the whole frame).
PICK_MODES = ("auto", "centre", "none")


class PickError(ValueError):
    """No object could be picked (no support plane, nothing under the point); the message says what to give."""


@dataclass(frozen=True)
class PickConfig:
    """Every threshold of the picking, with its unit."""

    large_frame_px: int = 40_000  # valid pixels above which a frame with no mask/ROI is "large" (warned, auto-picked)
    scene_plane_share: float = 0.25  # auto: the support plane must hold this share of the valid pixels (0..1)
    ransac_iterations: int = 400  # plane hypotheses drawn
    ransac_points: int = 20_000  # at most this many valid points (an even stride) take part in RANSAC
    plane_inlier_mm: float = 8.0  # RANSAC inlier distance to a hypothesis (millimetres)
    plane_drop_mm: float = 12.0  # points this close to the support plane, or behind it, are dropped (millimetres)
    max_plane_tilt_deg: float = 80.0  # the support plane's normal within this angle of the viewing axis (degrees)
    max_planes: int = 3  # support planes dropped at most: the largest, then ones parallel to it (table on a floor)
    extra_plane_share: float = 0.06  # a further plane must hold this share of the valid pixels (0..1) ...
    parallel_deg: float = 10.0  # ... lie within this angle of the first plane (degrees) ...
    extra_plane_height_mm: float = 250.0  # ... and this high above it: a table top over a floor, not a box top
    connect_step_mm: float = 8.0  # 4-neighbours join one object when their depths differ by less than this (mm) ...
    connect_step_rel: float = 0.01  # ... plus this fraction of their depth (a step grows with distance)
    flying_window_px: int = 5  # a reading with a nearer and a farther layer inside this window (pixels, odd; 0 =
    # off) lies between two surfaces (`depth_clean.flying_pixels`): it joins a piece but never joins two
    flying_grazing_deg: float = 80.0  # a layer is a reading farther / nearer than a surface seen at this incidence
    # would be across half the window (degrees from the viewing ray; a jump of (window // 2) px x z / fx x tan of
    # it: 9.8 mm at 0.92 m on the real frames' fx 1066 px): readings on a face seen less obliquely never count
    min_object_px: int = 150  # smaller pieces are not objects (speckle, edges of the plane)
    search_radius_px: float = 60.0  # no object under the point: the nearest one within this distance (pixels)
    seed: int = 0  # RANSAC's random draws


@dataclass(frozen=True)
class PickRequest:
    """What the user asked for: mode (one of `PICK_MODES`) and point (u, v) pixels or None (the image centre)."""

    mode: str = "none"
    point: tuple[int, int] | None = None


@dataclass
class PickResult:
    """The picked object: mask (H, W) bool; box (x0, y0, x1, y1) pixels, x1/y1 exclusive; point (u, v) asked for;
    plane (normal (3,), offset d: n . p + d = 0, metres, normal towards the camera); plane_share of the valid
    pixels on the plane (0..1); how: one line saying what was picked and how to override it."""

    mask: np.ndarray
    box: tuple[int, int, int, int]
    point: tuple[int, int]
    plane: tuple[np.ndarray, float]
    plane_share: float
    how: str


_CURRENT: contextvars.ContextVar[PickRequest | None] = contextvars.ContextVar("v2c_pick", default=None)


def current_pick() -> PickRequest:
    """The `PickRequest` in force: ``mode="none"`` unless inside `pick_request`."""
    return _CURRENT.get() or PickRequest()


def pick_request(request: PickRequest) -> contextlib.AbstractContextManager[PickRequest]:
    """Make ``request`` the one `v2c.scan.load_scan` follows inside the block (the commands' --pick / --point)."""
    return scoped(_CURRENT, request)


def parse_point(text: str | tuple | list | None) -> tuple[int, int] | None:
    """``"X,Y"`` (pixels, column then row) or a pair -> (u, v) ints; None stays None. Raises PickError."""
    if text is None:
        return None
    parts = [p.strip() for p in text.split(",")] if isinstance(text, str) else list(text)
    try:
        vals = [float(p) for p in parts]
    except (TypeError, ValueError):
        raise PickError(f"point {text!r}: expected two pixel coordinates X,Y (e.g. 320,240)") from None
    if len(vals) != 2 or not all(math.isfinite(v) and v >= 0 and v == int(v) for v in vals):
        raise PickError(f"point {text!r}: expected two non-negative whole pixel coordinates X,Y (e.g. 320,240)")
    return int(vals[0]), int(vals[1])


def should_pick(request: PickRequest, has_mask: bool, has_roi: bool, has_gt: bool) -> bool:
    """Whether to try picking at all: never with a mask or ROI, never for mode none; auto skips scans with ground
    truth (synthetic scans behave as before); centre or a point always tries."""
    if has_mask or has_roi or (request.mode == "none" and request.point is None):
        return False
    return not (request.mode == "auto" and request.point is None and has_gt)


def fit_support_plane(
    points: np.ndarray, cfg: PickConfig, parallel_to: np.ndarray | None = None
) -> tuple[np.ndarray, float, np.ndarray]:
    """RANSAC plane on (N, 3) camera-frame points (metres): the hypothesis with the most inliers within
    ``plane_inlier_mm`` among those whose normal is within ``max_plane_tilt_deg`` of the viewing axis (and within
    ``parallel_deg`` of the unit normal ``parallel_to`` when given), refined by least squares on its inliers.
    Returns (unit normal pointing towards the camera, d with n . p + d = 0, inlier flags over ``points``).
    Raises PickError when no plane qualifies."""
    n_all = len(points)
    if n_all < 3:
        raise PickError("fewer than 3 depth readings: no support plane")
    stride = max(1, n_all // cfg.ransac_points)
    sub = points[::stride]
    rng = np.random.default_rng(cfg.seed)
    idx = rng.integers(0, len(sub), size=(cfg.ransac_iterations, 3))
    a, b, c = sub[idx[:, 0]], sub[idx[:, 1]], sub[idx[:, 2]]
    nrm = np.cross(b - a, c - a)
    length = np.linalg.norm(nrm, axis=1)
    ok = length > 1e-12
    nrm = nrm[ok] / length[ok, None]
    a = a[ok]
    cos_tilt = math.cos(math.radians(cfg.max_plane_tilt_deg))
    facing = np.abs(nrm[:, 2]) >= cos_tilt
    if parallel_to is not None:
        facing &= np.abs(nrm @ parallel_to) >= math.cos(math.radians(cfg.parallel_deg))
    nrm, a = nrm[facing], a[facing]
    if not len(nrm):
        raise PickError(f"no plane within {cfg.max_plane_tilt_deg:g} degrees of facing the camera")
    d = -np.einsum("ij,ij->i", nrm, a)
    tol = cfg.plane_inlier_mm / 1000.0
    counts = (np.abs(sub @ nrm.T + d) < tol).sum(axis=0)  # (hypotheses,)
    best = int(np.argmax(counts))
    n, dd = nrm[best], float(d[best])
    for _ in range(2):  # least squares on the inliers; a second pass settles the inlier set
        inl = np.abs(points @ n + dd) < tol
        if inl.sum() < 3:
            break
        centre = points[inl].mean(axis=0)
        _, _, vt = np.linalg.svd(points[inl] - centre, full_matrices=False)
        n = vt[2]
        dd = float(-n @ centre)
    if dd < 0:  # orient towards the camera (the origin): n . 0 + d > 0
        n, dd = -n, -dd
    return n, dd, np.abs(points @ n + dd) < tol


def depth_pieces(
    keep: np.ndarray, depth: np.ndarray, K: np.ndarray, cfg: PickConfig | None = None, fly: np.ndarray | None = None
) -> tuple[int, np.ndarray]:
    """Depth-connected pieces of the pixels ``keep``: 4-neighbours join when their depths differ by less than
    connect_step_mm + connect_step_rel x depth. A flying pixel (a reading between two layers of a depth edge,
    `flying_mask`, with intrinsics ``K``) never joins two pieces: a sensor's ramp of such
    readings across a depth step (a box in front of the object behind it) would otherwise make one piece of both.
    It takes the piece of the joined neighbour nearest in depth (repeated along a ramp), or one of its own.
    ``fly``: the flying pixels when the caller has them (`flying_mask`). Returns (count, (H, W) int labels, -1
    outside ``keep``)."""
    cfg = cfg or PickConfig()
    h, w = keep.shape
    fly = keep & (flying_mask(depth, K, cfg) if fly is None else fly)
    core = keep & ~fly
    ids = np.arange(h * w).reshape(h, w)
    rows, cols = [], []
    for sl_a, sl_b in _NEIGHBOUR_SLICES:
        join = core[sl_a] & core[sl_b] & _joins(depth[sl_a], depth[sl_b], cfg)
        rows.append(ids[sl_a][join])
        cols.append(ids[sl_b][join])
    r, c = np.concatenate(rows), np.concatenate(cols)
    graph = sparse.coo_matrix((np.ones(len(r), np.int8), (r, c)), shape=(h * w, h * w))
    count, labels = connected_components(graph, directed=False)
    labels = np.where(core, labels.reshape(h, w), -1)
    labels = _attach(labels, fly, depth, cfg)
    left = fly & (labels < 0)
    if left.any():  # flying pixels no piece reaches: pieces of their own
        sub = depth_pieces(left, depth, K, replace(cfg, flying_window_px=0))[1]
        labels = np.where(left, sub + count, labels)
    used, labels_c = np.unique(labels[keep], return_inverse=True)
    out = np.full((h, w), -1, np.int64)
    out[keep] = labels_c
    return len(used), out


#: (a, b) slices of the horizontal and the vertical 4-neighbour pairs of an image.
_NEIGHBOUR_SLICES = (
    ((slice(None), slice(0, -1)), (slice(None), slice(1, None))),
    ((slice(0, -1),), (slice(1, None),)),
)


def _joins(za: np.ndarray, zb: np.ndarray, cfg: PickConfig) -> np.ndarray:
    """Whether neighbours of depths ``za``, ``zb`` (metres) are one surface: their step under the join step."""
    return np.abs(za - zb) < cfg.connect_step_mm / 1000.0 + cfg.connect_step_rel * np.minimum(za, zb)


def flying_mask(depth: np.ndarray, K: np.ndarray, cfg: PickConfig) -> np.ndarray:
    """(H, W) bool: the flying pixels of ``depth`` (metres; intrinsics ``K``, pixels) by the pick's flying_*
    settings."""
    if cfg.flying_window_px <= 0:
        return np.zeros(depth.shape, bool)
    rel = (cfg.flying_window_px // 2) * math.tan(math.radians(cfg.flying_grazing_deg)) / float(K[0, 0])
    fc = DepthCleanConfig(flying_window_px=cfg.flying_window_px, flying_jump_m=0.0, flying_jump_rel=rel)
    return flying_pixels(np.asarray(depth, np.float32), fc)


def _attach(labels: np.ndarray, fly: np.ndarray, depth: np.ndarray, cfg: PickConfig) -> np.ndarray:
    """``labels`` with each flying pixel given the piece of its joined 4-neighbour nearest in depth, ring by ring
    (a pixel attached in one ring passes its piece on in the next) until no more attach: pieces only grow, none
    joins another, so a steep face of one object that reads as flying pixels throughout stays whole."""
    labels = labels.copy()
    h, w = labels.shape
    while True:
        todo = fly & (labels < 0)
        if not todo.any():
            break
        best = np.full((h, w), np.inf)
        new = labels.copy()
        for dy, dx in ((0, 1), (0, -1), (1, 0), (-1, 0)):
            lab_n = np.full((h, w), -1, labels.dtype)
            z_n = np.zeros((h, w))
            ys = slice(max(dy, 0), h + min(dy, 0))
            yd = slice(max(-dy, 0), h + min(-dy, 0))
            xs = slice(max(dx, 0), w + min(dx, 0))
            xd = slice(max(-dx, 0), w + min(-dx, 0))
            lab_n[yd, xd] = labels[ys, xs]  # the neighbour at (y + dy, x + dx)
            z_n[yd, xd] = depth[ys, xs]
            step = np.abs(z_n - depth)
            ok = todo & (lab_n >= 0) & _joins(depth, z_n, cfg) & (step < best)
            new[ok] = lab_n[ok]
            best[ok] = step[ok]
        if (new == labels).all():
            break
        labels = new
    return labels


def pick_object(
    depth: np.ndarray,
    K: np.ndarray,
    valid: np.ndarray,
    point: tuple[int, int] | None = None,
    cfg: PickConfig | None = None,
) -> PickResult:
    """Pick the object under ``point`` ((u, v) pixels; None = the image centre) of a depth map (H, W) metres with
    intrinsics K (pixels), among the ``valid`` pixels: drop the support plane, split the rest into depth-connected
    pieces, return the piece under the point (or the nearest within search_radius_px). Raises PickError naming
    what failed."""
    cfg = cfg or PickConfig()
    h, w = depth.shape
    at = "the image centre" if point is None else "--point"
    if point is None:
        point = (w // 2, h // 2)
    u, v = point
    if not (0 <= u < w and 0 <= v < h):
        raise PickError(f"point ({u}, {v}) lies outside the image ({w}x{h}; need 0 <= X < {w}, 0 <= Y < {h})")
    pts = backproject(depth, K)
    n, d, on_plane = fit_support_plane(pts[valid], cfg)
    share = float(on_plane.mean())
    drop_m = cfg.plane_drop_mm / 1000.0
    keep = valid & (pts @ n + d > drop_m)  # above the largest plane, towards the camera
    for _ in range(cfg.max_planes - 1):  # a table on a floor: drop the parallel planes that hold a share too
        try:
            n2, d2, on2 = fit_support_plane(pts[keep], cfg, parallel_to=n)
        except PickError:
            break
        if on2.sum() < cfg.extra_plane_share * valid.sum():
            break
        if np.median(pts[keep][on2] @ n + d) < cfg.extra_plane_height_mm / 1000.0:
            break  # a large flat face of an object on the support, not a further support
        keep &= np.abs(pts @ n2 + d2) > drop_m
    _, labels = depth_pieces(keep, depth.astype(np.float64), K, cfg)
    sizes = np.bincount(labels[keep], minlength=1)
    big = keep & (sizes[np.maximum(labels, 0)] >= cfg.min_object_px)
    if big[v, u]:
        label, how_found = int(labels[v, u]), "under"
    else:
        vv, uu = np.nonzero(big)
        if not len(uu):
            raise PickError(f"no object of {cfg.min_object_px} px or more stands off the support plane")
        dist2 = (uu - u) ** 2 + (vv - v) ** 2
        k = int(np.argmin(dist2))
        if dist2[k] > cfg.search_radius_px**2:
            raise PickError(
                f"no object under or within {cfg.search_radius_px:g} px of pixel ({u}, {v}) once the support "
                f"plane is removed (nearest at {math.sqrt(dist2[k]):.0f} px, pixel ({uu[k]}, {vv[k]}))"
            )
        label, how_found = int(labels[vv[k], uu[k]]), f"{math.sqrt(dist2[k]):.0f} px from"
    mask = labels == label
    ys, xs = np.nonzero(mask)
    box = (int(xs.min()), int(ys.min()), int(xs.max()) + 1, int(ys.max()) + 1)
    how = (
        f"picked the object {how_found} {at} ({u}, {v}): {int(mask.sum()):,} px in box {box[0]},{box[1]},"
        f"{box[2]},{box[3]} (support plane dropped: {100 * share:.0f} % of the valid pixels; points within "
        f"{cfg.plane_drop_mm:g} mm of it or behind it left out; an object = pixels joined by depth steps under "
        f"{cfg.connect_step_mm:g} mm + {100 * cfg.connect_step_rel:g} %)"
    )
    return PickResult(mask=mask, box=box, point=(u, v), plane=(n, d), plane_share=share, how=how)


def large_frame_warning(n_valid: int, cfg: PickConfig | None = None) -> str | None:
    """The warning for a frame reconstructed whole: None when it has at most large_frame_px valid pixels."""
    cfg = cfg or PickConfig()
    if n_valid <= cfg.large_frame_px:
        return None
    return (
        f"no mask.png or --roi: the whole frame is reconstructed ({n_valid:,} valid px, over "
        f"{cfg.large_frame_px:,}), which can take minutes; give --roi x0,y0,x1,y1, a mask.png, --point X,Y or "
        "--pick centre"
    )
