"""Model selection that resists near-degenerate primitives (issue 17, deliverable 3).

Patches are rendered as depth images (640x480, f = 600 px) and given the synthetic `sensor` profile's depth noise,
sigma = 0.0015 z^2 m (`synth.noise.SensorNoise`), so points and depth-gradient normals come from
`geometry.points.instance_points` as in a scan; labelled patches go through the whole `fit_scan` (the check of a
label runs after the part frame's axis test). Ground truth: the rendered primitive.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest

from v2c.camera import backproject
from v2c.fit import fit_scan
from v2c.fit.config import FitConfig
from v2c.fit.stage import _ransac_instances
from v2c.geometry.points import estimate_part_size, instance_points
from v2c.geometry.selection import curvature_support, fit_instance, patch_extent, supported
from v2c.labels import label_of
from v2c.primitives import Cylinder, Plane, Primitive, Sphere
from v2c.primitives.directions import unit
from v2c.segment.types import Segmentation
from v2c.synth.noise import SensorNoise

K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
W, H = 640, 480
SIGMA_COEFF = SensorNoise().sigma_coeff_per_m  # 1/m: sigma = coeff * z^2


def _rays() -> np.ndarray:
    u, v = np.meshgrid(np.arange(W), np.arange(H))
    return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones((H, W))], axis=-1)


def plane_depth(normal: np.ndarray, z0: float, box: tuple[int, int, int, int]) -> np.ndarray:
    """Depth (m) of the plane through (0, 0, z0) with ``normal`` inside the pixel box (x0, y0, x1, y1), 0 outside."""
    d = _rays()
    n = unit(np.asarray(normal, float))
    depth = np.zeros((H, W))
    x0, y0, x1, y1 = box
    depth[y0:y1, x0:x1] = (z0 * n[2]) / (d[y0:y1, x0:x1] @ n)
    return depth


def cylinder_depth(radius: float, z0: float, arc_deg: float, cols: tuple[int, int]) -> np.ndarray:
    """Depth (m) of the camera-facing arc (``arc_deg`` wide, centred on the view direction) of a cylinder with
    its axis along the camera x axis through (0, 0, z0), within the pixel columns ``cols``; 0 elsewhere."""
    d = _rays()
    vy = d[..., 1]
    a = vy**2 + 1.0
    b = -2.0 * z0
    c = z0**2 - radius**2
    disc = b * b - 4 * a * c
    t = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), 0.0)
    y, z = t * vy, t
    phi = np.arctan2(y, -(z - z0))  # angle around the axis from the point facing the camera
    keep = (disc >= 0) & (np.abs(phi) <= np.deg2rad(arc_deg) / 2)
    keep[:, : cols[0]] = False
    keep[:, cols[1] :] = False
    return np.where(keep, t, 0.0)


def noisy_patch(depth: np.ndarray, seed: int, coeff: float = SIGMA_COEFF) -> tuple[np.ndarray, np.ndarray, float]:
    """(points, normals, part size) of the valid pixels of ``depth`` with sensor depth noise added."""
    rng = np.random.default_rng(seed)
    valid = depth > 0
    noisy = np.where(valid, depth + coeff * depth**2 * rng.standard_normal(depth.shape), 0.0)
    pts = backproject(noisy, K)
    inst = valid.astype(np.int32)
    cfg = FitConfig()
    ip = instance_points(pts, valid, inst, np.array([1]), cfg)[1]
    return ip.points, ip.normals, estimate_part_size(ip.points, cfg.scale_trim)


@dataclass
class PatchScan:
    """The part of `v2c.scan.Scan` that `fit_scan` reads."""

    depth: np.ndarray
    K: np.ndarray
    valid: np.ndarray
    path: Path = Path("<test patch>")
    gt: object = None
    mask: np.ndarray | None = None


def labelled_scan(
    seen: np.ndarray, inst: np.ndarray, label: int, score: float, seed: int
) -> tuple[PatchScan, Segmentation]:
    """The scan of depth ``seen`` (m; sensor noise added, seeded) and its segmentation ``inst``: instance 1
    labelled ``label`` at ``score``, instance 2 a plane labelled Z at 0.9."""
    rng = np.random.default_rng(seed)
    noisy = np.where(seen > 0, seen + SIGMA_COEFF * seen**2 * rng.standard_normal(seen.shape), 0.0)
    seg = Segmentation(
        instances=inst,
        labels=np.array([0, label, label_of("plane", "Z")], np.uint8),
        scores=np.array([0.0, score, 0.9], np.float32),
        method="learned",
    )
    return PatchScan(noisy.astype(np.float32), K, noisy > 0), seg


def fit_labelled(
    patch: np.ndarray,
    label: int,
    score: float,
    seed: int,
    label_certain: float | None = None,
    nested_certain: float | None = None,
    nested_from_axis: bool = True,
    unsupported: bool = True,
    flat: bool = True,
) -> Primitive:
    """The primitive `fit_scan` gives instance 1, the rendered ``patch`` (depth, m) with ``label`` at confidence
    ``score``, on a part whose other instance (2) is a plane labelled Z with its normal orthogonal to the camera
    x axis (the part is 0.3 m across, as in a scan); sensor depth noise on both."""
    floor = plane_depth(np.array([0.0, -0.5, -0.866]), 0.8, (200, 40, 440, 120))
    depth = np.where(patch > 0, patch, floor)
    inst = np.where(patch > 0, 1, np.where(floor > 0, 2, 0)).astype(np.int32)
    scan, seg = labelled_scan(depth, inst, label, score, seed)
    cfg = replace(FitConfig(), seed=seed)
    if label_certain is not None:
        cfg = replace(cfg, support_label_certain=label_certain)
    if nested_certain is not None:
        cfg = replace(cfg, nested_label_certain=nested_certain)
    cfg = replace(cfg, nested_from_axis=nested_from_axis, unsupported_labels=unsupported)
    if not flat:  # the rule for curved labels their own plane explains and their fit does not (flat_label_sigma) off
        cfg = replace(cfg, flat_label_sigma=0.0)
    return fit_scan(scan, seg, cfg).primitives[1]


#: A learned segmenter's usual confidence in a label it gets wrong on real frames (a flat box face: 0.83); the
#: type search runs below FitConfig.label_score_min (0.6).
LEARNED_SCORE = 0.85
WEAK_SCORE = 0.3


@pytest.mark.parametrize("score", [LEARNED_SCORE, WEAK_SCORE])
def test_noisy_plane_is_never_a_cylinder(score: float) -> None:
    """A tilted 107 mm square plane patch at 0.8 m (sigma 0.96 mm) labelled cylinder, confidently or weakly (type
    search), comes out a plane for every one of 20 noise seeds: the weak label by the type search (the default),
    the confident one where the labelled test is on (support_label_certain above its score; off by default,
    see FitConfig)."""
    depth = plane_depth(np.array([0.25, -0.5, -0.83]), 0.8, (280, 200, 360, 280))
    for seed in range(20):
        p = fit_labelled(depth, label_of("cylinder", "X"), score, seed, label_certain=0.999)
        assert isinstance(p, Plane), (seed, p)


def test_noisy_plane_patch_alone_is_never_curved() -> None:
    """The same plane patch on its own, every type fitted and chosen by GRIC with the sensor's noise model
    (`ransac.fit_instance` type search): a plane for every one of 25 noise seeds."""
    depth = plane_depth(np.array([0.25, -0.5, -0.83]), 0.8, (280, 200, 360, 280))
    for seed in range(25):
        x, n, scale = noisy_patch(depth, seed)
        t, f = fit_instance(x, n, None, scale, FitConfig(), np.random.default_rng(seed))
        assert t == "plane" and f is not None and isinstance(f.primitive, Plane), (seed, t)


def test_cylinder_of_90_degrees_stays_a_cylinder() -> None:
    """A 30 mm radius cylinder seen over 90 degrees at 0.5 m (sigma 0.38 mm): a cylinder with its radius within
    2 %, labelled or type-searched."""
    depth = cylinder_depth(0.03, 0.5, 90.0, (284, 356))
    for seed in range(5):
        for score in (LEARNED_SCORE, WEAK_SCORE):
            p = fit_labelled(depth, label_of("cylinder", "X"), score, seed)
            assert isinstance(p, Cylinder), (seed, score, p)
            assert abs(p.radius - 0.03) < 0.02 * 0.03, (seed, score, p.radius)


def test_shallow_cylinder_under_the_noise_is_a_plane() -> None:
    """A 60 mm radius cylinder seen over 30 degrees at 1.2 m: its sagitta (2.0 mm) is under the depth noise's
    sigma (2.2 mm) and its normals turn by less than 75 degrees, so it is a plane. Its radius (60 mm) is within
    3 times the patch's extent (48 mm along the axis) and its normals turn by more than 19.2 degrees: this is the
    sagitta rule, not the extent rule."""
    cfg = FitConfig()
    depth = cylinder_depth(0.06, 1.2, 30.0, (308, 332))
    gt = Cylinder([0.0, 0.0, 1.2], [1.0, 0.0, 0.0], 0.06)
    exact = backproject(depth, K)[depth > 0]
    turn, sag = curvature_support(gt, exact, cfg)
    # both trimmed at 2 % of the points at each end: a little under the arc's 30 degrees and 2.0 mm
    assert 0.8 * 30.0 < np.rad2deg(turn) <= 30.0
    assert 0.75 * 0.06 * (1 - np.cos(np.deg2rad(15.0))) < sag <= 0.06 * (1 - np.cos(np.deg2rad(15.0)))
    assert sag < cfg.noise_sigma_coeff * 1.2**2
    assert not supported(gt, exact, cfg)
    for seed in range(10):  # with the labelled test on (off by default, see FitConfig.support_label_certain)
        assert isinstance(
            fit_labelled(depth, label_of("cylinder", "X"), LEARNED_SCORE, seed, label_certain=0.999), Plane
        ), seed


def test_large_radius_over_a_small_patch_is_a_plane() -> None:
    """A 400 mm radius over a 15-degree arc (a 105 mm chord, the flat box faces of the real frames) at 0.8 m: the
    radius is over 3 times the patch's extent, so the cylinder label gives a plane."""
    depth = cylinder_depth(0.4, 0.8, 15.0, (280, 360))
    gt = Cylinder([0.0, 0.0, 0.8], [1.0, 0.0, 0.0], 0.4)
    assert not supported(gt, backproject(depth, K)[depth > 0], FitConfig())
    for seed in range(10):  # with the labelled test on (off by default, see FitConfig.support_label_certain)
        assert isinstance(
            fit_labelled(depth, label_of("cylinder", "X"), LEARNED_SCORE, seed, label_certain=0.999), Plane
        ), seed


