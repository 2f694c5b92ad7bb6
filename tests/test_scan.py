"""v2c.scan: loading, validation errors, camera.json forms, ROI/mask, ground truth, back-projection, real frames."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from v2c.scan import ScanError, backproject, load_camera, load_scan, parse_roi

from conftest import TINY, camera_dict, listing, real_scan_dirs, tiny_depth_m, write_tiny_scan

# ------------------------------------------------------------------------------------------------------------------
# a valid scan


def test_tiny_scan_loads_with_exact_values(tiny_scan_dir: Path) -> None:
    scan = load_scan(tiny_scan_dir)
    assert (scan.height, scan.width) == (TINY.height, TINY.width)
    assert scan.color.shape == (TINY.height, TINY.width, 3) and scan.color.dtype == np.uint8
    assert scan.depth.dtype == np.float32 and scan.K.dtype == np.float64
    np.testing.assert_array_equal(scan.K, TINY.K)
    # colour comes back RGB (the file is BGR on disk): R = 4u mod 256, G = 5v mod 256, B = 90
    assert tuple(scan.color[7, 9]) == (36, 35, 90)
    # depth in metres: quantised to the 0.1 mm unit, so within half a unit of the exact plane
    exact = tiny_depth_m()
    x0, y0, x1, y1 = TINY.hole_box
    exact[y0:y1, x0:x1] = 0
    assert np.abs(scan.depth - exact).max() <= 0.5 * TINY.depth_scale + 1e-6
    assert scan.depth[y0:y1, x0:x1].max() == 0
    assert scan.mask is None and scan.roi is None
    assert scan.valid.sum() == TINY.width * TINY.height - (x1 - x0) * (y1 - y0)
    assert scan.camera_format == "v2c" and scan.depth_scale == pytest.approx(TINY.depth_scale)
    assert scan.files["depth"].name == "depth.png" and scan.files["color"].name == "color.png"


def test_points_lie_on_the_plane(tiny_scan_dir: Path) -> None:
    scan = load_scan(tiny_scan_dir)
    pts = scan.points()
    assert pts.shape == (TINY.height, TINY.width, 3)
    on = pts[scan.valid]
    dist = (on - TINY.plane_point) @ TINY.plane_normal
    # depth quantisation (0.05 mm) is the only error
    assert np.abs(dist).max() < 1e-4
    assert np.all(pts[~scan.valid] == 0)


def test_backproject_matches_pinhole_model_and_reprojects() -> None:
    rng = np.random.default_rng(3)
    K = np.array([[500.0, 1.5, 319.2], [0.0, 510.0, 241.7], [0.0, 0.0, 1.0]])  # with a skew term
    depth = rng.uniform(0.3, 2.0, size=(7, 9))
    pts = backproject(depth, K)
    assert pts.shape == (7, 9, 3)
    np.testing.assert_allclose(pts[..., 2], depth)
    proj = pts @ K.T
    uv = proj[..., :2] / proj[..., 2:]
    u, v = np.meshgrid(np.arange(9.0), np.arange(7.0))
    np.testing.assert_allclose(uv[..., 0], u, atol=1e-9)
    np.testing.assert_allclose(uv[..., 1], v, atol=1e-9)
    # one pixel by hand, no skew
    K0 = np.array([[100.0, 0, 10.0], [0, 200.0, 20.0], [0, 0, 1]])
    p = backproject(np.full((30, 40), 2.0), K0)[25, 30]
    np.testing.assert_allclose(p, [(30 - 10) / 100 * 2, (25 - 20) / 200 * 2, 2.0])


def test_depth_npy_equals_depth_png(tmp_path: Path) -> None:
    a = load_scan(write_tiny_scan(tmp_path / "png"))
    b = load_scan(write_tiny_scan(tmp_path / "npy", depth_format="npy"))
    assert b.files["depth"].name == "depth.npy"
    assert np.abs(a.depth - b.depth).max() <= 0.5 * TINY.depth_scale + 1e-6
    np.testing.assert_array_equal(a.valid, b.valid)


def test_jpeg_colour(tmp_path: Path) -> None:
    scan = load_scan(write_tiny_scan(tmp_path / "s", color_ext="jpg"))
    assert scan.files["color"].name == "color.jpg"
    ref = load_scan(write_tiny_scan(tmp_path / "p")).color.astype(int)
    assert np.abs(scan.color.astype(int) - ref).mean() < 6  # lossy, but the same picture, RGB order


# ------------------------------------------------------------------------------------------------------------------
# camera.json forms


@pytest.mark.parametrize("form", ["v2c", "v2c-flat", "open3d", "bop", "bop-file"])
def test_camera_forms_give_the_same_K_and_depth(form: str, tmp_path: Path) -> None:
    ref = load_scan(write_tiny_scan(tmp_path / "ref"))
    scan = load_scan(write_tiny_scan(tmp_path / form, camera=form))
    np.testing.assert_allclose(scan.K, TINY.K, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(scan.depth, ref.depth)
    assert scan.depth_scale == pytest.approx(TINY.depth_scale)
    assert scan.camera_format == {"v2c-flat": "v2c", "bop-file": "bop"}.get(form, form)


def test_open3d_without_depth_scale_defaults_to_millimetres(tmp_path: Path) -> None:
    p = tmp_path / "camera.json"
    d = camera_dict("open3d")
    del d["depth_scale"]
    p.write_text(json.dumps(d))
    cam = load_camera(p)
    assert cam.depth_scale == pytest.approx(0.001) and cam.format == "open3d"
    np.testing.assert_allclose(cam.K, TINY.K)
    d["depth_scale"] = 1000.0  # Open3D's own convention: depth units per metre
    p.write_text(json.dumps(d))
    assert load_camera(p).depth_scale == pytest.approx(0.001)


def test_bop_default_depth_scale_is_one_millimetre(tmp_path: Path) -> None:
    p = tmp_path / "camera.json"
    p.write_text(json.dumps({"cam_K": TINY.K.reshape(-1).tolist()}))
    assert load_camera(p).depth_scale == pytest.approx(0.001)


# ------------------------------------------------------------------------------------------------------------------
# ROI and mask


def test_roi_restricts_validity_and_keeps_full_arrays(tiny_scan_dir: Path) -> None:
    roi = (10, 5, 30, 25)
    scan = load_scan(tiny_scan_dir, roi=roi)
    assert scan.roi == roi
    assert scan.depth.shape == (TINY.height, TINY.width) and scan.color.shape[:2] == scan.depth.shape
    expected = np.zeros((TINY.height, TINY.width), bool)
    expected[5:25, 10:30] = True
    np.testing.assert_array_equal(scan.valid, expected & (scan.depth > 0))
    assert scan.valid.sum() == 20 * 20
    # the string form of the command line gives the same scan
    np.testing.assert_array_equal(load_scan(tiny_scan_dir, roi="10,5,30,25").valid, scan.valid)
    # whole-image ROI is allowed (x1, y1 exclusive)
    assert (
        load_scan(tiny_scan_dir, roi=(0, 0, TINY.width, TINY.height)).valid.sum()
        == load_scan(tiny_scan_dir).valid.sum()
    )


def test_parse_roi() -> None:
    assert parse_roi("1,2,3,4") == (1, 2, 3, 4)
    assert parse_roi(" 1, 2 ,3,4 ") == (1, 2, 3, 4)
    assert parse_roi((0, 0, 5, 6)) == (0, 0, 5, 6)
    assert parse_roi(None) is None
    for bad in ("1,2,3", "a,b,c,d", "1,2,3,4,5", "1.5,2,3,4", "5,0,5,4", "0,4,5,4", "3,0,1,4"):
        with pytest.raises(ScanError, match="ROI"):
            parse_roi(bad)


def test_mask_restricts_validity(tmp_path: Path) -> None:
    scan = load_scan(write_tiny_scan(tmp_path / "s", mask=True))
    assert scan.mask is not None and scan.mask.dtype == bool
    assert scan.mask.sum() == 32 * 32 and scan.mask[8:40, 16:48].all()
    np.testing.assert_array_equal(scan.valid, scan.mask & (scan.depth > 0))
    both = load_scan(tmp_path / "s", roi=(0, 0, 20, 48))
    assert both.valid.sum() == 32 * 4  # columns 16..19 of the mask


def test_roi_without_readings_is_an_error(tiny_scan_dir: Path) -> None:
    x0, y0, x1, y1 = TINY.hole_box
    with pytest.raises(ScanError, match="no depth reading inside ROI"):
        load_scan(tiny_scan_dir, roi=(x0, y0, x1, y1))


# ------------------------------------------------------------------------------------------------------------------
# ground truth


def test_ground_truth_loads(tiny_scan_dir: Path) -> None:
    gt = load_scan(tiny_scan_dir).gt
    assert gt is not None
    assert gt.faces.dtype == np.uint16 and gt.labels.dtype == np.uint8
    x0, y0, x1, y1 = TINY.face_box
    assert (gt.faces == 1).sum() == (x1 - x0) * (y1 - y0)
    assert set(np.unique(gt.labels)) == {0, 4}
    assert [p["type"] for p in gt.primitives] == ["plane", "cylinder"]
    assert gt.part_size_m == pytest.approx(TINY.part_size_m)
    assert gt.step_path.name == "part.step" and gt.step_path.is_file()
    assert list(gt.visible_face_ids()) == [0]
    # depth_clean uses depth.png's scale: metres, exact plane within half a unit, 0 off the part
    exact = np.where(gt.faces > 0, tiny_depth_m(), 0)
    assert gt.depth_clean.dtype == np.float32
    assert np.abs(gt.depth_clean - exact).max() <= 0.5 * TINY.depth_scale + 1e-6


def test_no_ground_truth_without_gt_folder(tmp_path: Path) -> None:
    assert load_scan(write_tiny_scan(tmp_path / "s")).gt is None


# ------------------------------------------------------------------------------------------------------------------
# bad input: every case names the file and the problem


def _write_png(path: Path, arr: np.ndarray) -> None:
    assert cv2.imwrite(str(path), arr)


def _truncate(path: Path, keep: float = 0.6) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def _camera(folder: Path, d: dict | str) -> None:
    (folder / "camera.json").write_text(d if isinstance(d, str) else json.dumps(d))


def _depth_npy(folder: Path, bad_value: float) -> None:
    (folder / "depth.png").unlink()
    d = tiny_depth_m().astype(np.float32)
    d[5, 7] = bad_value
    np.save(folder / "depth.npy", d)


def _flip_png_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    i = data.find(b"IDAT") + 20
    data[i] ^= 0xFF
    path.write_bytes(bytes(data))


def _jpeg_truncated(folder: Path) -> None:
    (folder / "color.png").unlink()
    rgb = np.random.default_rng(0).integers(0, 255, (TINY.height, TINY.width, 3), dtype=np.uint8)
    cv2.imwrite(str(folder / "color.jpg"), rgb)
    _truncate(folder / "color.jpg", 0.7)


H, W = TINY.height, TINY.width

#: (case id, how to break the scan, file named in the error, words of the problem, roi)
BAD_INPUTS = [
    ("missing-color", lambda f: (f / "color.png").unlink(), "color.png", "not found", None),
    ("missing-depth", lambda f: (f / "depth.png").unlink(), "depth.png", "not found", None),
    ("missing-camera", lambda f: (f / "camera.json").unlink(), "camera.json", "not found", None),
    (
        "size-mismatch",
        lambda f: _write_png(f / "depth.png", np.full((H, W + 2), 5000, np.uint16)),
        "depth.png",
        "differs from color.png",
        None,
    ),
    (
        "depth-8bit",
        lambda f: _write_png(f / "depth.png", np.full((H, W), 100, np.uint8)),
        "depth.png",
        "8-bit depth",
        None,
    ),
    (
        "depth-3-channel",
        lambda f: _write_png(f / "depth.png", np.full((H, W, 3), 100, np.uint16)),
        "depth.png",
        "one channel",
        None,
    ),
    (
        "depth-all-zero",
        lambda f: _write_png(f / "depth.png", np.zeros((H, W), np.uint16)),
        "depth.png",
        "all depth values are zero",
        None,
    ),
    ("depth-npy-nan", lambda f: _depth_npy(f, np.nan), "depth.npy", "non-finite", None),
    ("depth-npy-inf", lambda f: _depth_npy(f, np.inf), "depth.npy", "non-finite", None),
    ("depth-npy-negative", lambda f: _depth_npy(f, -0.5), "depth.npy", "negative", None),
    (
        "depth-npy-truncated",
        lambda f: (_depth_npy(f, 0.0), _truncate(f / "depth.npy")),
        "depth.npy",
        "cannot read",
        None,
    ),
    ("both-depths", lambda f: np.save(f / "depth.npy", tiny_depth_m()), "depth.npy", "keep one", None),
    (
        "K-2x3",
        lambda f: _camera(f, dict(camera_dict(), K=[[60, 0, 31.5], [0, 62, 23.5]])),
        "camera.json",
        "not 3x3",
        None,
    ),
    (
        "K-ragged",
        lambda f: _camera(f, dict(camera_dict(), K=[[60, 0, 31.5], [0, 62], [0, 0, 1]])),
        "camera.json",
        "3x3 matrix",
        None,
    ),
    (
        "K-9x1",
        lambda f: _camera(f, dict(camera_dict(), K=[[v] for v in TINY.K.reshape(-1)])),
        "camera.json",
        "not 3x3",
        None,
    ),
    ("K-string", lambda f: _camera(f, dict(camera_dict(), K="identity")), "camera.json", "3x3 matrix", None),
    (
        "K-nan",
        lambda f: _camera(f, dict(camera_dict(), K=[[60, 0, 31.5], [0, 62, 23.5], [0, 0, float("nan")]])),
        "camera.json",
        "non-finite",
        None,
    ),
    (
        "K-bottom-row",
        lambda f: _camera(f, dict(camera_dict(), K=[[60, 0, 31.5], [0, 62, 23.5], [0, 1, 1]])),
        "camera.json",
        "not a pinhole",
        None,
    ),
    (
        "K-fx-zero",
        lambda f: _camera(f, dict(camera_dict(), K=[[0, 0, 31.5], [0, 62, 23.5], [0, 0, 1]])),
        "camera.json",
        "non-positive focal length",
        None,
    ),
    (
        "K-fy-negative",
        lambda f: _camera(f, dict(camera_dict(), K=[[60, 0, 31.5], [0, -62, 23.5], [0, 0, 1]])),
        "camera.json",
        "non-positive focal length",
        None,
    ),
    (
        "K-open3d-row-major",
        lambda f: _camera(f, dict(camera_dict("open3d"), intrinsic_matrix=TINY.K.reshape(-1).tolist())),
        "camera.json",
        "not a pinhole",
        None,
    ),
    ("K-missing", lambda f: _camera(f, {"width": W, "height": H}), "camera.json", "no intrinsics", None),
    ("depth-scale-zero", lambda f: _camera(f, dict(camera_dict(), depth_scale=0)), "camera.json", "depth_scale", None),
    ("camera-size", lambda f: _camera(f, camera_dict(size=(640, 480))), "camera.json", "disagrees", None),
    (
        "invalid-json",
        lambda f: _camera(f, '{"K": [[60, 0, 31.5], [0, 62, 23.5], [0, 0, 1]'),
        "camera.json",
        "invalid JSON",
        None,
    ),
    (
        "color-garbage",
        lambda f: (f / "color.png").write_bytes(b"this is not an image at all"),
        "color.png",
        "not a PNG or JPEG",
        None,
    ),
    ("color-empty", lambda f: (f / "color.png").write_bytes(b""), "color.png", "empty file", None),
    ("color-png-truncated", lambda f: _truncate(f / "color.png"), "color.png", "truncated PNG", None),
    ("depth-png-truncated", lambda f: _truncate(f / "depth.png", 0.9), "depth.png", "truncated PNG", None),
    ("color-png-corrupt", lambda f: _flip_png_byte(f / "color.png"), "color.png", "CRC", None),
    ("color-jpeg-truncated", _jpeg_truncated, "color.jpg", "truncated JPEG", None),
    (
        "color-16bit",
        lambda f: _write_png(f / "color.png", np.full((H, W, 3), 300, np.uint16)),
        "color.png",
        "8-bit",
        None,
    ),
    (
        "mask-size",
        lambda f: _write_png(f / "mask.png", np.full((H - 1, W), 255, np.uint8)),
        "mask.png",
        "differs",
        None,
    ),
    (
        "mask-empty",
        lambda f: _write_png(f / "mask.png", np.zeros((H, W), np.uint8)),
        "mask.png",
        "marks no pixel",
        None,
    ),
    (
        "mask-truncated",
        lambda f: (_write_png(f / "mask.png", np.full((H, W), 255, np.uint8)), _truncate(f / "mask.png")),
        "mask.png",
        "truncated",
        None,
    ),
    ("roi-outside", None, "color.png", "outside the image", (10, 10, W + 1, 20)),
    ("roi-negative", None, "color.png", "outside the image", (-1, 0, 10, 10)),
    ("roi-beyond", None, "color.png", "outside the image", (W + 5, 0, W + 10, 10)),
    ("roi-empty", None, "ROI", "empty", (10, 10, 10, 20)),
    ("gt-faces-missing", lambda f: (f / "gt" / "faces.png").unlink(), "faces.png", "not found", None),
    (
        "gt-faces-size",
        lambda f: _write_png(f / "gt" / "faces.png", np.ones((H, W - 1), np.uint16)),
        "faces.png",
        "differs",
        None,
    ),
    (
        "gt-primitives-json",
        lambda f: (f / "gt" / "primitives.json").write_text("[{"),
        "primitives.json",
        "invalid JSON",
        None,
    ),
    (
        "gt-face-without-primitive",
        lambda f: _write_png(f / "gt" / "faces.png", np.full((H, W), 9, np.uint16)),
        "faces.png",
        "lists only 2 faces",
        None,
    ),
]


def _break(folder: Path, mutate) -> None:
    if mutate is not None:
        mutate(folder)


@pytest.mark.parametrize("case,mutate,fname,problem,roi", BAD_INPUTS, ids=[c[0] for c in BAD_INPUTS])
def test_bad_input_names_file_and_problem(case, mutate, fname, problem, roi, scan_copy: Path) -> None:
    _break(scan_copy, mutate)
    before = listing(scan_copy)
    with pytest.raises(ScanError) as err:
        load_scan(scan_copy, roi=roi)
    msg = str(err.value)
    assert fname in msg, msg
    assert problem.lower() in msg.lower(), msg
    assert isinstance(err.value, ValueError)
    assert listing(scan_copy) == before


def test_missing_folder_and_file_instead_of_folder(tmp_path: Path) -> None:
    with pytest.raises(ScanError, match="scan folder not found") as err:
        load_scan(tmp_path / "nowhere")
    assert "nowhere" in str(err.value)
    f = tmp_path / "file.txt"
    f.write_text("x")
    with pytest.raises(ScanError, match="not a folder"):
        load_scan(f)


@pytest.mark.parametrize("cut", [12, 1, 13])
def test_png_missing_its_end_is_truncated(cut: int, scan_copy: Path) -> None:
    """Only the last bytes gone (the IEND chunk or part of it): still reported as a truncated PNG, whatever the
    OpenCV build would make of it."""
    p = scan_copy / "depth.png"
    p.write_bytes(p.read_bytes()[:-cut])
    with pytest.raises(ScanError, match="truncated PNG") as err:
        load_scan(scan_copy)
    assert "depth.png" in str(err.value)


# ------------------------------------------------------------------------------------------------------------------
# real frames of ../shared/data/real


def test_real_frames_load(shared_data: Path) -> None:
    dirs = real_scan_dirs()
    assert len(dirs) >= 6, dirs
    for d in dirs:
        cam = json.loads((d / "camera.json").read_text())
        scan = load_scan(d)
        assert (scan.width, scan.height) == (640, 480), d
        has = scan.depth > 0
        assert 0.5 < has.mean() <= 1.0, d
        # tabletop scenes about 0.7-3.6 m away: a wrong depth scale would be off by 10x
        assert 0.3 < float(np.median(scan.depth[has])) < 4.0, d
        if "cam_K" in cam:  # BOP form, depth_scale in mm
            assert scan.camera_format == "bop"
            np.testing.assert_allclose(scan.K, np.reshape(cam["cam_K"], (3, 3)))
            assert scan.depth_scale == pytest.approx(cam.get("depth_scale", 1.0) * 1e-3)
        else:
            assert scan.camera_format == "v2c"
            np.testing.assert_allclose(scan.K, np.asarray(cam["K"], float))
            assert scan.depth_scale == pytest.approx(cam["depth_scale"])


def test_real_frame_with_roi(shared_data: Path, tmp_path: Path) -> None:
    src = shared_data / "real" / "lm_occluded_example"
    scan = load_scan(src, roi=(200, 150, 400, 300))
    assert scan.valid.sum() <= 200 * 150 and scan.valid[:150].sum() == 0
    # a copy in another camera.json form gives the same intrinsics
    dst = Path(shutil.copytree(src, tmp_path / "lm"))
    cam = json.loads((src / "camera.json").read_text())
    K = np.reshape(cam["cam_K"], (3, 3))
    (dst / "camera.json").write_text(
        json.dumps({"width": 640, "height": 480, "intrinsic_matrix": K.T.reshape(-1).tolist()})
    )
    scan2 = load_scan(dst, roi=(200, 150, 400, 300))
    np.testing.assert_allclose(scan2.K, scan.K)
    np.testing.assert_array_equal(scan2.depth, scan.depth)  # both 1 mm per unit
