"""`v2c bench --suite unseen` (v2c.bench.suite): the corpus split and its size bands, the leave-out families hook,
the scan cache, and the two counts (faces bounded by their mesh outline in the STEP, failures) on known cases.

The end-to-end case renders two corpus test parts of known face counts (kcl washer: 4 faces, band < 30; charm
gear: 51 faces, band 30-100) at 320 x 240, one view each, oracle segmentation, and checks every group of the
table against the per-scan rows and against an independent STEP export; then breaks one cached scan and checks
that its failure is counted and named in its own band while the other part is still measured, nothing re-rendered.
"""

from __future__ import annotations

import sys
import types
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from v2c.bench import run as R
from v2c.bench import suite as S

from conftest import SHARED_DATA

WASHER, GEAR = "kcl__washer.step", "charm__gear1.step"  # test split: 4 and 51 faces


@pytest.fixture(scope="module")
def corpus() -> Path:
    folder = SHARED_DATA / "cad_corpus"
    if not folder.is_dir():
        pytest.skip(f"CAD corpus not found at {folder} (../shared/data/cad_corpus next to the repository)")
    return folder


def test_bands_split_at_30_and_100_faces() -> None:
    assert [S.band_of(n) for n in (4, 29, 30, 100, 101, 500)] == ["<30", "<30", "30-100", "30-100", ">100", ">100"]
    assert S.band_labels() == ("<30", "30-100", ">100")
    assert S.band_of(10, S.BandConfig(small_below=5, large_above=8)) == ">8"


def test_committed_split_test_parts_by_band() -> None:
    test = [p for p in S.read_split() if p.split == "test"]
    assert len(test) == 28 and len([p for p in S.read_split() if p.split == "val"]) == 15
    bands = [S.band_of(p.n_faces) for p in test]
    assert (bands.count("<30"), bands.count("30-100"), bands.count(">100")) == (13, 7, 8)
    assert {p.file: p.n_faces for p in test}[WASHER] == 4 and {p.file: p.n_faces for p in test}[GEAR] == 51


def test_each_suite_renders_one_split_and_only_unseen_has_the_families() -> None:
    """corpus-train renders the training split (what a map may be fitted on), corpus-val the validation split,
    unseen the test split plus the leave-out families; the three splits share no file."""
    splits = {name: S.SuiteConfig(suite=name).corpus_split for name in ("corpus-train", "corpus-val", "unseen")}
    assert splits == {"corpus-train": "train", "corpus-val": "val", "unseen": "test"}
    assert S.SUITES_WITH_FAMILIES == ("unseen",)
    files = {k: {p.file for p in S.read_split() if p.split == k} for k in ("train", "val", "test")}
    assert len(files["train"]) == 104 and not (files["train"] & files["val"]) and not (files["train"] & files["test"])


def test_leave_out_families_come_from_the_feature_module(monkeypatch, tmp_path: Path) -> None:
    cfg = S.SuiteConfig(
        suite="unseen", parts=(), family_scans=3, bench=R.BenchConfig(ablations=("full",), cache_dir=tmp_path)
    )
    monkeypatch.setattr(S, "UNSEEN_FAMILIES_SOURCE", ("v2c_no_such_module", "LEAVE_OUT_FAMILIES"))
    scans, notes = S.plan_scans(cfg)
    assert scans == [] and len(notes) == 1 and "skipped" in notes[0] and "v2c_no_such_module" in notes[0]
    fake = types.ModuleType("v2c_fake_features")
    fake.LEAVE_OUT_FAMILIES = ("knob", "no-such-family")
    monkeypatch.setitem(sys.modules, "v2c_fake_features", fake)
    monkeypatch.setattr(S, "UNSEEN_FAMILIES_SOURCE", ("v2c_fake_features", "LEAVE_OUT_FAMILIES"))
    scans, notes = S.plan_scans(cfg)
    assert [(s.source, s.name, s.view) for s in scans] == [("family", "knob", i) for i in range(3)]
    assert len(notes) == 1 and "no-such-family" in notes[0]
    assert len({s.seed for s in scans}) == 1 and scans[0].seed == S.derived_seed(0, "family:knob")
    # the option overrides the constant; the validation suite never adds leave-out families
    assert S.plan_scans(S.SuiteConfig(suite="unseen", parts=(), families=(), bench=cfg.bench)) == ([], [])
    assert S.plan_scans(S.SuiteConfig(suite="corpus-val", parts=(), bench=cfg.bench))[0] == []


