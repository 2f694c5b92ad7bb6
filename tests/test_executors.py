"""`v2c.executors` and the atomic outputs of its tasks (`v2c.io_safe`) without Ray: the local executor (here and in a
process pool), the error that says how to get Ray, and atomic outputs that leave nothing behind, whichever machine
a killed attempt ran on (the Ray runs: tests/test_scale_ray.py)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from v2c.commands.synth import command as synth_command
from v2c.commands.to_step import command as to_step_command
from v2c.executors import RAY_INSTALL_HINT, ExecutorConfig, ExecutorError, run_tasks
from v2c.io_safe import HOST_ID, TMP_TAG, atomic_dir, atomic_write, sweep_stale_temporaries, temp_dir, temp_path

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


def _left_by_another_node(final: Path, folder: bool = False) -> Path:
    """What a killed attempt on another machine leaves next to ``final``: a temporary whose host is not this one
    (its pid may well run here: pids of two machines say nothing about each other)."""
    other = "ffffffff" if HOST_ID != "ffffffff" else "00000000"
    p = final.with_name(f".{final.name}{TMP_TAG}{other}-1-abcdefgh{'' if folder else final.suffix}")
    if folder:
        (p / "gt").mkdir(parents=True)
    else:
        p.write_text("half")
    return p


def test_atomic_write_replaces_and_leaves_other_outputs_alone(tmp_path: Path) -> None:
    final = tmp_path / "part.step"
    other = temp_path(tmp_path / "other.step")  # a temporary of another output, in flight
    with atomic_write(final) as tmp:
        assert tmp.parent == tmp_path and tmp.suffix == ".step" and tmp.exists() and not final.exists()
        assert TMP_TAG in tmp.name and tmp.name.startswith(".part.step")
        tmp.write_text("complete")
    assert final.read_text() == "complete"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([final.name, other.name])


def test_atomic_write_leaves_nothing_on_error(tmp_path: Path) -> None:
    final = tmp_path / "fig.png"
    final.write_bytes(b"old")
    with pytest.raises(OSError, match="disk full"), atomic_write(final) as tmp:
        tmp.write_bytes(b"new, half")
        raise OSError("disk full")
    assert final.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["fig.png"]


def test_atomic_dir_new_and_merged(tmp_path: Path) -> None:
    final = tmp_path / "scan_00001"
    stale = _left_by_another_node(final, folder=True)  # a killed attempt's half-written folder, another node
    stale_file = _left_by_another_node(tmp_path / "scan_00001.png")  # not this output's: stays
    with atomic_dir(final, last=("gt/meta.json",)) as tmp:
        assert tmp.parent == tmp_path and tmp.name.startswith(f".scan_00001{TMP_TAG}{HOST_ID}-")
        (tmp / "gt").mkdir()
        (tmp / "gt" / "meta.json").write_text("1")
        (tmp / "color.png").write_bytes(b"c1")
    assert not stale.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["scan_00001", stale_file.name])
    stale_file.unlink()
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
    assert sweep_stale_temporaries(final, single_writer=True) == []
    # a failed attempt leaves nothing; a temporary folder is exclusive and never a planted symlink's target
    with pytest.raises(RuntimeError), atomic_dir(tmp_path / "scan_00002") as tmp:
        (tmp / "color.png").write_bytes(b"half")
        raise RuntimeError("renderer failed")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scan_00001"]
    assert temp_dir(final) != temp_dir(final)


def test_atomic_dir_never_merges_through_a_symlink(tmp_path: Path) -> None:
    victim = tmp_path / "elsewhere"
    (victim / "gt").mkdir(parents=True)
    out = tmp_path / "out"
    out.mkdir()
    (out / "scan_00001").symlink_to(victim, target_is_directory=True)
    with pytest.raises(OSError), atomic_dir(out / "scan_00001") as tmp:
        (tmp / "color.png").write_bytes(b"c")
    assert sorted(p.name for p in victim.rglob("*")) == ["gt"]
    (out / "scan_00001").unlink()
    (out / "scan_00001" / "gt").mkdir(parents=True)
    (out / "scan_00001" / "gt" / "x").write_text("x")
    (out / "scan_00001" / "sub").symlink_to(victim, target_is_directory=True)
    with (
        pytest.raises(OSError, match="a symlink where a folder of the output should be"),
        atomic_dir(out / "scan_00001") as tmp,
    ):
        (tmp / "sub").mkdir()
        (tmp / "sub" / "color.png").write_bytes(b"c")
    assert sorted(p.name for p in victim.rglob("*")) == ["gt"]
