"""Network inputs and training targets of the learned segmenter.

Inputs (``compute_features``), one (C, H, W) float32 stack per scan, all from the scan alone:

=====  =========================================================================================
0-2    RGB, normalised ((x / 255 - 0.5) / 0.25)
3-5    surface normals from the depth, expressed in a gravity frame: (forward, left, up). ``up`` is the
       ground plane's normal found by RANSAC, ``forward`` the viewing ray to the part projected on the
       ground. Axis classes are view-corrected (SCAN_FORMAT.md), so in this frame an X plane has
       |n_forward| > |n_left| and a Z plane has |n_up| ~ 1: axis classes become nearly per-pixel.
6      height above the ground plane / ``height_scale_m`` (0 where unknown)
7      depth discontinuity: largest relative depth jump to a 4-neighbour, scaled and clipped to [0, 1]
8      1 where the depth has no reading
=====  =========================================================================================

Targets: the 18-class label map (255 = ignored) and a face-boundary map (pixels whose 3x3 neighbourhood
holds two different face ids, background included: a band 2 px wide). Clutter (objects beside the part that
random appearance places, `v2c.synth.appearance`) is ignored, not background: `ignore_clutter`.

Scans are cached once into uint8 memory-mapped arrays (``build_cache``) so training does no image decoding.
Frames: camera (OpenCV), metres.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from v2c.camera import backproject

if TYPE_CHECKING:  # the scan loader (pydantic, picking, recordings) only where a scan folder is read
    from v2c.scan import Scan

NUM_INPUTS = 9
MIRROR_SIGN_CHANNEL = 4  # the "left" normal component: the only channel a horizontal mirror negates
RGB_MEAN, RGB_STD = 0.5, 0.25


@dataclass(frozen=True)
class FeatureConfig:
    """Parameters of the input features (units in the comments)."""

    smooth_sigma_px: float = 1.5  # Gaussian smoothing of back-projected points before differencing (pixels)
    diff_step_px: int = 2  # half-baseline of the central differences for normals (pixels)
    edge_gain: float = 25.0  # depth-edge channel = clip(relative depth jump * gain, 0, 1) (1 / relative depth)
    height_scale_m: float = 0.1  # height above ground is divided by this (metres)
    height_clip: float = 4.0  # height channel clipped to [-height_clip, height_clip] (scaled units)
    ground_stride_px: int = 4  # subsampling of pixels for the ground RANSAC (pixels)
    ground_iters: int = 150  # RANSAC hypotheses for the ground plane
    ground_inlier_rel: float = 0.012  # ground inlier distance, relative to the depth (metres per metre)
    ground_min_share: float = 0.08  # ground must hold at least this share of sampled valid pixels
    ground_max_tilt_deg: float = 80.0  # ground normal within this angle of the camera's -y (degrees)
    seed: int = 0  # RANSAC seed (features are deterministic)


@dataclass
class Ground:
    """Ground plane in the camera frame: points p with up . p + offset = 0; up points towards the camera side."""

    up: np.ndarray  # (3,) unit normal, camera frame
    offset: float  # metres
    share: float  # share of sampled valid pixels that are inliers


def estimate_normals(depth: np.ndarray, K: np.ndarray, cfg: FeatureConfig = FeatureConfig()) -> np.ndarray:
    """(H, W, 3) float32 unit normals in the camera frame, facing the camera; 0 where depth is 0.

    Smooths the back-projected points with a validity-normalised Gaussian (so holes do not bleed in), then
    takes central differences ``diff_step_px`` pixels apart.
    """
    valid = (depth > 0).astype(np.float32)
    pts = backproject(depth, K).astype(np.float32)
    s = cfg.smooth_sigma_px
    wsum = cv2.GaussianBlur(valid, (0, 0), s)
    sm = cv2.GaussianBlur(pts * valid[..., None], (0, 0), s) / np.maximum(wsum, 1e-6)[..., None]
    k = cfg.diff_step_px
    pad = np.pad(sm, ((k, k), (k, k), (0, 0)), mode="edge")
    du = pad[k:-k, 2 * k :] - pad[k:-k, : -2 * k]
    dv = pad[2 * k :, k:-k] - pad[: -2 * k, k:-k]
    n = -np.cross(du, dv)
    norm = np.linalg.norm(n, axis=2, keepdims=True)
    n = np.where(norm > 1e-12, n / np.maximum(norm, 1e-12), 0.0)
    # face the camera: n . p < 0
    flip = np.sum(n * sm, axis=2) > 0
    n[flip] *= -1
    n[valid == 0] = 0
    return n.astype(np.float32)


def estimate_ground(
    depth: np.ndarray, K: np.ndarray, mask: np.ndarray | None = None, cfg: FeatureConfig = FeatureConfig()
) -> Ground | None:
    """RANSAC the ground plane from the depth (pixels of ``mask`` = part are excluded). None if not found.

    Among planes whose normal lies within ``ground_max_tilt_deg`` of the camera's up (-y), the one with the most
    inliers; refined by least squares on its inliers.
    """
    st = cfg.ground_stride_px
    d = depth[::st, ::st]
    ok = d > 0
    if mask is not None:
        ok &= ~mask[::st, ::st]
    pts = backproject(depth, K)[::st, ::st][ok]
    if len(pts) < 30:
        return None
    rng = np.random.default_rng(cfg.seed)
    tol = cfg.ground_inlier_rel * pts[:, 2]
    cos_tilt = np.cos(np.deg2rad(cfg.ground_max_tilt_deg))
    idx = rng.integers(0, len(pts), size=(cfg.ground_iters, 3))
    a, b, c = pts[idx[:, 0]], pts[idx[:, 1]], pts[idx[:, 2]]
    nrm = np.cross(b - a, c - a)
    ln = np.linalg.norm(nrm, axis=1)
    good = ln > 1e-12
    nrm[good] /= ln[good, None]
    nrm[nrm[:, 1] > 0] *= -1  # up has negative camera y
    good &= -nrm[:, 1] >= cos_tilt
    if not good.any():
        return None
    nrm, a = nrm[good], a[good]
    off = -np.sum(nrm * a, axis=1)
    counts = (np.abs(pts @ nrm.T + off[None, :]) < tol[:, None]).sum(axis=0)
    best = int(np.argmax(counts))
    inl = np.abs(pts @ nrm[best] + off[best]) < tol
    if inl.sum() < cfg.ground_min_share * len(pts):
        return None
    q = pts[inl]
    cen = q.mean(axis=0)
    _, _, vt = np.linalg.svd(q - cen, full_matrices=False)
    up = vt[2]
    if up[1] > 0:
        up = -up
    offset = -float(up @ cen)
    if offset < 0:  # camera must be on the up side; otherwise keep the RANSAC orientation
        up, offset = nrm[best], float(off[best])
    return Ground(up=up.astype(np.float64), offset=offset, share=float(inl.mean()))


def gravity_frame(ground: Ground | None, K: np.ndarray, mask: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray:
    """(3, 3) rows (forward, left, up) in the camera frame.

    up: the ground normal (camera -y without ground); forward: the ray to the mask centroid (image centre without
    mask) projected on the ground plane; left = up x forward.
    """
    h, w = shape
    up = ground.up if ground is not None else np.array([0.0, -1.0, 0.0])
    if mask is not None and mask.any():
        vv, uu = np.nonzero(mask)
        u, v = uu.mean(), vv.mean()
    else:
        u, v = (w - 1) / 2.0, (h - 1) / 2.0
    ray = np.linalg.solve(K, np.array([u, v, 1.0]))
    fwd = ray - (ray @ up) * up
    if np.linalg.norm(fwd) < 1e-9:
        fwd = np.array([0.0, 0.0, 1.0]) - up[2] * up
    fwd /= np.linalg.norm(fwd)
    left = np.cross(up, fwd)
    return np.stack([fwd, left, up])


def compute_features(
    color: np.ndarray,
    depth: np.ndarray,
    K: np.ndarray,
    mask: np.ndarray | None = None,
    cfg: FeatureConfig = FeatureConfig(),
) -> np.ndarray:
    """(NUM_INPUTS, H, W) float32 network input of one scan (see the module docstring for the channels).

    color: (H, W, 3) uint8 RGB; depth: (H, W) metres, 0 = none; K: (3, 3) pixels; mask: optional (H, W) bool
    part mask (only used to exclude the part from the ground fit and to find the viewing direction).
    """
    h, w = depth.shape
    out = np.empty((NUM_INPUTS, h, w), np.float32)
    out[0:3] = ((color.astype(np.float32) / 255.0 - RGB_MEAN) / RGB_STD).transpose(2, 0, 1)
    n = estimate_normals(depth, K, cfg)
    ground = estimate_ground(depth, K, mask, cfg)
    frame = gravity_frame(ground, K, mask, (h, w)).astype(np.float32)
    out[3:6] = np.einsum("hwc,kc->khw", n, frame)
    valid = depth > 0
    if ground is not None:
        pts = backproject(depth, K)
        hgt = (pts @ ground.up + ground.offset) / cfg.height_scale_m
        out[6] = np.where(valid, np.clip(hgt, -cfg.height_clip, cfg.height_clip), 0.0)
    else:
        out[6] = 0.0
    out[7] = depth_edges(depth, cfg.edge_gain)
    out[8] = ~valid
    return out


@dataclass(frozen=True)
class TargetConfig:
    """How training targets are made from a generated scan's ground truth (units in the comments)."""

    clutter_height_m: float = 0.002  # non-part pixels of the clean depth this far above the ground are clutter


