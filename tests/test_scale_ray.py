"""`--executor ray` (issue 21, docs/scale.md) on a local Ray instance of 2 CPUs: `v2c synth` and `v2c to-step` give
the local executor's files, a failed scan is reported by name without stopping the rest, and a task whose worker
process is killed midway is retried to the same output with no stray files.

Skipped as a whole, with the reason, when Ray (the optional extra `pip install 'v2c[ray]'`) is not installed.
"""

from __future__ import annotations

import filecmp
import json
import os
import re
from dataclasses import replace
from functools import partial
from pathlib import Path

import pytest
from click.testing import CliRunner

ray = pytest.importorskip("ray", reason="Ray is not installed (pip install 'v2c[ray]'): the Ray executor tests need it")

# the imports below come after the skip on purpose: without Ray, none of this module runs
from v2c.commands.synth import command as synth_command  # noqa: E402
from v2c.commands.to_step import _to_step_task  # noqa: E402
from v2c.commands.to_step import command as to_step_command  # noqa: E402
from v2c.executors import ExecutorConfig, run_tasks  # noqa: E402
from v2c.io_safe import JOURNAL_PREFIX, TMP_TAG  # noqa: E402
from v2c.synth.dataset import SynthConfig, generate_scan, scan_name  # noqa: E402

from conftest import write_tiny_scan  # noqa: E402

# One Ray instance for the whole file: with pytest-xdist (--dist loadgroup) these tests share one worker.
pytestmark = pytest.mark.xdist_group("ray")

SEED, SIZE = 0, "160x120"
N_SYNTH, N_TO_STEP = 8, 6
RAY = ExecutorConfig(kind="ray", max_retries=2)


def _run(command, args: list[str]):
    return CliRunner().invoke(command, args, catch_exceptions=False)


@pytest.fixture(scope="module")
def cluster():
    """A local Ray instance with 2 CPUs. Its workers inherit this process's environment, so they import this
    v2c, and this folder is put on their path for the task functions defined in this file."""
    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (str(Path(__file__).parent), old) if p)
    try:
        # "local": a new instance, whatever cluster $RAY_ADDRESS or a `ray start` on this machine names
        ray.init(address="local", num_cpus=2, include_dashboard=False)
    finally:
        if old is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = old
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def local_synth(tmp_path_factory) -> Path:
    """N_SYNTH scans by the local executor (this process)."""
    out = tmp_path_factory.mktemp("synth_local")
    res = _run(synth_command, [str(out), "--n", str(N_SYNTH), "--seed", str(SEED), "--size", SIZE, "--quiet"])
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def to_step_inputs(local_synth: Path, tmp_path_factory) -> list[Path]:
    """The first N_TO_STEP synthetic scans and one broken scan (no depth) after them."""
    broken = write_tiny_scan(tmp_path_factory.mktemp("broken") / "zz_broken", gt=True)
    (broken / "depth.png").unlink()
    return [local_synth / scan_name(i) for i in range(N_TO_STEP)] + [broken]


@pytest.fixture(scope="module")
def local_steps(to_step_inputs: list[Path], tmp_path_factory) -> tuple[Path, str]:
    """`v2c to-step` of the inputs by the local executor: (output folder, stdout)."""
    out = tmp_path_factory.mktemp("to_step_local")
    res = _run(to_step_command, [*map(str, to_step_inputs), "-o", str(out)])
    assert res.exit_code == 1  # the broken scan
    return out, res.stdout


def _step_text(path: Path) -> str:
    """A STEP file without its header's timestamp (the only part that differs between two writes)."""
    return re.sub(r"'\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d'", "'T'", path.read_text(), count=1)


def _without_timings(obj):
    if isinstance(obj, dict):
        return {k: _without_timings(v) for k, v in obj.items() if "timings" not in k}
    if isinstance(obj, list):
        return [_without_timings(v) for v in obj]
    return obj


