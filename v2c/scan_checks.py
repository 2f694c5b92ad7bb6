"""Plausibility limits of a scan and the checked readers of its files (images, .npy, JSON, camera.json).

Every limit is a field of `ScanLimits` with its unit. The readers look at a file's header before decoding it
(Pillow for PNG/JPEG headers and PNG chunk CRCs, numpy's .npy header), so an image of 30000 x 30000 pixels is
refused from its first bytes instead of after allocating gigabytes. Every refusal is a `ScanError` naming the
file, the value and the expected range.

camera.json (`load_camera`, `parse_camera`) comes in three accepted forms, validated with pydantic; its
intrinsics are then checked against the image size (`check_intrinsics_plausible`):

- v2c: ``K`` (3x3 nested, or 9 numbers row-major), ``depth_scale`` (metres per unit; default 0.001),
  ``width``/``height`` optional.
- Open3D ``PinholeCameraIntrinsic``: ``intrinsic_matrix`` (9 numbers, column-major), ``width``, ``height``.
  Open3D files carry no depth scale, so 0.001 m/unit is assumed unless ``depth_scale`` is given; a given value
  above 1 is read in Open3D's own convention (units per metre, e.g. 1000), otherwise as metres per unit.
- BOP ``scene_camera.json`` entry: ``cam_K`` (9 numbers, row-major), ``depth_scale`` in MILLIMETRES per unit
  (default 1). A whole BOP file keyed by image id is accepted too: its first entry (smallest id) is used.

Numbers must be JSON numbers: ``true`` or ``"0.001"`` is refused, not read as 1.0 or 0.001.
"""

from __future__ import annotations

import contextlib
import contextvars
import json
import math
import os
import stat
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Any, BinaryIO

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Strict, ValidationError

from v2c.camera import DEFAULT_DEPTH_SCALE_M, Camera, backproject
from v2c.contexts import scoped
from v2c.errors import ScanError

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_JPEG_SIGNATURE = b"\xff\xd8"
#: CRC of the empty IEND chunk: the last 4 bytes of every complete PNG.
_IEND_CRC = b"\xaeB`\x82"


@dataclass(frozen=True)
class ScanLimits:
    """What a plausible scan looks like. Units in the field comments.

    The defaults admit every sensor we know of (RealSense, Azure Kinect, Zivid, BOP datasets, our synthetic
    scans) and refuse what can only be a mistake: a depth in the wrong unit, a focal length off by orders of
    magnitude, a principal point far outside the image, noise instead of depth.
    """

    #: Largest image, in pixels (width x height): 2.1 megapixels, so 1920 x 1080 passes and 4000 x 3000 does
    #: not. Runtime and memory grow with it (a 4000 x 3000 scan took 25 min and wrote a 90 MB STEP); raise it
    #: with ``--max-pixels``.
    max_pixels: int = 2_100_000
    #: Largest file size per pixel of the image header (bytes): 16-bit RGBA is 8 bytes per pixel uncompressed,
    #: plus ``file_overhead_bytes`` for metadata; a file far larger than its pixels is not an image we read.
    max_file_bytes_per_pixel: float = 8.0
    file_overhead_bytes: int = 4 * 2**20
    #: Largest JSON file (camera.json, gt/*.json), bytes. A BOP scene_camera.json of a few thousand frames is
    #: about 1 MB.
    max_json_bytes: int = 64 * 2**20
    #: Plausible depth of a reading, metres: no depth camera we know measures nearer than 2 cm or farther
    #: than 20 m (65535 units of 1 mm is 65.5 m: a saturated or "no reading" marker, not a distance).
    min_depth_m: float = 0.02
    max_depth_m: float = 20.0
    #: Share of readings outside [min_depth_m, max_depth_m] that is dropped (set to 0, "no reading") with a
    #: note; above it the depth is refused as being in the wrong unit or broken (fraction of readings).
    max_out_of_range_share: float = 0.01
    #: Plausible depth_scale after the camera.json form's convention, metres per depth unit (1 um .. 10 cm).
    min_depth_scale_m: float = 1e-6
    max_depth_scale_m: float = 0.1
    #: Plausible horizontal and vertical field of view of the pinhole K, degrees (2 atan(w / 2 fx)).
    min_fov_deg: float = 1.0
    max_fov_deg: float = 165.0
    #: Largest fx / fy (or fy / fx): pixel aspect ratio (dimensionless).
    max_focal_ratio: float = 2.0
    #: How far the principal point may lie outside the image, as a fraction of its width / height.
    principal_point_margin: float = 0.5
    #: Largest |skew| / fx (dimensionless; 0.1 is a pixel axis 5.7 degrees off square).
    max_skew_ratio: float = 0.1
    #: Fewest pixels with depth inside mask/ROI: below this no face can be made (the segmenter dissolves
    #: instances under 50 pixels, v2c.segment.instances.InstanceConfig.min_area_px).
    min_valid_pixels: int = 50
    #: Largest extent of the valid points (metres, 1st-99th percentile box diagonal): a part, not a landscape.
    max_part_size_m: float = 10.0
    #: Largest median relative depth step between 4-neighbour readings |d1 - d2| / min(d1, d2): surfaces
    #: give under 0.01 (sensor noise included); uniform noise gives about 0.3.
    max_median_depth_step: float = 0.05


