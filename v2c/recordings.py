"""Read one colour + depth frame from a sensor recording: a ROS1 ``.bag`` (the RealSense Viewer's and realsense-ros'
recordings), read with the pure-Python `rosbags` package, or an Open3D RGBD folder (`open3d_frame_files`).

`read_bag_frame` returns a `RecordedFrame` (colour RGB, depth in metres, K in pixels); `v2c.scan.load_scan` turns
it into a `Scan` when its path is a ``.bag`` file. Which frame: the ``frame_index``-th complete colour+depth pair
(0 = the first), a pair being a colour message and the depth message nearest in time, at most
`RecordingConfig.pair_tolerance_s` apart; the commands' ``--frame-index N`` sets it (`recording_frame`).

Topics: the colour stream is the `sensor_msgs/Image` topic with a colour encoding (rgb8, bgr8, rgba8, bgra8, mono8),
the depth stream the one with a depth encoding (16UC1 / mono16: units of the bag's ``Depth Units`` option
(RealSense SDK) or millimetres (ROS REP 118); 32FC1: metres), a topic named ``aligned`` preferred. The intrinsics
are those of the colour stream's `sensor_msgs/CameraInfo` (the one whose topic shares the longest prefix with the
image topic). Depth must be aligned to colour: an ``aligned_depth_to_color`` topic, or a depth stream whose own
camera info has the colour's size and intrinsics; otherwise `RecordingError` says so (v2c does not reproject
depth; record with realsense-ros ``align_depth:=true`` or align with pyrealsense2's ``rs.align``).

An Open3D RGBD folder (what Open3D's ``realsense_recorder.py`` writes, and its reconstruction system reads): colour
images in ``color/``, depth images in ``depth/`` (registered to colour, 16-bit), the intrinsics in
``camera_intrinsic.json`` (or ``intrinsic.json``; Open3D's ``PinholeCameraIntrinsic`` form). Pairs are the file
stems present in both folders, in sorted order; `open3d_frame_files` names the files of one pair and
`v2c.scan.load_scan` reads them as it reads a scan folder's ``color.png``, ``depth.png`` and ``camera.json``.
"""

from __future__ import annotations

import contextlib
import contextvars
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from v2c.contexts import scoped
from v2c.errors import ScanError

__all__ = [
    "RECORDING_SUFFIXES",
    "RecordedFrame",
    "RecordingConfig",
    "RecordingError",
    "current_frame_index",
    "is_open3d_folder",
    "is_recording",
    "open3d_frame_files",
    "read_bag_frame",
    "recording_frame",
]

#: File suffixes read as recordings (lower case).
RECORDING_SUFFIXES = (".bag",)
_COLOR_ENCODINGS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1}
_DEPTH_ENCODINGS = {"16UC1": np.dtype("u2"), "mono16": np.dtype("u2"), "32FC1": np.dtype("f4")}
_IMAGE = "sensor_msgs/msg/Image"
_INFO = "sensor_msgs/msg/CameraInfo"
_FLOAT = "std_msgs/msg/Float32"


class RecordingError(ScanError):
    """A recording that cannot give a frame; the message names the file, the value and what was expected."""


@dataclass(frozen=True)
class RecordingConfig:
    """Settings of reading a recording, with units."""

    pair_tolerance_s: float = 0.02  # a colour and a depth message further apart in time are no pair (seconds)
    default_depth_unit_m: float = 0.001  # 16-bit depth without a "Depth Units" option: millimetres (ROS REP 118)
    intrinsics_rel_tol: float = 1e-6  # depth and colour K equal within this relative difference = aligned


@dataclass
class RecordedFrame:
    """One frame: color (H, W, 3) uint8 RGB; depth (H, W) float64 metres, 0 = no reading (not range-checked);
    K (3, 3) pixels; depth_unit: how the depth numbers became metres; topics: "color", "depth", "camera_info";
    index: the pair's index; n_pairs: complete pairs in the recording."""

    color: np.ndarray
    depth: np.ndarray
    K: np.ndarray
    depth_unit: str
    topics: dict[str, str]
    index: int
    n_pairs: int
    notes: list[str] = field(default_factory=list)


_CURRENT: contextvars.ContextVar[int | None] = contextvars.ContextVar("v2c_frame_index", default=None)


def current_frame_index() -> int:
    """The frame index in force: 0 (the first complete pair) unless inside `recording_frame`."""
    v = _CURRENT.get()
    return 0 if v is None else v