def test_suite_refuses_unknown_parts_and_family_options(corpus: Path, tmp_path: Path) -> None:
    cfg = S.SuiteConfig(parts=("not_a_part.step",), corpus_dir=corpus, bench=R.BenchConfig(cache_dir=tmp_path))
    with pytest.raises(ValueError, match="not_a_part.step not in the test split"):
        S.plan_scans(cfg)
    from v2c.commands.bench import command

    res = CliRunner().invoke(command, ["--suite", "unseen", "--cad", str(tmp_path)])
    assert res.exit_code == 2 and "--cad belongs to --suite family" in res.output


def _row(result: dict, part: str) -> dict:
    (row,) = [r for r in result["rows"] if r["part"] == part]
    return row


def test_unseen_suite_bands_and_counts(corpus: Path, tmp_path: Path) -> None:
    bench = R.BenchConfig(
        noise="sensor",
        size=(320, 240),
        segmentations=("oracle",),
        ablations=("full",),
        jobs=1,
        cache_dir=tmp_path / "cache",
    )
    cfg = S.SuiteConfig(suite="unseen", bench=bench, corpus_dir=corpus, views=1, parts=(WASHER, GEAR), families=())
    res = S.run_suite(cfg, progress=False)
    assert res["groups"] == ["corpus test", "corpus test <30", "corpus test 30-100", "corpus test >100"]
    summ = res["summary"]["oracle/full"]
    assert res["config"]["bench"]["network_precision"] is None  # no network ran
    washer, gear = _row(res, WASHER), _row(res, GEAR)
    assert (washer["band"], washer["n_faces"], gear["band"], gear["n_faces"]) == ("<30", 4, "30-100", 51)
    assert washer["ok"] and gear["ok"], (washer.get("error"), gear.get("error"))
    # per band: exactly that part's scan; the whole split: both; the empty band says so
    assert [summ[g]["scans"] for g in res["groups"]] == [2, 1, 1, 0]
    assert [summ[g]["parts"] for g in res["groups"]] == [2, 1, 1, 0]
    for key in ("precision", "recall", "chamfer", "alignment", "type_accuracy", "axis_accuracy"):
        assert summ["corpus test <30"][key] == pytest.approx(washer[key])
        assert summ["corpus test 30-100"][key] == pytest.approx(gear[key])
        assert summ["corpus test"][key] == pytest.approx(np.mean([washer[key], gear[key]]))
    # the washer (a ring: two planes, two cylinders) with the oracle segmentation: every seen face found
    assert washer["precision"] == washer["recall"] == washer["type_accuracy"] == 1.0
    # the mesh-outline count is the STEP writer's own, recomputed here outside the bench
    from exporters.readback import check_written
    from exporters.step import write
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan
    from v2c.segment import segment

    for row in (washer, gear):
        scan = load_scan(row["path"])
        vbrep = reconstruct(scan, segmentation=segment(scan, "oracle"))
        rep = write(vbrep, tmp_path / "x.step", frame="camera")
        assert row["step_fallback_faces"] == len(rep.fallback_faces) and row["step_faces"] == rep.n_faces
        # the read-back figures too: faces within 2 % of their mesh area, the bounding boxes' largest extents
        back = check_written(vbrep, tmp_path / "x.step", rep.frame_map)
        assert row["step_area_faces"] == len(back.faces) == len(vbrep.faces)
        assert row["step_area_ok_faces"] == len(back.faces) - len(back.off_faces())
        # every face in the file is drawn by OCCT's mesher (no hole in a viewer)
        assert row["step_unmeshed_faces"] == len(back.unmeshed_faces()) == 0
        assert all(f.meshed is not None and f.meshed > 0.98 * f.written for f in back.faces if f.written > 0)
        ext_w = (back.box_written[1] - back.box_written[0]).max()
        ext_r = (back.box_reconstructed[1] - back.box_reconstructed[0]).max()
        assert row["step_box_ratio"] == pytest.approx(ext_w / ext_r)
        # the widest gap the file's topology bridges, in part sizes
        assert row["step_max_tol_rel"] == pytest.approx(back.max_tolerance / back.part_size)
    assert summ["corpus test"]["area_ok_faces"] == washer["step_area_ok_faces"] + gear["step_area_ok_faces"]
    assert summ["corpus test"]["box_ratio_max"] == max(washer["step_box_ratio"], gear["step_box_ratio"])
    assert summ["corpus test"]["fallback_faces"] == washer["step_fallback_faces"] + gear["step_fallback_faces"]
    assert summ["corpus test"]["step_faces"] == washer["step_faces"] + gear["step_faces"]
    assert summ["corpus test 30-100"]["fallback_faces"] == gear["step_fallback_faces"]
    tols = [washer["step_max_tol_rel"], gear["step_max_tol_rel"]]
    assert summ["corpus test"]["tol_rel_max"] == max(tols)
    assert summ["corpus test"]["tol_rel_median"] == pytest.approx(np.median(tols))
    assert summ["corpus test"]["tol_over"] == sum(t > S.TOLERANCE_GAP_REL for t in tols)
    assert all(summ[g]["failed"] == 0 and summ[g]["failures"] == [] for g in res["groups"])
    table = S.format_suite_tables(res)
    assert "| metric | corpus test | corpus test <30 | corpus test 30-100 | corpus test >100 |" in table
    assert (
        f"| STEP faces bounded by their mesh outline / STEP faces | {summ['corpus test']['fallback_faces']} / "
        f"{summ['corpus test']['step_faces']} | {washer['step_fallback_faces']} / {washer['step_faces']} | "
        f"{gear['step_fallback_faces']} / {gear['step_faces']} | 0 / 0 |"
    ) in table
    assert (
        f"| STEP faces read back within 2 % of their mesh area / faces | {summ['corpus test']['area_ok_faces']} / "
        f"{summ['corpus test']['area_faces']} | {washer['step_area_ok_faces']} / {washer['step_area_faces']} | "
    ) in table
    assert "| STEP faces OCCT's mesher leaves short (holes in a viewer) | 0 | 0 | 0 | 0 |" in table
    assert "| failures (scans that raised) | 0 | 0 | 0 | 0 |" in table
    assert "| scans (parts) | 2 (2) | 1 (1) | 1 (1) | 0 (0) |" in table

    # A scan that raises (its depth image gone) is a counted, named failure of its band; the run goes on, and
    # the cache renders nothing again.
    gear_color = Path(gear["path"]) / "color.png"
    stamp = gear_color.stat().st_mtime_ns
    (Path(washer["path"]) / "depth.png").unlink()
    res2 = S.run_suite(cfg, progress=False)
    assert gear_color.stat().st_mtime_ns == stamp
    summ2 = res2["summary"]["oracle/full"]
    assert [summ2[g]["failed"] for g in res2["groups"]] == [1, 1, 0, 0]
    (fail,) = summ2["corpus test <30"]["failures"]
    assert fail["scan"] == f"{WASHER}/v0" and "depth.png" in fail["error"]
    assert summ2["corpus test 30-100"]["precision"] == pytest.approx(gear["precision"])
    assert summ2["corpus test"]["precision"] == pytest.approx(gear["precision"] / 2)  # a failure counts 0
    assert "| failures (scans that raised) | 1 | 1 | 0 | 0 |" in S.format_suite_tables(res2)
    assert f"{WASHER}/v0 (scan_00000): " in S.format_suite_notes(res2)


