"""The default clearance of a fixture follows the reconstruction's uncertainty (docs/fixtures.md, "Clearance from
uncertainty").

A generated bracket (320 x 240) is reconstructed (oracle segmentation) from its noise-free depth with Gaussian depth
noise of sigma c * z^2 injected, c growing, and the pipeline told the same law (`VBRepConfig.sigma_depth_coeff_per_m`
= c); a corner locator designed with the default parameters then gets a clearance of CLEARANCE_K times its mating
faces' 1-sigma, which grows with c. A pin's radial clearance follows the hole radius's error instead, which on the
training holes did not follow the depth noise (`fixtures_design.design.HOLE_RADIUS_SIGMA_MM`): PIN_CLEARANCE_K times
that 1-sigma, the same at every c and without the scan's depth offset; the pin still fits the true hole.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fixtures_design import design_fixture
from fixtures_design.design import (
    CLEARANCE_K,
    DEFAULT_PARAMS,
    DEPTH_BIAS_MM,
    HOLE_RADIUS_SIGMA_MM,
    PIN_CLEARANCE_K,
    mating_sigma_mm,
)
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
    out: dict[str, list] = {"corner": [], "pin": [], "pin_fit": []}
    for c in COEFFS:
        scan = load_scan(path)
        clean = scan.gt.depth_clean.astype(np.float64)
        rng = np.random.default_rng(7)
        noisy = np.where(clean > 0, clean + rng.normal(0.0, 1.0, clean.shape) * c * clean**2, 0.0)
        scan.depth = noisy.astype(scan.depth.dtype)
        cfg = PipelineConfig(vbrep=replace(VBRepConfig(), sigma_depth_coeff_per_m=c))
        vb = reconstruct(scan, "oracle", config=cfg)
        for kind in ("corner", "pin"):
            # The injected noise has no depth offset over the part (no fBm warp): the design is told so.
            fx = design_fixture(vb, kind, bias_mm=0.0)
            with_bias = design_fixture(vb, kind).params.clearance  # the default: the sensor's offset too
            out[kind].append((fx.params.clearance, mating_sigma_mm(vb, fx.reference), with_bias))
            if kind == "pin":  # the pin against the true hole: the radius the pin got, the true hole's radius
                true_r = _true_hole_radius_mm(scan, fx.reference)
                out["pin_fit"].append((fx.notes["pin_radius_mm"], true_r, 1000.0 * fx.reference.radius))
    return out


@pytest.mark.parametrize("kind", ["corner"])
def test_default_clearance_grows_with_the_depth_noise(designs: dict[str, list], kind: str) -> None:
    own = DEFAULT_PARAMS[FixtureKind(kind)].clearance
    clearances = [c for c, _, _ in designs[kind]]
    for clearance, sigma, with_bias in designs[kind]:
        assert sigma is not None and sigma > 0
        assert clearance == pytest.approx(max(own, CLEARANCE_K * sigma))
        assert with_bias == pytest.approx(max(own, CLEARANCE_K * np.hypot(sigma, DEPTH_BIAS_MM)))
    assert clearances[0] > own  # k sigma, not the kind's own clearance, sets it even at the sensor's noise
    assert all(b > 1.5 * a for a, b in zip(clearances, clearances[1:])), clearances  # doubling c: well above 1.5x


def test_a_pins_clearance_follows_the_hole_radius_error_not_the_depth_noise(designs: dict[str, list]) -> None:
    own = DEFAULT_PARAMS[FixtureKind.PIN].clearance
    for clearance, _, with_bias in designs["pin"]:
        assert clearance == pytest.approx(max(own, PIN_CLEARANCE_K * HOLE_RADIUS_SIGMA_MM)) and clearance > own
        assert with_bias == clearance  # the scan's depth offset moves the whole part, not the hole's radius
    # the pin enters the true hole at every noise level: the hole's fitted radius less the clearance is under the
    # true radius (this bracket's 10.2 mm hole is fitted 0.7-0.9 mm small at 320 x 240, so the pin sits loose)
    for (pin_r, true_r, fit_r), (clearance, _, _) in zip(designs["pin_fit"], designs["pin"], strict=True):
        assert pin_r == pytest.approx(fit_r - clearance)
        assert 8.0 < pin_r < true_r < 11.0


def _true_hole_radius_mm(scan, ref) -> float:
    """The radius (mm) of the true cylinder nearest to a hole reference's axis (ground truth, camera frame)."""
    best = (np.inf, np.nan)
    for p in scan.gt.primitives:
        if p["type"] != "cylinder":
            continue
        a, o = np.asarray(p["params"]["axis"], float), np.asarray(p["params"]["origin"], float)
        if abs(abs(float(a @ ref.axis)) - 1.0) > 0.01:
            continue
        off = (ref.center - o) - float((ref.center - o) @ a) * a
        d = float(np.linalg.norm(off)) + abs(float(p["params"]["radius"]) - ref.radius)
        best = min(best, (d, 1000.0 * float(p["params"]["radius"])))
    return best[1]


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
