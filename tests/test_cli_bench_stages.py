"""`v2c bench --stage segmentation|fit|vbrep|synth|parts` (issue 20: the former `python -m` entry points folded into
the one CLI): each stage's JSON holds the numbers of the same function called directly, and against ground truth
where there is one; the argparse entry points are gone."""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from v2c.cli import main

REPO = Path(__file__).resolve().parents[1]
TIMING = ("_s", "seconds", "time", "wall", "cpu", "_ms", "t_")


def _bench(args: list[str]) -> tuple[str, dict | None]:
    res = CliRunner().invoke(main, ["bench", *args], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    json_out = args[args.index("--json") + 1] if "--json" in args else None
    return res.output, json.loads(Path(json_out).read_text()) if json_out else None


def _same(a: object, b: object, path: str = "") -> list[str]:
    """Leaves that differ between two JSON-like values, timings left out (NaN equals NaN and None)."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [
            d
            for k in sorted(set(a) | set(b))
            if not any(t in k for t in TIMING)
            for d in _same(a.get(k), b.get(k), f"{path}/{k}")
        ]
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        if len(a) != len(b):
            return [path]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in _same(x, y, f"{path}/{i}")]

    def nan(v: object) -> bool:
        return v is None or (isinstance(v, float) and math.isnan(v))

    return [] if a == b or (nan(a) and nan(b)) else [f"{path}: {a!r} != {b!r}"]


@pytest.fixture(scope="module")
def scans(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two generated `sensor` scans at 160x120 (seed 0: a bracket and a knob)."""
    from v2c.synth.dataset import SynthConfig, generate_dataset

    folder = tmp_path_factory.mktemp("stages") / "scans"
    generate_dataset(folder, 2, 0, SynthConfig(width=160, height=120), jobs=1, progress=False)
    return folder


def test_stage_fit_is_the_geometry_bench(tiny_scan_dir: Path, tmp_path: Path) -> None:
    from v2c.bench.fit import fit_benchmark, single_thread

    out = tmp_path / "fit.json"
    text, got = _bench(
        ["--stage", "fit", "--scans", str(tiny_scan_dir), "--n", "1", "--ablation", "full,fit-only", "--json", str(out)]
    )
    assert got["generator"].startswith("v2c ")
    with single_thread():
        direct = fit_benchmark([tiny_scan_dir], ["full", "fit-only"])
    assert _same(got["summary"], direct["summary"]) == []
    assert _same(got["rows"], json.loads(json.dumps(direct["rows"], default=float))) == []
    # the tiny scan is one tilted plane with exact ground truth
    for a in ("full", "fit-only"):
        s = got["summary"][a]
        assert s["scans"] == 1 and s["pairs"] == 1 and s["plane_count"] == 1
        assert s["alignment"] < 0.002 and s["plane_offset_err_median_pct"] < 0.2
    assert "1 scans, geometry stage alone (oracle segmentation, one thread)" in text.splitlines()
    assert f"| full | 1 | {got['summary']['full']['alignment']:.4f} | 1 |" in text
    # the thread limits of the stage end with it
    import cv2

    n = cv2.getNumThreads()
    with single_thread():
        assert cv2.getNumThreads() == 1
    assert cv2.getNumThreads() == n


def test_stage_vbrep_per_family(scans: Path, tmp_path: Path) -> None:
    from v2c.bench.vbrep import evaluate, summarize

    out = tmp_path / "vbrep.json"
    text, got = _bench(
        ["--stage", "vbrep", "--scans", str(scans), "--n", "2", "--segmentation", "oracle", "--json", str(out)]
    )
    assert list(got["columns"]) == ["oracle/full"]  # the default ablation of this stage: full
    col = got["columns"]["oracle/full"]
    dirs = sorted(str(p) for p in scans.iterdir() if (p / "camera.json").exists())
    rows = evaluate(dirs, "oracle", "full")
    assert _same(col["rows"], rows) == []
    assert _same(col["summary"], summarize(rows)) == []
    fams = {r["family"] for r in rows}
    assert len(fams) == 2 and set(col["families"]) == fams
    for f in fams:
        assert _same(col["families"][f], summarize([r for r in rows if r["family"] == f])) == []
        assert col["families"][f]["scans"] == 1
    s = col["summary"]
    assert s["scans"] == 2 and s["chamfer"] < 0.03  # oracle segmentation: within 3 % of the part size
    assert 0.5 < s["matched_accuracy"] <= 1.0 and 0 < s["coverage"] <= 1.0
    all_row = next(line for line in text.splitlines() if "| **all** |" in line)
    assert all_row.startswith(f"| oracle/full | **all** | 2 | {s['chamfer']:.4f} ({s['chamfer_max']:.4f}) |")


def test_stage_segmentation_and_its_old_flag(scans: Path, tmp_path: Path) -> None:
    from v2c.bench.segmentation import run

    out, old = tmp_path / "seg.json", tmp_path / "seg_old.json"
    common = ["--scans", str(scans), "--n", "2", "--segmentation", "oracle,geometric", "-q"]
    text, got = _bench(["--stage", "segmentation", *common, "--json", str(out)])
    _, got_old = _bench(["--segmentation-only", *common, "--json", str(old)])
    dirs = sorted(p for p in scans.iterdir() if (p / "camera.json").exists())
    direct = run(dirs, ["oracle", "geometric"], log=lambda m: None)
    for m in ("oracle", "geometric"):
        assert _same(got[m]["summary"], direct[m]["summary"]) == []
        assert _same(got_old[m]["summary"], direct[m]["summary"]) == []
    s = got["oracle"]["summary"]  # the oracle's instances are the gt faces
    assert s["scans"] == 2 and s["precision"] == s["recall"] == s["type_acc"] == s["axis_acc"] == 1.0
    assert "| oracle | 2 | 1.000 | 1.000 |" in text


def test_stage_synth_times_the_generator(tmp_path: Path) -> None:
    from v2c.synth.dataset import SynthConfig

    out = tmp_path / "synth.json"
    text, got = _bench(
        ["--stage", "synth", "--n", "2", "--size", "64x48", "--families", "block,shaft", "--json", str(out)]
    )
    assert got["scans"] == 2 and got["size"] == "64x48" and got["noise"] == "sensor" and got["seed"] == 0
    assert got["families"] == ["block", "shaft"]
    cpu, wall = np.array(got["cpu_s"]), np.array(got["wall_s"])
    assert len(cpu) == len(wall) == 2 and (cpu > 0).all() and (wall > 0).all()
    assert got["scans_per_cpu_s"] == pytest.approx(2 / cpu.sum())
    assert got["cpu_mean_ms"] == pytest.approx(1e3 * cpu.mean()) and got["cpu_max_ms"] == pytest.approx(1e3 * cpu.max())
    assert got["wall_median_ms"] == pytest.approx(1e3 * np.median(wall))
    assert text.splitlines()[0].startswith(
        f"64x48 noise=sensor n=2: {got['scans_per_cpu_s']:.2f} scans/s per core by CPU time"
    )
    # without --families: the generator's default mix
    _, default = _bench(["--stage", "synth", "--n", "1", "--size", "48x48", "--json", str(tmp_path / "d.json")])
    assert default["families"] == list(SynthConfig().families)


def test_stage_parts_is_measure(tmp_path: Path) -> None:
    from v2c.synth.features import measure

    out = tmp_path / "parts.json"
    text, got = _bench(["--stage", "parts", "--n", "2", "--seed", "3", "--families", "feat_plate", "--json", str(out)])
    direct = measure(2, 3, ("feat_plate",))
    assert _same({k: v for k, v in got.items() if k != "generator"}, direct) == []
    assert got["parts"] == 2 and got["valid_per_family"] == {"feat_plate": got["valid"]}
    assert got["features_applied"] == sum(got["kinds"].values())
    assert text.splitlines()[0].startswith(f"2 parts: {got['valid']} valid ({100 * got['valid_share']:.1f} %)")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--stage", "fit", "--segmentation", "learned"], "--stage fit measures the geometry stage on oracle"),
        (["--families", "block"], "--families belongs to --stage synth / parts"),
        (["--stage", "synth", "--scans", "."], "--scans does not apply to --stage synth"),
        (["--stage", "parts", "--families", "block"], "block: --stage parts takes feat_prismatic"),
        (["--stage", "vbrep", "--ablation", "gt"], "--ablation gt (the ideal VB-Rep) belongs to --stage pipeline"),
        (["--stage", "fit", "--suite", "unseen"], "--suite belongs to --stage pipeline, not --stage fit"),
        (["--stage", "fit", "--segmentation-only"], "--segmentation-only contradicts --stage fit"),
    ],
)
def test_stage_usage_errors(args: list[str], message: str) -> None:
    res = CliRunner().invoke(main, ["bench", *args])
    assert res.exit_code == 2 and message in res.output, res.output