def test_certain_label_is_kept() -> None:
    """A label at confidence 1 (the oracle's ground truth) stays a cylinder even on the shallow patch."""
    depth = cylinder_depth(0.4, 0.8, 15.0, (280, 360))
    assert isinstance(fit_labelled(depth, label_of("cylinder", "X"), 1.0, 0), Cylinder)


def test_support_of_exact_surfaces() -> None:
    """Noise-free: a 90-degree cylinder arc and a 60-degree sphere cap are supported; a sphere of 10 times the
    cap's extent is not."""
    cfg = FitConfig()
    depth = cylinder_depth(0.03, 0.6, 90.0, (290, 350))
    cyl = Cylinder([0.0, 0.0, 0.6], [1.0, 0.0, 0.0], 0.03)
    assert supported(cyl, backproject(depth, K)[depth > 0], cfg)
    rng = np.random.default_rng(0)
    for radius, cap_deg, ok in ((0.05, 60.0, True), (0.5, 5.7, False)):
        sph = Sphere([0.0, 0.0, 0.8], radius)
        # uniform on the cap facing the camera (polar angle from -z up to cap_deg / 2)
        theta = np.arccos(1 - rng.uniform(size=2000) * (1 - np.cos(np.deg2rad(cap_deg) / 2)))
        phi = rng.uniform(0, 2 * np.pi, 2000)
        d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), -np.cos(theta)], axis=1)
        assert supported(sph, sph.origin + radius * d, cfg) is ok, radius


