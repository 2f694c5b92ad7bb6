"""Depth and colour noise: the `paper` and `sensor` profiles of BENCHMARK.md, and `none`.

Depth maps are (H, W) float metres (z in the camera frame), 0 = no reading. All randomness comes from the
generator passed in, so one scan seed gives one noise map.

`paper`: fBm over Perlin noise (lacunarity 2, persistence 0.5, 7 octaves, scale 1000 px) min-max mapped to
[-0.25, 0.25] and added to the depth, then a bilateral blur. The paper gives no unit for 0.25; we read it as
MILLIMETRES (`PaperNoise.amplitude_m` = 0.25e-3), i.e. 0.08-0.5 % of our 0.05-0.3 m parts.

`sensor`: a RealSense D4xx at 0.3-1 m: Gaussian noise with sigma = 0.0015 z^2 m, the same fBm warp at 2 mm, missing
readings at grazing angles, along occlusion edges and as sparse speckle, flying pixels between depth layers, and
quantisation to the 0.1 mm depth unit.

`structured_light`: fitted to the Asus Xtion frames of ../shared/data/real (docs/synth.md, "Sensor model against
real frames"): the `sensor` steps with a weaker white noise (0.0005 z^2 m), a spatially correlated noise on top
(0.0016 z^2 m, Gaussian-blurred over 3 px: a structured-light sensor matches a window, so neighbours err
together), the 1 mm depth unit of the frames, and fewer flying pixels.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from pyfastnoiselite.pyfastnoiselite import FastNoiseLite, FractalType, NoiseType

PROFILES = ("sensor", "paper", "none", "structured_light")


@dataclass(frozen=True)
class FbmConfig:
    """Fractal Brownian motion over Perlin noise on the pixel grid (BENCHMARK.md)."""

    octaves: int = 7
    lacunarity: float = 2.0
    persistence: float = 0.5
    scale_px: float = 1000.0  # feature size of the first octave (pixels)
    sample_step_px: int = 2  # evaluation lattice, bilinearly upsampled to every pixel


@dataclass(frozen=True)
class PaperNoise:
    """The paper's profile."""

    amplitude_m: float = 0.25e-3  # the paper's 0.25, read as millimetres; fBm min-max mapped to +-amplitude
    bilateral_diameter_px: int = 5
    bilateral_sigma_space_px: float = 1.5
    bilateral_sigma_depth_m: float = 0.004  # edge-preserving: depth steps well above this are not blurred
    fbm: FbmConfig = FbmConfig()


@dataclass(frozen=True)
class SensorNoise:
    """A RealSense D4xx-like profile."""

    sigma_coeff_per_m: float = 0.0015  # Gaussian sigma = coeff * z^2 (z in metres)
    warp_amplitude_m: float = 2e-3  # the fBm warp, min-max mapped to +-amplitude
    grazing_start_deg: float = 70.0  # incidence angle where readings start to go missing...
    grazing_full_deg: float = 85.0  # ...and where all are missing (linear ramp in between)
    edge_jump_m: float = 0.01  # a depth step above this (absolute)...
    edge_jump_rel: float = 0.03  # ...and above this fraction of the depth is an occlusion edge
    edge_band_px: tuple[int, int] = (1, 3)  # width of the band around occlusion edges that may lose readings
    edge_drop_far_prob: float = 0.6  # chance of no reading for a band pixel on the far (occluded) side...
    edge_drop_near_prob: float = 0.15  # ...and on the near (occluding) side
    flying_prob: float = 0.15  # chance that a kept band pixel floats between the two depth layers
    speckle_prob: float = 0.002  # isolated missing readings anywhere
    quantum_m: float = 1e-4  # depth unit
    fbm: FbmConfig = FbmConfig()


@dataclass(frozen=True)
class StructuredLightNoise:
    """An Asus Xtion / Kinect v1-like profile, fitted to the real frames (scripts/sensor_stats.py)."""

    correlated_coeff_per_m: float = 0.0016  # correlated noise sigma = coeff * z^2 (z in metres)...
    correlated_length_px: float = 3.0  # ...a white field Gaussian-blurred with this sigma (pixels), rescaled to std 1
    sensor: SensorNoise = SensorNoise(
        sigma_coeff_per_m=0.0005,  # the white (per-pixel) part: sigma = coeff * z^2
        quantum_m=1e-3,  # the frames' depth unit (1 mm)
        flying_prob=0.03,  # flying pixels at depth edges, fitted to their share in the frames
    )


