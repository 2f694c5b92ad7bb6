"""`v2c fit` on the tiny hand-made scan (one tilted plane with exact ground truth), the oracle segmentation, the
geometry benchmark's metrics and degenerate inputs of fit_scan."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from v2c.cli import main
from v2c.fit import FitConfig, fit_scan
from v2c.primitives import from_dict
from v2c.primitives.directions import angle_between_axes
from v2c.segment import segment
from v2c.segment.oracle import segment_oracle
from v2c.segment.types import Segmentation

from conftest import TINY


def test_fit_command_recovers_the_tilted_plane(tiny_scan_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "fit.json"
    r = CliRunner().invoke(main, ["fit", str(tiny_scan_dir), "--segmentation", "oracle", "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert "plane" in r.output and "1 primitives" in r.output
    data = json.loads(out.read_text())
    assert data["ablation"] == "full" and len(data["primitives"]) == 1
    p = from_dict(data["primitives"][0])
    assert np.rad2deg(angle_between_axes(p.axis_vector, TINY.plane_normal)) < 0.1  # degrees
    assert abs((p.origin - TINY.plane_point) @ TINY.plane_normal) < 1e-4  # metres (depth unit 0.1 mm)
    assert data["primitives"][0]["axis_label"] == "U"
    assert data["primitives"][0]["rms_m"] < 1e-4


def test_fit_command_bad_input_writes_nothing(tmp_path: Path) -> None:
    out = tmp_path / "fit.json"
    r = CliRunner().invoke(main, ["fit", str(tmp_path / "missing"), "-o", str(out)])
    assert r.exit_code == 1 and r.output.startswith("error: ") and "scan folder not found" in r.output
    assert not out.exists()


def test_oracle_relabels_and_drops_non_analytic(tiny_scan_dir: Path) -> None:
    from v2c.scan import load_scan

    scan = load_scan(tiny_scan_dir)
    faces = np.zeros_like(scan.gt.faces)
    faces[10:20, 10:20] = 3
    faces[20:30, 10:20] = 7
    faces[30:40, 10:20] = 9
    labels = np.zeros_like(scan.gt.labels)
    labels[faces == 3] = 6
    labels[faces == 7] = 255
    labels[faces == 9] = 17
    scan.gt.faces, scan.gt.labels = faces, labels
    seg = segment_oracle(scan)
    assert seg.method == "oracle"
    assert seg.instances[15, 15] == 1 and seg.instances[25, 15] == 0 and seg.instances[35, 15] == 2
    assert seg.labels.tolist() == [0, 6, 17] and np.allclose(seg.scores[1:], 1.0)


def test_segment_dispatch_rejects_unknown_method(tiny_scan_dir: Path) -> None:
    from v2c.scan import load_scan

    with pytest.raises(ValueError, match="unknown segmentation method"):
        segment(load_scan(tiny_scan_dir), "magic")


def test_bench_metrics_on_the_tiny_scan(tiny_scan_dir: Path) -> None:
    from v2c.bench.fit import fit_benchmark

    out = fit_benchmark([tiny_scan_dir], ["full", "fit-only"])
    for a in ("full", "fit-only"):
        s = out["summary"][a]
        assert s["scans"] == 1 and s["pairs"] == 1 and s["plane_count"] == 1
        assert s["alignment"] < 0.002  # min(|a - b|, |a + b|) of unit normals
        assert s["plane_offset_err_median_pct"] < 0.2  # % of the 5 cm part size


def test_fit_scan_degenerate_inputs() -> None:
    class Empty:
        depth = np.zeros((20, 30), np.float32)
        K = np.array([[50.0, 0, 15], [0, 50.0, 10], [0, 0, 1]])
        valid = np.zeros((20, 30), bool)

    seg = Segmentation(np.zeros((20, 30), np.int32), np.zeros(1, np.uint8), np.zeros(1, np.float32), "oracle")
    res = fit_scan(Empty(), seg, FitConfig())
    assert res.primitives == {} and res.frame.shape == (3, 3) and len(res.vertex_depths) == 0
    with pytest.raises(ValueError, match="ablation"):
        fit_scan(Empty(), seg, FitConfig(), "no-such")
