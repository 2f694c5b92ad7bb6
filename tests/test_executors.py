"""`v2c.executors` and `v2c.atomic` without Ray: the local executor (here and in a process pool), the error that
says how to get Ray, and atomic outputs that leave nothing behind (the Ray runs: tests/test_scale_ray.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from v2c.atomic import TMP_TAG, atomic_dir, atomic_file, sweep, temp_name
from v2c.commands.synth import command as synth_command
from v2c.commands.to_step import command as to_step_command
from v2c.executors import RAY_INSTALL_HINT, ExecutorConfig, ExecutorError, run_tasks

from conftest import listing, write_tiny_scan


def _square_or_fail(x: int) -> int:
    if x == 3:
        raise ValueError(f"item {x} is bad")
    return x * x


@pytest.mark.parametrize("jobs", [1, 2])
def test_local_executor_yields_every_item_and_reports_failures(jobs: int) -> None:
    out = list(run_tasks(_square_or_fail, range(6), "local", jobs=jobs))
    assert sorted(item for item, _, _ in out) == list(range(6))
    results = {item: (res, exc) for item, res, exc in out}
    for i in (0, 1, 2, 4, 5):
        assert results[i] == (i * i, None)
    res, exc = results[3]
    assert res is None and isinstance(exc, ValueError) and str(exc) == "item 3 is bad"
    if jobs == 1:  # in this process: in order
        assert [item for item, _, _ in out] == list(range(6))


def test_unknown_executor_is_refused() -> None:
    with pytest.raises(ExecutorError, match="executor 'dask': expected one of local, ray"):
        run_tasks(_square_or_fail, [1], ExecutorConfig(kind="dask"))


@pytest.fixture
def no_ray(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make `import ray` fail as it does where the extra is not installed."""
    monkeypatch.setitem(sys.modules, "ray", None)


def test_ray_missing_says_how_to_install_it(no_ray, tmp_path: Path) -> None:
    with pytest.raises(ExecutorError, match="needs the Ray package"):
        run_tasks(_square_or_fail, [1], "ray")
    scan = write_tiny_scan(tmp_path / "scan", gt=True)
    before = listing(tmp_path)
    res = CliRunner().invoke(to_step_command, [str(scan), "--executor", "ray"])
    assert res.exit_code == 1
    assert res.output.strip().splitlines()[-1] == (
        f"Error: --executor ray needs the Ray package, which is not installed: {RAY_INSTALL_HINT}"
    )
    assert listing(tmp_path) == before  # nothing written
    res = CliRunner().invoke(synth_command, [str(tmp_path / "synth"), "--n", "1", "--executor", "ray"])
    assert res.exit_code == 1 and RAY_INSTALL_HINT in res.output
    assert not (tmp_path / "synth").exists()


def test_ray_address_needs_the_ray_executor(tmp_path: Path) -> None:
    res = CliRunner().invoke(synth_command, [str(tmp_path / "s"), "--n", "1", "--ray-address", "auto"])
    assert res.exit_code == 2 and "--ray-address needs --executor ray" in res.output
    assert not (tmp_path / "s").exists()


# ------------------------------------------------------------------------------------------------- atomic


def test_atomic_file_replaces_and_sweeps_a_killed_attempt(tmp_path: Path) -> None:
    final = tmp_path / "part.step"
    stale = temp_name(final)  # what a killed attempt leaves: a complete or partial temporary file
    stale.write_text("half")
    other = temp_name(tmp_path / "other.step")
    other.write_text("not ours")
    assert TMP_TAG in stale.name and stale.suffix == ".step" and stale.name.startswith(".part.step")
    with atomic_file(final) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".step" and tmp.exists() and not final.exists()
        tmp.write_text("complete")
    assert final.read_text() == "complete"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([final.name, other.name])  # only ours swept


def test_atomic_file_leaves_nothing_on_error(tmp_path: Path) -> None:
    final = tmp_path / "fig.png"
    final.write_bytes(b"old")
    with pytest.raises(OSError, match="disk full"), atomic_file(final) as tmp:
        tmp.write_bytes(b"new, half")
        raise OSError("disk full")
    assert final.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]


def test_atomic_dir_new_and_merged(tmp_path: Path) -> None:
    final = tmp_path / "scan_00001"
    stale = temp_name(final)
    (stale / "gt").mkdir(parents=True)  # a killed attempt's half-written folder
    with atomic_dir(final, last=("gt/meta.json",)) as tmp:
        (tmp / "gt").mkdir()
        (tmp / "gt" / "meta.json").write_text("1")
        (tmp / "color.png").write_bytes(b"c1")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scan_00001"]
    assert (final / "gt" / "meta.json").read_text() == "1" and (final / "color.png").read_bytes() == b"c1"
    # an existing folder is updated file by file; its other files stay (e.g. a reconstruction written into it)
    (final / "reconstruction.step").write_text("kept")
    with atomic_dir(final, last=("gt/meta.json",)) as tmp:
        (tmp / "gt").mkdir()
        (tmp / "gt" / "meta.json").write_text("2")
        (tmp / "color.png").write_bytes(b"c2")
    assert (final / "gt" / "meta.json").read_text() == "2" and (final / "color.png").read_bytes() == b"c2"
    assert (final / "reconstruction.step").read_text() == "kept"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scan_00001"]
    assert sweep(final) == []
