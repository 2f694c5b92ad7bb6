"""Every threshold of the geometry optimisation stage, with its unit (one place, ARCHITECTURE.md rule).

"part-size units" are multiples of the part size estimated from the scan itself (`points.estimate_part_size`),
never the ground truth's part_size_m.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FitConfig:
    """Thresholds and budgets of RANSAC, the aligned fit and the intersection refinement."""

    # -- part size and normals ------------------------------------------------------------------------------------
    scale_trim: float = 0.01            # fraction of points trimmed at each end of every axis of the part's extent
    normal_window_px: int = 5           # box filter (pixels) smoothing an instance's point map before the gradient
    normal_sobel_px: int = 5            # Sobel kernel size (pixels) of the point-map gradient
    min_instance_px: int = 30           # instances with fewer valid pixels are not fitted (pixels)

    # -- RANSAC per instance (Schnabel-style minimal sets) --------------------------------------------------------
    d_inlier: float = 0.03              # inlier distance (part-size units), paper
    normal_angle_deg: float = 30.0      # inlier normal deviation from the surface normal (degrees)
    ransac_hypotheses: int = 48         # minimal samples drawn per type (count)
    torus_radius_steps: int = 8         # minor-radius candidates tried per torus sample (count)
    torus_minor_range: tuple[float, float] = (0.02, 0.6)  # minor-radius candidates, fractions of the patch extent
    torus_min_ratio: float = 1.0        # tori need major radius > this * minor radius (ratio): ring tori, the
                                        # fillets and rounds CAD makes; a spindle "blob" can wrap a thin band
    torus_normal_axis_deg: float = 20.0  # torus hypotheses: the sample normals must lie within this of the
                                        # planes through the axis (degrees)
    torus_minor_span: tuple[float, float] = (0.3, 1.5)  # torus minor radius bounds, multiples of the patch's
                                        # cross-section span (its extent in the torus' own (rho, h) half-plane;
                                        # a quarter-circle fillet has r = 0.71 span) (ratio)
    torus_span_pct: float = 5.0         # the span and the radial range are taken between these percentiles (%)
    torus_minor_prior: float = 0.8      # weak prior of the torus refinement: r = this * cross-section span (ratio)
    torus_prior_weight: float = 0.2     # its residual weight per point ((r - r0) vs point distances; 0 = off)
    torus_prior_max_span: float = 2.0   # ... applied only while the span is below this many d_inlier (ratio)
    min_normal_angle_deg: float = 3.0   # minimal samples whose normals are closer than this are degenerate (deg)
    ransac_points: int = 1000           # points per instance used to score hypotheses (count)
    ransac_prescore_points: int = 200   # points scoring every hypothesis first (count)
    ransac_keep: int = 8                # hypotheses re-scored on all ransac_points (count)
    refine_points: int = 1500           # inlier points per instance used by the local least-squares refinement
    max_radius: float = 5.0             # larger radii/distances are rejected as degenerate (part-size units)
    min_half_angle_deg: float = 3.0     # cone half angles outside [min, 90 - min] are rejected (degrees)
    label_score_min: float = 0.6        # below this label confidence every type is tried ([0, 1]); the geometric
                                        # segmenter's 0.5 counts as weak (docs/geometry.md)
    type_selection: str = "gric"        # type search rule: "gric" (ransac.select_type) or "inliers" (inlier
                                        # fraction minus complexity_penalty per parameter beyond a plane's 3)
    complexity_penalty: float = 0.02    # "inliers" rule: inlier-fraction penalty per parameter (fraction)
    gric_trunc: float = 4.0             # GRIC: squared residuals are truncated at this many sigma^2 (ratio)
    gric_min_sigma: float = 0.0005      # GRIC: floor of the noise level (part-size units)
    # -- model selection against near-degenerate primitives (ransac.curvature_support, docs/geometry.md) ---------
    noise_sigma_coeff: float = 0.0015   # depth noise sigma = this * z^2 (1/m, z in metres): the D4xx model of the
                                        # synthetic `sensor` profile (synth.noise.SensorNoise.sigma_coeff_per_m);
                                        # used as a per-point floor of GRIC's sigma and by the sagitta test
    support_extent_ratio: float = 3.0   # a curved fit whose radius exceeds this many times the patch's extent
                                        # across its curvature is not supported by the patch: its normals turn by
                                        # less than 2 asin(1 / (2 ratio)) = 19.2 degrees over it (ratio); a plane
    support_sagitta_sigma: float = 2.0  # nor is one departing from its own best plane by less than this many
                                        # depth sigmas (the sagitta, in noise units; ratio) ...
    support_sagitta_turn_deg: float = 75.0  # ... while its normals turn by less than this over the patch (degrees):
                                        # most of a quarter circle is curvature however shallow (a fillet a few
                                        # pixels wide); a noisy fit of a shallow arc turns by up to ~55 degrees
    support_trim_pct: float = 2.0       # percentiles trimmed at each end for the turn and the sagitta (%)
    support_label_certain: float = 0.0  # a curved label at least this probable is kept even where its patch
                                        # cannot show the curvature ([0, 1]); below it, the support and GRIC test
                                        # can turn a labelled curved instance into a plane. 0: every label is kept
                                        # (only the type search of weak labels is tested). Chosen on validation
                                        # (40 scans, seed 9000, learned, full): 0.999 gave type 97.3 %, axis 96.5 %,
                                        # alignment 0.0419; 0.9: 97.5 / 96.7 / 0.0389; 0: 99.2 / 98.2 / 0.0274
                                        # (before the rule: 98.8 / 97.6 / 0.0366). It demoted true cylinders the
                                        # learned segmenter labels at 0.6-0.9; on real frames 0.999 also set the
                                        # tuna can's radius right (43.1 mm for 42.8; 36.5 mm at 0)
    seed: int = 0                       # seed of all random sampling

    # -- global aligned fit (shared frame R) ----------------------------------------------------------------------
    align_points: int = 400             # points per primitive in the joint least squares (count)
    frame_outlier_deg: float = 8.0      # frame init: labelled axes further than this from their class consensus
                                        # are ignored (degrees)
    label_keep_ratio: float = 0.9       # an axis label stands if the axis-constrained fit keeps this share of the
                                        # free fit's inliers (fraction)
    snap_deg: float = 3.0               # type-searched (weak label) axes within this of a frame axis join the frame
    recon_weighting: str = "sample"      # "all": a subsampled point counts for the inliers it stands for, so E_recon
                                        # is the paper's sum over all inliers; "sample": every point counts once
    loss: str = "soft_l1"               # robust loss of scipy least_squares
    loss_scale: float = 0.005           # soft-l1 knee (part-size units): residuals beyond it count linearly
    max_nfev: int = 40                  # function evaluations (excluding finite differences) per least squares
    jacobian: str = "analytic"          # "analytic" or "fd" (sparse finite differences) for the joint fits
    lsmr_tol: float = 1e-5              # relative tolerance of the iterative (lsmr) trust-region steps
    ftol: float = 1e-6                  # relative cost / step tolerance of the joint least squares

    # -- iterative intersection refinement ------------------------------------------------------------------------
    d_int: float = 0.05                 # vertex-to-surface distance for membership in I_i (part-size units), paper
    d_int_second_factor: float = 0.2    # the second round uses d_int * this (paper: d_int / 5)
    w_r: float = 1.0                    # weight of E_recon against E_int (paper: 0.1; see docs/geometry.md)
    membership: str = "current"         # second round's I_i measured against "fitted" (before any intersection
                                        # pull) or "current" surfaces (see intersect.py)
    parallel_deg: float = 10.0          # planes with normals within this angle are never forced to meet (degrees)
    coaxial_tol: float = 0.02           # nor are cylinders with parallel axes whose axis lines are closer than this
                                        # (part-size units)
    simplify_px: float = 1.0            # Douglas-Peucker tolerance of the edge graph (pixels)
    edge_sample_px: float = 8.0         # intersection points are sampled along edges at this spacing (pixels)
    depth_window_px: int = 2            # half window for the depth-map initialisation of vertex depths (pixels)
    depth_search: float = 0.1           # vertex depth search range around the depth-map value (part-size units)