def recording_frame(index: int) -> contextlib.AbstractContextManager[int]:
    """Make ``index`` the pair `v2c.scan.load_scan` reads from a recording inside the block (``--frame-index``)."""
    return scoped(_CURRENT, index)


def is_recording(path: Path) -> bool:
    """Whether ``path`` is read as a recording (a file with a suffix of `RECORDING_SUFFIXES`)."""
    return path.suffix.lower() in RECORDING_SUFFIXES and not path.is_dir()


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS1_NOETIC)


def _field(msg: Any, name: str) -> Any:
    """A message field by its ROS1 (K, D) or ROS2 (k, d) spelling."""
    return getattr(msg, name) if hasattr(msg, name) else getattr(msg, name.lower())


def _pixels(msg: Any, path: Path, topic: str) -> np.ndarray:
    """A sensor_msgs/Image -> (H, W) or (H, W, C) array (colour RGB uint8, 16-bit or float depth as stored)."""
    enc, h, w, step = str(msg.encoding), int(msg.height), int(msg.width), int(msg.step)
    if enc in _COLOR_ENCODINGS:
        dtype, channels = np.dtype("u1"), _COLOR_ENCODINGS[enc]
    elif enc in _DEPTH_ENCODINGS:
        dtype, channels = _DEPTH_ENCODINGS[enc], 1
    else:
        raise RecordingError(
            f"{path}: topic {topic}: image encoding {enc!r} (expected one of "
            f"{', '.join([*_COLOR_ENCODINGS, *_DEPTH_ENCODINGS])})"
        )
    data = np.asarray(msg.data, dtype=np.uint8)
    row = w * channels * dtype.itemsize
    if h <= 0 or w <= 0 or step < row or data.size < step * h:
        raise RecordingError(
            f"{path}: topic {topic}: image {w}x{h} {enc} with step {step} needs {step * h} bytes, holds {data.size}"
        )
    rows = data[: step * h].reshape(h, step)[:, :row]
    arr = np.ascontiguousarray(rows).view(dtype.newbyteorder(">" if msg.is_bigendian else "<"))
    arr = arr.reshape(h, w, channels).astype(dtype.newbyteorder("="))
    if enc in _DEPTH_ENCODINGS:
        return arr[..., 0]
    if enc == "mono8":
        return np.repeat(arr, 3, axis=2)
    rgb = arr[..., :3]
    return np.ascontiguousarray(rgb[..., ::-1] if enc.startswith("bgr") else rgb)


def _common_prefix(a: str, b: str) -> int:
    """Number of leading topic components two topic names share."""
    n = 0
    for x, y in zip(a.strip("/").split("/"), b.strip("/").split("/"), strict=False):
        if x != y:
            break
        n += 1
    return n


def _info_for(topic: str, infos: dict[str, Any]) -> str | None:
    """The CameraInfo topic sharing the most leading components with ``topic`` (None when none shares any)."""
    best = max(infos, key=lambda t: (_common_prefix(t, topic), t), default=None)
    return best if best is not None and _common_prefix(best, topic) > 0 else None


def read_bag_frame(path: str | Path, frame_index: int = 0, cfg: RecordingConfig | None = None) -> RecordedFrame:
    """Read the ``frame_index``-th complete colour+depth pair of a ROS1 bag (module doc). Raises RecordingError
    naming the file, the value and what was expected (not a bag, no colour/depth topic, no camera info, depth not
    aligned to colour, an index past the last pair)."""
    from rosbags.rosbag1 import Reader, ReaderError

    cfg = cfg or RecordingConfig()
    path = Path(path)
    if frame_index < 0:
        raise RecordingError(f"{path}: frame index {frame_index}; expected 0 or more")
    store = _typestore()
    try:
        with Reader(path) as reader:
            return _read_frame(reader, store, path, frame_index, cfg)
    except ReaderError as e:
        raise RecordingError(f"{path}: not a readable ROS1 bag ({e})") from None
    except OSError as e:
        raise RecordingError(f"{path}: {e.strerror or type(e).__name__}") from None


def _first(reader: Any, store: Any, conn: Any) -> Any:
    for _, _, raw in reader.messages(connections=[conn]):
        return store.deserialize_ros1(raw, conn.msgtype)
    return None


