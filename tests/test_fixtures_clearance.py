"""The default clearance of a fixture follows the depth noise (docs/fixtures.md, "Clearance from uncertainty").

A generated bracket (320 x 240) is reconstructed (oracle segmentation) from its noise-free depth with Gaussian depth
noise of sigma c * z^2 injected, c growing, and the pipeline told the same law (`VBRepConfig.sigma_depth_coeff_per_m`
= c); a corner locator and a pin designed with the default parameters then get a clearance of CLEARANCE_K times
their mating faces' 1-sigma, which grows with c.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fixtures_design import design_fixture
from fixtures_design.design import CLEARANCE_K, DEFAULT_PARAMS, DEPTH_BIAS_MM, mating_sigma_mm
from fixtures_design.model import FixtureKind
from v2c.pipeline import PipelineConfig, reconstruct
from v2c.scan import load_scan
from v2c.vbrep.config import VBRepConfig

from scenes.truth import synthetic_scan

#: Depth noise laws injected (sigma = c * z^2, c in 1/m): the sensor profile's 0.0015, then twice and four times.
COEFFS = (0.0015, 0.003, 0.006)


@pytest.fixture(scope="module")
def designs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, list]:
    path = synthetic_scan(tmp_path_factory.mktemp("clearance_scans"), "bracket", 1)
    out: dict[str, list] = {"corner": [], "pin": []}
    for c in COEFFS:
        scan = load_scan(path)
        clean = scan.gt.depth_clean.astype(np.float64)
        rng = np.random.default_rng(7)
        noisy = np.where(clean > 0, clean + rng.normal(0.0, 1.0, clean.shape) * c * clean**2, 0.0)
        scan.depth = noisy.astype(scan.depth.dtype)
        cfg = PipelineConfig(vbrep=replace(VBRepConfig(), sigma_depth_coeff_per_m=c))
        vb = reconstruct(scan, "oracle", config=cfg)
        for kind in out:
            # The injected noise has no depth offset over the part (no fBm warp): the design is told so.
            fx = design_fixture(vb, kind, bias_mm=0.0)
            with_bias = design_fixture(vb, kind).params.clearance  # the default: the sensor's offset too
            out[kind].append((fx.params.clearance, mating_sigma_mm(vb, fx.reference), with_bias))
    return out


@pytest.mark.parametrize("kind", ["corner", "pin"])
def test_default_clearance_grows_with_the_depth_noise(designs: dict[str, list], kind: str) -> None:
    own = DEFAULT_PARAMS[FixtureKind(kind)].clearance
    clearances = [c for c, _, _ in designs[kind]]
    for clearance, sigma, with_bias in designs[kind]:
        assert sigma is not None and sigma > 0
        assert clearance == pytest.approx(max(own, CLEARANCE_K * sigma))
        assert with_bias == pytest.approx(max(own, CLEARANCE_K * np.hypot(sigma, DEPTH_BIAS_MM)))
    assert clearances[0] > own  # k sigma, not the kind's own clearance, sets it even at the sensor's noise
    assert all(b > 1.5 * a for a, b in zip(clearances, clearances[1:])), clearances  # doubling c: well above 1.5x


def test_part_inside_share_sees_a_fixture_pushed_into_the_part() -> None:
    """The box corner's locator leaves the (reconstructed) box outside; the same block pushed 5 mm into the box
    along the two faces' inward normals holds part of its surface (what ``max_part_inside_share`` refuses)."""
    from dataclasses import replace as dc_replace

    from build123d import Location

    from fixtures_design.verify import part_inside_share

    from scenes.vbrep import box_corner

    vb = box_corner()
    fx = design_fixture(vb, "corner")
    assert part_inside_share(fx, vb) == 0.0
    inward = -fx.fmap.vectors(np.sum(fx.reference.normals, axis=0))
    d = 5.0 * inward / np.linalg.norm(inward)
    pushed = dc_replace(fx, solid=fx.solid.moved(Location(tuple(float(x) for x in d))))
    share = part_inside_share(pushed, vb)
    assert share > 0.01  # ten times a 0.1 % max_part_inside_share
    assert design_fixture(vb, "corner", max_part_inside_share=0.001).params == fx.params  # nothing inside: kept