def ignore_clutter(
    labels: np.ndarray,
    faces: np.ndarray,
    depth_clean: np.ndarray,
    K: np.ndarray,
    cfg: TargetConfig = TargetConfig(),
    features: FeatureConfig = FeatureConfig(),
) -> np.ndarray:
    """``labels`` with clutter set to ignored (255): pixels off the part whose clean depth stands more than
    ``clutter_height_m`` above the ground plane (RANSAC on the clean depth without the part).

    The generator's ground truth labels the part only, so boxes, cylinders and spheres standing beside it read as
    background, and a network trained on that is taught to call part-like surfaces background, which no input
    feature can tell apart from the part's own (the pipeline takes the part from the scan's mask or ROI). Without a
    ground plane the labels are returned unchanged.
    """
    ground = estimate_ground(depth_clean, K, faces > 0, features)
    if ground is None:
        return labels
    height = backproject(depth_clean, K) @ ground.up + ground.offset
    clutter = (faces == 0) & (depth_clean > 0) & (height > cfg.clutter_height_m)
    return np.where(clutter, np.uint8(255), labels).astype(np.uint8)


def depth_edges(depth: np.ndarray, gain: float) -> np.ndarray:
    """(H, W) float32 in [0, 1]: largest |depth jump| to a 4-neighbour / depth, times ``gain``, clipped."""
    pad = np.pad(depth, 1, mode="edge")
    jump = np.zeros_like(depth)
    for dv, du in ((0, 1), (2, 1), (1, 0), (1, 2)):
        nb = pad[dv : dv + depth.shape[0], du : du + depth.shape[1]]
        both = (nb > 0) & (depth > 0)
        jump = np.maximum(jump, np.where(both, np.abs(nb - depth), 0.0))
    rel = jump / np.maximum(depth, 1e-3)
    return np.clip(rel * gain, 0.0, 1.0).astype(np.float32)


