"""`v2c synth OUT` into a folder that already holds scans (issue 20: "synth into a used folder mixes two sets"):
scans of another run (seed, size, noise, families, look) are refused with one line naming the folder and what
differs, before anything is written; the same run resumed or extended, and --force, go on."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from v2c.cli import main as v2c_main

BASE = ["--n", "1", "--seed", "3", "--size", "64x48", "--noise", "none", "--families", "block", "--quiet"]


def _synth(out: Path, *args: str):
    return CliRunner().invoke(v2c_main, ["synth", str(out), *args], catch_exceptions=False)


def _tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def used(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with scan_00000 of the BASE run."""
    out = tmp_path_factory.mktemp("used") / "scans"
    res = _synth(out, *BASE)
    assert res.exit_code == 0, res.output
    return out


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        (["--seed", "4"], "seed 3, not 4"),
        (["--size", "80x60"], "size 64x48, not 80x60"),
        (["--noise", "sensor"], "noise none, not sensor"),
        (["--families", "shaft,knob"], "family block, not one of shaft,knob"),
        (["--appearance", "random"], "appearance plain, not random; framing fill, not extent"),
    ],
)
def test_scans_of_another_run_are_refused(used: Path, change: list[str], expected: str) -> None:
    before = _tree(used)
    args = list(BASE)
    if change[0] in args:
        args[args.index(change[0]) + 1] = change[1]
    else:
        args += change
    res = _synth(used, *args, "--start", "1")
    assert res.exit_code == 1, res.output
    assert res.output == (
        f"error: {used}: holds scans of another run (scan_00000: {expected}); adding to them would mix two sets: "
        "choose another folder, or pass --force to add to it anyway\n"
    )
    assert _tree(used) == before  # nothing written


def test_the_same_run_resumed_or_extended_goes_on(used: Path, tmp_path: Path) -> None:
    out = tmp_path / "scans"
    assert _synth(out, *BASE).exit_code == 0
    first = _tree(out)
    res = _synth(out, *BASE, "--n", "2")  # resumed: scan 0 again (the same bytes), scan 1 added
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == ["scan_00000", "scan_00001"]
    assert {k: v for k, v in _tree(out).items() if k.startswith("scan_00000")} == first
    assert _synth(out, *BASE, "--start", "2").exit_code == 0  # extended
    assert sorted(p.name for p in out.iterdir()) == ["scan_00000", "scan_00001", "scan_00002"]
    # the last scan is looked at too: another run's scan added with --force is refused afterwards
    assert _synth(out, *[a if a != "3" else "9" for a in BASE], "--start", "7", "--force").exit_code == 0
    res = _synth(out, *BASE, "--start", "3")
    assert res.exit_code == 1 and "(scan_00007: seed 9, not 3)" in res.output, res.output
    # files of other kinds in the folder are not scans of a run: no refusal
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    (other / "scan_00000").mkdir()  # an incomplete scan folder (no gt/meta.json): not a run's scan
    assert _synth(other, *BASE, "--seed", "5").exit_code == 0
    assert json.loads((other / "scan_00000" / "gt" / "meta.json").read_text())["seed"] == 5


def test_force_adds_to_another_run(used: Path, tmp_path: Path) -> None:
    out = tmp_path / "scans"
    assert _synth(out, *BASE).exit_code == 0
    res = _synth(
        out, "--n", "1", "--seed", "4", "--size", "64x48", "--noise", "none", "--quiet", "--start", "1", "--force"
    )
    assert res.exit_code == 0, res.output
    seeds = [json.loads((out / s / "gt" / "meta.json").read_text())["seed"] for s in ("scan_00000", "scan_00001")]
    assert seeds == [3, 4]


def test_random_scans_of_an_older_framing_are_refused(tmp_path: Path) -> None:
    out = tmp_path / "scans"
    look = [*BASE, "--appearance", "random"]
    assert _synth(out, *look).exit_code == 0
    meta_p = out / "scan_00000" / "gt" / "meta.json"
    meta = json.loads(meta_p.read_text())
    assert meta["framing"]["version"] == 2
    del meta["framing"]["version"]  # as written before the framing fix (version 1)
    meta_p.write_text(json.dumps(meta))
    before = _tree(out)
    res = _synth(out, *look[:1], "2", *look[2:])
    assert res.exit_code != 0 and "framing version 1, not 2" in res.output
    assert _tree(out) == before
