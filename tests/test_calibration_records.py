"""The calibration script's labelled-edge records carry the fingerprint of the code that labelled them
(scripts/calibrate_confidence.py): records of other code are set aside, never mixed into a new fit."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "calibrate_confidence.py"


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("calibrate_confidence", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_fingerprint_follows_the_code_and_weights(script, tmp_path) -> None:
    pkg = tmp_path / "v2c"
    (pkg / "segment" / "weights").mkdir(parents=True)
    (pkg / "a.py").write_text("x = 1\n")
    (pkg / "segment" / "b.py").write_text("y = 2\n")
    (pkg / "segment" / "weights" / "unet.pt").write_bytes(b"\x00\x01")
    (pkg / "notes.md").write_text("not code")
    first = script.code_fingerprint(pkg)
    assert first == script.code_fingerprint(pkg)  # deterministic
    (pkg / "notes.md").write_text("other words")  # not code: same fingerprint
    assert script.code_fingerprint(pkg) == first
    (pkg / "segment" / "b.py").write_text("y = 3\n")
    second = script.code_fingerprint(pkg)
    assert second != first
    (pkg / "segment" / "weights" / "unet.pt").write_bytes(b"\x00\x02")
    assert script.code_fingerprint(pkg) not in (first, second)
    # the real package's fingerprint is a SHA-1
    assert len(script.code_fingerprint()) == 40


def test_records_of_other_code_are_set_aside(script, tmp_path, capsys) -> None:
    path = tmp_path / "records.json"
    rows = {"/scan_00000|learned": [{"type": "intersection", "ok": 1}]}
    script.save_records(dict(rows), path, "aaa")
    assert json.loads(path.read_text())[script.FINGERPRINT_KEY] == "aaa"
    same = script.load_records(path, "aaa")
    assert same["/scan_00000|learned"] == rows["/scan_00000|learned"]
    assert script.load_records(path, "bbb") == {}
    err = capsys.readouterr().err
    assert str(path) in err and "aaa" in err and "bbb" in err and "--reuse-stale-records" in err
    assert script.load_records(path, "bbb", reuse_stale=True)["/scan_00000|learned"] == rows["/scan_00000|learned"]
    # a file written before fingerprints: stale
    path.write_text(json.dumps(rows))
    assert script.load_records(path, "aaa") == {}
    assert script.load_records(tmp_path / "missing.json", "aaa") == {}