def assert_same_outputs(a: Path, b: Path) -> None:
    """Folders a and b hold the same files: STEP equal but for the timestamp, VB-Rep JSON equal but for timings,
    everything else byte for byte."""
    files = _files(a)
    assert files and _files(b) == files
    for rel in files:
        fa, fb = a / rel, b / rel
        if fa.suffix == ".step" and fa.parent.name != "gt":
            assert _step_text(fa) == _step_text(fb), rel
        elif fa.name.endswith(".vbrep.json"):
            assert _without_timings(json.loads(fa.read_text())) == _without_timings(json.loads(fb.read_text())), rel
        else:
            assert filecmp.cmp(fa, fb, shallow=False), rel


def _files(folder: Path) -> list[Path]:
    return sorted(p.relative_to(folder) for p in folder.rglob("*") if p.is_file())


def _is_temporary(p: Path) -> bool:
    """A temporary of `v2c.io_safe` (synth scan folders, STEP, JSON, figure): ``.<name>.v2c-tmp-...``, or a commit
    journal ``.v2c-commit-...`` (or any other hidden name with "tmp" in it)."""
    return TMP_TAG in p.name or p.name.startswith(JOURNAL_PREFIX) or (p.name.startswith(".") and "tmp" in p.name)


def _no_temporaries(folder: Path) -> list[str]:
    return [str(p) for p in folder.rglob("*") if _is_temporary(p)]


def _summary_lines(stdout: str, out: Path) -> list[str]:
    """stdout lines in a fixed order (Ray reports scans as they finish), without their timings and with the output
    folder as OUT."""
    text = re.sub(r"written in \d+\.\d+ s", "written in T s", stdout.replace(str(out), "OUT"))
    return sorted(text.splitlines())


def test_synth_on_ray_equals_local(cluster, local_synth: Path, tmp_path: Path) -> None:
    out = tmp_path / "synth_ray"
    res = _run(
        synth_command,
        [str(out), "--n", str(N_SYNTH), "--seed", str(SEED), "--size", SIZE, "--quiet", "--executor", "ray"],
    )
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.iterdir()) == [scan_name(i) for i in range(N_SYNTH)]
    assert_same_outputs(local_synth, out)  # every file byte for byte, part.step included
    assert _no_temporaries(out) == []


def test_to_step_on_ray_equals_local_and_reports_the_failed_scan(
    cluster, to_step_inputs: list[Path], local_steps: tuple[Path, str], tmp_path: Path
) -> None:
    out = tmp_path / "to_step_ray"
    res = _run(to_step_command, [*map(str, to_step_inputs), "-o", str(out), "--executor", "ray"])
    assert res.exit_code == 1
    broken = to_step_inputs[-1]
    assert f"{N_TO_STEP} of {N_TO_STEP + 1} scans written, 1 failed:" in res.stdout
    assert f"\n  {broken / 'depth.png'}: file not found (depth: need one of" in res.stdout
    local_out, local_stdout = local_steps
    assert _summary_lines(res.stdout, out) == _summary_lines(local_stdout, local_out)
    expected = sorted(f"{p.name}{ext}" for p in to_step_inputs[:-1] for ext in (".step", ".vbrep.json", ".png"))
    assert sorted(p.name for p in out.iterdir()) == expected
    assert_same_outputs(local_out, out)
    assert _no_temporaries(out) == []


def test_bench_and_training_data_on_ray_equal_local(cluster, local_synth: Path, tmp_path: Path) -> None:
    from v2c.bench.run import BenchConfig, run_benchmark
    from v2c.segment.train import generate_training_data

    cfg = BenchConfig(
        n=3, size=(160, 120), segmentations=("oracle",), ablations=("full",), jobs=1, scans_dir=local_synth
    )
    rows = {}
    for kind in ("local", "ray"):
        result = run_benchmark(replace(cfg, executor=kind), progress=False)
        rows[kind] = [{k: v for k, v in r.items() if k != "runtime"} for r in result["rows"]]
    assert len(rows["local"]) == 3 and all(r["ok"] for r in rows["local"])
    assert rows["ray"] == rows["local"]  # every metric of every scan
    recipe = ((160, 120, "none", 2, 7),)  # one row of a training recipe: 2 scans of seed 7
    local = generate_training_data(tmp_path / "local", recipe=recipe)
    remote = generate_training_data(tmp_path / "ray", recipe=recipe, executor=RAY)
    assert [p.relative_to(tmp_path / "ray") for p in remote] == [p.relative_to(tmp_path / "local") for p in local]
    assert len(local) == 2
    assert_same_outputs(tmp_path / "local", tmp_path / "ray")