def scan_features(scan: Scan, cfg: FeatureConfig = FeatureConfig()) -> np.ndarray:
    """``compute_features`` of a loaded scan (uses mask.png when the scan has one)."""
    return compute_features(scan.color, scan.depth, scan.K, scan.mask, cfg)


def boundary_map(faces: np.ndarray, radius_px: int = 1) -> np.ndarray:
    """(H, W) bool: pixels whose (2r+1)^2 neighbourhood holds two different face ids (background = 0 counts)."""
    k = np.ones((2 * radius_px + 1,) * 2, np.uint8)
    f = faces.astype(np.float32)  # cv2 dilate/erode work on float32 exactly for ids < 2^24
    return cv2.dilate(f, k) != cv2.erode(f, k)


# ---------------------------------------------------------------------------------------------------------------
# cache of many scans as uint8 memmaps


def quantise(feat: np.ndarray) -> np.ndarray:
    """float32 features -> uint8 for the cache (rgb and normals and edges keep ~0.01 precision)."""
    q = np.empty(feat.shape, np.uint8)
    q[0:3] = np.clip(feat[0:3] * RGB_STD + RGB_MEAN, 0, 1) * 255 + 0.5
    q[3:6] = np.clip(feat[3:6] * 127.0 + 128.0, 0, 255) + 0.5
    q[6] = np.clip(feat[6] * 30.0 + 128.0, 0, 255) + 0.5
    q[7:9] = np.clip(feat[7:9], 0, 1) * 255 + 0.5
    return q


