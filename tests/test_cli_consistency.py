"""The `v2c` command as a tool (issue 20): version flags, `python -m v2c`, one default segmentation, `-o DIR/`,
never replacing a file v2c did not write unless --force, -v/-q logging, and the error line format."""

from __future__ import annotations

import inspect
import os
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

import v2c
from v2c.cli import main
from v2c.io_safe import written_by_v2c

from conftest import write_tiny_scan

REPO = Path(__file__).resolve().parents[1]


def _v2c(args: list[str]):
    return CliRunner().invoke(main, args, catch_exceptions=False)


def test_version_everywhere() -> None:
    from importlib.metadata import version

    assert v2c.__version__ == version("v2c")
    for flag in ("--version", "-V"):
        res = _v2c([flag])
        assert res.exit_code == 0 and res.output.strip() == f"v2c, version {v2c.__version__}", res.output
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run([sys.executable, "-m", "v2c", "-V"], env=env, capture_output=True, text=True, check=True)
    assert r.stdout.strip() == f"v2c, version {v2c.__version__}"


def test_one_default_segmentation_learned() -> None:
    from v2c.api import reconstruct as api_reconstruct
    from v2c.api import scan_to_step
    from v2c.pipeline import reconstruct

    for fn in (reconstruct, api_reconstruct, scan_to_step):
        assert inspect.signature(fn).parameters["segmentation"].default == "learned", fn
    for name in ("to-step", "reconstruct", "fit", "fixture"):
        opt = next(p for p in main.commands[name].params if "--segmentation" in p.opts)
        assert opt.default == "learned", name


@pytest.fixture(scope="module")
def scan(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_tiny_scan(tmp_path_factory.mktemp("cli") / "plane", gt=True)


def test_output_folder_with_trailing_slash_is_made(scan: Path, tmp_path: Path) -> None:
    out = tmp_path / "new" / "deeper"
    res = _v2c(["to-step", str(scan), "-o", f"{out}/", "--segmentation", "oracle"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["plane.png", "plane.step", "plane.vbrep.json"]
    assert all(written_by_v2c(p) for p in out.iterdir())


def test_never_replaces_a_file_v2c_did_not_write(scan: Path, tmp_path: Path) -> None:
    foreign = tmp_path / "existing.txt"
    foreign.write_text("my notes")
    res = _v2c(["to-step", str(scan), "-o", str(foreign), "--segmentation", "oracle"])
    assert res.exit_code == 1, res.output
    assert res.output.strip() == (
        f"error: {foreign}: exists and is a file that v2c did not write; pass --force to "
        "replace it (or choose another -o)"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing.txt"] and foreign.read_text() == "my notes"
    # v2c's own files are replaced without --force; a foreign one only with it
    step = tmp_path / "part.step"
    assert _v2c(["to-step", str(scan), "-o", str(step), "--segmentation", "oracle"]).exit_code == 0
    assert _v2c(["to-step", str(scan), "-o", str(step), "--segmentation", "oracle"]).exit_code == 0
    (tmp_path / "part.png").write_bytes(b"someone else's picture")
    res = _v2c(["to-step", str(scan), "-o", str(step), "--segmentation", "oracle"])
    assert res.exit_code == 1 and "part.png: exists and is a file that v2c did not write" in res.output
    assert (tmp_path / "part.png").read_bytes() == b"someone else's picture"
    res = _v2c(["to-step", str(scan), "-o", str(step), "--segmentation", "oracle", "--force"])
    assert res.exit_code == 0, res.output
    assert written_by_v2c(tmp_path / "part.png") and written_by_v2c(step)
    assert written_by_v2c(tmp_path / "part.vbrep.json")


@pytest.mark.parametrize("command", ["reconstruct", "fit"])
def test_reconstruct_and_fit_respect_foreign_files(command: str, scan: Path, tmp_path: Path) -> None:
    name = "reconstruction.png" if command == "reconstruct" else "fit.json"
    target = tmp_path / name
    target.write_text("not v2c's")
    out = ["-o", str(tmp_path)] if command == "reconstruct" else ["-o", str(target)]
    res = _v2c([command, str(scan), *out, "--segmentation", "oracle"])
    assert res.exit_code == 1 and f"{target}: exists and is a file that v2c did not write" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == [name] and target.read_text() == "not v2c's"
    res = _v2c([command, str(scan), *out, "--segmentation", "oracle", "--force"])
    assert res.exit_code == 0, res.output
    assert written_by_v2c(target)


def test_verbose_shows_the_stages_and_quiet_hides_warnings(scan: Path, tmp_path: Path) -> None:
    res = _v2c(["-v", "to-step", str(scan), "-o", str(tmp_path / "a.step"), "--segmentation", "oracle"])
    assert res.exit_code == 0, res.output
    for stage in ("segment (oracle): 1 instances", "fit (full): 1 primitives", "VB-Rep: 1 faces"):
        assert stage in res.output, res.output
    res = _v2c(["-q", "to-step", str(scan), "-o", str(tmp_path / "b.step"), "--segmentation", "oracle"])
    assert res.exit_code == 0 and "segment (" not in res.output, res.output


def test_oracle_without_ground_truth_is_one_clear_line(tmp_path: Path) -> None:
    s = write_tiny_scan(tmp_path / "nogt")
    for command in ("reconstruct", "to-step", "fit"):
        res = _v2c([command, str(s), "--segmentation", "oracle"])
        assert res.exit_code == 1, res.output
        assert res.output.strip() == (
            f"error: {s}: oracle segmentation needs gt/ (a synthetic scan); use --segmentation learned"
        ), (command, res.output)
    assert sorted(p.name for p in s.iterdir()) == ["camera.json", "color.png", "depth.png"]


def test_scan_commands_share_roi_max_pixels_and_force() -> None:
    for name in ("info", "to-step", "reconstruct", "fit", "fixture"):
        opts = {o for p in main.commands[name].params for o in p.opts}
        assert {"--roi", "--max-pixels", "--segmentation" if name != "info" else "--roi"} <= opts, name
    for name in ("to-step", "reconstruct", "fit"):
        assert "--force" in {o for p in main.commands[name].params for o in p.opts}, name


def test_reconstruct_without_a_face_writes_nothing(scan: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A pipeline that ends with no face (issue 20: `reconstruct` wrote a VB-Rep of 0 faces) is an error."""
    import v2c.pipeline
    from v2c.segment.oracle import segment_oracle

    from scenes.vbrep import box_corner

    def no_faces(s, segmentation="learned", ablation="full", return_stages=False, **kw):
        v = box_corner()
        v.faces, v.edges, v.vertices = [], [], []
        return v, segment_oracle(s), None

    monkeypatch.setattr(v2c.pipeline, "reconstruct", no_faces)
    res = _v2c(["reconstruct", str(scan), "-o", str(tmp_path / "out")])
    assert res.exit_code == 1, res.output
    assert res.output.strip() == (
        f"error: {scan}: no face could be reconstructed (1 surface instances segmented); nothing written"
    )
    assert not (tmp_path / "out").exists()