# ------------------------------------------------------------------------------------ a worker killed midway


def _attempts(marker: Path) -> int:
    return len(marker.read_text().split()) if marker.exists() else 0


def _die_on_first_attempt(marker: Path) -> bool:
    """Record this attempt (its pid) in ``marker``; True on the first attempt, which is to be killed."""
    first = not marker.exists()
    with marker.open("a") as f:
        f.write(f"{os.getpid()}\n")
    return first


def _to_step_killed_once(marker: Path, task, scan: Path):
    """`v2c to-step`'s task for one scan; its first attempt kills its process right after the STEP is written
    to its temporary name, before the rename (what a crash or an OOM kill in the middle of a write leaves)."""
    if _die_on_first_attempt(marker):
        import exporters.step

        real = exporters.step.write_xcaf_step

        def write_then_die(path, *args, **kwargs):
            real(path, *args, **kwargs)
            assert Path(path).stat().st_size > 0 and _is_temporary(Path(path))
            os._exit(1)

        exporters.step.write_xcaf_step = write_then_die
    return task(scan)


def _synth_killed_once(marker: Path, args: tuple):
    """`v2c synth`'s task for one scan; its first attempt kills its process after three of the scan's images."""
    if _die_on_first_attempt(marker):
        import v2c.synth.dataset as D

        real, calls = D._write_png, []

        def write_then_die(path, *a, **kw):
            real(path, *a, **kw)
            calls.append(path)
            if len(calls) == 3:
                os._exit(1)

        D._write_png = write_then_die
    return generate_scan(*args)


def test_to_step_worker_killed_midway_is_retried(
    cluster, to_step_inputs: list[Path], local_steps: tuple[Path, str], tmp_path: Path
) -> None:
    scans, out, marker = to_step_inputs[:2], tmp_path / "out", tmp_path / "attempts.txt"
    task = partial(_to_step_task, out=out, batch=True, frame="part", segmentation="learned", extras=True, roi=None)
    victim = partial(_to_step_killed_once, marker, task)
    results = list(run_tasks(lambda s: victim(s) if s == scans[0] else task(s), scans, RAY))
    assert [exc for _, _, exc in results] == [None, None]
    assert _attempts(marker) == 2  # killed once, retried once
    assert sorted(res.step.name for _, res, _ in results) == [f"{s.name}.step" for s in scans]
    assert _no_temporaries(out) == []
    expected = sorted(f"{s.name}{ext}" for s in scans for ext in (".step", ".vbrep.json", ".png"))
    assert sorted(p.name for p in out.iterdir()) == expected
    local_out = local_steps[0]
    for s in scans:
        assert _step_text(out / f"{s.name}.step") == _step_text(local_out / f"{s.name}.step")
        assert filecmp.cmp(out / f"{s.name}.png", local_out / f"{s.name}.png", shallow=False)


def test_synth_worker_killed_midway_is_retried(cluster, local_synth: Path, tmp_path: Path) -> None:
    out, marker = tmp_path / "synth", tmp_path / "attempts.txt"
    cfg = SynthConfig(width=160, height=120)
    tasks = [(out, SEED, i, cfg) for i in (2, 3)]
    results = list(run_tasks(lambda a: _synth_killed_once(marker, a) if a[2] == 2 else generate_scan(*a), tasks, RAY))
    assert [exc for _, _, exc in results] == [None, None]
    assert _attempts(marker) == 2
    assert sorted(p.name for p in out.iterdir()) == [scan_name(2), scan_name(3)]  # no temporary folder left
    for i in (2, 3):
        assert_same_outputs(local_synth / scan_name(i), out / scan_name(i))