@dataclass(frozen=True)
class ColorNoise:
    """Camera-like degradation of the rendered colour (8-bit units)."""

    sigma: float = 2.0  # Gaussian read noise, 8-bit levels
    blur_sigma_px: float = 0.5  # lens softness / anti-aliasing stand-in


def fbm_map(rng: np.random.Generator, width: int, height: int, cfg: FbmConfig) -> np.ndarray:
    """(H, W) float32 fBm over Perlin noise, min-max mapped to [-1, 1]; a random seed and offset per call.

    Evaluated every `cfg.sample_step_px` pixels and bilinearly upsampled: the finest octave's period
    (scale / 2^(octaves-1), 15.6 px by default) spans many lattice steps, so this changes the map negligibly.
    """
    noise = FastNoiseLite(int(rng.integers(0, 2**31 - 1)))
    noise.noise_type = NoiseType.NoiseType_Perlin
    noise.fractal_type = FractalType.FractalType_FBm
    noise.fractal_octaves = cfg.octaves
    noise.fractal_lacunarity = cfg.lacunarity
    noise.fractal_gain = cfg.persistence
    noise.frequency = 1.0 / cfg.scale_px
    off = rng.uniform(0, 10 * cfg.scale_px, 2)
    step = cfg.sample_step_px
    hs, ws = -(-height // step), -(-width // step)
    u = np.arange(ws) * step + 0.5 * (step - 1) + off[0]
    v = np.arange(hs) * step + 0.5 * (step - 1) + off[1]
    coords = np.stack([np.tile(u, hs), np.repeat(v, ws)]).astype(np.float32)
    val = np.asarray(noise.gen_from_coords(coords), np.float32).reshape(hs, ws)
    if step > 1:
        val = cv2.resize(val, (ws * step, hs * step), interpolation=cv2.INTER_LINEAR)[:height, :width]
    lo, hi = float(val.min()), float(val.max())
    return (2.0 / max(hi - lo, 1e-12)) * (val - lo) - 1.0


def apply_paper(depth: np.ndarray, rng: np.random.Generator, cfg: PaperNoise = PaperNoise()) -> np.ndarray:
    """The paper's fBm + bilateral blur (see the module docstring)."""
    valid = depth > 0
    noisy = depth + cfg.amplitude_m * fbm_map(rng, depth.shape[1], depth.shape[0], cfg.fbm)
    noisy = cv2.bilateralFilter(
        np.where(valid, noisy, 0.0).astype(np.float32),
        cfg.bilateral_diameter_px,
        cfg.bilateral_sigma_depth_m,
        cfg.bilateral_sigma_space_px,
    )
    return np.where(valid, noisy, 0.0)


def apply_sensor(
    depth: np.ndarray, cos_incidence: np.ndarray, rng: np.random.Generator, cfg: SensorNoise = SensorNoise()
) -> np.ndarray:
    """RealSense-like noise on a clean depth map; `cos_incidence` (H, W) is |cos| of the angle between each
    pixel's ray and the surface normal."""
    h, w = depth.shape
    valid = depth > 0
    beyond = float(depth.max()) + 1.0
    far = np.where(valid, depth, beyond).astype(np.float32)
    # Occlusion edges: pixels whose 3x3 neighbourhood spans a large depth step.
    kernel = np.ones((3, 3), np.uint8)
    zmax = cv2.dilate(far, kernel)
    zmin = cv2.erode(far, kernel)
    edge = (zmax - zmin) > np.maximum(cfg.edge_jump_m, cfg.edge_jump_rel * zmin)
    band_px = int(rng.integers(cfg.edge_band_px[0], cfg.edge_band_px[1] + 1))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * band_px + 1, 2 * band_px + 1))
    band = cv2.dilate(edge.astype(np.uint8), disc) > 0
    # Far side of the edge: deeper than the band's nearest surface by more than a jump (stereo shadow side).
    z_near_band = cv2.erode(far, disc)
    far_side = (far - z_near_band) > np.maximum(cfg.edge_jump_m, cfg.edge_jump_rel * z_near_band)
    p_edge = np.where(band, np.where(far_side, cfg.edge_drop_far_prob, cfg.edge_drop_near_prob), 0.0)
    cos_start = np.cos(np.deg2rad(cfg.grazing_start_deg))
    cos_full = np.cos(np.deg2rad(cfg.grazing_full_deg))
    p_graze = np.clip((cos_start - cos_incidence) / (cos_start - cos_full), 0.0, 1.0)  # ~linear in the angle

    # Draw every random field in a fixed order (the noise map depends on the seed only).
    warp = fbm_map(rng, w, h, cfg.fbm)
    gauss = rng.standard_normal((h, w), dtype=np.float32)
    r_graze = rng.random((h, w), dtype=np.float32)
    r_edge = rng.random((h, w), dtype=np.float32)
    r_fly = rng.random((h, w), dtype=np.float32)
    lam = rng.uniform(0.2, 0.8, (h, w)).astype(np.float32)
    r_speckle = rng.random((h, w), dtype=np.float32)

    noisy = depth + cfg.warp_amplitude_m * warp + (cfg.sigma_coeff_per_m * gauss) * (depth * depth)
    dropped_edge = r_edge < p_edge
    flying = band & valid & ~dropped_edge & (r_fly < cfg.flying_prob)
    near = np.where(zmin < beyond, zmin, depth)
    deep = np.where(zmax < beyond, zmax, depth)
    noisy = np.where(flying, near + lam * (deep - near), noisy)
    missing = ~valid | (r_graze < p_graze) | dropped_edge | (r_speckle < cfg.speckle_prob)
    noisy = np.round(noisy / cfg.quantum_m) * cfg.quantum_m
    return np.where(missing | (noisy <= 0), 0.0, noisy)