#: The limits `load_scan` applies when it is given none: the defaults, or what the `v2c` command set with
#: ``--max-pixels`` for the rest of the command (see `scan_limits`).
_CURRENT: contextvars.ContextVar[ScanLimits | None] = contextvars.ContextVar("v2c_scan_limits", default=None)


def current_limits() -> ScanLimits:
    """The `ScanLimits` in force (defaults unless inside `scan_limits`)."""
    return _CURRENT.get() or ScanLimits()


@contextlib.contextmanager
def scan_limits(limits: ScanLimits | None = None, **changes: Any) -> Iterator[ScanLimits]:
    """Use ``limits`` (or the current limits with ``changes``, e.g. ``max_pixels=12_000_000``) inside the block."""
    with scoped(_CURRENT, replace(limits or current_limits(), **changes)) as new:
        yield new


# ------------------------------------------------------------------------------------------------ files
def _open_regular(path: Path) -> tuple[BinaryIO, int]:
    """Open a regular file for reading (following a symlink to a regular file); (file object, size in bytes)."""
    if not os.path.lexists(path):
        raise ScanError(f"{path}: file not found")
    try:
        st = path.stat()
    except OSError as e:
        raise ScanError(f"{path}: cannot read ({e.strerror or type(e).__name__}; a broken symlink?)") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, pipe or socket)"
        raise ScanError(f"{path}: expected a file, found {kind}")
    try:
        fp = open(path, "rb")  # noqa: SIM115 - closed by the caller
    except OSError as e:
        raise ScanError(f"{path}: cannot read ({e.strerror or type(e).__name__})") from None
    return fp, st.st_size


def check_pixels(path: Path, width: int, height: int, limits: ScanLimits) -> None:
    """Refuse an image header of more than ``limits.max_pixels`` pixels, or of no pixels."""
    n = int(width) * int(height)
    if n <= 0:
        raise ScanError(f"{path}: image of {width}x{height} pixels is empty")
    if n > limits.max_pixels:
        raise ScanError(
            f"{path}: image of {width}x{height} = {n:,} pixels exceeds the limit of {limits.max_pixels:,} pixels "
            f"({limits.max_pixels / 1e6:.1f} megapixels; runtime and memory grow with it): downscale the scan or "
            f"pass --max-pixels {n}"
        )


def _check_file_size(path: Path, size: int, width: int, height: int, limits: ScanLimits) -> None:
    cap = limits.max_file_bytes_per_pixel * width * height + limits.file_overhead_bytes
    if size > cap:
        raise ScanError(
            f"{path}: file of {size} bytes for a {width}x{height} image (expected at most {int(cap)} bytes)"
        )


