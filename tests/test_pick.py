"""Picking the part in a cluttered frame (v2c.pick, issue 17 item 4): a table with a box at the image centre, a
second box and a cylinder elsewhere, ray-cast in numpy; a whole frame without ROI picks the centre object, --point
another one, and scans with a mask, a ROI or ground truth are left as they were."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from v2c.cli import main
from v2c.pick import PickConfig, PickError, PickRequest, parse_point, pick_object, should_pick
from v2c.scan import ScanError, load_scan

from scenes.raycast import BoundedFace, Scene, _box_bound, _cyl, _plane, render_scene

W, H = 320, 240
K = np.array([[300.0, 0.0, 160.0], [0.0, 300.0, 120.0], [0.0, 0.0, 1.0]])
DEPTH_SCALE = 0.0001  # metres per depth.png unit
#: objects on the table (part frame: table z = 0, metres): name -> (kind, centre x, y, size)
OBJECTS = {
    "centre_box": ("box", 0.0, 0.0, (0.08, 0.06, 0.10)),
    "side_box": ("box", 0.19, 0.06, (0.06, 0.06, 0.09)),
    "cylinder": ("cylinder", -0.17, 0.09, (0.035, 0.08)),
}


def _box_faces(cx: float, cy: float, size: tuple[float, float, float]) -> list[BoundedFace]:
    sx, sy, sz = size
    lo, hi = np.array([cx - sx / 2, cy - sy / 2, 0.0]), np.array([cx + sx / 2, cy + sy / 2, sz])
    b = _box_bound(lo, hi)
    faces = [BoundedFace(_plane((cx, cy, sz), (0, 0, 1)), b, 3, "Z")]
    for axis, sign in ((0, 1), (0, -1), (1, 1), (1, -1)):
        o = np.array([cx, cy, sz / 2])
        o[axis] += sign * size[axis] / 2
        n = np.zeros(3)
        n[axis] = sign
        faces.append(BoundedFace(_plane(tuple(o), tuple(n)), b, 1, "X"))
    return faces


def _cylinder_faces(cx: float, cy: float, r: float, h: float) -> list[BoundedFace]:
    def side(p: np.ndarray) -> np.ndarray:
        return (p[:, 2] >= -1e-7) & (p[:, 2] <= h + 1e-7)

    def top(p: np.ndarray) -> np.ndarray:
        return np.hypot(p[:, 0] - cx, p[:, 1] - cy) <= r + 1e-7

    return [
        BoundedFace(_cyl((cx, cy, 0), (0, 0, 1), r), side, 7, "Z"),
        BoundedFace(_plane((cx, cy, h), (0, 0, 1)), top, 3, "Z"),
    ]


@pytest.fixture(scope="module")
def table_scene(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, np.ndarray]]:
    """The scan folder (no mask, no ROI, no gt/) and each object's true (H, W) mask."""
    faces = [BoundedFace(_plane((0, 0, 0), (0, 0, 1)), lambda p: np.all(np.abs(p[:, :2]) <= 0.6, axis=1), 3, "Z")]
    owner = [""]
    for name, (kind, cx, cy, size) in OBJECTS.items():
        new = _box_faces(cx, cy, size) if kind == "box" else _cylinder_faces(cx, cy, *size)
        faces += new
        owner += [name] * len(new)
    target = np.array([0.0, 0.0, 0.05])
    eye = target + 0.75 * np.array([0.15, -0.75, 0.65]) / np.linalg.norm([0.15, -0.75, 0.65])
    r = render_scene(Scene(faces, eye, target, 0.5, K=K.copy(), image_size=(W, H)))
    rng = np.random.default_rng(0)
    depth = np.where(r.depth > 0, r.depth + rng.normal(0.0, 0.001, r.depth.shape), 0.0)  # 1 mm sensor noise
    truth = {name: np.isin(r.faces, [k + 1 for k, o in enumerate(owner) if o == name]) for name in OBJECTS}
    folder = tmp_path_factory.mktemp("table") / "scene"
    folder.mkdir()
    cv2.imwrite(str(folder / "color.png"), np.full((H, W, 3), 128, np.uint8))
    cv2.imwrite(str(folder / "depth.png"), np.round(depth / DEPTH_SCALE).astype(np.uint16))
    cam = {"width": W, "height": H, "K": K.tolist(), "depth_scale": DEPTH_SCALE}
    (folder / "camera.json").write_text(json.dumps(cam))
    return folder, truth


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def test_scene_is_what_the_test_says(table_scene: tuple[Path, dict[str, np.ndarray]]) -> None:
    """The centre pixel sees the centre box, every object is visible, and the frame is large."""
    _, truth = table_scene
    assert truth["centre_box"][H // 2, W // 2]
    for name, m in truth.items():
        assert m.sum() > 300, name
    assert sum(m.sum() for m in truth.values()) < 0.5 * W * H
    assert W * H > PickConfig().large_frame_px


def test_whole_frame_without_roi_picks_the_centre_object(
    table_scene: tuple[Path, dict[str, np.ndarray]], caplog: pytest.LogCaptureFixture
) -> None:
    folder, truth = table_scene
    with caplog.at_level(logging.WARNING, logger="v2c"):
        scan = load_scan(folder, pick=PickRequest(mode="auto"))
    assert scan.mask is not None and scan.picked is not None
    assert _iou(scan.mask, truth["centre_box"]) >= 0.9
    for other in ("side_box", "cylinder"):
        assert not (scan.mask & truth[other]).any(), other
    said = [r.getMessage() for r in caplog.records if "picked the object" in r.getMessage()]
    assert len(said) == 1 and "--roi" in said[0] and "--point" in said[0] and str(folder) in said[0]
    assert "\n" not in said[0]
    assert (scan.valid & ~truth["centre_box"]).sum() <= 0.1 * truth["centre_box"].sum()


def test_point_picks_another_object(table_scene: tuple[Path, dict[str, np.ndarray]]) -> None:
    folder, truth = table_scene
    for name in ("side_box", "cylinder"):
        ys, xs = np.nonzero(truth[name])
        point = (int(np.median(xs)), int(np.median(ys)))
        assert truth[name][point[1], point[0]]
        scan = load_scan(folder, pick=PickRequest(mode="auto", point=point))
        assert _iou(scan.mask, truth[name]) >= 0.9, name
        for other in set(OBJECTS) - {name}:
            assert not (scan.mask & truth[other]).any(), (name, other)


def test_cli_point_and_pick_none(table_scene: tuple[Path, dict[str, np.ndarray]]) -> None:
    folder, truth = table_scene
    ys, xs = np.nonzero(truth["cylinder"])
    point = f"{int(np.median(xs))},{int(np.median(ys))}"
    res = CliRunner().invoke(main, ["info", str(folder), "--point", point])
    assert res.exit_code == 0, res.output
    line = next(x for x in res.output.splitlines() if x.startswith("mask"))
    n_cyl = int(line.split("picked:")[1].split()[0])
    assert abs(n_cyl - truth["cylinder"].sum()) <= 0.1 * truth["cylinder"].sum()
    res = CliRunner().invoke(main, ["info", str(folder), "--pick", "none"])
    assert res.exit_code == 0, res.output
    assert "mask        none" in res.output
    res = CliRunner().invoke(main, ["info", str(folder), "--point", point, "--roi", "0,0,10,10"])
    assert res.exit_code == 2 and "give one" in res.output


def test_whole_frame_warns_with_the_pixel_count(
    table_scene: tuple[Path, dict[str, np.ndarray]], caplog: pytest.LogCaptureFixture
) -> None:
    folder, _ = table_scene
    with caplog.at_level(logging.WARNING, logger="v2c"):
        scan = load_scan(folder, pick=PickRequest(mode="none"))
    assert scan.mask is None and scan.picked is None
    n = int((scan.depth > 0).sum())
    said = [r.getMessage() for r in caplog.records]
    assert len(said) == 1 and f"{n:,} valid px" in said[0] and "--roi" in said[0]


def test_mask_roi_and_library_default_are_unchanged(
    table_scene: tuple[Path, dict[str, np.ndarray]], tmp_path: Path
) -> None:
    folder, truth = table_scene
    assert load_scan(folder).mask is None  # the library default never picks
    roi_scan = load_scan(folder, roi=(0, 0, W, H), pick=PickRequest(mode="centre"))
    assert roi_scan.mask is None and roi_scan.picked is None
    masked = tmp_path / "masked"
    masked.mkdir()
    for f in folder.iterdir():
        (masked / f.name).write_bytes(f.read_bytes())
    cv2.imwrite(str(masked / "mask.png"), truth["side_box"].astype(np.uint8) * 255)
    scan = load_scan(masked, pick=PickRequest(mode="centre"))
    assert scan.picked is None and np.array_equal(scan.mask, truth["side_box"])


def test_should_pick_rules() -> None:
    auto, centre, none = PickRequest("auto"), PickRequest("centre"), PickRequest("none")
    assert should_pick(auto, False, False, False) and should_pick(centre, False, False, True)
    assert not should_pick(auto, False, False, True)  # synthetic scans (gt/) as before
    assert not should_pick(none, False, False, False)
    assert should_pick(PickRequest("none", (3, 4)), False, False, False)
    for req in (auto, centre):
        assert not should_pick(req, True, False, False) and not should_pick(req, False, True, False)


def test_nothing_to_pick_is_one_clear_error(tmp_path: Path) -> None:
    """A bare plane: --pick centre finds no object and says so, naming the depth file."""
    folder = tmp_path / "plane"
    folder.mkdir()
    z = np.full((H, W), 0.8)
    cv2.imwrite(str(folder / "color.png"), np.full((H, W, 3), 128, np.uint8))
    cv2.imwrite(str(folder / "depth.png"), np.round(z / DEPTH_SCALE).astype(np.uint16))
    (folder / "camera.json").write_text(json.dumps({"width": W, "height": H, "K": K.tolist(), "depth_scale": 1e-4}))
    with pytest.raises(ScanError, match=r"depth\.png: no object .* off the support plane"):
        load_scan(folder, pick=PickRequest(mode="centre"))
    assert load_scan(folder, pick=PickRequest(mode="auto")).mask is None  # auto: the whole frame, with a warning
    with pytest.raises(PickError):
        pick_object(z, K, z > 0, point=(W, 0))


def test_parse_point() -> None:
    assert parse_point("12, 34") == (12, 34) and parse_point(None) is None
    for bad in ("1", "1,2,3", "a,b", "-1,2", "1.5,2", "nan,1"):
        with pytest.raises(PickError, match="point"):
            parse_point(bad)


def test_table_on_a_floor_drops_both_planes() -> None:
    """The floor is the largest plane; the table top (0.5 m above it, parallel) is dropped too, so the box on the
    table comes out alone rather than with the table top it stands on."""
    table = 0.5  # table top height above the floor (metres)
    faces = [
        BoundedFace(_plane((0, 0, -table), (0, 0, 1)), lambda p: np.all(np.abs(p[:, :2]) <= 3.0, axis=1), 3, "Z"),
        BoundedFace(_plane((0, 0, 0), (0, 0, 1)), lambda p: np.all(np.abs(p[:, :2]) <= 0.3, axis=1), 3, "Z"),
    ]
    box = _box_faces(0.0, 0.0, (0.08, 0.06, 0.10))
    faces += box
    target = np.array([0.0, 0.0, 0.0])
    eye = target + 1.1 * np.array([0.1, -0.7, 0.7]) / np.linalg.norm([0.1, -0.7, 0.7])
    r = render_scene(Scene(faces, eye, target, 0.5, K=K.copy(), image_size=(W, H)))
    floor, top, box_mask = r.faces == 1, r.faces == 2, r.faces >= 3
    assert floor.sum() > top.sum() > PickConfig().extra_plane_share * (r.depth > 0).sum() and box_mask[H // 2, W // 2]
    res = pick_object(r.depth.astype(np.float64), K, r.depth > 0)
    assert _iou(res.mask, box_mask) >= 0.9
    assert not (res.mask & (floor | top)).any()


def test_roi_without_mask_keeps_the_one_object_it_frames(table_scene: tuple[Path, dict[str, np.ndarray]]) -> None:
    """A ROI is a box, and neighbours reach into it. Framing the centre box with a ROI that also holds a third of
    the side box and most of the cylinder, the part region (`segment.geometric.part_region`, what the learned and
    geometric segmenters take without a mask) is the centre box alone: its largest depth-connected piece above
    the ground found around the ROI. Pixels without depth that the object encloses (a hole cut in its readings, a
    shiny lid) are the object's too. Without roi_one_object the neighbours' pixels stay in."""
    from dataclasses import replace

    from v2c.segment.geometric import GeometricConfig, part_region

    folder, truth = table_scene
    ys, xs = np.nonzero(truth["centre_box"])
    roi = (int(xs.min()) - 40, int(ys.min()) - 15, int(xs.max()) + 60, int(ys.max()) + 15)
    scan = load_scan(folder, roi=roi)
    inside = scan.roi_mask()
    assert (truth["side_box"] & inside).sum() > 300 and (truth["cylinder"] & inside).sum() > 300  # as described
    part, _ = part_region(scan, GeometricConfig())
    box = truth["centre_box"]
    assert (part & box).sum() >= 0.97 * box.sum()
    assert not (part & (truth["side_box"] | truth["cylinder"])).any()
    assert (part & ~box).sum() <= 0.02 * box.sum()  # a few table pixels along its foot at most
    whole, _ = part_region(scan, GeometricConfig(roi_one_object=False))
    assert (whole & (truth["side_box"] | truth["cylinder"])).sum() > 600
    hole = np.zeros_like(box)
    hole[int(np.median(ys)) - 3 : int(np.median(ys)) + 4, int(np.median(xs)) - 3 : int(np.median(xs)) + 4] = True
    assert (hole <= box).all()
    holed = replace(scan, depth=np.where(hole, 0.0, scan.depth))
    part, _ = part_region(holed, GeometricConfig())
    assert part[hole].all() and not (part & (truth["side_box"] | truth["cylinder"])).any()


#: Intrinsics of `_ramp_depth` (pixels): the real YCB-Video frames' focal length.
RAMP_K = np.array([[1066.0, 0.0, 30.0], [0.0, 1066.0, 20.0], [0.0, 0.0, 1.0]])


def _ramp_depth() -> np.ndarray:
    """(40, 60) metres, seen with `RAMP_K`: a far surface (0.85 m, rows 0-16) behind a near one (0.80 m, rows
    20-39), and between them the ramp of flying pixels a real sensor draws across such a step: rows 17-19 at
    0.8375, 0.825 and 0.8125 m, each 12.5 mm from the next, under the pick's join step (8 mm + 1 % of the depth =
    16 mm), and steeper than a surface seen at 80 degrees from the ray (9 mm over 2 px)."""
    depth = np.full((40, 60), 0.85)
    depth[20:] = 0.80
    depth[17:20] = np.array([[0.8375], [0.825], [0.8125]])
    return depth


def test_flying_pixels_never_join_two_pieces() -> None:
    """Without the flying-pixel rule the ramp makes one piece of the two surfaces (the real lying sugar box and the
    drill behind it, ycb_video_000005, were one object); with it they are two, each ramp pixel in one of them."""
    from v2c.pick import depth_pieces, flying_mask

    depth = _ramp_depth()
    keep = np.ones(depth.shape, bool)
    n_off, lab_off = depth_pieces(keep, depth, RAMP_K, PickConfig(flying_window_px=0))
    assert n_off == 1 and (lab_off == lab_off[0, 0]).all()
    fly = flying_mask(depth, RAMP_K, PickConfig())
    assert fly[17:20].all() and not fly[:17].any() and not fly[20:].any()
    n, lab = depth_pieces(keep, depth, RAMP_K)
    far, near = lab[0, 0], lab[-1, -1]
    assert n == 2 and far != near
    assert (lab[:17] == far).all() and (lab[20:] == near).all()
    assert set(np.unique(lab[17:20]).tolist()) <= {int(far), int(near)}


def test_roi_object_does_not_reach_the_surface_behind_it_through_flying_pixels() -> None:
    """`segment.geometric._one_object` (the ROI's one object) keeps the near surface and leaves the far one out:
    the flying pixels neither join the two pieces nor bring the far one within the join step in space. Without the
    rule (flying_window_px 0) the far surface is taken too."""
    from types import SimpleNamespace

    from v2c.segment.geometric import _one_object

    depth = _ramp_depth()
    scan = SimpleNamespace(depth=depth, K=RAMP_K)
    part = np.ones(depth.shape, bool)
    obj = _one_object(part, scan)  # type: ignore[arg-type]
    assert obj[20:].all() and not obj[:17].any()
    assert _one_object(part, scan, PickConfig(flying_window_px=0)).all()  # type: ignore[arg-type]


def test_an_instance_of_flying_pixels_is_dropped() -> None:
    """`segment.learned.without_flying`: on the ramp scene, an instance of the ramp's rows alone (every reading a
    flying pixel) becomes background and the others keep their ids, labels and scores; the near surface with the
    ramp's rows in it (180 flying of 1,380 readings) stays; a share of 1 keeps everything."""
    from v2c.segment.learned import without_flying
    from v2c.segment.types import Segmentation

    depth = _ramp_depth()
    inst = np.zeros(depth.shape, np.int32)
    inst[:17], inst[17:20], inst[20:] = 1, 2, 3
    seg = Segmentation(inst, np.array([0, 3, 4, 1], np.uint8), np.array([0.0, 0.9, 0.4, 0.8], np.float32), "learned")
    out = without_flying(seg, depth, RAMP_K, 0.5)
    assert (out.instances[17:20] == 0).all()
    assert (out.instances[:17] == 1).all() and (out.instances[20:] == 3).all()
    assert out.labels.tolist() == [0, 3, 4, 1] and np.allclose(out.scores, [0.0, 0.9, 0.4, 0.8])
    whole = Segmentation(np.where(inst == 2, 3, inst), seg.labels, seg.scores, "learned")
    assert without_flying(whole, depth, RAMP_K, 0.5) is whole
    assert without_flying(seg, depth, RAMP_K, 1.0) is seg


def test_the_real_bench_counts_the_objects_readings_above_its_support(tmp_path: Path) -> None:
    """`v2c.bench.real.object_on_support`, the real-frame bench's object pixels: a box on a table top, with a floor
    0.3 m below that is the frame's largest plane, and the box's outline drawn 4 px too wide (a hand-drawn polygon takes
    in the table around the object). The frame's ground is the floor, so every polygon pixel stands above it,
    table and box alike (the ruler of ``coverage_3mm_object``); the pixels standing above the support found around
    the ROI are the box's alone: at least 97 % of its pixels, and not one of the table's."""
    from v2c.bench.real import object_on_support
    from v2c.segment.geometric import GeometricConfig, part_region

    faces = [
        BoundedFace(_plane((0, 0, -0.3), (0, 0, 1)), lambda p: np.all(np.abs(p[:, :2]) <= 3.0, axis=1), 3, "Z"),
        BoundedFace(_plane((0, 0, 0), (0, 0, 1)), lambda p: np.all(np.abs(p[:, :2]) <= 0.3, axis=1), 3, "Z"),
        *_box_faces(0.0, 0.0, (0.08, 0.06, 0.10)),
    ]
    target = np.array([0.0, 0.0, 0.05])
    eye = target + 0.9 * np.array([0.15, -0.75, 0.65]) / np.linalg.norm([0.15, -0.75, 0.65])
    r = render_scene(Scene(faces, eye, target, 0.5, K=K.copy(), image_size=(W, H)))
    floor, table, box = r.faces == 1, r.faces == 2, r.faces >= 3
    assert floor.sum() > table.sum() and box.sum() > 1000  # the floor is the frame's largest plane
    depth = np.where(r.depth > 0, r.depth + np.random.default_rng(1).normal(0.0, 0.001, r.depth.shape), 0.0)
    folder = tmp_path / "scene"
    folder.mkdir()
    cv2.imwrite(str(folder / "color.png"), np.full((H, W, 3), 128, np.uint8))
    cv2.imwrite(str(folder / "depth.png"), np.round(depth / DEPTH_SCALE).astype(np.uint16))
    (folder / "camera.json").write_text(
        json.dumps({"width": W, "height": H, "K": K.tolist(), "depth_scale": DEPTH_SCALE})
    )
    ys, xs = np.nonzero(box)
    roi = (int(xs.min()) - 10, int(ys.min()) - 10, int(xs.max()) + 10, int(ys.max()) + 10)
    scan = load_scan(folder, roi=roi)
    polygon = cv2.dilate(box.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    ring = polygon & table & scan.valid
    assert ring.sum() > 200  # the polygon takes in the table around the box
    old = part_region(scan, GeometricConfig(roi_one_object=False, roi_ground_margin=0.0))[0] & polygon
    assert (old & ring).sum() > 0.9 * ring.sum()  # above the floor: counted as the object's
    got = object_on_support(scan, polygon)
    assert not (got & ring).any()
    assert (got & box).sum() >= 0.97 * (box & scan.valid).sum()
