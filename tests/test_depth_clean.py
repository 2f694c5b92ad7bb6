"""v2c.depth_clean: each step on a scene with known answers, and where load_scan applies it (mode auto: real
frames, i.e. scans without gt/, only)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from v2c.depth_clean import DepthCleanConfig, clean_depth, current_mode, depth_clean, flying_pixels, speckle
from v2c.scan import load_scan

from conftest import write_tiny_scan

H, W = 60, 80


def _step() -> np.ndarray:
    """0.8 m on the left half, 0.9 m on the right: one depth edge between columns 39 and 40."""
    d = np.full((H, W), 0.9, np.float32)
    d[:, :40] = 0.8
    return d


def test_flying_pixels_between_layers_are_removed_and_layers_kept() -> None:
    d = _step()
    d[10:20, 40] = 0.85  # a column of readings halfway between the layers
    fly = flying_pixels(d, DepthCleanConfig())
    assert fly[10:20, 40].all()
    assert fly.sum() == 10  # the two layers themselves, edge pixels included, are kept
    out, counts = clean_depth(d, DepthCleanConfig())
    assert counts["flying"] == 10 and (out[10:20, 40] == 0).all()
    np.testing.assert_array_equal(out[:, :40], d[:, :40])


def test_a_tilted_plane_is_not_flying() -> None:
    # 4 mm per pixel along u at 0.8 m: steep, but one surface
    d = (0.8 + 0.004 * np.arange(W))[None, :].repeat(H, axis=0).astype(np.float32)
    assert not flying_pixels(d, DepthCleanConfig()).any()


def test_speckle_island_removed_large_piece_kept() -> None:
    d = _step()
    d[30:33, 10:13] = 0.5  # a 9-pixel island of wrong depth
    cfg = DepthCleanConfig(flying_window_px=0, speckle_max_px=30)
    spk = speckle(d, cfg)
    assert spk[30:33, 10:13].all() and spk.sum() == 9


def test_small_flat_hole_filled_large_or_steep_hole_left() -> None:
    d = _step()
    d[20:23, 10:13] = 0  # 9 px inside the 0.8 m plane
    d[40:50, 55:75] = 0  # 200 px: too big
    d[5:8, 38:42] = 0  # across the depth edge: rim spans 0.1 m
    out, counts = clean_depth(d, DepthCleanConfig(flying_window_px=0, hole_max_px=50))
    assert counts["filled"] == 9
    np.testing.assert_allclose(out[20:23, 10:13], 0.8, atol=1e-6)
    assert (out[40:50, 55:75] == 0).all() and (out[5:8, 38:42] == 0).all()


def test_bilateral_smooths_a_plane_but_not_the_edge() -> None:
    rng = np.random.default_rng(0)
    d = _step() + rng.normal(0, 0.001, (H, W)).astype(np.float32)
    out, _ = clean_depth(d, DepthCleanConfig(flying_window_px=0, bilateral_diameter_px=5))
    inner = np.s_[5:-5, 5:30]
    assert out[inner].std() < 0.6 * d[inner].std()
    assert out[:, 38].max() < 0.81 and out[:, 41].min() > 0.89  # no blur across the 0.1 m step


def test_mode_auto_cleans_real_frames_only(tmp_path: Path) -> None:
    real = write_tiny_scan(tmp_path / "real")
    synth = write_tiny_scan(tmp_path / "synth", gt=True)
    assert current_mode()[0] == "off"  # measured on the real frames: no step improved every figure
    default_real = load_scan(real).depth
    with depth_clean("off"):
        raw_real, raw_synth = load_scan(real).depth, load_scan(synth).depth
    np.testing.assert_array_equal(default_real, raw_real)
    big = DepthCleanConfig(bilateral_diameter_px=5)  # changes the readings along the hole's rim
    with depth_clean("auto", big):
        auto_real, auto_synth = load_scan(real).depth, load_scan(synth).depth
    with depth_clean("on", big):
        on_synth = load_scan(synth).depth
    np.testing.assert_array_equal(auto_synth, raw_synth)
    assert not np.array_equal(auto_real, raw_real)
    np.testing.assert_array_equal(auto_real, clean_depth(raw_real, big)[0])
    np.testing.assert_array_equal(on_synth, clean_depth(raw_synth, big)[0])
    with pytest.raises(ValueError, match="expected one of auto, on, off"):
        with depth_clean("sometimes"):
            pass