def dequantise(q: np.ndarray) -> np.ndarray:
    """Inverse of ``quantise`` on a (..., C, H, W) uint8 array (any leading batch dims); float32."""
    q = q.astype(np.float32)
    f = np.empty_like(q)
    f[..., 0:3, :, :] = (q[..., 0:3, :, :] / 255.0 - RGB_MEAN) / RGB_STD
    f[..., 3:6, :, :] = (q[..., 3:6, :, :] - 128.0) / 127.0
    f[..., 6, :, :] = (q[..., 6, :, :] - 128.0) / 30.0
    f[..., 7:9, :, :] = q[..., 7:9, :, :] / 255.0
    return f


def find_scans(root: str | Path) -> list[Path]:
    """Scan folders (holding camera.json and gt/labels.png) under ``root``, sorted."""
    out = []
    for dirpath, dirnames, filenames in os.walk(Path(root), followlinks=True):
        dirnames[:] = [d for d in dirnames if d != "gt" and not d.startswith(".")]
        if "camera.json" in filenames and (Path(dirpath) / "gt" / "labels.png").is_file():
            out.append(Path(dirpath))
    return sorted(out)


def build_cache(
    scans: list[Path], cache_dir: str | Path, cfg: FeatureConfig = FeatureConfig(), log_every: int = 200
) -> Path:
    """Write features (uint8), labels and boundaries of ``scans`` to ``cache_dir`` (x.u8, y.u8, b.u8, index.json).

    Idempotent: an existing complete cache made from the same scan list is reused. A scan that `load_scan`
    refuses (`ScanError`, e.g. a generated clutter object nearer than the depth limit) is left out with a line
    naming it; the index lists the scans kept (``scans``) and the ones asked for (``requested``).
    """
    from v2c.scan import ScanError, load_scan

    cache_dir = Path(cache_dir)
    index_p = cache_dir / "index.json"
    names = [str(p) for p in scans]
    if index_p.is_file():
        idx = json.loads(index_p.read_text())
        if idx.get("requested", idx.get("scans")) == names:
            return cache_dir
    cache_dir.mkdir(parents=True, exist_ok=True)
    entries = []
    off = 0
    with (
        open(cache_dir / "x.u8", "wb") as fx,
        open(cache_dir / "y.u8", "wb") as fy,
        open(cache_dir / "b.u8", "wb") as fb,
    ):
        kept: list[str] = []
        for i, p in enumerate(scans):
            try:
                scan = load_scan(p)
            except ScanError as exc:
                print(f"cache: left out {p}: {exc}", flush=True)
                continue
            assert scan.gt is not None
            kept.append(str(p))
            q = quantise(scan_features(scan, cfg))
            fx.write(q.tobytes())
            labels = ignore_clutter(scan.gt.labels.astype(np.uint8), scan.gt.faces, scan.gt.depth_clean, scan.K)
            fy.write(labels.tobytes())
            fb.write(boundary_map(scan.gt.faces).astype(np.uint8).tobytes())
            h, w = scan.height, scan.width
            entries.append({"offset": off, "h": h, "w": w})
            off += h * w
            if log_every and (i + 1) % log_every == 0:
                print(f"cache: {i + 1}/{len(scans)} scans", flush=True)
    index_p.write_text(json.dumps({"scans": kept, "requested": names, "entries": entries, "channels": NUM_INPUTS}))
    return cache_dir