def test_a_cones_radius_to_support_is_its_radius_of_curvature() -> None:
    """The radius a cone's patch must support is its radius of curvature across the generators, distance from the
    axis over cos(half angle): 20 mm for points 10 mm off the axis of a 60-degree cone, 115 mm for points 10 mm
    off the axis of an 85-degree one (nearly a plane), which a patch about 10 mm across therefore does not
    support (3 extents: about 30 mm), though its points lie 10 mm from the axis."""
    from v2c.geometry.selection import patch_radii, radius_supported
    from v2c.primitives import Cone

    cfg = FitConfig()
    for half_deg, expect_mm, ok in ((60.0, 20.0, True), (85.0, 114.7, False)):
        a = np.deg2rad(half_deg)
        cone = Cone([0.0, 0.0, 0.6], [1.0, 0.0, 0.0], a)
        phi = np.linspace(-0.5, 0.5, 40)  # 1 radian around the axis, facing the camera
        radial = np.stack([np.zeros_like(phi), np.sin(phi), -np.cos(phi)], axis=1)
        slant = 0.01 / np.sin(a) + np.linspace(-0.005, 0.005, 40)  # 10 mm along the generators about radius 10 mm
        gen = np.array([np.cos(a), 0.0, 0.0])[None, None, :] + np.sin(a) * radial[:, None, :]
        pts = (cone.origin + slant[None, :, None] * gen).reshape(-1, 3)
        assert abs(1000.0 * patch_radii(cone, pts)[0] - expect_mm) < 0.02 * expect_mm, half_deg
        assert radius_supported(cone, pts, cfg) is ok, half_deg


def cone_depth(radius: float, half_angle_deg: float, z0: float, cols: tuple[int, int]) -> np.ndarray:
    """Depth (m) of the camera-facing side of a cone whose axis runs along the camera x axis through (0, 0, z0):
    radius ``radius`` at x = 0, growing by tan(half_angle) per metre of x (a cylinder at 0), within the pixel
    columns ``cols``; 0 elsewhere. A ray t (vx, vy, 1) meets it where t^2 vy^2 + (t - z0)^2 = (radius + tan t vx)^2
    (the axis is orthogonal to `fit_labelled`'s floor normal: the label's axis class X is the frame's)."""
    d = _rays()
    along, across = d[..., 0], d[..., 1]  # the ray's slopes along the axis (x) and across it (y)
    tan = np.tan(np.deg2rad(half_angle_deg))
    a = across**2 + 1.0 - (tan * along) ** 2
    b = -2.0 * (z0 + radius * tan * along)
    c = z0**2 - radius**2
    disc = b * b - 4 * a * c
    t = np.where(disc >= 0, (-b - np.sqrt(np.maximum(disc, 0))) / (2 * a), 0.0)
    keep = (disc >= 0) & (t > 0)
    keep[:, : cols[0]] = False
    keep[:, cols[1] :] = False
    return np.where(keep, t, 0.0)