def _read_frame(reader: Any, store: Any, path: Path, index: int, cfg: RecordingConfig) -> RecordedFrame:
    images = [c for c in reader.connections if c.msgtype == _IMAGE]
    infos = {c.topic: c for c in reader.connections if c.msgtype == _INFO}
    colors, depths = [], []
    for c in images:
        msg = _first(reader, store, c)
        if msg is None:
            continue
        if str(msg.encoding) in _COLOR_ENCODINGS:
            colors.append(c)
        elif str(msg.encoding) in _DEPTH_ENCODINGS:
            depths.append(c)
    found = ", ".join(sorted(f"{c.topic} ({c.msgtype})" for c in reader.connections)) or "none"
    if not colors or not depths:
        missing = "colour" if not colors else "depth"
        raise RecordingError(
            f"{path}: no {missing} image topic (sensor_msgs/Image with encoding "
            f"{' / '.join(_COLOR_ENCODINGS if not colors else _DEPTH_ENCODINGS)}); topics: {found}"
        )
    color_c = sorted(colors, key=lambda c: c.topic)[0]
    depth_c = sorted(depths, key=lambda c: ("aligned" not in c.topic, c.topic))[0]
    info_topic = _info_for(color_c.topic, infos)
    if info_topic is None:
        raise RecordingError(f"{path}: no sensor_msgs/CameraInfo for colour topic {color_c.topic}; topics: {found}")
    info = _first(reader, store, infos[info_topic])
    K = np.asarray(_field(info, "K"), dtype=np.float64).reshape(3, 3)
    size = (int(info.width), int(info.height))
    if "aligned" not in depth_c.topic:
        dinfo_topic = _info_for(depth_c.topic, {t: c for t, c in infos.items() if t != info_topic})
        dinfo = _first(reader, store, infos[dinfo_topic]) if dinfo_topic else None
        dK = None if dinfo is None else np.asarray(_field(dinfo, "K"), dtype=np.float64).reshape(3, 3)
        same = (
            dinfo is not None
            and (int(dinfo.width), int(dinfo.height)) == size
            and np.allclose(dK, K, rtol=cfg.intrinsics_rel_tol, atol=0.0)
        )
        if not same:
            what = (
                "has no camera info of its own"
                if dinfo is None
                else (
                    f"has {int(dinfo.width)}x{int(dinfo.height)} px, fx {dK[0, 0]:.2f} "
                    f"(colour: {size[0]}x{size[1]} px, fx {K[0, 0]:.2f})"
                )
            )
            raise RecordingError(
                f"{path}: depth topic {depth_c.topic} is not aligned to colour topic {color_c.topic} (it {what}); "
                "expected depth registered to colour: record with realsense-ros align_depth:=true "
                "(an aligned_depth_to_color topic) or align with pyrealsense2 rs.align before recording"
            )
    c_times = np.array([t for _, t, _ in reader.messages(connections=[color_c])], dtype=np.int64)
    d_times = np.array([t for _, t, _ in reader.messages(connections=[depth_c])], dtype=np.int64)
    j = np.clip(np.searchsorted(d_times, c_times), 1, len(d_times) - 1) if len(d_times) > 1 else np.zeros_like(c_times)
    if len(d_times) > 1:
        j = np.where(np.abs(d_times[j - 1] - c_times) <= np.abs(d_times[j] - c_times), j - 1, j)
    ok = np.abs(d_times[j] - c_times) <= cfg.pair_tolerance_s * 1e9
    pairs = np.flatnonzero(ok)
    if index >= len(pairs):
        raise RecordingError(
            f"{path}: frame index {index}, but the bag holds {len(pairs)} complete colour+depth pairs "
            f"({len(c_times)} colour, {len(d_times)} depth messages, pairs within {cfg.pair_tolerance_s:g} s); "
            f"expected 0..{len(pairs) - 1}"
            if len(pairs)
            else f"{path}: no colour and depth messages within {cfg.pair_tolerance_s:g} s of each other "
            f"({len(c_times)} colour, {len(d_times)} depth messages)"
        )
    ci = int(pairs[index])
    tc, td = int(c_times[ci]), int(d_times[j[ci]])
    color = _pixels(_at(reader, store, color_c, tc), path, color_c.topic)
    raw = _pixels(_at(reader, store, depth_c, td), path, depth_c.topic)
    if raw.shape != color.shape[:2] or (color.shape[1], color.shape[0]) != size:
        raise RecordingError(
            f"{path}: depth {raw.shape[1]}x{raw.shape[0]}, colour {color.shape[1]}x{color.shape[0]}, camera info "
            f"{size[0]}x{size[1]} px; expected one size (depth registered to colour)"
        )
    if raw.dtype.kind == "f":
        depth = np.where(np.isfinite(raw), raw, 0.0).astype(np.float64)  # ROS float depth: NaN = no reading
        unit = f"float metres from {depth_c.topic}"
    else:
        scale, where = _depth_unit(reader, store, cfg)
        depth = raw.astype(np.float64) * scale
        unit = f"{scale:g} m per unit ({where}) from {depth_c.topic}"
    return RecordedFrame(
        color=color,
        depth=depth,
        K=K,
        depth_unit=unit,
        topics={"color": color_c.topic, "depth": depth_c.topic, "camera_info": info_topic},
        index=index,
        n_pairs=len(pairs),
    )


