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

import json
import math
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

#: Metres per depth unit when camera.json does not say (RealSense default; SCAN_FORMAT.md).
DEFAULT_DEPTH_SCALE_M = 0.001
#: BOP's default depth unit when its camera entry has no ``depth_scale`` (millimetres per unit).
BOP_DEFAULT_DEPTH_SCALE_MM = 1.0

COLOR_NAMES = ("color.png", "color.jpg", "color.jpeg")
DEPTH_NAMES = ("depth.png", "depth.npy")
GT_DIR = "gt"

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


class ScanError(ValueError):
    """A scan folder that cannot be used. The message names the file and the problem."""


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
        return (f"GroundTruth({len(self.primitives)} faces, {self.faces.shape[1]}x{self.faces.shape[0]}, "
                f"step={str(self.step_path)!r})")

    def visible_face_ids(self) -> np.ndarray:
        """Sorted 0-based face indices that cover at least one pixel of faces.png."""
        vals = np.unique(self.faces)
        return (vals[vals > 0].astype(np.int64) - 1)


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

    @property
    def height(self) -> int:
        return int(self.depth.shape[0])

    @property
    def width(self) -> int:
        return int(self.depth.shape[1])

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
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
        return (f"Scan({str(self.path)!r}, {self.width}x{self.height}, fx={self.fx:.2f}, "
                f"mask={'yes' if self.mask is not None else 'no'}, roi={self.roi}, "
                f"gt={'yes' if self.gt is not None else 'no'})")


# ----------------------------------------------------------------------------------------------------------------
# geometry


