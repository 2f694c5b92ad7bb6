"""Order statistics of 1-D samples that equal numpy's bit for bit, without its per-call overhead.

`np.percentile` and `np.median` spend tens of microseconds per call in argument handling (axis normalisation,
index arrays, `np.unique`, error states) before one `np.partition`; the torus bounds (`ransac.torus_limits`) call
them tens of thousands of times per scan on a few hundred points. These replicate numpy 2's default 'linear'
method (Hyndman & Fan's 7th: virtual index (n - 1) q, its `_lerp` with the ``t >= 0.5`` branch) and its median
(the mean of the middle one or two order statistics, a sum that starts from +0.0) operation for operation in
float64 scalar arithmetic (IEEE, as numpy's), so the results are the same; a sample holding NaN gives NaN, as
numpy does (without numpy's warning). The partitions take numpy's own indices, so that equal values of
different bits (0.0 and -0.0) end up where numpy's do.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def _linear_index(n: int, pct: float) -> tuple[int, int, float]:
    """The neighbouring order statistics (indices, -1 = the largest) and weight of the ``pct`` percentile of
    ``n`` values, as numpy's `_get_indexes` and `_get_gamma` of its 'linear' method."""
    virtual = (n - 1) * (pct / 100.0)
    prev = math.floor(virtual)
    nxt = prev + 1
    if virtual >= n - 1:
        prev = nxt = -1
    elif virtual < 0:
        prev = nxt = 0
    return prev, nxt, virtual - prev


def _lerp(a: float, b: float, t: float) -> float:
    """Linear interpolation as numpy's `_lerp`: from the lower neighbour below t = 0.5, from the upper one above."""
    diff = b - a
    return b - diff * (1 - t) if t >= 0.5 else a + diff * t


def percentile_values(values: np.ndarray, pcts: Sequence[float]) -> list[float]:
    """``np.percentile(values, pcts)`` (method 'linear') of a non-empty float sample ``values`` (flattened), for
    the percentages ``pcts`` (each in [0, 100]), as a list of floats in the units of ``values``."""
    arr = np.asarray(values, dtype=np.float64).ravel()
    idx = [_linear_index(arr.size, p) for p in pcts]
    # numpy's partition indices exactly (its `_quantile`): equal values (0.0 and -0.0) then land where numpy's do
    part = np.partition(arr, sorted({0, -1, *(i for prev, nxt, _ in idx for i in (prev, nxt))}))
    if math.isnan(part[-1]):  # NaN sorts last: numpy's result is NaN
        return [math.nan] * len(idx)
    return [_lerp(float(part[prev]), float(part[nxt]), t) for prev, nxt, t in idx]


def median_exact(values: np.ndarray) -> float:
    """``np.median(values)`` of a non-empty float sample ``values`` (flattened), in its units."""
    arr = np.asarray(values, dtype=np.float64).ravel()
    n = arr.size
    half = n // 2
    part = np.partition(arr, [half - 1, half, -1] if n % 2 == 0 else [half, -1])  # numpy's `_median` indices
    if math.isnan(part[-1]):
        return math.nan
    # numpy's mean: a sum that starts from +0.0 (so -0.0 becomes 0.0), divided by the count
    if n % 2 == 1:
        return (0.0 + float(part[half])) / 1.0
    return (0.0 + float(part[half - 1]) + float(part[half])) / 2.0
