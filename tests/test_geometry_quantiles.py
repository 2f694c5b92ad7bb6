"""`geometry.quantiles` equals numpy's percentile and median bit for bit (signed zeros and NaN included)."""

from __future__ import annotations

import numpy as np
import pytest

from v2c.geometry.quantiles import median_exact, percentile_values


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    both_nan = np.isnan(a) & np.isnan(b)
    return a.shape == b.shape and bool(np.all(both_nan | (a.view(np.int64) == b.view(np.int64))))


def _samples() -> list[np.ndarray]:
    rng = np.random.default_rng(7)
    out = [np.array([1.5]), np.array([-0.0]), np.array([2.0, -1.0]), np.array([-0.0, -0.0]), np.array([0.0, -0.0])]
    out += [np.full(5, 3.25), np.array([1.0, 1.0, 2.0, 2.0]), np.array([-0.0, -0.0, -0.0])]
    for n in (1, 2, 3, 4, 5, 10, 11, 57, 100, 101, 400, 1001):
        out.append(rng.normal(size=n) * 10.0 ** rng.uniform(-6, 3))
        out.append(np.round(rng.normal(size=n), 1))  # repeated values
        out.append(rng.integers(-3, 3, size=n).astype(float) * 1e-3)
    return out


@pytest.mark.parametrize("pct", [0.0, 2.0, 5.0, 10.0, 25.0, 33.3, 50.0, 66.7, 90.0, 95.0, 98.0, 100.0])
def test_percentile_values_equal_numpy(pct: float) -> None:
    for x in _samples():
        want = np.percentile(x, [pct, 100 - pct])
        got = percentile_values(x, [pct, 100 - pct])
        assert _same_bits(got, want), (len(x), pct, got, want)
        assert _same_bits(percentile_values(x, [pct]), np.percentile(x, [pct]))


def test_median_exact_equals_numpy() -> None:
    for x in _samples():
        assert _same_bits(median_exact(x), np.median(x)), (len(x), x[:4])
    x = np.random.default_rng(3).normal(size=(301, 2))
    assert _same_bits([median_exact(x[:, 0]), median_exact(x[:, 1])], np.median(x, axis=0))


def test_nan_sample_gives_nan() -> None:
    x = np.array([1.0, np.nan, 3.0, 0.5])
    assert np.all(np.isnan(percentile_values(x, [5.0, 95.0])))
    assert np.isnan(median_exact(x))
    assert np.isnan(percentile_values(x, [5.0])[0])


def test_input_left_unchanged() -> None:
    x = np.array([3.0, 1.0, 2.0, 5.0, 4.0])
    percentile_values(x, [10.0, 90.0])
    median_exact(x)
    assert x.tolist() == [3.0, 1.0, 2.0, 5.0, 4.0]