def _verify_png(fp: BinaryIO, path: Path, limits: ScanLimits, size: int) -> None:
    """PNG: header size check, then Pillow walks every chunk and checks its CRC without decoding pixels."""
    from PIL import PngImagePlugin

    try:
        im = PngImagePlugin.PngImageFile(fp)  # parses IHDR only; Image.open's own pixel cap is not applied
    except Exception:  # noqa: BLE001 - Pillow raises SyntaxError/OSError/struct.error for a bad header
        raise ScanError(f"{path}: not a readable PNG (bad or truncated header)") from None
    width, height = im.size
    check_pixels(path, width, height, limits)
    _check_file_size(path, size, width, height, limits)
    try:
        im.verify()
    except SyntaxError as e:
        # Pillow says "incomplete checksum" when the file stops inside a CRC, "bad ... checksum" for a wrong one
        if "incomplete" in str(e):
            raise ScanError(f"{path}: truncated PNG (ends inside a chunk)") from None
        raise ScanError(f"{path}: corrupt PNG (a chunk's CRC mismatch)") from None
    except (OSError, EOFError, ValueError):
        raise ScanError(f"{path}: truncated PNG (ends inside the chunk list, no IEND)") from None
    # Pillow stops at the IEND chunk's type without reading its CRC: a file missing only its last bytes
    # passes verify(), so check that the CRC is there.
    if fp.read(4) != _IEND_CRC:
        raise ScanError(f"{path}: truncated PNG (the IEND chunk is incomplete)")


def _verify_jpeg(fp: BinaryIO, path: Path, limits: ScanLimits, size: int) -> None:
    from PIL import JpegImagePlugin

    try:
        im = JpegImagePlugin.JpegImageFile(fp)
    except Exception:  # noqa: BLE001 - Pillow raises SyntaxError/OSError for a bad header
        raise ScanError(f"{path}: not a readable JPEG (bad or truncated header)") from None
    width, height = im.size
    check_pixels(path, width, height, limits)
    _check_file_size(path, size, width, height, limits)
    # Decoders grey-fill a truncated tail silently: a complete JPEG ends with EOI (FFD9).
    fp.seek(max(0, size - 64))
    if not fp.read().rstrip(b"\x00\r\n ").endswith(b"\xff\xd9"):
        raise ScanError(f"{path}: truncated JPEG (no EOI marker at the end)")


def read_image_bytes(path: Path, limits: ScanLimits | None = None) -> bytes:
    """The bytes of a PNG or JPEG file whose header, size and completeness were checked (nothing decoded)."""
    limits = limits or current_limits()
    path = Path(path)
    fp, size = _open_regular(path)
    with fp:
        if size == 0:
            raise ScanError(f"{path}: empty file")
        head = fp.read(8)
        fp.seek(0)
        if head.startswith(_PNG_SIGNATURE):
            _verify_png(fp, path, limits, size)
        elif head.startswith(_JPEG_SIGNATURE):
            _verify_jpeg(fp, path, limits, size)
        else:
            raise ScanError(f"{path}: not a PNG or JPEG image")
        fp.seek(0)
        try:
            return fp.read()
        except OSError as e:
            raise ScanError(f"{path}: cannot read ({e.strerror or type(e).__name__})") from None


def read_npy(path: Path, limits: ScanLimits | None = None) -> np.ndarray:
    """A 2-D numeric array from a .npy file, its header (shape, dtype) checked before the data is read."""
    limits = limits or current_limits()
    path = Path(path)
    fp, size = _open_regular(path)
    with fp:
        try:
            version = np.lib.format.read_magic(fp)
            read_header = (
                np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            )
            shape, fortran, dtype = read_header(fp)
        except Exception:  # noqa: BLE001 - numpy raises ValueError/EOFError/OSError for a bad header
            raise ScanError(f"{path}: cannot read .npy (not a NumPy array file, or its header is damaged)") from None
        if len(shape) != 2:
            raise ScanError(f"{path}: depth must be a 2-D (H, W) array, got shape {shape}")
        if dtype.hasobject or dtype.kind not in "fiub":
            raise ScanError(f"{path}: depth must be a real-number array (float metres), got {dtype}")
        check_pixels(path, shape[1], shape[0], limits)
        need = fp.tell() + dtype.itemsize * shape[0] * shape[1]
        if size < need:
            raise ScanError(f"{path}: cannot read .npy: truncated ({size} bytes, the header needs {need})")
        try:
            arr = np.fromfile(fp, dtype=dtype, count=shape[0] * shape[1])
        except (OSError, ValueError) as e:
            raise ScanError(f"{path}: cannot read .npy ({getattr(e, 'strerror', None) or 'read failed'})") from None
    return arr.reshape(shape, order="F" if fortran else "C")