def apply_structured_light(
    depth: np.ndarray,
    cos_incidence: np.ndarray,
    rng: np.random.Generator,
    cfg: StructuredLightNoise = StructuredLightNoise(),
) -> np.ndarray:
    """Structured-light noise: the correlated field (drawn first) displaces the surface, then `apply_sensor` with
    ``cfg.sensor`` adds its white noise, missing readings, flying pixels and quantisation."""
    h, w = depth.shape
    field = cv2.GaussianBlur(rng.standard_normal((h, w), dtype=np.float32), (0, 0), cfg.correlated_length_px)
    field *= np.float32(1.0 / max(float(field.std()), 1e-12))
    shifted = np.where(depth > 0, depth + (cfg.correlated_coeff_per_m * field) * (depth * depth), 0.0)
    return apply_sensor(shifted, cos_incidence, rng, cfg.sensor)


def apply_depth_noise(
    profile: str, depth: np.ndarray, cos_incidence: np.ndarray, rng: np.random.Generator
) -> np.ndarray:
    """Noisy depth (metres) for one of PROFILES."""
    if profile == "none":
        return depth.copy()
    if profile == "paper":
        return apply_paper(depth, rng)
    if profile == "sensor":
        return apply_sensor(depth, cos_incidence, rng)
    if profile == "structured_light":
        return apply_structured_light(depth, cos_incidence, rng)
    raise ValueError(f"unknown noise profile {profile!r} (choose from {', '.join(PROFILES)})")


def noise_params(profile: str) -> dict:
    """The parameters of a profile, for meta.json."""
    from dataclasses import asdict

    if profile == "paper":
        return asdict(PaperNoise())
    if profile == "sensor":
        return asdict(SensorNoise())
    if profile == "structured_light":
        return asdict(StructuredLightNoise())
    return {}


def finish_color(
    linear: np.ndarray, rng: np.random.Generator, profile: str, cfg: ColorNoise = ColorNoise()
) -> np.ndarray:
    """Linear RGB float (H, W, 3) -> sRGB uint8 with blur and (unless profile is none) read noise."""
    lin = np.clip(linear, 0.0, 1.0).astype(np.float32)
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.power(np.maximum(lin, 0.0031308), 1 / 2.4) - 0.055)
    img = srgb * np.float32(255.0)
    if cfg.blur_sigma_px > 0:
        img = cv2.GaussianBlur(img, (0, 0), cfg.blur_sigma_px)
    if profile != "none":
        img += cfg.sigma * rng.standard_normal(img.shape, dtype=np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