@pytest.mark.parametrize("seed", range(5))
def test_cone_label_on_a_cylinder_gives_a_cylinder_of_its_radius(seed: int) -> None:
    """A can's side (radius 33 mm at 0.8 m, 100 px long, sensor noise sigma 0.96 mm) labelled cone comes out a
    cylinder (a cone of half angle 0) within 5 % of its radius: the cone's extra parameter does not earn its
    place by GRIC with the sensor's noise model; a true 20-degree cone so labelled stays a cone."""
    can = cone_depth(0.033, 0.0, 0.8, (270, 370))
    p = fit_labelled(can, label_of("cone", "X"), LEARNED_SCORE, seed)
    assert isinstance(p, Cylinder), (seed, p)
    assert abs(p.radius - 0.033) <= 0.05 * 0.033, (seed, p.radius)
    cone = cone_depth(0.033, 20.0, 0.8, (270, 370))
    q = fit_labelled(cone, label_of("cone", "X"), LEARNED_SCORE, seed)
    assert q.type == "cone", (seed, q)


@pytest.mark.parametrize("seed", range(3))
def test_certain_cone_label_skips_the_nested_test(seed: int) -> None:
    """The nested test (`FitConfig.nested_label_certain`, 0.9) only runs on labels under that confidence: the
    same can side labelled cone at 0.95 stays a cone (the label is trusted, as the ground truth's chamfer cones
    of 36-172 points are, which the cylinder beat by GRIC for want of points); at 0.85 it becomes the cylinder
    (test above); with the threshold above 1 every label is tested again and it becomes the cylinder too."""
    can = cone_depth(0.033, 0.0, 0.8, (270, 370))
    p = fit_labelled(can, label_of("cone", "X"), 0.95, seed)
    assert p.type == "cone", (seed, p)
    q = fit_labelled(can, label_of("cone", "X"), 0.95, seed, nested_certain=1.01)
    assert isinstance(q, Cylinder) and abs(q.radius - 0.033) <= 0.05 * 0.033, (seed, q)


#: Partly seen tapered sides (radius m, half angle degrees, depth m, pixel columns, pixel rows): a band of each
#: cone's camera-facing side, as a boss's draft or a countersink shows between its neighbours.
PARTLY_SEEN_CONES = [
    (0.03, 5.0, 0.6, (240, 400), (200, 235)),
    (0.03, 8.0, 0.6, (260, 380), (205, 240)),
    (0.02, 10.0, 0.5, (280, 360), (215, 240)),
]


def test_partly_seen_cone_is_not_taken_for_a_tilted_cylinder() -> None:
    """A band of a cone's side (5-10 degrees half angle, 1,800-3,900 px, sensor noise) labelled cone at 0.85
    (under `nested_label_certain`, so the nested test runs) stays a cone on its axis (within 1 degree) for every
    one of 3 noise seeds: it is tested against the cylinder nested in it (`FitConfig.nested_from_axis`, on the
    cone's axis direction). A free RANSAC cylinder tilts by about the half angle to lie along the seen band and
    wins GRIC on some of these seeds, which is what the nested test replaced."""
    tilted = 0
    for r, half, z0, cols, rows in PARTLY_SEEN_CONES:
        band = cone_depth(r, half, z0, cols)
        band[: rows[0]] = 0.0
        band[rows[1] :] = 0.0
        for seed in range(3):
            p = fit_labelled(band, label_of("cone", "X"), LEARNED_SCORE, seed)
            assert p.type == "cone", (half, seed, p)
            assert np.degrees(np.arccos(min(1.0, abs(float(p.axis_vector[0]))))) < 1.0, (half, seed, p)
            q = fit_labelled(band, label_of("cone", "X"), LEARNED_SCORE, seed, nested_from_axis=False)
            tilt = np.degrees(np.arccos(min(1.0, abs(float(q.axis_vector[0])))))
            tilted += int(isinstance(q, Cylinder) and abs(tilt - half) < 1.5)
    assert tilted >= 1


