"""`v2c.segment.train.generate_training_data` when the generator cannot make some scans (a part OCCT's check
refuses fails again on every try, since a scan is a pure function of (seed, index))."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from v2c.synth import dataset as D


def fake_generator(bad: set[tuple[int, int]], calls: list[tuple[int, int, int]]):
    """A stand-in for `generate_dataset` that writes scans start..start+n-1 of run ``seed`` (their gt/meta.json,
    as the real one writes last) except the (seed, index) pairs of ``bad``, then raises `SynthError` as the real
    one does when any failed; every call is recorded as (seed, start, n)."""

    def generate(out_dir, n, seed, cfg, jobs=1, progress=True, start=0, executor="local"):
        calls.append((seed, start, n))
        failed = []
        for i in range(start, start + n):
            if (seed, i) in bad:
                failed.append(D.scan_name(i))
                continue
            (Path(out_dir) / D.scan_name(i) / "gt").mkdir(parents=True, exist_ok=True)
            (Path(out_dir) / D.scan_name(i) / "gt" / "meta.json").write_text("{}")
        if failed:
            raise D.SynthError(f"{len(failed)} of {n} scans failed ({out_dir}): {', '.join(failed)}: invalid part")
        return [Path(out_dir) / D.scan_name(i) for i in range(start, start + n)]

    return generate


RECIPE = ((64, 48, "none", 30, 1, 0.0, ("block",)), (64, 48, "none", 20, 2, 0.0, ("shaft",)))


def test_a_scan_that_cannot_be_made_does_not_stop_the_recipe(tmp_path, monkeypatch, caplog) -> None:
    """One failing scan of row 1 (index 7 of 30): row 2 is still generated, the 49 scans made are returned in
    order, a warning names the failed scan; a resumed run asks the generator only for the missing scan."""
    from v2c.segment.train import generate_training_data

    calls: list[tuple[int, int, int]] = []
    monkeypatch.setattr(D, "generate_dataset", fake_generator({(1, 7)}, calls))
    with caplog.at_level(logging.WARNING, logger="v2c.segment.train"):
        done = generate_training_data(tmp_path, recipe=RECIPE)
    assert calls == [(1, 0, 30), (2, 0, 20)]
    assert len(done) == 49
    assert [p.name for p in done[:29]] == [D.scan_name(i) for i in range(30) if i != 7]
    assert {p.parent.name for p in done[29:]} == {"64x48_none_shaft_s2"}
    assert "1 of 50 training scans could not be generated" in caplog.text and "scan_00007" in caplog.text
    calls.clear()
    again = generate_training_data(tmp_path, recipe=RECIPE)
    assert calls == [(1, 7, 1)] and again == done


def test_too_many_failures_raise_naming_them(tmp_path, monkeypatch) -> None:
    """Failures over `MAX_FAILED_SHARE` of the recipe (here 3 of 50 against a 5 % limit of 2.5, and 1 of 50
    against 0 %) raise `SynthError` with the failed scans named, after the rows were all tried."""
    from v2c.segment.train import MAX_FAILED_SHARE, generate_training_data

    assert MAX_FAILED_SHARE == pytest.approx(0.05)
    calls: list[tuple[int, int, int]] = []
    monkeypatch.setattr(D, "generate_dataset", fake_generator({(1, 3), (1, 4), (2, 0)}, calls))
    with pytest.raises(D.SynthError, match=r"3 of 50 training scans.*scan_00003, scan_00004.*scan_00000"):
        generate_training_data(tmp_path / "a", recipe=RECIPE)
    assert calls == [(1, 0, 30), (2, 0, 20)]
    monkeypatch.setattr(D, "generate_dataset", fake_generator({(2, 5)}, []))
    with pytest.raises(D.SynthError, match=r"1 of 50 .*more than 0% of the recipe"):
        generate_training_data(tmp_path / "b", recipe=RECIPE, max_failed_share=0.0)
