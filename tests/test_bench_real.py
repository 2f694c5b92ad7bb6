"""`v2c bench --real` (v2c/bench/real.py): distances to the read-back STEP mesh, the table, and one real frame
end to end through the CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import trimesh
from click.testing import CliRunner

from v2c.bench import real as R


def test_distances_to_mesh_are_exact_near_the_threshold() -> None:
    """Against trimesh's exact distance on a coarse box (long edges: the vertex bound alone would be far off): the
    same points within ``near``, and never below the true distance (an upper bound where it is not exact)."""
    box = trimesh.creation.box(extents=(100.0, 60.0, 40.0))  # mm, 12 triangles
    rng = np.random.default_rng(0)
    pts = rng.uniform(-60, 60, (3000, 3))
    near = 3.0
    got = R.distances_to_mesh(pts, np.asarray(box.vertices), np.asarray(box.faces), near)
    truth = np.abs(trimesh.proximity.signed_distance(box, pts))
    assert 50 < np.count_nonzero(truth < near) < len(pts) - 50
    assert np.array_equal(got < near, truth < near)
    assert np.all(got >= truth - 1e-6)


def test_surface_distances_leave_out_pixels_without_depth() -> None:
    """Points of a plane 2 mm off its fitted plane are 2 mm away; an instance pixel without depth (its point the
    camera centre, 0.8 m from the plane) is not a distance (it once made the mask path's depth RMS 74-602 mm)."""
    from types import SimpleNamespace

    from v2c.primitives import Plane

    plane = Plane(np.array([0.0, 0.0, 0.8]), np.array([0.0, 0.0, -1.0]))
    pts = np.zeros((2, 3, 3))
    pts[..., 2] = 0.802  # 2 mm behind the plane
    pts[0, 0] = 0.0  # no depth reading: backproject gives the camera centre
    valid = np.ones((2, 3), bool)
    valid[0, 0] = False
    inst = np.ones((2, 3), np.int32)
    d = R._surface_distances(pts, inst, SimpleNamespace(primitives={1: plane}), valid)
    assert d.shape == (5,) and np.allclose(d, 0.002)


def test_format_table_rows_and_summary() -> None:
    row = {
        "frame": "f1",
        "object": "can",
        "segmentation": "learned",
        "ok": True,
        "faces": 4,
        "faces_per_side": 2.0,
        "can": {"cylinder_faces": 1, "radius_mm": 34.0, "error_pct": 3.03},
        "expected": {"radius_mm": 33.0},
        "depth_rms_mm": 1.5,
        "coverage_3mm": 0.91,
        "coverage_3mm_faces": 0.95,
        "seconds": 4.2,
        "cpu_seconds": 3.9,
        "max_tolerance_mm": 0.0123,
    }
    report = {
        "frames": [row],
        "near_mm": 3.0,
        "process_start_s": 3.0,
        "summary": {"learned": R._summary([{**row, "visible_sides": 2}])},
    }
    text = R.format_table(report)
    assert (
        "| f1 | can | learned | 4 | 2.0 | radius 34.0 mm (+3.0 %) | 33.0 mm | 1.50 | 91.0 / 95.0 % | 0.0123 | "
        "4.2 (3.9) |" in text
    )
    assert "can radius error 3.0 % (1 of 1 cans with a cylindrical face)" in text and "within 3 mm 91.0 %" in text
    # a can whose reconstruction has no cylindrical face is said so, and counted in the summary
    bare = {**row, "frame": "f2", "can": {"cylinder_faces": 0, "radius_mm": float("nan")}}
    report = {**report, "frames": [row, bare], "summary": {"learned": R._summary([row, bare])}}
    text = R.format_table(report)
    assert "| f2 | can | learned | 4 | 2.0 | no cylindrical face | 33.0 mm |" in text
    assert "can radius error 3.0 % (1 of 2 cans with a cylindrical face)" in text


def test_bench_real_one_frame(shared_data: Path, tmp_path: Path) -> None:
    """The watering-can frame (the smallest ROI) with the learned segmenter: a STEP read back, every measure in
    range, JSON written."""
    from v2c.cli import main

    frames = R.load_frames()
    rois = tmp_path / "rois.json"
    rois.write_text(json.dumps({"frames": {"lm_occluded_example": frames["lm_occluded_example"]}}))
    out = tmp_path / "real.json"
    res = CliRunner().invoke(
        main,
        [
            "bench",
            "--real",
            str(shared_data / "real"),
            "--rois",
            str(rois),
            "--segmentation",
            "learned",
            "--out",
            str(tmp_path / "o"),
            "--json",
            str(out),
            "-q",
        ],
    )
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    (row,) = data["frames"]
    assert row["ok"], row.get("error")
    assert row["faces"] >= 1 and Path(row["step"]).is_file()
    assert 0.0 <= row["coverage_3mm"] <= 1.0 and 0.0 <= row["coverage_3mm_faces"] <= 1.0
    assert 0.0 <= row["coverage_3mm_object"] <= 1.0  # the frame has a mask polygon
    assert row["object_px"] > 1000 and row["depth_rms_mm"] > 0 and row["seconds"] > 0
    # the widest gap the file's topology joins, measured on the STEP as read back
    from OCP.BRep import BRep_Tool
    from OCP.TopAbs import TopAbs_EDGE, TopAbs_VERTEX
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopoDS import TopoDS

    from exporters import read_typed

    shape = read_typed(row["step"]).shape
    tols = []
    for kind, cast in ((TopAbs_VERTEX, TopoDS.Vertex_s), (TopAbs_EDGE, TopoDS.Edge_s)):
        ex = TopExp_Explorer(shape, kind)
        while ex.More():
            tols.append(BRep_Tool.Tolerance_s(cast(ex.Current())))
            ex.Next()
    assert row["max_tolerance_mm"] >= max(tols) >= 1e-7
    assert "lm_occluded_example | can | learned" in res.output
    assert data["summary"]["learned"]["frames"] == 1
    from v2c.segment.learned import network_precision

    assert data["network_precision"] == network_precision() in ("bf16", "fp32")  # it changes the figures


def test_polygon_mask_rasterises_the_outline() -> None:
    """A 10 x 20 px rectangle's polygon covers its 11 x 21 pixel centres (outline included), nothing else; a
    triangle covers about its area."""
    m = R.polygon_mask([[5, 5], [25, 5], [25, 15], [5, 15]], 40, 50)
    assert m.sum() == 11 * 21 and m[5:16, 5:26].all()
    tri = R.polygon_mask([[0, 0], [39, 0], [0, 39]], 40, 40)
    assert abs(int(tri.sum()) - 40 * 41 / 2) <= 41


def test_every_frame_has_a_mask_polygon_inside_its_roi() -> None:
    """real_rois.json: each frame's mask polygon (drawn on color.png) has at least 3 vertices, lies within its ROI
    (2 px of slack) and covers a fair share of it (an outline, not a stray shape)."""
    for name, spec in R.load_frames().items():
        poly = np.asarray(spec["mask"], float)
        x0, y0, x1, y1 = spec["roi"]
        assert len(poly) >= 3, name
        assert poly[:, 0].min() >= x0 - 2 and poly[:, 0].max() <= x1 + 2, name
        assert poly[:, 1].min() >= y0 - 2 and poly[:, 1].max() <= y1 + 2, name
        share = R.polygon_mask(spec["mask"], 480, 640).sum() / ((x1 - x0) * (y1 - y0))
        assert 0.3 < share < 1.0, name


def test_bench_real_uses_the_given_weights(shared_data: Path, tmp_path: Path, monkeypatch) -> None:
    """`--weights` reaches the real frames' learned segmenter (it was once accepted and ignored there): the
    segmenter is called with the given file (a copy of the shipped weights), the frame is reconstructed with it and
    the report records the file."""
    import shutil

    import v2c.segment as S
    from v2c.cli import main
    from v2c.segment.learned import DEFAULT_WEIGHTS

    frames = R.load_frames()
    rois = tmp_path / "rois.json"
    rois.write_text(json.dumps({"frames": {"lm_occluded_example": frames["lm_occluded_example"]}}))
    given = tmp_path / "given.pt"
    shutil.copyfile(DEFAULT_WEIGHTS, given)
    seen: list[object] = []
    real_segment = S.segment

    def spy(scan, method="learned", **kwargs):  # type: ignore[no-untyped-def]
        seen.append(kwargs.get("weights"))
        return real_segment(scan, method, **kwargs)

    monkeypatch.setattr(S, "segment", spy)
    out = tmp_path / "real.json"
    args = ["bench", "--real", str(shared_data / "real"), "--rois", str(rois), "--segmentation", "learned"]
    args += ["--weights", str(given), "--out", str(tmp_path / "o"), "--json", str(out), "-q"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    data = json.loads(out.read_text())
    (row,) = data["frames"]
    assert row["ok"], row.get("error")
    assert seen and all(Path(str(w)) == given for w in seen)
    assert data["weights"] == str(given)


def test_faces_per_box_side_averages_the_box_frames_alone() -> None:
    """Issue 17's figure, faces per visible box side, is the mean over the box frames; faces_per_side keeps the mean
    over boxes and cans."""
    common = {"segmentation": "learned", "ok": True, "depth_rms_mm": 1.0, "coverage_3mm": 0.9, "seconds": 4.0}
    common["cpu_seconds"] = 3.0
    box = {**common, "frame": "b", "object": "box", "faces": 4, "faces_per_side": 4 / 3, "expected": {}}
    box["box"] = {"largest_two_deg": 90.0}
    can = {**common, "frame": "c", "object": "can", "faces": 6, "faces_per_side": 3.0, "expected": {"radius_mm": 33.0}}
    can["can"] = {"cylinder_faces": 1, "radius_mm": 33.0, "error_pct": 0.0}
    s = R._summary([box, can])
    assert s["faces_per_box_side"] == 4 / 3 and s["faces_per_side"] == (4 / 3 + 3.0) / 2