def torus_depth(major: float, minor: float, z0: float, half_deg: float) -> np.ndarray:
    """Depth (m) of the camera-facing patch of a torus with its axis along the camera y axis whose outer equator's
    nearest point is (0, 0, z0): the points within ``half_deg`` of that point around the axis and around the
    tube, z-buffered from a dense sampling; 0 elsewhere."""
    a = np.deg2rad(half_deg)
    u, v = np.meshgrid(np.linspace(-a, a, 1500), np.linspace(-a, a, 1500))  # around the axis, around the tube
    ring = major + minor * np.cos(v)
    c = z0 + major + minor  # the axis line x = 0, z = c
    pts = np.stack([ring * np.sin(u), minor * np.sin(v), c - ring * np.cos(u)], axis=-1).reshape(-1, 3)
    px = np.round(pts[:, 0] / pts[:, 2] * K[0, 0] + K[0, 2]).astype(int)
    py = np.round(pts[:, 1] / pts[:, 2] * K[1, 1] + K[1, 2]).astype(int)
    ok = (px >= 0) & (px < W) & (py >= 0) & (py < H)
    depth = np.full(H * W, np.inf)
    np.minimum.at(depth, py[ok] * W + px[ok], pts[ok, 2])
    depth = depth.reshape(H, W)
    return np.where(np.isfinite(depth), depth, 0.0)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_weak_plane_label_lends_no_axis_to_the_curved_type_found(seed: int) -> None:
    """A torus patch facing the camera (major radius 300 mm, tube 60 mm, 25 degrees either way of its outer
    equator's nearest point at 0.6 m: a board bowed both ways, its normal the view direction), weakly labelled
    "plane Z" beside a plane labelled Z that faces the camera too: the type search finds a torus, which does not
    want frame Z (the plane label's normal) as its axis but decides later ("?"), as the plane instance keeps its
    label's Z; the fit comes out along the true axis (camera y) within the noise. (On the real lying sugar box the
    torus held on the plane label's axis kept its inlier count on a loose band and came out 26-49 mm off its
    points; on this clean patch the constrained fit loses its inliers and the next axis is taken either way.)"""
    patch = torus_depth(0.3, 0.06, 0.6, 25.0)
    floor = plane_depth(np.array([0.0, 0.0, -1.0]), 0.75, (200, 20, 440, 100))
    depth = np.where(patch > 0, patch, floor)
    inst = np.where(patch > 0, 1, np.where(floor > 0, 2, 0)).astype(np.int32)
    scan, seg = labelled_scan(depth, inst, label_of("plane", "Z"), WEAK_SCORE, seed)
    cfg = replace(FitConfig(), seed=seed)
    pts = backproject(scan.depth, K)
    ipts = instance_points(pts, scan.valid, inst, np.array([1, 2]), cfg)
    fits = _ransac_instances(ipts, seg, estimate_part_size(pts[scan.valid], cfg.scale_trim), cfg)
    assert fits.prims[1].type == "torus" and fits.want[1] == "?", (seed, fits.prims[1], fits.want[1])
    assert fits.want[2] == 2
    fit = fit_scan(scan, seg, cfg)
    p = fit.primitives[1]
    assert not isinstance(p, Plane), (seed, p)
    assert 1 in fit.types_searched
    assert abs(p.axis_vector @ np.array([0.0, 1.0, 0.0])) > np.cos(np.deg2rad(10.0)), (seed, p)
    x = backproject(scan.depth, K)[inst == 1]
    assert np.median(np.abs(p.signed_distance(x))) < 2 * SIGMA_COEFF * 0.6**2, seed


def test_type_searched_curve_the_pixels_rays_miss_is_a_plane() -> None:
    """An instance of 80 x 80 pixels, weakly labelled, whose only readings are a thin band across its middle that
    truly is curved (a 12 mm radius cylinder seen over 120 degrees at 0.8 m, 8 px wide: the rim of a shiny lid
    whose face reads nothing): the type search takes the band for that cylinder, but the rays of the instance's
    other pixels, which read nothing, miss a cylinder that thin, so the instance is fitted as a plane, through
    the band (its points within 6 mm of it). Without the ray test it came out the cylinder, and its face a band
    of spikes over the instance's pixels."""
    band = cylinder_depth(0.012, 0.8, 120.0, (280, 360))
    rows = np.flatnonzero(band.any(axis=1))
    assert 4 <= len(rows) <= 16
    inst = np.zeros((H, W), np.int32)
    inst[200:280, 280:360] = 1
    floor = plane_depth(np.array([0.0, 0.0, -1.0]), 0.9, (200, 20, 440, 100))
    inst[floor > 0] = 2
    seen = np.where(band > 0, band, floor)
    for seed in range(5):
        scan, seg = labelled_scan(seen, inst, label_of("plane", "U"), WEAK_SCORE, seed)
        p = fit_scan(scan, seg, replace(FitConfig(), seed=seed)).primitives[1]
        assert isinstance(p, Plane), (seed, p)
        x = backproject(scan.depth, K)[(inst == 1) & scan.valid]
        assert np.median(np.abs(p.signed_distance(x))) < 0.006, seed


