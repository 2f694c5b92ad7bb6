"""`v2c.segment.segment`: method dispatch and the geometric fallback when no learned weights exist."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from v2c.scan import load_scan
from v2c.segment import learned, segment

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "bracket_planes_cylinders"


def test_learned_without_weights_falls_back_to_geometric(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(learned, "DEFAULT_WEIGHTS", tmp_path / "missing.pt")
    scan = load_scan(SAMPLE)
    with pytest.warns(UserWarning, match="geometric"):
        seg = segment(scan, "learned")
    assert seg.method == "geometric"
    # The fallback's instances cover the part (mask.png) and split it into several faces, as the geometric
    # segmenter itself does on this scan.
    direct = segment(scan, "geometric")
    np.testing.assert_array_equal(seg.instances, direct.instances)
    covered = (seg.instances > 0) & scan.mask
    assert covered.sum() >= 0.9 * scan.mask.sum()
    assert seg.instances.max() >= 3


def test_named_missing_weights_are_an_error(tiny_scan_dir: Path, tmp_path: Path) -> None:
    scan = load_scan(tiny_scan_dir)
    with pytest.raises(FileNotFoundError, match="missing.pt"):
        segment(scan, "learned", weights=tmp_path / "missing.pt")


def test_unknown_method_is_rejected(tiny_scan_dir: Path) -> None:
    with pytest.raises(ValueError, match="unknown segmentation method"):
        segment(load_scan(tiny_scan_dir), "magic")


def test_default_method_is_learned() -> None:
    import inspect

    assert inspect.signature(segment).parameters["method"].default == "learned"


def test_refine_and_ransac_settings_reach_the_refining_segmenter(
    tiny_scan_dir: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from v2c.fit import FitConfig
    from v2c.segment import geometric
    from v2c.segment.refine import RefineConfig

    seen: dict[str, dict] = {}
    monkeypatch.setattr(learned, "weights_available", lambda path=None: True)
    monkeypatch.setattr(learned, "segment_learned", lambda scan, **kw: seen.setdefault("learned", kw))
    monkeypatch.setattr(geometric, "segment_geometric", lambda scan, **kw: seen.setdefault("geometric", kw))
    scan = load_scan(tiny_scan_dir)
    refine, fit = RefineConfig(merge=False), FitConfig(d_inlier=0.02)
    segment(scan, "learned", refine=refine, ransac=fit)
    assert seen["learned"]["refine"] is refine and seen["learned"]["ransac"] is fit
    segment(scan, "geometric", refine=refine, ransac=fit)  # no geometric check there: nothing to hand down
    assert seen["geometric"] == {}
