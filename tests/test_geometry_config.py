"""`v2c.geometry.RansacConfig` and `v2c.fit.FitConfig`: one set of RANSAC settings shared by the segmentation
check and the fit stage."""

from __future__ import annotations

from dataclasses import fields

from v2c.fit import FitConfig
from v2c.geometry import RansacConfig


def test_fit_config_is_a_ransac_config_with_the_same_defaults() -> None:
    fit, ransac = FitConfig(), RansacConfig()
    assert isinstance(fit, RansacConfig)
    for f in fields(RansacConfig):
        assert getattr(fit, f.name) == getattr(ransac, f.name), f.name


def test_fit_config_takes_ransac_fields_by_keyword() -> None:
    cfg = FitConfig(d_inlier=0.02, ransac_hypotheses=10, w_r=0.1)
    assert (cfg.d_inlier, cfg.ransac_hypotheses, cfg.w_r) == (0.02, 10, 0.1)
