"""`v2c.geometry.points.mad_sigma`: the robust residual level the segmenters and the type selection share."""

from __future__ import annotations

import numpy as np

from v2c.geometry.points import mad_sigma


def test_mad_sigma_recovers_a_normal_sigma_and_ignores_outliers() -> None:
    """Normal residuals of sigma 2 give 2 within 2 %; replacing 20 % of them by huge outliers moves it by less
    than 40 % (the median's breakdown is 50 %), while the standard deviation grows a thousandfold."""
    rng = np.random.default_rng(7)
    r = rng.normal(0.0, 2.0, 200_000)
    assert abs(mad_sigma(r) - 2.0) < 0.04
    r[: len(r) // 5] = 1e4
    assert mad_sigma(r) < 2.8
    assert float(np.std(r)) > 1000.0


def test_mad_sigma_is_about_zero_not_the_median() -> None:
    """Residuals are distances to a fitted surface, so the level is taken about 0: a constant offset of 5 with no
    spread has level 1.4826 x 5, not 0."""
    assert abs(mad_sigma(np.full(11, 5.0)) - 1.4826 * 5.0) < 1e-12
    assert mad_sigma(np.zeros(5)) == 0.0
