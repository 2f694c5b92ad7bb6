"""`v2c bench --stage fixtures` (`v2c.bench.fixtures`): the ground-truth marks of holes and horizontal cylinders on
generated scans, and one run of the stage whose JSON agrees with itself and with the designs' own numbers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fixtures_design.design import DEPTH_BIAS_MM
from v2c.bench.fixtures import FixtureBenchConfig, visible_cylinders
from v2c.cli import main
from v2c.scan import load_scan

from scenes.truth import synthetic_scan


@pytest.mark.parametrize(
    ("family", "seed", "hole", "horizontal", "hole_any", "horizontal_any"),
    [
        ("shaft", 0, False, True, False, True),  # a lying stepped shaft: bosses with horizontal axes, no bore
        ("block", 0, False, False, False, False),  # no feature (meta "feature": "none"): 90-degree corner fillets
        # the bracket whose hole takes the pin of tests/test_fixtures_design.py
        ("bracket", 0, True, False, True, False),
        # an upright knob with 7 flutes round its base (concave cylinders of r 3.4 mm whose wall the part closes
        # in under half of the directions round their axes) and a blind hole too small to be seen: no hole
        ("feat_knob", 3, False, False, True, False),
        # a pillow block: counterbored holes in its base; its bearing housing (a horizontal convex cylinder) stands
        # on its pedestal and base plate, which fill the place of a cradle's block under it: no horizontal cylinder
        ("feat_block", 0, True, False, True, True),
    ],
)
def test_visible_holes_and_horizontal_cylinders(
    tmp_path: Path, family: str, seed: int, hole: bool, horizontal: bool, hole_any: bool, horizontal_any: bool
):
    scan = load_scan(synthetic_scan(tmp_path, family, seed))
    marks = visible_cylinders(scan, FixtureBenchConfig(min_visible_px=50))  # 320 x 240: a quarter of the pixels
    assert marks == {
        "hole": hole,
        "horizontal_cylinder": horizontal,
        "hole_any": hole_any,
        "horizontal_cylinder_any": horizontal_any,
    }


def test_stage_fixtures_on_a_shaft(tmp_path: Path) -> None:
    """One generated shaft (seed 0, 320 x 240, oracle segmentation) at k = 0 and 1: a cradle qualifies and is
    designed at both k; at k = 1 its clearance is hypot(its faces' sigma, DEPTH_BIAS_MM) and it cuts less; the
    summary counts the rows; the row holds the scan's depth offset (its depth against the clean depth); every design
    is also seated (the true part pushed home) and the cradle, seated, touches the shaft."""
    out = tmp_path / "fx.json"
    args = ["bench", "--stage", "fixtures", "--n", "1", "--seed", "0", "--families", "shaft", "--size", "320x240"]
    args += ["--segmentation", "oracle", "--clearance-k", "0,1", "--cache", str(tmp_path / "cache")]
    res = CliRunner().invoke(main, [*args, "--json", str(out), "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "| 1 | cradle | 1 |" in res.output
    r = json.loads(out.read_text())
    (row,) = r["rows"]
    assert row["family"] == "shaft" and row["horizontal_cylinder"] and not row["hole"]
    cradles = {d["k"]: d for d in row["designs"] if d["kind"] == "cradle"}
    assert cradles[0.0]["ok"] and cradles[1.0]["ok"]
    assert isinstance(row["depth_bias_mm"], float) and abs(row["depth_bias_mm"]) < 3.0  # the warp is +-2 mm
    assert cradles[0.0]["clearance"] == pytest.approx(0.2)
    # k x hypot(the faces' sigma, the scan's depth offset 1-sigma DEPTH_BIAS_MM)
    assert cradles[1.0]["clearance"] == pytest.approx(
        max(0.2, float(np.hypot(cradles[1.0]["sigma_mm"], DEPTH_BIAS_MM)))
    )
    assert cradles[1.0]["clearance"] > 0.2
    assert cradles[1.0]["cut_share"] < cradles[0.0]["cut_share"]
    for d in row["designs"]:
        if d["ok"]:
            assert d["cuts"] == (d["cut_share"] > 0.001)
            assert d["touches"] == (d["mating_median_mm"] <= 1.0)
            assert 0 <= d["mating_median_mm"] <= d["mating_max_mm"]
            # Seated: a failed seat (over 3 x the clearance + 2 mm, + a nest's floor gap) cuts and does not touch.
            assert d["seat_mm"] == pytest.approx(float(np.linalg.norm(d["seat_move_mm"])))
            assert d["seat_ok"] == (d["seat_reason"] == "")
            if d["kind"] != "nest":
                assert d["seat_bound_mm"] == pytest.approx(3 * d["clearance"] + 2.0)
            assert d["seat_ok"] == (d["seat_mm"] <= d["seat_bound_mm"]) or d["seat_reason"]
            if d["seat_ok"]:
                assert d["seated_cuts"] == (d["seated_cut_share"] > 0.001)
                assert d["seated_touches"] == (d["seated_mating_median_mm"] <= 1.0)
            else:
                assert d["seated_cuts"] and not d["seated_touches"] and d["seated_cut_share"] is None
    # The cradle pushed down into its groove: seated, it touches the true shaft and does not cut it.
    assert cradles[1.0]["seat_ok"] and cradles[1.0]["seated_touches"] and not cradles[1.0]["seated_cuts"]
    assert cradles[1.0]["seated_mating_median_mm"] < cradles[1.0]["mating_median_mm"]
    for k in ("0", "1"):
        s = r["summary"][k]
        assert s["cradle"]["qualifying_scans"] == 1 and s["cradle"]["designed_on"] == 1
        assert s["pin"]["qualifying_scans"] == 0
        ok = [d for d in row["designs"] if d["ok"] and d["k"] == float(k)]
        assert s["all"]["designs"] == len(ok)
        assert s["all"]["cut_rate"] == pytest.approx(sum(d["cuts"] for d in ok) / len(ok))
        assert s["all"]["touch_rate"] == pytest.approx(sum(d["touches"] for d in ok) / len(ok))
        assert s["all"]["seated_cut_rate"] == pytest.approx(sum(d["seated_cuts"] for d in ok) / len(ok))
        assert s["all"]["seated_touch_rate"] == pytest.approx(sum(d["seated_touches"] for d in ok) / len(ok))
        assert s["all"]["seat_failures"] == sum(not d["seat_ok"] for d in ok)


def test_clearance_k_belongs_to_the_fixture_stage() -> None:
    res = CliRunner().invoke(main, ["bench", "--stage", "fit", "--clearance-k", "1"])
    assert res.exit_code == 2 and "--clearance-k belongs to --stage fixtures" in res.output
    res = CliRunner().invoke(main, ["bench", "--stage", "fixtures", "--clearance-k", "-1"])
    assert res.exit_code == 2 and "expected numbers >= 0" in res.output


def test_fixture_kinds_belong_to_the_fixture_stage_and_are_checked() -> None:
    res = CliRunner().invoke(main, ["bench", "--stage", "fit", "--fixture-kinds", "pin"])
    assert res.exit_code == 2 and "--fixture-kinds belongs to --stage fixtures" in res.output
    res = CliRunner().invoke(main, ["bench", "--stage", "fixtures", "--fixture-kinds", "pin,clamp"])
    assert res.exit_code == 2 and "'pin,clamp': expected kinds from corner, pin, cradle, nest" in res.output


def test_fixture_kinds_choose_what_is_designed(tmp_path: Path) -> None:
    """--fixture-kinds cradle on one generated shaft: only cradles are designed, reported and summarised."""
    out = tmp_path / "fx.json"
    args = ["bench", "--stage", "fixtures", "--n", "1", "--seed", "0", "--families", "shaft", "--size", "320x240"]
    args += ["--segmentation", "oracle", "--fixture-kinds", "cradle", "--cache", str(tmp_path / "cache")]
    res = CliRunner().invoke(main, [*args, "--json", str(out), "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    r = json.loads(out.read_text())
    assert r["config"]["kinds"] == ["cradle"]
    assert {d["kind"] for row in r["rows"] for d in row["designs"]} == {"cradle"}
    assert set(r["summary"]["1"]) == {"cradle", "all"} and r["summary"]["1"]["cradle"]["designs"] == 1
    assert "| 1 | cradle | 1 |" in res.output and "| corner |" not in res.output


def test_stage_fixtures_on_a_corpus_split(tmp_path: Path) -> None:
    """--suite corpus-val --n 1: the first scan of the corpus validation split as the suites render it (a real CAD
    part, view 0, 320 x 240, oracle segmentation): its corner is designed and, pushed home, holds the true part
    without cutting it; the suites' own options and --families refuse."""
    from v2c.synth.corpus import SPLIT_FILE, read_split

    if not (Path(__file__).resolve().parents[2] / "shared" / "data" / "cad_corpus").is_dir():
        pytest.skip("CAD corpus not found (../shared/data/cad_corpus next to the repository)")
    out = tmp_path / "fx.json"
    args = ["bench", "--stage", "fixtures", "--suite", "corpus-val", "--n", "1", "--size", "320x240"]
    args += ["--segmentation", "oracle", "--fixture-kinds", "corner", "--cache", str(tmp_path / "cache")]
    res = CliRunner().invoke(main, [*args, "--json", str(out), "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    assert "1 scans of the corpus-val split's corpus parts" in res.output
    r = json.loads(out.read_text())
    assert r["config"]["suite"] == "corpus-val"
    (row,) = r["rows"]
    assert row["family"] == "cad"
    scan = Path(row["scan"])
    val = {Path(p.file).stem for p in read_split(SPLIT_FILE) if p.split == "val"}
    assert scan.name == "scan_00000" and scan.parent.name.rsplit("_", 1)[0] in val
    (d,) = row["designs"]
    # The part's corner (oracle segmentation), pushed home: it holds the true part without cutting it.
    assert d["kind"] == "corner" and d["ok"] and d["seat_ok"]
    assert d["seated_touches"] and not d["seated_cuts"] and d["seated_mating_median_mm"] < 0.5
    for extra in (["--families", "train"], ["--views", "3"]):
        res = CliRunner().invoke(main, ["bench", "--stage", "fixtures", "--suite", "corpus-val", *extra])
        assert res.exit_code == 2 and "does not apply to --stage fixtures" in res.output
