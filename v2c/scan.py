"""Load and validate one RGB-D scan folder (../shared/SCAN_FORMAT.md).

A scan folder holds ``color.png`` (or ``color.jpg``), ``depth.png`` (uint16, scaled by ``depth_scale``) or
``depth.npy`` (float metres), ``camera.json``, optionally ``mask.png`` and, for synthetic scans, ``gt/``.

Everything is checked before it is returned; any problem raises :class:`ScanError`, whose message always names the
file and the problem. Inside the pipeline: metres, camera frame (OpenCV: x right, y down, z forward), pixel
coordinates (u, v) = (column, row) with pixel centres at integers.

Region of interest: ``roi = (x0, y0, x1, y1)`` in pixels, x1/y1 exclusive. It does NOT crop: every array keeps the
full image size (so K, pixel coordinates and ground truth stay valid) and the ROI only restricts
:attr:`Scan.valid`. Use :meth:`Scan.roi_mask` or ``scan.valid`` to restrict work to it.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from v2c.camera import DEFAULT_DEPTH_SCALE_M, Camera, backproject
from v2c.depth_clean import clean_loaded_depth
from v2c.errors import ScanError
from v2c.pick import PickConfig, PickError, PickRequest, current_pick, large_frame_warning, pick_object, should_pick
from v2c.recordings import current_frame_index, is_open3d_folder, is_recording, open3d_frame_files, read_bag_frame
from v2c.scan_checks import (
    ScanLimits,
    check_depth_surface,
    check_depth_values,
    check_intrinsics_plausible,
    check_pixels,
    current_limits,
    load_camera,
    parse_camera,
    read_image_bytes,
    read_json,
    read_npy,
    scan_limits,
)

__all__ = [
    "Camera",
    "GroundTruth",
    "Scan",
    "ScanError",
    "ScanLimits",
    "backproject",
    "load_camera",
    "load_scan",
    "parse_camera",
    "parse_roi",
    "read_image",
    "roi_to_mask",
    "scan_limits",
]

COLOR_NAMES = ("color.png", "color.jpg", "color.jpeg")
DEPTH_NAMES = ("depth.png", "depth.npy")
GT_DIR = "gt"

log = logging.getLogger("v2c.scan")


@dataclass
class GroundTruth:
    """Ground truth of a synthetic scan (``gt/``), all in the scan's camera frame.

    faces: (H, W) uint16, 1 + B-rep face index, 0 = background/ground.
    labels: (H, W) uint8, 18-class label (255 = non-analytic face).
    primitives: primitives.json entries as loaded (params in metres, camera frame).
    depth_clean: (H, W) float32 metres, noise-free depth, 0 = no part/ground reading.
    meta: meta.json (part_size_m, axes_cam rows X, Y, Z in the camera frame, seed, family, ...).
    step_path: gt/part.step (camera frame, millimetres).
    """

    faces: np.ndarray
    labels: np.ndarray
    primitives: list[dict]
    depth_clean: np.ndarray
    meta: dict
    step_path: Path

    @property
    def part_size_m(self) -> float | None:
        """Largest side of the part's rest-pose bounding box (metres), if meta.json gives it."""
        v = self.meta.get("part_size_m")
        return None if v is None else float(v)

    def __repr__(self) -> str:
        return (
            f"GroundTruth({len(self.primitives)} faces, {self.faces.shape[1]}x{self.faces.shape[0]}, "
            f"step={str(self.step_path)!r})"
        )

    def visible_face_ids(self) -> np.ndarray:
        """Sorted 0-based face indices that cover at least one pixel of faces.png."""
        vals = np.unique(self.faces)
        return vals[vals > 0].astype(np.int64) - 1