def read_json(path: Path, limits: ScanLimits | None = None) -> Any:
    """Parse a JSON file (UTF-8) of at most ``limits.max_json_bytes``; ScanError naming the file otherwise."""
    limits = limits or current_limits()
    path = Path(path)
    fp, size = _open_regular(path)
    with fp:
        if size > limits.max_json_bytes:
            raise ScanError(f"{path}: JSON file of {size} bytes (expected at most {limits.max_json_bytes})")
        try:
            text = fp.read().decode("utf-8-sig")  # a byte-order mark some Windows editors write is fine
        except UnicodeDecodeError as e:
            raise ScanError(f"{path}: not UTF-8 text (byte {e.start})") from None
        except OSError as e:
            raise ScanError(f"{path}: cannot read ({e.strerror or type(e).__name__})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ScanError(f"{path}: invalid JSON ({e.msg} at line {e.lineno}, column {e.colno})") from None
    except RecursionError:
        raise ScanError(f"{path}: invalid JSON for v2c (nested too deeply; expected a flat object)") from None


# ------------------------------------------------------------------------------------------------ depth
def _fmt(x: float) -> str:
    return f"{x:.4g}"


def check_depth_values(depth: np.ndarray, path: Path, limits: ScanLimits, unit: str) -> tuple[np.ndarray, list[str]]:
    """Check float depth in metres (0 = no reading) against the plausible range.

    depth: (H, W) float64 metres. unit: how the file's numbers became metres (for the message). Returns the
    depth as float32 (readings outside the range dropped to 0 when they are at most
    ``max_out_of_range_share`` of all) and notes about what was dropped.
    """
    bad = ~np.isfinite(depth)
    if bad.any():
        raise ScanError(f"{path}: {int(bad.sum())} non-finite depth values (NaN/inf); use 0 for no reading")
    neg = depth < 0
    if neg.any():
        raise ScanError(
            f"{path}: {int(neg.sum())} negative depth values (min {_fmt(float(depth.min()))}); "
            "depth is metres, 0 = no reading"
        )
    has = depth > 0
    n = int(has.sum())
    if n == 0:
        raise ScanError(f"{path}: all depth values are zero (no readings)")
    out = has & ((depth < limits.min_depth_m) | (depth > limits.max_depth_m))
    n_out = int(out.sum())
    notes: list[str] = []
    if n_out:
        vals = depth[out]
        what = (
            f"{n_out} of {n} readings ({100.0 * n_out / n:.3g} %) lie outside {limits.min_depth_m:g} .. "
            f"{limits.max_depth_m:g} m (range {_fmt(float(vals.min()))} .. {_fmt(float(vals.max()))} m, "
            f"{unit})"
        )
        if n_out > limits.max_out_of_range_share * n:
            raise ScanError(
                f"{path}: {what}; expected depth in metres within {limits.min_depth_m:g} .. "
                f"{limits.max_depth_m:g} m: wrong depth_scale or unit?"
            )
        depth = np.where(out, 0.0, depth)
        notes.append(f"{path.name}: {what}: dropped as no reading")
    return depth.astype(np.float32), notes


def check_depth_surface(
    depth: np.ndarray, valid: np.ndarray, K: np.ndarray, path: Path, limits: ScanLimits, where: str
) -> None:
    """Refuse depth that cannot make one face: too few valid readings, noise instead of surfaces, or points
    spread wider than a part. depth: (H, W) float32 metres; valid: (H, W) bool; K: (3, 3) pixels."""
    n = int(valid.sum())
    if n < limits.min_valid_pixels:
        raise ScanError(
            f"{path}: only {n} pixel{'' if n == 1 else 's'} with depth{where}; at least "
            f"{limits.min_valid_pixels} are needed to make one face"
        )
    d = np.where(valid, depth, 0.0).astype(np.float64)
    steps = []
    for a, b in ((d[:, 1:], d[:, :-1]), (d[1:, :], d[:-1, :])):
        both = (a > 0) & (b > 0)
        steps.append(np.abs(a[both] - b[both]) / np.minimum(a[both], b[both]))
    step = np.concatenate(steps)
    if step.size < limits.min_valid_pixels:
        raise ScanError(
            f"{path}: the {n} readings{where} are scattered ({step.size} neighbouring pairs); "
            f"at least {limits.min_valid_pixels} are needed to make one face"
        )
    med = float(np.median(step))
    if med > limits.max_median_depth_step:
        raise ScanError(
            f"{path}: depth looks like noise{where}: neighbouring readings differ by a median "
            f"{100 * med:.1f} % of their depth (expected under {100 * limits.max_median_depth_step:g} "
            "% for surfaces)"
        )
    pts = backproject(d, K)[valid]
    lo, hi = np.percentile(pts, [1.0, 99.0], axis=0)
    size = float(np.linalg.norm(hi - lo))
    if not math.isfinite(size) or size > limits.max_part_size_m:
        raise ScanError(
            f"{path}: the points{where} span {_fmt(size)} m (1st-99th percentile box diagonal); "
            f"expected a part under {limits.max_part_size_m:g} m: give mask.png or --roi"
        )


# ------------------------------------------------------------------------------------------------ camera.json
#: BOP's default depth unit when its camera entry has no ``depth_scale`` (millimetres per unit).
BOP_DEFAULT_DEPTH_SCALE_MM = 1.0


def _positive(v: float) -> float:
    if not math.isfinite(v) or v <= 0:
        raise ValueError("expected a positive finite number")
    return v


def _size(v: float) -> int:
    if not math.isfinite(v) or v != int(v) or v <= 0:
        raise ValueError("expected a positive integer (pixels)")
    return int(v)


def _matrix(v: list) -> list:
    nested = bool(v) and isinstance(v[0], list)
    if nested and len({len(r) for r in v}) > 1:
        raise ValueError("K is not 3x3 (rows of different lengths): expected a 3x3 matrix or 9 numbers")
    shape = (len(v), len(v[0])) if nested else (len(v),)
    if shape not in ((3, 3), (9,)):
        raise ValueError(f"K is not 3x3 (got shape {shape}): expected a 3x3 matrix or 9 numbers")
    if not all(math.isfinite(x) for x in np.ravel(v)):
        raise ValueError("K holds non-finite values (NaN/inf)")
    return v


#: A JSON number (int or float); booleans and strings are refused.
Number = Annotated[float, Strict()]
Positive = Annotated[Number, AfterValidator(_positive)]
Size = Annotated[Number, AfterValidator(_size)]
Matrix = Annotated[list[Number] | list[list[Number]], AfterValidator(_matrix)]

#: What each key must hold, for the messages.
_EXPECTED = {
    "K": "a 3x3 matrix or 9 numbers row-major",
    "intrinsic_matrix": "9 numbers, column-major (a 3x3 K)",
    "cam_K": "9 numbers, row-major (a 3x3 K)",
    "depth_scale": "a positive number",
    "width": "a positive integer (pixels)",
    "height": "a positive integer (pixels)",
}


class _CameraModel(BaseModel):
    model_config = ConfigDict(extra="allow")  # other keys (distortion, BOP poses, ...) are kept, unused
    width: Size | None = None
    height: Size | None = None


class V2cCamera(_CameraModel):
    """camera.json in v2c's form: ``K`` row-major, ``depth_scale`` in metres per depth unit."""

    K: Matrix
    depth_scale: Positive = DEFAULT_DEPTH_SCALE_M  # metres per unit


class Open3dCamera(_CameraModel):
    """Open3D's ``PinholeCameraIntrinsic``: ``intrinsic_matrix`` column-major, optional ``depth_scale``."""

    intrinsic_matrix: Matrix
    depth_scale: Positive | None = None  # > 1: units per metre (Open3D); <= 1: metres per unit


class BopCamera(_CameraModel):
    """A BOP ``scene_camera.json`` entry: ``cam_K`` row-major, ``depth_scale`` in millimetres per depth unit."""

    cam_K: Matrix
    depth_scale: Positive = BOP_DEFAULT_DEPTH_SCALE_MM  # millimetres per unit


def _short(value: Any, n: int = 60) -> str:
    text = repr(value)
    return text if len(text) <= n else text[: n - 3] + "..."


def _scan_error(path: Path, err: ValidationError, data: dict) -> ScanError:
    """One line from pydantic's first error: the key, its value and what it must hold."""
    e = err.errors(include_url=False)[0]
    key = str(e["loc"][0]) if e["loc"] else "?"
    if e["type"] == "missing":
        return ScanError(f"{path}: '{key}' is missing: expected {_EXPECTED.get(key, 'a value')}")
    if e["type"] == "value_error":
        problem = str(e.get("ctx", {}).get("error", e["msg"]))
    else:
        problem = f"expected {_EXPECTED.get(key, e['msg'])}"
    return ScanError(f"{path}: '{key}' = {_short(data.get(key))}: {problem}")


def _select_bop_entry(d: dict) -> dict:
    """A whole BOP scene_camera.json keyed by image id: {"0": {"cam_K": ...}, ...} -> its first entry."""
    if (
        d
        and not any(k in d for k in ("K", "intrinsic_matrix", "cam_K"))
        and all(isinstance(v, dict) and "cam_K" in v for v in d.values())
    ):

        def _key(k: str) -> tuple[int, Any]:
            return (0, int(k)) if str(k).lstrip("-").isdigit() else (1, str(k))

        return d[min(d, key=_key)]
    return d


def parse_camera(d: Any, path: Path, limits: ScanLimits | None = None) -> Camera:
    """Interpret a camera.json object in one of the three accepted forms (module docstring).

    Returns K (pixels) and depth_scale in metres per depth unit; raises ScanError naming the file, the key,
    its value and what was expected.
    """
    limits = limits or current_limits()
    path = Path(path)
    if not isinstance(d, dict):
        raise ScanError(f"{path}: camera.json must hold a JSON object, got {type(d).__name__}")
    d = _select_bop_entry(d)
    if "K" in d:
        fmt, model, key = "v2c", V2cCamera, "K"
    elif "intrinsic_matrix" in d:
        fmt, model, key = "open3d", Open3dCamera, "intrinsic_matrix"
    elif "cam_K" in d:
        fmt, model, key = "bop", BopCamera, "cam_K"
    else:
        raise ScanError(
            f"{path}: no intrinsics found: need 'K' (v2c), 'intrinsic_matrix' (Open3D) or 'cam_K' (BOP); "
            f"keys are {sorted(map(str, d))[:10]}"
        )
    try:
        m = model.model_validate(d)
    except ValidationError as err:
        raise _scan_error(path, err, d) from None
    K = np.asarray(getattr(m, key), dtype=np.float64).reshape(3, 3)
    if fmt == "open3d":
        K = K.T  # column-major
    if fmt == "v2c":
        scale, unit = m.depth_scale, "metres per unit"
    elif fmt == "open3d":
        s = m.depth_scale
        scale = DEFAULT_DEPTH_SCALE_M if s is None else (1.0 / s if s > 1.0 else s)
        unit = "Open3D: units per metre when above 1, else metres per unit"
    else:
        scale, unit = 1e-3 * m.depth_scale, "BOP: millimetres per unit"
    if not limits.min_depth_scale_m <= scale <= limits.max_depth_scale_m:
        hint = (
            f"; {d['depth_scale']!r} looks like units per metre: use {1.0 / d['depth_scale']:g}"
            if fmt == "v2c" and scale > 1.0
            else ""
        )
        raise ScanError(
            f"{path}: 'depth_scale' = {_short(d.get('depth_scale'))} ({unit}) gives {scale:g} m per depth unit: "
            f"expected {limits.min_depth_scale_m:g} .. {limits.max_depth_scale_m:g} m per unit{hint}"
        )
    check_pinhole(K, path)
    return Camera(K=K, depth_scale=float(scale), width=m.width, height=m.height, format=fmt)


def check_pinhole(K: np.ndarray, path: Path) -> None:
    """K must read [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with positive focal lengths (pixels)."""
    if K.shape != (3, 3):
        raise ScanError(f"{path}: K must be 3x3, got shape {K.shape}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ScanError(
            f"{path}: K has a non-positive focal length (fx={K[0, 0]:g}, fy={K[1, 1]:g}); expected positive pixels"
        )
    if abs(K[1, 0]) > 1e-9 or abs(K[2, 0]) > 1e-9 or abs(K[2, 1]) > 1e-9 or abs(K[2, 2] - 1.0) > 1e-9:
        raise ScanError(
            f"{path}: K is not a pinhole intrinsic matrix (need [[fx, s, cx], [0, fy, cy], [0, 0, 1]]); "
            f"got {K.tolist()} (an Open3D matrix written row-major?)"
        )


def check_intrinsics_plausible(
    K: np.ndarray, width: int, height: int, path: Path, limits: ScanLimits | None = None
) -> None:
    """Focal lengths, principal point and skew (pixels) against an image of width x height pixels."""
    limits = limits or current_limits()
    fx, s, cx = (float(x) for x in K[0])
    fy, cy = float(K[1, 1]), float(K[1, 2])
    lo, hi = limits.min_fov_deg, limits.max_fov_deg
    for name, f, n in (("fx", fx, width), ("fy", fy, height)):
        fov = math.degrees(2.0 * math.atan2(n / 2.0, f))
        if not lo <= fov <= hi:
            f_lo = n / 2.0 / math.tan(math.radians(hi) / 2.0)
            f_hi = n / 2.0 / math.tan(math.radians(lo) / 2.0)
            raise ScanError(
                f"{path}: {name} = {f:g} px gives a field of view of {fov:.3g} degrees over {n} "
                f"pixels: expected {f_lo:.3g} .. {f_hi:.4g} px ({lo:g} .. {hi:g} degrees)"
            )
    ratio = max(fx / fy, fy / fx)
    if ratio > limits.max_focal_ratio:
        raise ScanError(
            f"{path}: fx = {fx:g} and fy = {fy:g} px differ by a factor {ratio:.3g}: expected at most "
            f"{limits.max_focal_ratio:g} (pixel aspect ratio)"
        )
    m = limits.principal_point_margin
    for name, c, n in (("cx", cx, width), ("cy", cy, height)):
        if not -m * n <= c <= (1.0 + m) * n:
            raise ScanError(
                f"{path}: {name} = {c:g} px: expected {-m * n:g} .. {(1.0 + m) * n:g} px for an "
                f"image {n} pixels across (principal point near the image)"
            )
    if abs(s) > limits.max_skew_ratio * fx:
        raise ScanError(
            f"{path}: skew K[0][1] = {s:g} px: expected |skew| <= {limits.max_skew_ratio * fx:g} px "
            f"({limits.max_skew_ratio:g} x fx; usually 0)"
        )


def load_camera(path: Path, limits: ScanLimits | None = None) -> Camera:
    """Read and check a camera.json (any of the three forms of :func:`parse_camera`)."""
    path = Path(path)
    return parse_camera(read_json(path, limits), path, limits)