class CachedScans:
    """Random crops from a cache written by ``build_cache`` (numpy; the training loop makes tensors)."""

    def __init__(self, cache_dir: str | Path) -> None:
        cache_dir = Path(cache_dir)
        idx = json.loads((cache_dir / "index.json").read_text())
        self.entries = idx["entries"]
        self.scans = idx["scans"]
        total = sum(e["h"] * e["w"] for e in self.entries)
        self.x = np.memmap(cache_dir / "x.u8", np.uint8, "r", shape=(total * NUM_INPUTS,))
        self.y = np.memmap(cache_dir / "y.u8", np.uint8, "r", shape=(total,))
        self.b = np.memmap(cache_dir / "b.u8", np.uint8, "r", shape=(total,))

    def __len__(self) -> int:
        return len(self.entries)

    def full(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Quantised features (C, H, W) uint8, labels (H, W) uint8 and boundaries (H, W) uint8 of scan i."""
        e = self.entries[i]
        h, w, o = e["h"], e["w"], e["offset"]
        x = self.x[o * NUM_INPUTS : (o + h * w) * NUM_INPUTS].reshape(NUM_INPUTS, h, w)
        return x, self.y[o : o + h * w].reshape(h, w), self.b[o : o + h * w].reshape(h, w)

    def crop(
        self, i: int, size: int, rng: np.random.Generator, flip: bool, part_share: float = 0.75
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A random ``size`` x ``size`` crop of scan i (padded with ignore if smaller), optionally mirrored.

        A horizontal mirror keeps every label valid (types, and view-corrected axis classes since mirroring keeps
        angles to the viewing direction); only the 'left' normal component changes sign.
        Crops favour the part: the centre is drawn among part pixels ``part_share`` of the time.
        """
        x, y, b = self.full(i)
        h, w = y.shape
        if rng.random() < part_share:
            vv, uu = np.nonzero(y[::4, ::4] > 0)
            if len(vv):
                k = rng.integers(len(vv))
                cv, cu = vv[k] * 4, uu[k] * 4
            else:
                cv, cu = rng.integers(h), rng.integers(w)
            v0 = int(np.clip(cv - size // 2, 0, max(h - size, 0)))
            u0 = int(np.clip(cu - size // 2, 0, max(w - size, 0)))
        else:
            v0 = int(rng.integers(0, max(h - size, 0) + 1))
            u0 = int(rng.integers(0, max(w - size, 0) + 1))
        xs = np.zeros((NUM_INPUTS, size, size), np.uint8)
        ys = np.full((size, size), 255, np.uint8)
        bs = np.zeros((size, size), np.uint8)
        ch, cw = min(size, h), min(size, w)
        xs[:, :ch, :cw] = x[:, v0 : v0 + ch, u0 : u0 + cw]
        ys[:ch, :cw] = y[v0 : v0 + ch, u0 : u0 + cw]
        bs[:ch, :cw] = b[v0 : v0 + ch, u0 : u0 + cw]
        if flip:
            xs = xs[:, :, ::-1].copy()
            c = MIRROR_SIGN_CHANNEL  # q(-n) = 256 - q(n)
            xs[c] = (256 - xs[c].astype(np.int16)).clip(0, 255).astype(np.uint8)
            ys = ys[:, ::-1].copy()
            bs = bs[:, ::-1].copy()
        return xs, ys, bs