@dataclass
class Scan:
    """One loaded RGB-D scan.

    color: (H, W, 3) uint8 RGB. depth: (H, W) float32 metres along the camera z axis, 0 = no reading.
    K: (3, 3) float64 pinhole intrinsics (pixels). mask: (H, W) bool, True = part, or None.
    roi: (x0, y0, x1, y1) pixels, x1/y1 exclusive, or None; a validity restriction only (arrays stay full size).
    """

    path: Path
    color: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    mask: np.ndarray | None
    roi: tuple[int, int, int, int] | None
    gt: GroundTruth | None
    depth_scale: float = DEFAULT_DEPTH_SCALE_M  # metres per unit of depth.png (1.0 for depth.npy)
    camera_format: str = "v2c"  # "v2c" | "open3d" | "bop": which camera.json form was read
    files: dict[str, Path] = field(default_factory=dict)  # "color", "depth", "camera"[, "mask"]: files read
    notes: list[str] = field(default_factory=list)  # what the loader changed (readings dropped as implausible)
    picked: str | None = None  # how `v2c.pick` chose ``mask`` (no mask.png, no ROI), None when it did not

    @property
    def height(self) -> int:
        """Image height (pixels)."""
        return int(self.depth.shape[0])

    @property
    def width(self) -> int:
        """Image width (pixels)."""
        return int(self.depth.shape[1])

    @property
    def fx(self) -> float:
        """Focal length along u (pixels), K[0, 0]."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length along v (pixels), K[1, 1]."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point u (pixels), K[0, 2]."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point v (pixels), K[1, 2]."""
        return float(self.K[1, 2])

    def roi_mask(self) -> np.ndarray:
        """(H, W) bool: True inside the ROI (everywhere when there is none)."""
        return roi_to_mask(self.roi, self.height, self.width)

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: depth > 0, and inside mask.png and the ROI where given."""
        v = self.depth > 0
        if self.mask is not None:
            v &= self.mask
        if self.roi is not None:
            v &= self.roi_mask()
        return v

    def points(self) -> np.ndarray:
        """(H, W, 3) float64 camera-frame points in metres; (0, 0, 0) where depth is 0."""
        return backproject(self.depth, self.K)

    def __repr__(self) -> str:
        return (
            f"Scan({str(self.path)!r}, {self.width}x{self.height}, fx={self.fx:.2f}, "
            f"mask={'yes' if self.mask is not None else 'no'}, roi={self.roi}, "
            f"gt={'yes' if self.gt is not None else 'no'})"
        )


# ----------------------------------------------------------------------------------------------------------------
# region of interest


def roi_to_mask(roi: tuple[int, int, int, int] | None, height: int, width: int) -> np.ndarray:
    """(H, W) bool mask of a ROI (x0, y0, x1, y1), x1/y1 exclusive; all True when roi is None."""
    m = np.zeros((height, width), dtype=bool) if roi is not None else np.ones((height, width), dtype=bool)
    if roi is not None:
        x0, y0, x1, y1 = roi
        m[y0:y1, x0:x1] = True
    return m


def parse_roi(text: str | tuple | list | None) -> tuple[int, int, int, int] | None:
    """Parse ``"x0,y0,x1,y1"`` (pixels, x1/y1 exclusive) into a tuple of ints; None passes through.

    Raises ScanError for anything that is not four integers with x0 < x1 and y0 < y1. Whether it fits the image
    is checked by load_scan.
    """
    if text is None:
        return None
    if isinstance(text, str):
        parts = [p.strip() for p in text.replace(" ", ",").split(",") if p.strip()]
    else:
        parts = list(text)
    try:
        vals = []
        for p in parts:
            f = float(p)
            if not math.isfinite(f) or f != int(f):
                raise ValueError
            vals.append(int(f))
    except (TypeError, ValueError):
        raise ScanError(f"ROI {text!r}: expected four integers x0,y0,x1,y1 (pixels)") from None
    if len(vals) != 4:
        raise ScanError(f"ROI {text!r}: expected four integers x0,y0,x1,y1 (pixels), got {len(vals)}")
    x0, y0, x1, y1 = vals
    if x1 <= x0 or y1 <= y0:
        raise ScanError(f"ROI {tuple(vals)} is empty: need x0 < x1 and y0 < y1 (x1/y1 exclusive)")
    return (x0, y0, x1, y1)


# ----------------------------------------------------------------------------------------------------------------
# image files


def read_image(path: Path, flags: int = cv2.IMREAD_UNCHANGED, limits: ScanLimits | None = None) -> np.ndarray:
    """Read a PNG or JPEG fully: header (pixel count against ``limits.max_pixels``), chunk CRCs and completeness
    are checked before decoding (`v2c.scan_checks.read_image_bytes`).

    Returns the array as OpenCV decodes it (BGR channel order for colour). Raises ScanError naming the file.
    """
    path = Path(path)
    data = read_image_bytes(path, limits)
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if img is None or img.size == 0:
        raise ScanError(f"{path}: cannot decode image")
    return img


def _read_color(path: Path, limits: ScanLimits | None = None) -> np.ndarray:
    img = read_image(path, cv2.IMREAD_UNCHANGED, limits)
    if img.dtype != np.uint8:
        raise ScanError(f"{path}: colour image must be 8-bit, got {img.dtype}")
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)
    elif img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    elif img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    else:
        raise ScanError(f"{path}: colour image with {img.shape[2]} channels (need 1, 3 or 4)")
    return np.ascontiguousarray(img)


def _read_depth_png(path: Path, scale_m: float, limits: ScanLimits) -> tuple[np.ndarray, list[str]]:
    """depth.png (uint16 units x scale_m metres per unit) -> (float32 metres, notes); range-checked."""
    raw = read_image(path, cv2.IMREAD_UNCHANGED, limits)
    if raw.ndim != 2:
        raise ScanError(f"{path}: depth image must have one channel, got {raw.shape[2]}")
    if raw.dtype == np.uint8:
        raise ScanError(
            f"{path}: 8-bit depth image; depth must be 16-bit unsigned (depth units of camera.json depth_scale)"
        )
    if raw.dtype != np.uint16:
        raise ScanError(f"{path}: depth image must be 16-bit unsigned, got {raw.dtype}")
    if raw.size and (raw == np.iinfo(np.uint16).max).all():
        raise ScanError(
            f"{path}: every depth value is 65535, the 16-bit maximum (saturated or a 'no reading' "
            "marker); expected distances, 0 = no reading"
        )
    return check_depth_values(
        raw.astype(np.float64) * scale_m, path, limits, f"{scale_m:g} m per unit from camera.json"
    )


def _read_depth_npy(path: Path, limits: ScanLimits) -> tuple[np.ndarray, list[str]]:
    """depth.npy (float metres) -> (float32 metres, notes); integer arrays are refused (units unknown)."""
    arr = read_npy(path, limits)
    if arr.dtype.kind in "iub":
        raise ScanError(
            f"{path}: depth.npy holds {arr.dtype} numbers; expected float metres (for integer depth "
            "units write a 16-bit depth.png and give depth_scale in camera.json)"
        )
    return check_depth_values(arr.astype(np.float64), path, limits, "float metres")


def _read_label_png(path: Path, what: str) -> np.ndarray:
    img = read_image(path, cv2.IMREAD_UNCHANGED)
    if img.ndim != 2:
        raise ScanError(f"{path}: {what} must be a one-channel image, got {img.shape[2]} channels")
    return img


# ----------------------------------------------------------------------------------------------------------------
# the scan folder


def _pick(folder: Path, names: tuple[str, ...], what: str) -> Path:
    found = [folder / n for n in names if os.path.lexists(folder / n)]  # a broken link is reported by its reader
    if not found:
        raise ScanError(f"{folder / names[0]}: file not found ({what}: need one of {', '.join(names)})")
    if len(found) > 1:
        raise ScanError(f"{folder}: both {found[0].name} and {found[1].name} present; keep one {what}")
    return found[0]


def _check_size(arr: np.ndarray, h: int, w: int, path: Path, ref: Path) -> None:
    if arr.shape[:2] != (h, w):
        raise ScanError(f"{path}: size {arr.shape[1]}x{arr.shape[0]} differs from {ref.name} {w}x{h} (width x height)")


def load_ground_truth(
    folder: Path, height: int, width: int, depth_scale: float, depth_is_npy: bool = False
) -> GroundTruth:
    """Load ``folder`` (a scan's gt/) and check every image against the scan size (height, width in pixels).

    depth_clean.png is read with camera.json's depth_scale (metres per unit), like depth.png; depth_clean.npy
    (float metres) is accepted too. When both exist, the one in the format of the scan's depth is used.
    """
    folder = Path(folder)
    faces_p, labels_p = folder / "faces.png", folder / "labels.png"
    prim_p, meta_p, step_p = folder / "primitives.json", folder / "meta.json", folder / "part.step"
    limits = current_limits()
    for p in (faces_p, labels_p, prim_p, meta_p, step_p):
        if not p.is_file():
            raise ScanError(f"{p}: file not found (ground truth)")

    faces = _read_label_png(faces_p, "faces.png")
    if faces.dtype not in (np.uint8, np.uint16):
        raise ScanError(f"{faces_p}: face ids must be 16-bit unsigned, got {faces.dtype}")
    faces = faces.astype(np.uint16)
    _check_size(faces, height, width, faces_p, Path("the colour image"))
    labels = _read_label_png(labels_p, "labels.png")
    if labels.dtype != np.uint8:
        raise ScanError(f"{labels_p}: labels must be 8-bit, got {labels.dtype}")
    _check_size(labels, height, width, labels_p, Path("the colour image"))

    dc_png, dc_npy = folder / "depth_clean.png", folder / "depth_clean.npy"
    candidates = [p for p in ((dc_npy, dc_png) if depth_is_npy else (dc_png, dc_npy)) if p.is_file()]
    if not candidates:
        raise ScanError(f"{dc_png}: file not found (ground truth)")
    dc_path = candidates[0]  # the same format as the scan's depth when both exist
    # noise-free depth: finite and non-negative like the scan's depth, but no plausibility refusal (an
    # all-background ground truth is still ground truth)
    if dc_path.suffix == ".npy":
        dc = read_npy(dc_path, limits).astype(np.float64)
    else:
        dc = read_image(dc_path, cv2.IMREAD_UNCHANGED, limits)
        if dc.ndim != 2 or dc.dtype != np.uint16:
            raise ScanError(
                f"{dc_path}: noise-free depth must be a one-channel 16-bit image, got {dc.dtype} with shape {dc.shape}"
            )
        dc = dc.astype(np.float64) * depth_scale
    if not np.isfinite(dc).all() or (dc < 0).any():
        raise ScanError(f"{dc_path}: noise-free depth holds negative or non-finite values; expected metres >= 0")
    depth_clean = dc.astype(np.float32)
    _check_size(depth_clean, height, width, dc_path, Path("the colour image"))

    prims = read_json(prim_p, limits)
    if isinstance(prims, dict) and isinstance(prims.get("primitives"), list):
        prims = prims["primitives"]
    if not isinstance(prims, list) or not all(isinstance(p, dict) for p in prims):
        raise ScanError(f"{prim_p}: must hold a list of primitive objects")
    meta = read_json(meta_p, limits)
    if not isinstance(meta, dict):
        raise ScanError(f"{meta_p}: must hold a JSON object")
    n_faces = len(prims)
    fmax = int(faces.max()) if faces.size else 0
    if fmax > n_faces:
        raise ScanError(f"{faces_p}: face value {fmax} but {prim_p.name} lists only {n_faces} faces")
    return GroundTruth(
        faces=faces, labels=labels, primitives=prims, depth_clean=depth_clean, meta=meta, step_path=step_p
    )


def load_scan(
    path: str | Path,
    roi: tuple[int, int, int, int] | str | None = None,
    limits: ScanLimits | None = None,
    pick: PickRequest | None = None,
) -> Scan:
    """Load and validate a scan folder (SCAN_FORMAT.md).

    path: the folder. roi: optional (x0, y0, x1, y1) pixels, x1/y1 exclusive, or the string "x0,y0,x1,y1"; it
    restricts :attr:`Scan.valid` and must lie inside the image. limits: what a plausible scan is (image size,
    depth range, intrinsics, part size; default `current_limits()`). pick: whether to pick the object of a frame
    with no mask.png and no ROI (`v2c.pick`; default `v2c.pick.current_pick()`, which never picks outside the
    commands): the picked pixels become :attr:`Scan.mask` and :attr:`Scan.picked` says how. Returns a
    :class:`Scan` (depth in metres, camera frame); raises :class:`ScanError` naming the file, the value and what
    was expected.
    """
    limits = limits or current_limits()
    folder = Path(path)
    if not folder.exists():
        raise ScanError(f"{folder}: scan folder not found")
    if is_recording(folder):
        return _load_recording(folder, roi, limits, pick)
    if not folder.is_dir():
        raise ScanError(f"{folder}: not a folder (a scan is a folder with color, depth and camera.json)")
    roi_t = parse_roi(roi)

    recorded_note = None
    if is_open3d_folder(folder):  # `v2c.recordings`: one pair of an Open3D RGBD folder, read as a scan folder's
        color_p, depth_p, cam_p, n_pairs = open3d_frame_files(folder, current_frame_index())
        recorded_note = (
            f"frame {current_frame_index()} of {n_pairs} colour+depth pairs ({color_p.name}, {depth_p.name})"
        )
    else:
        cam_p = folder / "camera.json"
        color_p = _pick(folder, COLOR_NAMES, "colour image")
        depth_p = _pick(folder, DEPTH_NAMES, "depth")
    cam = load_camera(cam_p, limits)

    color = _read_color(color_p, limits)
    h, w = color.shape[:2]
    if depth_p.suffix == ".npy":
        depth, notes = _read_depth_npy(depth_p, limits)
    else:
        depth, notes = _read_depth_png(depth_p, cam.depth_scale, limits)
    if depth.shape != (h, w):
        raise ScanError(
            f"{depth_p}: size {depth.shape[1]}x{depth.shape[0]} differs from {color_p.name} {w}x{h} "
            "(width x height); depth must be registered to colour"
        )
    if (cam.width is not None and cam.width != w) or (cam.height is not None and cam.height != h):
        raise ScanError(f"{cam_p}: width x height {cam.width}x{cam.height} disagrees with the images ({w}x{h})")
    check_intrinsics_plausible(cam.K, w, h, cam_p, limits)

    mask = None
    mask_p = folder / "mask.png"
    if os.path.lexists(mask_p):
        m = read_image(mask_p, cv2.IMREAD_UNCHANGED, limits)
        if m.ndim == 3:
            m = m.max(axis=2)
        _check_size(m, h, w, mask_p, color_p)
        mask = m > 0
        if not mask.any():
            raise ScanError(f"{mask_p}: mask marks no pixel (all zero)")

    if roi_t is not None:
        x0, y0, x1, y1 = roi_t
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            raise ScanError(
                f"ROI {roi_t} lies outside the image of {color_p} ({w}x{h}; need 0 <= x0 < x1 <= {w}, "
                f"0 <= y0 < y1 <= {h})"
            )

    if recorded_note:
        notes = [recorded_note, *notes]
    gt = None
    if (folder / GT_DIR).is_dir():
        gt = load_ground_truth(folder / GT_DIR, h, w, cam.depth_scale, depth_is_npy=depth_p.suffix == ".npy")
    depth = clean_loaded_depth(depth, gt is not None, notes)  # v2c.depth_clean: off unless asked

    scan = Scan(
        path=folder,
        color=color,
        depth=depth,
        K=cam.K.astype(np.float64),
        mask=mask,
        roi=roi_t,
        gt=gt,
        depth_scale=1.0 if depth_p.suffix == ".npy" else cam.depth_scale,
        camera_format=cam.format,
        files={"color": color_p, "depth": depth_p, "camera": cam_p} | ({"mask": mask_p} if mask is not None else {}),
        notes=notes,
    )
    _pick_hook(scan, pick or current_pick(), depth_p)
    return _check_valid(scan, depth_p, limits)


def _check_valid(scan: Scan, depth_p: Path, limits: ScanLimits) -> Scan:
    """The last checks of a loaded scan: some depth inside its mask/ROI, and a surface rather than noise."""
    valid = scan.valid
    mask_name = "the picked mask" if scan.picked else "mask.png"
    where = " and ".join(x for x, on in ((mask_name, scan.mask is not None), (f"ROI {scan.roi}", scan.roi)) if on)
    if not valid.any():
        raise ScanError(f"{depth_p}: no depth reading inside {where}")
    check_depth_surface(scan.depth, valid, scan.K, depth_p, limits, f" inside {where}" if where else "")
    return scan


def _load_recording(
    path: Path, roi: tuple[int, int, int, int] | str | None, limits: ScanLimits, pick: PickRequest | None
) -> Scan:
    """A scan from one frame of a recording (`v2c.recordings`: a ROS1 .bag; frame `current_frame_index()`), checked
    as a scan folder is (size, depth range, intrinsics, ROI), then picked as a scan folder is."""
    roi_t = parse_roi(roi)
    frame = read_bag_frame(path, current_frame_index())
    h, w = frame.depth.shape
    check_pixels(path, w, h, limits)
    depth, notes = check_depth_values(frame.depth, path, limits, frame.depth_unit)
    check_intrinsics_plausible(frame.K, w, h, path, limits)
    if roi_t is not None:
        x0, y0, x1, y1 = roi_t
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            raise ScanError(
                f"ROI {roi_t} lies outside the image of {path} ({w}x{h}; need 0 <= x0 < x1 <= {w}, 0 <= y0 < y1 <= {h})"
            )
    scan = Scan(
        path=path,
        color=frame.color,
        depth=depth,
        K=frame.K,
        mask=None,
        roi=roi_t,
        gt=None,
        depth_scale=1.0,
        camera_format="rosbag",
        files={"recording": path},
        notes=[
            f"frame {frame.index} of {frame.n_pairs} colour+depth pairs ({frame.topics['color']}, "
            f"{frame.topics['depth']}, intrinsics of {frame.topics['camera_info']})",
            *notes,
        ],
    )
    _pick_hook(scan, pick or current_pick(), path)
    return _check_valid(scan, path, limits)


def _pick_hook(scan: Scan, request: PickRequest, depth_p: Path, cfg: PickConfig | None = None) -> None:
    """Pick the object of a frame with no mask.png and no ROI (`v2c.pick`): set ``scan.mask`` and ``scan.picked``
    and say so on stderr; warn when a large frame stays whole. An explicit --pick centre / --point that finds
    nothing raises ScanError; auto falls back to the whole frame with the warning."""
    cfg = cfg or PickConfig()
    if not should_pick(request, scan.mask is not None, scan.roi is not None, scan.gt is not None):
        if scan.mask is None and scan.roi is None and scan.gt is None:
            warning = large_frame_warning(int((scan.depth > 0).sum()), cfg)
            if warning:
                log.warning("%s: %s", scan.path, warning)
        return
    has = scan.depth > 0
    n_valid = int(has.sum())
    explicit = request.mode == "centre" or request.point is not None
    if not explicit and n_valid <= cfg.large_frame_px:
        return  # auto: a small frame is cheap to reconstruct whole
    try:
        result = pick_object(scan.depth, scan.K, has, request.point, cfg)
    except PickError as e:
        if explicit:
            raise ScanError(f"{depth_p}: {e}; give --roi x0,y0,x1,y1 or a mask.png instead") from None
        log.warning("%s: %s (%s)", scan.path, large_frame_warning(n_valid, cfg), e)
        return
    if not explicit and result.plane_share < cfg.scene_plane_share:
        log.warning(
            "%s: %s (not a scene: the largest plane holds %.0f %% of the valid pixels, under %.0f %%)",
            scan.path,
            large_frame_warning(n_valid, cfg),
            100 * result.plane_share,
            100 * cfg.scene_plane_share,
        )
        return
    scan.mask = result.mask
    scan.picked = result.how
    log.warning(
        "%s: no mask.png or --roi: %s; override with --roi x0,y0,x1,y1, a mask.png, --point X,Y or --pick none",
        scan.path,
        result.how,
    )
