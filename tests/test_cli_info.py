"""`v2c info`: what it prints for a scan, and that bad input fails with the loader's message and writes nothing."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from test_scan import BAD_INPUTS

from v2c.commands.info import command as info_command

from conftest import TINY, listing, real_scan_dirs


def _run(args: list[str], cwd: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(cwd)
    return CliRunner().invoke(info_command, args, catch_exceptions=False)


def _number_after(text: str, key: str) -> float:
    m = re.search(rf"{key}\s+(-?[0-9.]+)", text)
    assert m, (key, text)
    return float(m.group(1))


def test_info_prints_what_was_loaded(tiny_scan_dir: Path, tmp_path: Path, monkeypatch) -> None:
    before = listing(tiny_scan_dir)
    res = _run([str(tiny_scan_dir)], tmp_path, monkeypatch)
    assert res.exit_code == 0, res.output
    out = res.output
    assert f"{TINY.width} x {TINY.height} px" in out
    assert _number_after(out, "fx") == pytest.approx(TINY.K[0, 0], abs=1e-3)
    assert _number_after(out, "fy") == pytest.approx(TINY.K[1, 1], abs=1e-3)
    assert _number_after(out, "cx") == pytest.approx(TINY.K[0, 2], abs=1e-3)
    assert _number_after(out, "cy") == pytest.approx(TINY.K[1, 2], abs=1e-3)
    # depth range and valid share, against the loaded numbers
    from v2c.scan import load_scan

    scan = load_scan(tiny_scan_dir)
    d = scan.depth[scan.depth > 0]
    m = re.search(r"depth\s+([0-9.]+) \.\. ([0-9.]+) m", out)
    assert m and float(m.group(1)) == pytest.approx(float(d.min()), abs=1e-4)
    assert float(m.group(2)) == pytest.approx(float(d.max()), abs=1e-4)
    share = 100.0 * d.size / (TINY.width * TINY.height)
    assert f"readings on {share:.1f} % of pixels" in out
    # ground truth: 2 faces, 1 visible, plane U and cylinder Z, part size
    assert "ground truth  2 faces, 1 visible; part size 0.0500 m" in out
    assert re.search(r"plane\s+axis U\s+1 faces \(1 visible\)", out)
    assert re.search(r"cylinder\s+axis Z\s+1 faces \(0 visible\)", out)
    assert "mask        none" in out and "roi         none" in out
    assert listing(tiny_scan_dir) == before and list(tmp_path.iterdir()) == []


def test_info_with_roi(tiny_scan_dir: Path, tmp_path: Path, monkeypatch) -> None:
    res = _run([str(tiny_scan_dir), "--roi", "10,5,30,25"], tmp_path, monkeypatch)
    assert res.exit_code == 0, res.output
    assert "x 10..30, y 5..25 (exclusive ends): 400 px" in res.output
    assert re.search(r"valid\s+400 px", res.output)


@pytest.mark.parametrize("case,mutate,fname,problem,roi", BAD_INPUTS, ids=[c[0] for c in BAD_INPUTS])
def test_info_bad_input_fails_and_writes_nothing(
    case, mutate, fname, problem, roi, scan_copy: Path, tmp_path: Path, monkeypatch
) -> None:
    if mutate is not None:
        mutate(scan_copy)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    before = listing(scan_copy)
    args = [str(scan_copy)] + ([] if roi is None else ["--roi", ",".join(map(str, roi))])
    res = _run(args, cwd, monkeypatch)
    assert res.exit_code != 0, res.output
    assert fname in res.output and problem.lower() in res.output.lower(), res.output
    assert "Traceback" not in res.output
    assert listing(scan_copy) == before
    assert list(cwd.iterdir()) == []


def test_info_missing_folder(tmp_path: Path, monkeypatch) -> None:
    res = _run([str(tmp_path / "nowhere")], tmp_path, monkeypatch)
    assert res.exit_code == 1 and "nowhere: scan folder not found" in res.output
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("roi", ["1,2,3", "a,b,c,d", "5,5,5,9"])
def test_info_malformed_roi(roi: str, tiny_scan_dir: Path, tmp_path: Path, monkeypatch) -> None:
    res = _run([str(tiny_scan_dir), "--roi", roi], tmp_path, monkeypatch)
    assert res.exit_code != 0 and "ROI" in res.output and "--roi" in res.output


def test_info_on_real_frames(shared_data: Path, tmp_path: Path, monkeypatch) -> None:
    for d in real_scan_dirs():
        res = _run([str(d), "--roi", "200,150,400,300"], tmp_path, monkeypatch)
        assert res.exit_code == 0, (d, res.output)
        assert "640 x 480 px" in res.output and "ground truth  none" in res.output
        assert _number_after(res.output, "fx") > 500
    assert list(tmp_path.iterdir()) == []


def test_info_is_registered_in_the_v2c_group(tiny_scan_dir: Path) -> None:
    from v2c.cli import main

    res = CliRunner().invoke(main, ["info", str(tiny_scan_dir)])
    assert res.exit_code == 0, res.output
    assert np.isclose(_number_after(res.output, "fx"), TINY.K[0, 0])


def test_v2c_info_process_exit_code(scan_copy: Path, tmp_path: Path) -> None:
    """The real command line: a broken scan exits 1 with the message on stderr and writes nothing."""
    import subprocess
    import sys

    (scan_copy / "depth.png").write_bytes((scan_copy / "depth.png").read_bytes()[:100])
    before = listing(scan_copy)
    cmd = [sys.executable, "-m", "v2c.cli", "info"]
    res = subprocess.run([*cmd, str(scan_copy)], cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False)
    assert res.returncode == 1, (res.stdout, res.stderr)
    assert "depth.png: truncated PNG" in res.stderr and res.stdout == ""
    assert listing(scan_copy) == before and list(tmp_path.iterdir()) == [scan_copy]
    res = subprocess.run(
        [*cmd, str(scan_copy.parent / "nope")], cwd=tmp_path, capture_output=True, text=True, timeout=120, check=False
    )
    assert res.returncode == 1 and "scan folder not found" in res.stderr