def test_bench_json_respects_foreign_files(tmp_path: Path) -> None:
    foreign = tmp_path / "notes.json"
    foreign.write_text('{"mine": 1}')
    args = ["bench", "--stage", "parts", "--n", "1", "--families", "feat_plate", "--json", str(foreign)]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 1 and res.output.strip().startswith(
        f"error: {foreign}: exists and is a file that v2c did not write; pass --force"
    )
    assert foreign.read_text() == '{"mine": 1}'
    assert CliRunner().invoke(main, [*args, "--force"]).exit_code == 0
    first = json.loads(foreign.read_text())
    assert first["parts"] == 1 and "mine" not in first
    assert CliRunner().invoke(main, args).exit_code == 0  # now v2c's own file: replaced without --force


def test_no_argparse_entry_points_left() -> None:
    """Every v2c command is in `v2c --help`: no module of the v2c package parses its own command line (the
    FreeCAD macro of exporters and the example scripts of fixtures_design are scripts, not v2c commands)."""
    offenders = []
    for path in sorted((REPO / "v2c").rglob("*.py")):
        tree = ast.parse(path.read_text())
        imports = {a.name for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
        main_block = any(isinstance(n, ast.If) and "__main__" in ast.unparse(n.test) for n in tree.body)
        if "argparse" in imports or (main_block and path.name != "__main__.py"):
            offenders.append(str(path.relative_to(REPO)))
    # v2c/cli.py keeps `if __name__ == "__main__": run()`: the click command itself
    assert offenders == ["v2c/cli.py"]