def backproject(depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Back-project a depth map to camera-frame points.

    depth: (H, W) z-depth in metres (0 = no reading gives the point (0, 0, 0)); K: (3, 3) intrinsics in pixels,
    pixel centres at integer (u, v). Returns (H, W, 3) float64 points (x right, y down, z forward), metres.
    Handles a skew term K[0, 1].
    """
    depth = np.asarray(depth, dtype=np.float64)
    K = np.asarray(K, dtype=np.float64)
    if depth.ndim != 2:
        raise ValueError(f"depth must be (H, W), got shape {depth.shape}")
    if K.shape != (3, 3):
        raise ValueError(f"K must be 3x3, got shape {K.shape}")
    h, w = depth.shape
    fx, s, cx = K[0]
    fy, cy = K[1, 1], K[1, 2]
    v = np.arange(h, dtype=np.float64)[:, None]
    u = np.arange(w, dtype=np.float64)[None, :]
    yn = (v - cy) / fy  # (H, 1)
    xn = (u - cx - s * yn) / fx  # (H, W) with skew, (1, W) without
    out = np.empty((h, w, 3), dtype=np.float64)
    out[..., 0] = xn * depth
    out[..., 1] = yn * depth
    out[..., 2] = depth
    return out


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


def _check_png_complete(data: bytes, path: Path) -> None:
    """Walk the PNG chunks: signature, each chunk whole with a correct CRC, ending with IEND."""
    if not data.startswith(_PNG_SIGNATURE):
        raise ScanError(f"{path}: not a PNG file (bad signature)")
    pos, n = len(_PNG_SIGNATURE), len(data)
    while True:
        if pos + 12 > n:
            raise ScanError(f"{path}: truncated PNG (ends at byte {n} inside the chunk list, no IEND)")
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        ctype = data[pos + 4 : pos + 8]
        end = pos + 12 + length
        if end > n:
            raise ScanError(
                f"{path}: truncated PNG (chunk {ctype.decode('latin-1')!r} needs {end} bytes, file has {n})"
            )
        (crc,) = struct.unpack(">I", data[end - 4 : end])
        if zlib.crc32(data[pos + 4 : end - 4]) & 0xFFFFFFFF != crc:
            raise ScanError(f"{path}: corrupt PNG (CRC mismatch in chunk {ctype.decode('latin-1')!r})")
        if ctype == b"IEND":
            return
        pos = end


def _check_jpeg_complete(data: bytes, path: Path) -> None:
    """JPEG must start with SOI (FFD8) and end with EOI (FFD9); decoders silently grey-fill a truncated tail."""
    if not data.startswith(b"\xff\xd8"):
        raise ScanError(f"{path}: not a JPEG file (no SOI marker)")
    if not data.rstrip(b"\x00\r\n ").endswith(b"\xff\xd9"):
        raise ScanError(f"{path}: truncated JPEG (no EOI marker at the end)")


def read_image(path: Path, flags: int = cv2.IMREAD_UNCHANGED) -> np.ndarray:
    """Read a PNG or JPEG fully, checking that the file is complete before decoding it.

    Returns the array as OpenCV decodes it (BGR channel order for colour). Raises ScanError naming the file.
    """
    path = Path(path)
    if not path.is_file():
        raise ScanError(f"{path}: file not found")
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ScanError(f"{path}: cannot read ({e.strerror or e})") from None
    if not data:
        raise ScanError(f"{path}: empty file")
    if data.startswith(_PNG_SIGNATURE):
        _check_png_complete(data, path)
    elif data.startswith(b"\xff\xd8"):
        _check_jpeg_complete(data, path)
    else:
        raise ScanError(f"{path}: not a PNG or JPEG image")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), flags)
    if img is None or img.size == 0:
        raise ScanError(f"{path}: cannot decode image")
    return img


def _read_color(path: Path) -> np.ndarray:
    img = read_image(path, cv2.IMREAD_UNCHANGED)
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


def _read_depth_png(path: Path, scale_m: float) -> np.ndarray:
    raw = read_image(path, cv2.IMREAD_UNCHANGED)
    if raw.ndim != 2:
        raise ScanError(f"{path}: depth image must have one channel, got {raw.shape[2]}")
    if raw.dtype == np.uint8:
        raise ScanError(
            f"{path}: 8-bit depth image; depth must be 16-bit unsigned (depth units of camera.json depth_scale)"
        )
    if raw.dtype != np.uint16:
        raise ScanError(f"{path}: depth image must be 16-bit unsigned, got {raw.dtype}")
    return (raw.astype(np.float64) * scale_m).astype(np.float32)


def _read_depth_npy(path: Path) -> np.ndarray:
    try:
        arr = np.load(path, allow_pickle=False)
    except Exception as e:  # noqa: BLE001 - numpy raises ValueError/EOFError/OSError/UnpicklingError
        raise ScanError(f"{path}: cannot read .npy ({type(e).__name__}: {e})") from None
    if not isinstance(arr, np.ndarray) or arr.ndim != 2:
        raise ScanError(f"{path}: depth must be a 2-D (H, W) array, got shape {getattr(arr, 'shape', None)}")
    if arr.dtype.kind not in "fiu":
        raise ScanError(f"{path}: depth must be a real-number array (float metres), got {arr.dtype}")
    arr = arr.astype(np.float64)
    bad = ~np.isfinite(arr)
    if bad.any():
        raise ScanError(f"{path}: {int(bad.sum())} non-finite depth values (NaN/inf); use 0 for no reading")
    if (arr < 0).any():
        raise ScanError(f"{path}: {int((arr < 0).sum())} negative depth values; depth is metres, 0 = no reading")
    return arr.astype(np.float32)


def _read_label_png(path: Path, what: str) -> np.ndarray:
    img = read_image(path, cv2.IMREAD_UNCHANGED)
    if img.ndim != 2:
        raise ScanError(f"{path}: {what} must be a one-channel image, got {img.shape[2]} channels")
    return img


# ----------------------------------------------------------------------------------------------------------------
# camera.json


@dataclass
class Camera:
    """Intrinsics read from camera.json. K in pixels; depth_scale in metres per depth.png unit."""

    K: np.ndarray
    depth_scale: float
    width: int | None
    height: int | None
    format: str  # "v2c" | "open3d" | "bop"


def _numbers(value: Any, path: Path, key: str, count: int, what: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ScanError(f"{path}: '{key}' must be {what}, got {value!r}") from None
    if arr.size != count or (arr.ndim == 2 and arr.shape != (3, 3)) or arr.ndim > 2:
        raise ScanError(f"{path}: '{key}' must be {what}; K is not 3x3 (got shape {arr.shape})")
    if not np.all(np.isfinite(arr)):
        raise ScanError(f"{path}: '{key}' holds non-finite values")
    return arr


def _positive_scale(value: Any, path: Path, key: str) -> float:
    try:
        s = float(value)
    except (TypeError, ValueError):
        raise ScanError(f"{path}: '{key}' must be a number, got {value!r}") from None
    if not math.isfinite(s) or s <= 0:
        raise ScanError(f"{path}: '{key}' must be a positive number, got {value!r}")
    return s


def _optional_size(d: dict, key: str, path: Path) -> int | None:
    if key not in d or d[key] is None:
        return None
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or v != int(v) or v <= 0:
        raise ScanError(f"{path}: '{key}' must be a positive integer, got {v!r}")
    return int(v)


def parse_camera(d: Any, path: Path) -> Camera:
    """Interpret a camera.json object in one of the three accepted forms.

    - v2c: ``K`` (3x3 nested, or 9 numbers row-major), ``depth_scale`` (metres per unit; default 0.001),
      ``width``/``height`` optional.
    - Open3D ``PinholeCameraIntrinsic``: ``intrinsic_matrix`` (9 numbers, column-major), ``width``, ``height``.
      Open3D files carry no depth scale, so 0.001 m/unit is assumed unless ``depth_scale`` is given; a given value
      above 1 is read in Open3D's own convention (units per metre, e.g. 1000), otherwise as metres per unit.
    - BOP ``scene_camera.json`` entry: ``cam_K`` (9 numbers, row-major), ``depth_scale`` in MILLIMETRES per unit
      (default 1). A whole BOP file keyed by image id is accepted too: its first entry (smallest id) is used.
    """
    if not isinstance(d, dict):
        raise ScanError(f"{path}: camera.json must hold a JSON object, got {type(d).__name__}")
    # a BOP scene_camera.json keyed by image id: {"0": {"cam_K": ...}, ...}
    if d and not any(k in d for k in ("K", "intrinsic_matrix", "cam_K")) and all(
        isinstance(v, dict) and "cam_K" in v for v in d.values()
    ):
        def _key(k: str) -> tuple[int, Any]:
            return (0, int(k)) if str(k).lstrip("-").isdigit() else (1, str(k))

        d = d[min(d, key=_key)]

    if "K" in d:
        fmt = "v2c"
        K = _numbers(d["K"], path, "K", 9, "a 3x3 matrix or 9 numbers row-major").reshape(3, 3)
        scale = _positive_scale(d.get("depth_scale", DEFAULT_DEPTH_SCALE_M), path, "depth_scale")
    elif "intrinsic_matrix" in d:
        fmt = "open3d"
        K = _numbers(d["intrinsic_matrix"], path, "intrinsic_matrix", 9,
                     "9 numbers, column-major (a 3x3 K)").reshape(3, 3).T
        scale = DEFAULT_DEPTH_SCALE_M
        if "depth_scale" in d:
            s = _positive_scale(d["depth_scale"], path, "depth_scale")
            scale = 1.0 / s if s > 1.0 else s
    elif "cam_K" in d:
        fmt = "bop"
        K = _numbers(d["cam_K"], path, "cam_K", 9, "9 numbers, row-major (a 3x3 K)").reshape(3, 3)
        scale = 1e-3 * _positive_scale(d.get("depth_scale", BOP_DEFAULT_DEPTH_SCALE_MM), path, "depth_scale")
    else:
        raise ScanError(
            f"{path}: no intrinsics found: need 'K' (v2c), 'intrinsic_matrix' (Open3D) or 'cam_K' (BOP); "
            f"keys are {sorted(d)[:10]}"
        )
    _check_K(K, path)
    return Camera(K=K, depth_scale=scale, width=_optional_size(d, "width", path),
                  height=_optional_size(d, "height", path), format=fmt)


def _check_K(K: np.ndarray, path: Path) -> None:
    if K.shape != (3, 3):
        raise ScanError(f"{path}: K must be 3x3, got shape {K.shape}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ScanError(f"{path}: K has a non-positive focal length (fx={K[0, 0]:g}, fy={K[1, 1]:g})")
    if abs(K[1, 0]) > 1e-9 or abs(K[2, 0]) > 1e-9 or abs(K[2, 1]) > 1e-9 or abs(K[2, 2] - 1.0) > 1e-9:
        raise ScanError(
            f"{path}: K is not a pinhole intrinsic matrix (need [[fx, s, cx], [0, fy, cy], [0, 0, 1]]); "
            f"got {K.tolist()} (an Open3D matrix written row-major?)"
        )


def _load_json(path: Path) -> Any:
    if not path.is_file():
        raise ScanError(f"{path}: file not found")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise ScanError(f"{path}: invalid JSON ({e.msg} at line {e.lineno}, column {e.colno})") from None
    except (OSError, UnicodeDecodeError) as e:
        raise ScanError(f"{path}: cannot read ({e})") from None


def load_camera(path: Path) -> Camera:
    """Read and check a camera.json (any of the three forms of :func:`parse_camera`)."""
    path = Path(path)
    return parse_camera(_load_json(path), path)


# ----------------------------------------------------------------------------------------------------------------
# the scan folder


def _pick(folder: Path, names: tuple[str, ...], what: str) -> Path:
    found = [folder / n for n in names if (folder / n).is_file()]
    if not found:
        raise ScanError(f"{folder / names[0]}: file not found ({what}: need one of {', '.join(names)})")
    if len(found) > 1:
        raise ScanError(f"{folder}: both {found[0].name} and {found[1].name} present; keep one {what}")
    return found[0]


def _check_size(arr: np.ndarray, h: int, w: int, path: Path, ref: Path) -> None:
    if arr.shape[:2] != (h, w):
        raise ScanError(
            f"{path}: size {arr.shape[1]}x{arr.shape[0]} differs from {ref.name} {w}x{h} (width x height)"
        )


def load_ground_truth(folder: Path, height: int, width: int, depth_scale: float,
                      depth_is_npy: bool = False) -> GroundTruth:
    """Load ``folder`` (a scan's gt/) and check every image against the scan size (height, width in pixels).

    depth_clean.png is read with camera.json's depth_scale (metres per unit), like depth.png; depth_clean.npy
    (float metres) is accepted too. When both exist, the one in the format of the scan's depth is used.
    """
    folder = Path(folder)
    faces_p, labels_p = folder / "faces.png", folder / "labels.png"
    prim_p, meta_p, step_p = folder / "primitives.json", folder / "meta.json", folder / "part.step"
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
    if dc_path.suffix == ".npy":
        depth_clean = _read_depth_npy(dc_path)
    else:
        depth_clean = _read_depth_png(dc_path, depth_scale)
    _check_size(depth_clean, height, width, dc_path, Path("the colour image"))

    prims = _load_json(prim_p)
    if isinstance(prims, dict) and isinstance(prims.get("primitives"), list):
        prims = prims["primitives"]
    if not isinstance(prims, list) or not all(isinstance(p, dict) for p in prims):
        raise ScanError(f"{prim_p}: must hold a list of primitive objects")
    meta = _load_json(meta_p)
    if not isinstance(meta, dict):
        raise ScanError(f"{meta_p}: must hold a JSON object")
    n_faces = len(prims)
    fmax = int(faces.max()) if faces.size else 0
    if fmax > n_faces:
        raise ScanError(f"{faces_p}: face value {fmax} but {prim_p.name} lists only {n_faces} faces")
    return GroundTruth(faces=faces, labels=labels, primitives=prims, depth_clean=depth_clean, meta=meta,
                       step_path=step_p)


def load_scan(path: str | Path, roi: tuple[int, int, int, int] | str | None = None) -> Scan:
    """Load and validate a scan folder (SCAN_FORMAT.md).

    path: the folder. roi: optional (x0, y0, x1, y1) pixels, x1/y1 exclusive, or the string "x0,y0,x1,y1"; it
    restricts :attr:`Scan.valid` and must lie inside the image. Returns a :class:`Scan` (depth in metres, camera
    frame); raises :class:`ScanError` naming the file and the problem.
    """
    folder = Path(path)
    if not folder.exists():
        raise ScanError(f"{folder}: scan folder not found")
    if not folder.is_dir():
        raise ScanError(f"{folder}: not a folder (a scan is a folder with color, depth and camera.json)")
    roi_t = parse_roi(roi)

    cam_p = folder / "camera.json"
    color_p = _pick(folder, COLOR_NAMES, "colour image")
    depth_p = _pick(folder, DEPTH_NAMES, "depth")
    cam = load_camera(cam_p)

    color = _read_color(color_p)
    h, w = color.shape[:2]
    if depth_p.suffix == ".npy":
        depth = _read_depth_npy(depth_p)
    else:
        depth = _read_depth_png(depth_p, cam.depth_scale)
    if depth.shape != (h, w):
        raise ScanError(
            f"{depth_p}: size {depth.shape[1]}x{depth.shape[0]} differs from {color_p.name} {w}x{h} "
            "(width x height); depth must be registered to colour"
        )
    if (cam.width is not None and cam.width != w) or (cam.height is not None and cam.height != h):
        raise ScanError(
            f"{cam_p}: width x height {cam.width}x{cam.height} disagrees with the images ({w}x{h})"
        )
    if not (depth > 0).any():
        raise ScanError(f"{depth_p}: all depth values are zero (no readings)")

    mask = None
    mask_p = folder / "mask.png"
    if mask_p.exists():
        m = read_image(mask_p, cv2.IMREAD_UNCHANGED)
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

    gt = None
    if (folder / GT_DIR).is_dir():
        gt = load_ground_truth(folder / GT_DIR, h, w, cam.depth_scale, depth_is_npy=depth_p.suffix == ".npy")

    scan = Scan(path=folder, color=color, depth=depth, K=cam.K.astype(np.float64), mask=mask, roi=roi_t, gt=gt,
                depth_scale=1.0 if depth_p.suffix == ".npy" else cam.depth_scale, camera_format=cam.format,
                files={"color": color_p, "depth": depth_p, "camera": cam_p}
                | ({"mask": mask_p} if mask is not None else {}))
    if not scan.valid.any():
        where = " and ".join(x for x, on in (("mask.png", mask is not None), (f"ROI {roi_t}", roi_t)) if on)
        raise ScanError(f"{depth_p}: no depth reading inside {where}")
    return scan
