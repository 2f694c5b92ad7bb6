"""Thresholds of the geometry toolkit: instance points and normals, RANSAC, its local refinement and the type
selection, each with its unit.

"part-size units" are multiples of the part size estimated from the scan itself (`points.estimate_part_size`),
never the ground truth's part_size_m. `v2c.fit.FitConfig` extends this class with the geometry stage's own
thresholds, so a stage's config can be handed wherever a `RansacConfig` is taken.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class RansacConfig:
    """Thresholds and budgets of instance points, RANSAC per instance, its refinement and model selection."""

    # -- part size and normals ------------------------------------------------------------------------------------
    scale_trim: float = 0.01  # fraction of points trimmed at each end of every axis of the part's extent
    normal_window_px: int = 5  # box filter (pixels) smoothing an instance's point map before the gradient
    normal_sobel_px: int = 5  # Sobel kernel size (pixels) of the point-map gradient

    # -- RANSAC per instance (Schnabel-style minimal sets) --------------------------------------------------------
    d_inlier: float = 0.03  # inlier distance (part-size units), paper
    normal_angle_deg: float = 30.0  # inlier normal deviation from the surface normal (degrees)
    ransac_hypotheses: int = 48  # minimal samples drawn per type (count)
    torus_radius_steps: int = 8  # minor-radius candidates tried per torus sample (count)
    torus_minor_range: tuple[float, float] = (0.02, 0.6)  # minor-radius candidates, fractions of the patch extent
    torus_min_ratio: float = 1.0  # tori need major radius > this * minor radius (ratio): ring tori, the
    # fillets and rounds CAD makes; a spindle "blob" can wrap a thin band
    torus_normal_axis_deg: float = 20.0  # torus hypotheses: the sample normals must lie within this of the
    # planes through the axis (degrees)
    torus_minor_span: tuple[float, float] = (0.3, 1.5)  # torus minor radius bounds, multiples of the patch's
    # cross-section span (its extent in the torus' own (rho, h) half-plane;
    # a quarter-circle fillet has r = 0.71 span) (ratio)
    torus_span_pct: float = 5.0  # the span and the radial range are taken between these percentiles (%)
    torus_minor_prior: float = 0.8  # weak prior of the torus refinement: r = this * cross-section span (ratio)
    torus_prior_weight: float = 0.2  # its residual weight per point ((r - r0) vs point distances; 0 = off)
    torus_prior_max_span: float = 2.0  # ... applied only while the span is below this many d_inlier (ratio)
    min_normal_angle_deg: float = 3.0  # minimal samples whose normals are closer than this are degenerate (deg)
    ransac_points: int = 1000  # points per instance used to score hypotheses (count)
    ransac_prescore_points: int = 200  # points scoring every hypothesis first (count)
    ransac_keep: int = 8  # hypotheses re-scored on all ransac_points (count)
    refine_points: int = 1500  # inlier points per instance used by the local least-squares refinement
    max_radius: float = 5.0  # larger radii/distances are rejected as degenerate (part-size units)
    min_half_angle_deg: float = 3.0  # cone half angles outside [min, 90 - min] are rejected (degrees)
    type_selection: str = "gric"  # type search rule: "gric" (selection.select_type) or "inliers" (inlier
    # fraction minus complexity_penalty per parameter beyond a plane's 3)
    complexity_penalty: float = 0.02  # "inliers" rule: inlier-fraction penalty per parameter (fraction)
    gric_trunc: float = 4.0  # GRIC: squared residuals are truncated at this many sigma^2 (ratio)
    gric_min_sigma: float = 0.0005  # GRIC: floor of the noise level (part-size units)

    # -- model selection against near-degenerate primitives (selection.curvature_support, docs/geometry.md) ------
    noise_sigma_coeff: float = 0.0015  # depth noise sigma = this * z^2 (1/m, z in metres): the D4xx model of the
    # synthetic `sensor` profile (synth.noise.SensorNoise.sigma_coeff_per_m);
    # used as a per-point floor of GRIC's sigma and by the sagitta test
    support_extent_ratio: float = 3.0  # a curved fit whose radius exceeds this many times the patch's extent
    # across its curvature is not supported by the patch: its normals turn by
    # less than 2 asin(1 / (2 ratio)) = 19.2 degrees over it (ratio); a plane
    support_sagitta_sigma: float = 2.0  # nor is one departing from its own best plane by less than this many
    # depth sigmas (the sagitta, in noise units; ratio) ...
    support_sagitta_turn_deg: float = 75.0  # ... while its normals turn by less than this over the patch (degrees):
    # most of a quarter circle is curvature however shallow (a fillet a few
    # pixels wide); a noisy fit of a shallow arc turns by up to ~55 degrees
    support_trim_pct: float = 2.0  # percentiles trimmed at each end for the turn and the sagitta (%)

    # -- robust least squares (RANSAC's local refinement; the geometry stage's joint fits use the same) ----------
    loss: str = "soft_l1"  # robust loss of scipy least_squares
    loss_scale: float = 0.005  # soft-l1 knee (part-size units): residuals beyond it count linearly
    max_nfev: int = 40  # function evaluations (excluding finite differences) per least squares
    ftol: float = 1e-6  # relative cost / step tolerance of the least squares
