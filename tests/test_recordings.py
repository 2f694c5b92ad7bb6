"""Sensor recordings (v2c.recordings, issue 17 item 7): a ROS1 .bag written here with rosbags' writer (synthetic
colour, 16-bit depth with a RealSense "Depth Units" option, camera_info) loads as a Scan with the depth and
intrinsics written; --frame-index picks the pair; unaligned depth and broken bags give one clear error."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from rosbags.rosbag1 import Writer
from rosbags.typesys import Stores, get_typestore

from v2c.cli import main
from v2c.recordings import RecordingError, read_bag_frame, recording_frame
from v2c.scan import ScanError, load_scan

W, H = 64, 48
K = np.array([[60.0, 0.0, 31.5], [0.0, 61.0, 23.5], [0.0, 0.0, 1.0]])
DEPTH_UNIT = 0.0001  # metres per 16-bit unit, as the RealSense SDK's "Depth Units" option says
STORE = get_typestore(Stores.ROS1_NOETIC)
T0 = 1_700_000_000_000_000_000  # bag time of the first frame, nanoseconds
PERIOD = 33_333_333  # 30 fps


def _depth_units(frame: int) -> np.ndarray:
    """A tilted plane 0.5..0.6 m plus a step per frame, as 16-bit units."""
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    z = 0.5 + 0.1 * u / W + 0.01 * frame
    d = np.round(z / DEPTH_UNIT).astype(np.uint16)
    d[:4, :4] = 0  # no reading
    return d


def _color(frame: int) -> np.ndarray:
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    return np.stack([(4 * u) % 256, (5 * v) % 256, np.full_like(u, 40 * frame)], -1).astype(np.uint8)


def _header(t: int, frame_id: str) -> object:
    Header = STORE.types["std_msgs/msg/Header"]
    Time = STORE.types["builtin_interfaces/msg/Time"]
    return Header(seq=0, stamp=Time(sec=t // 10**9, nanosec=t % 10**9), frame_id=frame_id)


def _image(t: int, arr: np.ndarray, encoding: str) -> object:
    Image = STORE.types["sensor_msgs/msg/Image"]
    data = np.ascontiguousarray(arr).view(np.uint8).reshape(-1)
    step = arr.shape[1] * (arr.shape[2] if arr.ndim == 3 else 1) * arr.dtype.itemsize
    return Image(
        header=_header(t, "camera"),
        height=arr.shape[0],
        width=arr.shape[1],
        encoding=encoding,
        is_bigendian=0,
        step=step,
        data=data,
    )


def _info(t: int, k: np.ndarray) -> object:
    Info = STORE.types["sensor_msgs/msg/CameraInfo"]
    RegionOfInterest = STORE.types["sensor_msgs/msg/RegionOfInterest"]
    P = np.zeros((3, 4))
    P[:, :3] = k
    return Info(
        header=_header(t, "camera"),
        height=H,
        width=W,
        distortion_model="plumb_bob",
        D=np.zeros(5),
        K=k.reshape(-1),
        R=np.eye(3).reshape(-1),
        P=P.reshape(-1),
        binning_x=0,
        binning_y=0,
        roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False),
    )


def write_bag(path: Path, n_frames: int = 3, aligned: bool = True, depth_k: np.ndarray | None = None) -> Path:
    """A RealSense-like bag: colour + depth (aligned topic, or a depth stream with its own camera_info) + units."""
    depth_topic = "/camera/aligned_depth_to_color/image_raw" if aligned else "/camera/depth/image_rect_raw"
    Float32 = STORE.types["std_msgs/msg/Float32"]
    with Writer(path) as w:
        c_img = w.add_connection("/camera/color/image_raw", "sensor_msgs/msg/Image", typestore=STORE)
        c_info = w.add_connection("/camera/color/camera_info", "sensor_msgs/msg/CameraInfo", typestore=STORE)
        d_img = w.add_connection(depth_topic, "sensor_msgs/msg/Image", typestore=STORE)
        units = w.add_connection("/device_0/sensor_0/option/Depth Units/value", "std_msgs/msg/Float32", typestore=STORE)
        w.write(units, T0, STORE.serialize_ros1(Float32(data=DEPTH_UNIT), "std_msgs/msg/Float32"))
        d_info = None
        if not aligned:
            d_info = w.add_connection("/camera/depth/camera_info", "sensor_msgs/msg/CameraInfo", typestore=STORE)
        for f in range(n_frames):
            t = T0 + f * PERIOD
            w.write(c_info, t, STORE.serialize_ros1(_info(t, K), "sensor_msgs/msg/CameraInfo"))
            w.write(c_img, t, STORE.serialize_ros1(_image(t, _color(f), "rgb8"), "sensor_msgs/msg/Image"))
            td = t + 2_000_000  # depth 2 ms after colour: one pair
            w.write(d_img, td, STORE.serialize_ros1(_image(td, _depth_units(f), "16UC1"), "sensor_msgs/msg/Image"))
            if d_info is not None:
                dk = K if depth_k is None else depth_k
                w.write(d_info, td, STORE.serialize_ros1(_info(td, dk), "sensor_msgs/msg/CameraInfo"))
    return path


def test_bag_loads_as_the_scan_written(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "rec.bag")
    scan = load_scan(bag)
    assert scan.width == W and scan.height == H
    np.testing.assert_array_equal(scan.K, K)
    np.testing.assert_array_equal(scan.color, _color(0))
    want = _depth_units(0).astype(np.float64) * DEPTH_UNIT
    np.testing.assert_allclose(scan.depth, want, rtol=1e-6, atol=1e-7)
    assert scan.depth.dtype == np.float32 and (scan.depth[:4, :4] == 0).all()
    assert scan.mask is None and scan.gt is None and scan.files == {"recording": bag}
    assert "frame 0 of 3" in scan.notes[0]


def test_frame_index_picks_the_pair(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "rec.bag")
    with recording_frame(2):
        scan = load_scan(bag)
    np.testing.assert_array_equal(scan.color, _color(2))
    np.testing.assert_allclose(scan.depth, _depth_units(2) * DEPTH_UNIT, rtol=1e-6, atol=1e-7)
    with pytest.raises(RecordingError, match=r"rec\.bag: frame index 3, but the bag holds 3 complete .* 0\.\.2"):
        read_bag_frame(bag, 3)
    res = CliRunner().invoke(main, ["info", str(bag), "--frame-index", "1"])
    assert res.exit_code == 0, res.output
    assert "frame 1 of 3" in res.output and "fx 60.000  fy 61.000" in res.output


def test_depth_stream_with_the_colour_intrinsics_counts_as_aligned(tmp_path: Path) -> None:
    scan = load_scan(write_bag(tmp_path / "same.bag", aligned=False))
    np.testing.assert_allclose(scan.depth, _depth_units(0) * DEPTH_UNIT, rtol=1e-6, atol=1e-7)


def test_unaligned_depth_is_refused(tmp_path: Path) -> None:
    k2 = K.copy()
    k2[0, 0] = 70.0
    bag = write_bag(tmp_path / "raw.bag", aligned=False, depth_k=k2)
    with pytest.raises(ScanError, match=r"raw\.bag: depth topic /camera/depth/image_rect_raw is not aligned"):
        load_scan(bag)


@pytest.mark.parametrize("content", [b"", b"#ROSBAG V2.0\nnot really", b"PK\x03\x04 a zip file"])
def test_bad_bag_is_one_error_line(tmp_path: Path, content: bytes) -> None:
    bag = tmp_path / "bad.bag"
    bag.write_bytes(content)
    res = CliRunner().invoke(main, ["info", str(bag)])
    assert res.exit_code == 1
    lines = [x for x in res.output.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith(f"error: {bag}: not a readable ROS1 bag"), res.output


def test_bag_without_depth_names_what_it_holds(tmp_path: Path) -> None:
    bag = tmp_path / "colour_only.bag"
    with Writer(bag) as w:
        c = w.add_connection("/camera/color/image_raw", "sensor_msgs/msg/Image", typestore=STORE)
        w.write(c, T0, STORE.serialize_ros1(_image(T0, _color(0), "rgb8"), "sensor_msgs/msg/Image"))
    with pytest.raises(RecordingError, match=r"colour_only\.bag: no depth image topic .*/camera/color/image_raw"):
        load_scan(bag)


def write_open3d_folder(folder: Path, n_frames: int = 2) -> Path:
    """Open3D's RGBD layout: color/NNNNNN.jpg, depth/NNNNNN.png (millimetres), camera_intrinsic.json."""
    import cv2

    (folder / "color").mkdir(parents=True)
    (folder / "depth").mkdir()
    for f in range(n_frames):
        cv2.imwrite(str(folder / "color" / f"{f:06d}.png"), _color(f)[..., ::-1])
        mm = np.round(_depth_units(f).astype(np.float64) * DEPTH_UNIT * 1000.0).astype(np.uint16)
        cv2.imwrite(str(folder / "depth" / f"{f:06d}.png"), mm)
    intrinsic = {"width": W, "height": H, "intrinsic_matrix": K.T.reshape(-1).tolist()}  # column-major
    (folder / "camera_intrinsic.json").write_text(json.dumps(intrinsic))
    return folder


def test_open3d_folder_loads_the_pair_asked_for(tmp_path: Path) -> None:
    folder = write_open3d_folder(tmp_path / "o3d")
    with recording_frame(1):
        scan = load_scan(folder)
    np.testing.assert_array_equal(scan.K, K)
    np.testing.assert_array_equal(scan.color, _color(1))
    want = np.round(_depth_units(1) * DEPTH_UNIT * 1000.0) / 1000.0  # written in millimetres, Open3D's default
    np.testing.assert_allclose(scan.depth, want, rtol=1e-6, atol=1e-7)
    assert scan.files["depth"] == folder / "depth" / "000001.png" and "frame 1 of 2" in scan.notes[0]
    res = CliRunner().invoke(main, ["info", str(folder), "--frame-index", "2"])
    assert res.exit_code == 1
    assert res.output.strip() == f"error: {folder}: frame index 2, but the folder holds 2 colour+depth pairs " + (
        "(2 in color/, 2 in depth/, paired by file name); expected 0..1"
    )