@pytest.mark.parametrize("seed", range(3))
def test_a_searched_cone_is_tested_against_a_free_cylinder_too(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """A type-searched instance (no label said cone) that came out a cone is also tested against a free RANSAC
    cylinder (`FitConfig.nested_free_searched`), not only against the cylinder nested on the cone's axis: on the
    real tuna can's side with its ROI the cone's axis was tilted and the cylinder held on it lost. Here the nested
    cylinder is taken away (as if it had lost) and the cone is a can's side (33 mm at 0.8 m) taken for a
    4-degree cone on an axis tilted by as much, matching the side along its nearest line: the free cylinder wins
    with the can's radius. Without the flag, or for a labelled cone (no type search), the cone stays."""
    from v2c.fit import stage
    from v2c.primitives import Cone

    monkeypatch.setattr(stage, "_nested_cylinder", lambda *args, **kwargs: None)
    can = cone_depth(0.033, 0.0, 0.8, (270, 370))
    alpha = np.deg2rad(4.0)
    reach = 0.033 * np.cos(alpha) ** 2 / np.sin(alpha)  # apex to where its curvature across is the can's
    cone = Cone(np.array([-reach, 0.0, 0.8 - 0.033]), np.array([np.cos(alpha), 0.0, np.sin(alpha)]), float(alpha))
    rng = np.random.default_rng(seed)
    valid = can > 0
    noisy = np.where(valid, can + SIGMA_COEFF * can**2 * rng.standard_normal(can.shape), 0.0)
    ip = instance_points(backproject(noisy, K), valid, valid.astype(np.int32), np.array([1]), FitConfig())[1]
    size = estimate_part_size(ip.points, FitConfig().scale_trim)

    def run(cfg: FitConfig, searched: bool) -> Primitive:
        fits = stage._Fits(
            prims={1: cone},
            want={1: "?"},
            weights={1: float(len(ip.points))},
            inliers={1: np.ones(len(ip.points), bool)},
            searched=[1] if searched else [],
            scores={1: 0.3 if searched else LEARNED_SCORE},
        )
        stage._simpler_where_nested(fits, {1: ip}, {1: -1}, np.eye(3), size, cfg)
        return fits.prims[1]

    cfg = replace(FitConfig(), seed=seed)
    p = run(cfg, searched=True)
    assert isinstance(p, Cylinder) and abs(p.radius - 0.033) <= 0.05 * 0.033, (seed, p)
    assert run(replace(cfg, nested_free_searched=False), searched=True).type == "cone"
    assert run(cfg, searched=False).type == "cone"


def test_confident_cylinder_label_on_a_flat_patch_is_a_plane() -> None:
    """The plane patch of `test_noisy_plane_is_never_a_cylinder` labelled cylinder at the learned segmenter's
    confidence. The extent rule alone (FitConfig.unsupported_labels: a label is kept unless its radius exceeds
    support_extent_ratio patch extents and a plane explains the points as well by GRIC with the sensor's noise
    model; flat_label_sigma off): over 20 noise seeds, every cylinder the label held on (both rules off) that is
    wider than that bound comes out a plane, and no cylinder wider than it is left. With the default settings
    (its own plane explains it within the depth noise, the cylinder held on the part frame does not,
    flat_label_sigma) every seed gives a plane."""
    depth = plane_depth(np.array([0.25, -0.5, -0.83]), 0.8, (280, 200, 360, 280))
    x, _, _ = noisy_patch(depth, 0)
    bound = FitConfig().support_extent_ratio * patch_extent(x, FitConfig())
    wide = 0
    for seed in range(20):
        held = fit_labelled(depth, label_of("cylinder", "X"), LEARNED_SCORE, seed, unsupported=False, flat=False)
        assert isinstance(held, Cylinder), (seed, held)  # the label stands with the rules off
        p = fit_labelled(depth, label_of("cylinder", "X"), LEARNED_SCORE, seed, flat=False)
        if held.radius > 1.05 * bound:
            wide += 1
            assert isinstance(p, Plane), (seed, held.radius, bound, p)
        assert isinstance(p, Plane) or p.radius <= 1.05 * bound, (seed, p, bound)
    assert wide >= 10, wide  # a noisy plane's cylinder is mostly one of these
    for seed in range(20):  # with the default settings its own plane explains it and its held cylinder does not
        assert isinstance(fit_labelled(depth, label_of("cylinder", "X"), LEARNED_SCORE, seed), Plane), seed


def test_box_face_labelled_cylinder_leaves_the_frame_square() -> None:
    """A box (210 x 60 x 160 mm) seen from its corner at 0.8 m with 1 mm depth noise, segmented by the truth, its
    largest face labelled "cylinder Y" at 0.66 (the real cracker box's printed front), the top "plane Z" at 0.9
    and the third face weakly (0.4, type search); labels under 0.7 tested against a plane (support_label_certain).
    The face becomes a plane (and the frame is drawn again without the wrong label's axis), and the three fitted
    planes lie within 1 degree of the true faces' normals."""
    from scenes.raycast import box_scene, scene_inputs

    inp = scene_inputs(box_scene(size=(0.21, 0.06, 0.16), distance=0.8, view=(1.0, 0.6, 0.7)), noise_m=0.001, seed=5)
    inst = np.asarray(inp.seg.instances)
    counts = np.bincount(inst.ravel())[1:]
    assert len(counts) == 3
    order = np.argsort(-counts) + 1  # instances by size
    true = {k: np.asarray(inp.fit.primitives[k].axis_vector) for k in (1, 2, 3)}
    top = next(k for k in (1, 2, 3) if inp.fit.axis_labels[k] == "Z")
    big = next(k for k in order if k != top)
    third = 6 - top - big
    labels = np.zeros(4, np.uint8)
    scores = np.zeros(4, np.float32)
    labels[big], scores[big] = label_of("cylinder", "Y"), 0.66
    labels[top], scores[top] = label_of("plane", "Z"), 0.9
    labels[third], scores[third] = label_of("plane", "U"), 0.4
    seg = Segmentation(instances=inst, labels=labels, scores=scores, method="learned")
    fit = fit_scan(inp.scan, seg, replace(FitConfig(), seed=0, support_label_certain=0.7))
    for k in (1, 2, 3):
        p = fit.primitives[k]
        assert isinstance(p, Plane), (k, p)
        err = np.rad2deg(np.arccos(min(1.0, abs(float(p.axis_vector @ true[k])))))
        assert err < 1.0, (k, err)


def test_consensus_frame_ignores_a_lone_wrong_label() -> None:
    """The frame `_assign_axes` draws when a demoted label had named a frame axis (consensus=True): a box's three
    faces as planes (6820, 5801 and 4622 points, normals 1 degree off the true axes, the top labelled Z, the other
    two unlabelled as after a demotion and a type search) and a 233-point cylinder labelled X whose axis is 35
    degrees off every true axis. From the labels alone, X is the small cylinder's axis and the two large faces
    join no frame axis; by consensus the frame lies within 1.5 degrees of the true axes."""
    from scipy.spatial.transform import Rotation

    from v2c.fit.stage import _assign_axes
    from v2c.geometry.points import InstancePoints

    rng = np.random.default_rng(0)
    true = Rotation.from_euler("xyz", [-120.0, 10.0, 40.0], degrees=True).as_matrix().T  # rows: part axes
    prims, want, weights, ipts = {}, {}, {}, {}
    centre = np.array([0.0, 0.0, 0.8])
    for i, (k, n_pts) in enumerate([(0, 6820), (1, 5801), (2, 4622)], 1):
        tilt = Rotation.from_rotvec(np.deg2rad(1.0) * unit(rng.normal(size=3))).as_matrix()
        n = tilt @ true[k]
        n = n if n @ centre < 0 else -n  # facing the camera
        t1, t2 = np.linalg.svd(n[None, :])[2][1:]
        x = centre + 0.08 * n + rng.uniform(-0.05, 0.05, (n_pts, 1)) * t1 + rng.uniform(-0.05, 0.05, (n_pts, 1)) * t2
        prims[i] = Plane(x.mean(axis=0), n)
        ipts[i] = InstancePoints(np.arange(n_pts), x, np.repeat(n[None, :], n_pts, axis=0))
        want[i], weights[i] = (2 if k == 2 else "?"), float(n_pts)
    junk = Rotation.from_rotvec(np.deg2rad(35.0) * unit(np.array([1.0, 1.0, 1.0]))).as_matrix() @ true[0]
    xj = centre + rng.normal(0, 0.01, (233, 3))
    prims[4] = Cylinder(centre, junk, 0.02)
    ipts[4] = InstancePoints(np.arange(233), xj, np.repeat(-unit(centre)[None, :], 233, axis=0))
    want[4], weights[4] = 0, 233.0
    view = unit(centre)
    cfg = FitConfig()

    def worst(frame: np.ndarray) -> float:
        return max(np.rad2deg(np.arccos(min(1.0, np.max(np.abs(frame @ a))))) for a in true)

    labelled = _assign_axes(prims, want, weights, ipts, view, 0.2, cfg)[0]
    assert worst(labelled) > 10.0
    frame = _assign_axes(prims, want, weights, ipts, view, 0.2, cfg, consensus=True)[0]
    assert worst(frame) < 1.5, worst(frame)


def test_a_demoted_label_stays_a_plane_when_another_redraws_the_frame() -> None:
    """The box of `test_box_face_labelled_cylinder_leaves_the_frame_square` (1 mm noise, six seeds) with its third
    face labelled "cylinder U" at 0.66: whatever the rule makes of that face, it makes the same whether the
    largest face is labelled "cylinder Y" (demoted too, which draws the frame again from RANSAC's fits) or
    "plane X"; on seeds 1 and 3 the rule demotes it, and it stays a plane. (The frame drawn again once restored
    every instance but those whose label had named an axis, the unaligned one's curved fit among them.)"""
    from scenes.raycast import box_scene, scene_inputs

    for seed in range(6):
        inp = scene_inputs(
            box_scene(size=(0.21, 0.06, 0.16), distance=0.8, view=(1.0, 0.6, 0.7)), noise_m=0.001, seed=seed
        )
        inst = np.asarray(inp.seg.instances)
        order = np.argsort(-np.bincount(inst.ravel())[1:]) + 1  # instances by size
        top = next(k for k in (1, 2, 3) if inp.fit.axis_labels[k] == "Z")
        big = next(k for k in order if k != top)
        third = 6 - top - big
        types = []
        for big_label in (label_of("cylinder", "Y"), label_of("plane", "X")):
            labels = np.zeros(4, np.uint8)
            scores = np.zeros(4, np.float32)
            labels[big], scores[big] = big_label, 0.66
            labels[top], scores[top] = label_of("plane", "Z"), 0.9
            labels[third], scores[third] = label_of("cylinder", "U"), 0.66
            seg = Segmentation(instances=inst, labels=labels, scores=scores, method="learned")
            types.append(fit_scan(inp.scan, seg, replace(FitConfig(), seed=0)).primitives[third].type)
        assert types[0] == types[1], (seed, types)
        if seed in (1, 3):
            assert types == ["plane", "plane"], (seed, types)


def _one_fit(prim: Primitive, x: np.ndarray, n: np.ndarray, score: float) -> tuple[object, dict]:
    """The RANSAC results `stage._planes_where_unsupported` reads for one instance (1) fitted as ``prim`` with
    every point an inlier, its label ``score`` probable, and that instance's points."""
    from v2c.fit.stage import _Fits
    from v2c.geometry.points import InstancePoints

    fits = _Fits(
        prims={1: prim}, want={1: 0}, weights={1: float(len(x))}, inliers={1: np.ones(len(x), bool)}, scores={1: score}
    )
    return fits, {1: InstancePoints(np.arange(len(x)), x, n)}


@pytest.mark.parametrize("seed", range(5))
def test_a_curved_label_its_plane_explains_and_its_fit_does_not_is_a_plane(seed: int) -> None:
    """Issue 17: a noisy plane patch of 6,400 readings at 0.8 m carrying a 157 mm cylinder fit that touches it at
    its centre (the real cracker box's front, labelled cylinder at 0.67, its cylinder held on the part frame: a
    radius its patch supports, so the extent rule keeps it) becomes a plane: its own plane explains it within
    FitConfig.flat_label_sigma sensor sigmas and the cylinder explains it flat_label_worse times worse or more.
    The same fit labelled at 0.95 (over unsupported_label_certain) keeps its cylinder, and so does the flat patch
    with fewer than flat_label_min_px points. A true cylinder is kept: a 90-degree 30 mm arc (its plane does not
    explain it), and a shallow 200 mm arc read with half the modelled noise, which its plane explains within the
    noise but its own cylinder better (the rule without the second test, session 38, took it for a plane)."""
    from v2c.fit.stage import _plane_explains, _planes_where_unsupported
    from v2c.geometry.ransac import ransac_fit

    cfg = replace(FitConfig(), seed=seed)
    frame = np.eye(3)
    x, n, scale = noisy_patch(plane_depth(np.array([0.25, -0.5, -0.83]), 0.8, (280, 200, 360, 280)), seed)
    assert len(x) >= cfg.flat_label_min_px
    normal = unit(np.array([0.25, -0.5, -0.83]))
    bulged = Cylinder(x.mean(axis=0) - 0.157 * normal, [1.0, 0.0, 0.0], 0.157)  # touches the patch at its centre
    for score, plane in ((0.67, True), (0.95, False)):
        fits, ipts = _one_fit(bulged, x, n, score)
        demoted = _planes_where_unsupported(fits, ipts, {1: 0}, frame, False, scale, cfg)
        assert (demoted == [1]) is plane, (score, demoted)
        assert isinstance(fits.prims[1], Plane) is plane
    few = np.random.default_rng(seed).choice(len(x), cfg.flat_label_min_px - 1, replace=False)
    fits, ipts = _one_fit(bulged, x[few], n[few], 0.67)
    assert _planes_where_unsupported(fits, ipts, {1: 0}, frame, False, scale, cfg) == []
    for radius, z0, arc, cols, coeff in (
        (0.03, 0.5, 90.0, (284, 356), SIGMA_COEFF),
        (0.2, 0.8, 10.0, (200, 440), 0.5 * SIGMA_COEFF),
    ):
        xc, nc, sc = noisy_patch(cylinder_depth(radius, z0, arc, cols), seed, coeff)
        true = Cylinder([0.0, 0.0, z0], [1.0, 0.0, 0.0], radius)
        assert len(xc) >= cfg.flat_label_min_px
        fits, ipts = _one_fit(true, xc, nc, 0.67)
        assert _planes_where_unsupported(fits, ipts, {1: 0}, frame, False, sc, cfg) == []
        assert isinstance(fits.prims[1], Cylinder)
    # the shallow arc's plane explains it within the noise: only the second test keeps the cylinder
    f = ransac_fit("plane", xc, nc, sc, cfg, np.random.default_rng([cfg.seed, 1, 3]))
    assert not _plane_explains(f.primitive, true, xc, cfg)
    assert _plane_explains(f.primitive, true, xc, replace(cfg, flat_label_worse=0.0))