def test_worst_scan_line_says_n_a_for_figures_a_scan_has_none_of() -> None:
    row = {"precision": 0.5, "recall": 0.25, "type_accuracy": None, "alignment": None, "chamfer": 0.0064}
    line = S._worst_line({**row, "runtime": {"to_step": 1.5}})
    assert line == (
        "precision 50.0 %, recall 25.0 %, type n/a, alignment n/a, Chamfer 0.0064, "
        "mesh-outline faces n/a (no STEP), 1.50 s"
    )
    line = S._worst_line({**row, "step_faces": 20, "step_fallback_faces": 12, "runtime": {}})
    assert "mesh-outline faces 12 of 20, n/a s" in line


def test_whole_suite_group_holds_both_sources_only_when_both_are_there() -> None:
    """Issue 15 states its figures on the whole unseen suite: `group_names` ends with `WHOLE_SUITE` when corpus
    and family scans are both present (not otherwise), and `in_group` puts every scan of either source in it and
    each scan in its own source's groups."""
    from v2c.synth.dataset import SynthConfig

    def scan(source: str, name: str, band: str | None = None) -> S.SuiteScan:
        return S.SuiteScan(Path("x") / name, source, name, 0, 1, SynthConfig(), band=band)

    cfg = S.SuiteConfig(suite="unseen")
    both = [scan(S.CORPUS, "a.step", "<30"), scan(S.FAMILY, "feat_hex")]
    groups = S.group_names(cfg, both)
    assert groups[-1] == S.WHOLE_SUITE and groups.count(S.WHOLE_SUITE) == 1
    assert S.WHOLE_SUITE not in S.group_names(cfg, both[:1]) and S.WHOLE_SUITE not in S.group_names(cfg, both[1:])
    rows = [{"source": S.CORPUS, "part": "a.step", "band": "<30"}, {"source": S.FAMILY, "part": "feat_hex"}]
    assert [S.in_group(r, S.WHOLE_SUITE, cfg) for r in rows] == [True, True]
    assert [S.in_group(r, "leave-out families", cfg) for r in rows] == [False, True]
    assert [S.in_group(r, "corpus test", cfg) for r in rows] == [True, False]
