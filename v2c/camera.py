"""camera.json: the three accepted forms (v2c, Open3D, BOP), validated with pydantic, and the plausibility of
the intrinsics against the image size.

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

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Strict, ValidationError

from v2c.errors import ScanError
from v2c.scan_checks import ScanLimits, current_limits, read_json

#: Metres per depth unit when camera.json does not say (RealSense default; SCAN_FORMAT.md).
DEFAULT_DEPTH_SCALE_M = 0.001
#: BOP's default depth unit when its camera entry has no ``depth_scale`` (millimetres per unit).
BOP_DEFAULT_DEPTH_SCALE_MM = 1.0


@dataclass
class Camera:
    """Intrinsics read from camera.json. K in pixels; depth_scale in metres per depth.png unit."""

    K: np.ndarray
    depth_scale: float
    width: int | None
    height: int | None
    format: str  # "v2c" | "open3d" | "bop"


# ------------------------------------------------------------------------------------------------ models
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
    K: Matrix
    depth_scale: Positive = DEFAULT_DEPTH_SCALE_M  # metres per unit


class Open3dCamera(_CameraModel):
    intrinsic_matrix: Matrix
    depth_scale: Positive | None = None  # > 1: units per metre (Open3D); <= 1: metres per unit


class BopCamera(_CameraModel):
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
    if d and not any(k in d for k in ("K", "intrinsic_matrix", "cam_K")) and all(
        isinstance(v, dict) and "cam_K" in v for v in d.values()
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
        hint = (f"; {d['depth_scale']!r} looks like units per metre: use {1.0 / d['depth_scale']:g}"
                if fmt == "v2c" and scale > 1.0 else "")
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
        raise ScanError(f"{path}: K has a non-positive focal length (fx={K[0, 0]:g}, fy={K[1, 1]:g}); "
                        "expected positive pixels")
    if abs(K[1, 0]) > 1e-9 or abs(K[2, 0]) > 1e-9 or abs(K[2, 1]) > 1e-9 or abs(K[2, 2] - 1.0) > 1e-9:
        raise ScanError(
            f"{path}: K is not a pinhole intrinsic matrix (need [[fx, s, cx], [0, fy, cy], [0, 0, 1]]); "
            f"got {K.tolist()} (an Open3D matrix written row-major?)"
        )


def check_intrinsics_plausible(K: np.ndarray, width: int, height: int, path: Path,
                               limits: ScanLimits | None = None) -> None:
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
            raise ScanError(f"{path}: {name} = {f:g} px gives a field of view of {fov:.3g} degrees over {n} "
                            f"pixels: expected {f_lo:.3g} .. {f_hi:.4g} px ({lo:g} .. {hi:g} degrees)")
    ratio = max(fx / fy, fy / fx)
    if ratio > limits.max_focal_ratio:
        raise ScanError(f"{path}: fx = {fx:g} and fy = {fy:g} px differ by a factor {ratio:.3g}: expected at most "
                        f"{limits.max_focal_ratio:g} (pixel aspect ratio)")
    m = limits.principal_point_margin
    for name, c, n in (("cx", cx, width), ("cy", cy, height)):
        if not -m * n <= c <= (1.0 + m) * n:
            raise ScanError(f"{path}: {name} = {c:g} px: expected {-m * n:g} .. {(1.0 + m) * n:g} px for an "
                            f"image {n} pixels across (principal point near the image)")
    if abs(s) > limits.max_skew_ratio * fx:
        raise ScanError(f"{path}: skew K[0][1] = {s:g} px: expected |skew| <= {limits.max_skew_ratio * fx:g} px "
                        f"({limits.max_skew_ratio:g} x fx; usually 0)")


def load_camera(path: Path, limits: ScanLimits | None = None) -> Camera:
    """Read and check a camera.json (any of the three forms of :func:`parse_camera`)."""
    path = Path(path)
    return parse_camera(read_json(path, limits), path, limits)