def _at(reader: Any, store: Any, conn: Any, t: int) -> Any:
    """The message of ``conn`` written at bag time ``t`` (nanoseconds)."""
    for _, _, raw in reader.messages(connections=[conn], start=t, stop=t + 1):
        return store.deserialize_ros1(raw, conn.msgtype)
    raise RecordingError(f"message of {conn.topic} at {t} ns vanished")  # not reached for a readable bag


def _depth_unit(reader: Any, store: Any, cfg: RecordingConfig) -> tuple[float, str]:
    """Metres per 16-bit depth unit: the RealSense SDK's "Depth Units" option when the bag has it, else mm."""
    for c in reader.connections:
        if c.msgtype == _FLOAT and "depth units" in c.topic.lower():
            msg = _first(reader, store, c)
            if msg is not None and float(msg.data) > 0:
                return float(msg.data), f"the bag's {c.topic}"
    return cfg.default_depth_unit_m, "no Depth Units option: millimetres, ROS REP 118"


#: Open3D RGBD folder: its sub-folders and the intrinsics file names accepted (first found wins).
OPEN3D_COLOR_DIR, OPEN3D_DEPTH_DIR = "color", "depth"
OPEN3D_INTRINSIC_NAMES = ("camera_intrinsic.json", "intrinsic.json")
_OPEN3D_COLOR_EXT = (".jpg", ".jpeg", ".png")
_OPEN3D_DEPTH_EXT = (".png",)


def is_open3d_folder(path: Path) -> bool:
    """Whether ``path`` is an Open3D RGBD folder (``color/`` and ``depth/`` sub-folders, no ``color.png`` of a
    scan folder)."""
    return (
        path.is_dir()
        and (path / OPEN3D_COLOR_DIR).is_dir()
        and (path / OPEN3D_DEPTH_DIR).is_dir()
        and not any((path / n).exists() for n in ("color.png", "color.jpg", "color.jpeg"))
    )


def open3d_frame_files(folder: Path, frame_index: int = 0) -> tuple[Path, Path, Path, int]:
    """(colour image, depth image, intrinsics JSON, pairs in the folder) of the ``frame_index``-th pair of an Open3D
    RGBD folder (pairs: file stems present in both ``color/`` and ``depth/``, sorted). Raises RecordingError."""
    folder = Path(folder)
    intrinsic = next((folder / n for n in OPEN3D_INTRINSIC_NAMES if (folder / n).is_file()), None)
    if intrinsic is None:
        raise RecordingError(
            f"{folder}: Open3D RGBD folder without intrinsics; expected {' or '.join(OPEN3D_INTRINSIC_NAMES)} "
            "(Open3D PinholeCameraIntrinsic JSON)"
        )

    def stems(sub: str, exts: tuple[str, ...]) -> dict[str, Path]:
        files = sorted(p for p in (folder / sub).iterdir() if p.suffix.lower() in exts and p.is_file())
        return {p.stem: p for p in reversed(files)}  # one file per stem; the first in name order wins

    colors, depths = stems(OPEN3D_COLOR_DIR, _OPEN3D_COLOR_EXT), stems(OPEN3D_DEPTH_DIR, _OPEN3D_DEPTH_EXT)
    pairs = sorted(set(colors) & set(depths))
    if frame_index < 0 or frame_index >= len(pairs):
        raise RecordingError(
            f"{folder}: frame index {frame_index}, but the folder holds {len(pairs)} colour+depth pairs "
            f"({len(colors)} in {OPEN3D_COLOR_DIR}/, {len(depths)} in {OPEN3D_DEPTH_DIR}/, paired by file name)"
            + (f"; expected 0..{len(pairs) - 1}" if pairs else "")
        )
    stem = pairs[frame_index]
    return colors[stem], depths[stem], intrinsic, len(pairs)
