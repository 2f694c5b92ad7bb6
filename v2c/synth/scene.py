"""Random scene around a rest-pose part: physical size, turn about Z, camera, lights, materials, ground texture.

World frame: the rest frame of the part scaled to metres (Z up, ground plane z = 0). Camera frame: OpenCV
(x right, y down, z forward), metres. `Scene.world_to_cam` maps world points to camera points.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class SceneConfig:
    """Ranges the scene is drawn from (units in the names)."""

    elevation_deg: tuple[float, float] = (15.0, 75.0)  # camera elevation above the ground plane
    fill: tuple[float, float] = (0.3, 0.7)  # bounding-sphere diameter / min(image width, height)
    distance_m: tuple[float, float] = (0.3, 1.0)  # camera to part-centre distance drawn first
    part_size_m: tuple[float, float] = (0.05, 0.3)  # largest side of the rest-pose bbox, clamped to this
    hfov_deg: tuple[float, float] = (55.0, 70.0)  # horizontal field of view of the camera
    principal_jitter_px: float = 4.0  # principal point offset from the image centre, +-
    roll_deg: float = 4.0  # camera roll about its optical axis, +-
    target_jitter: float = 0.08  # look-at point offset, fraction of the image's min side (keeps part inside)
    key_light_elevation_deg: tuple[float, float] = (25.0, 80.0)
    ambient: tuple[float, float] = (0.08, 0.25)  # ambient light intensity (linear)
    key_intensity: tuple[float, float] = (0.7, 1.3)
    fill_intensity: tuple[float, float] = (0.0, 0.5)
    print_share: float = 0.0  # share of scans whose part carries a printed texture (packaging-like artwork that
    # ignores face boundaries; drawn from its own generator, so 0 leaves every other draw unchanged)


@dataclass
class Material:
    """Blinn-Phong material: linear RGB albedo, specular strength, shininess exponent."""

    albedo: np.ndarray  # (3,) linear RGB in [0, 1]
    specular: float
    shininess: float
    name: str


@dataclass
class Light:
    """Directional light: unit direction towards the light (camera frame), linear RGB intensity, casts shadows."""

    direction: np.ndarray
    color: np.ndarray
    shadow: bool


@dataclass
class GroundLook:
    """Procedural ground texture parameters (world metres)."""

    kind: str  # "concrete" | "wood" | "tiles" | "plain"
    color_a: np.ndarray  # (3,) linear RGB
    color_b: np.ndarray
    scale_m: float  # feature size of the texture
    angle: float  # texture orientation (radians)
    seed: int
    specular: float
    print_look: PrintLook | None = None  # kind "printed": a print (render.print_texture) on the ground


@dataclass
class PrintLook:
    """Procedural print on the part (world metres): flat colour regions with sharp edges, like packaging art."""

    kind: str  # "blocks" (cells of flat colour) | "stripes" | "blotches" (thresholded fBm) | "text" (fine marks)
    palette: np.ndarray  # (k, 3) linear RGB
    scale_m: float  # feature size of the pattern
    direction: np.ndarray  # (3,) unit world direction of stripes and text lines
    seed: int


@dataclass
class Scene:
    """Everything about one scan except the part's geometry."""

    width: int
    height: int
    K: np.ndarray  # (3, 3) intrinsics, pixels
    world_to_cam: np.ndarray  # (3, 4) rigid transform, metres
    part_scale: float  # metres per rest-pose millimetre (uniform scale of `rest_to_world`)
    rest_to_world: np.ndarray  # (3, 4) similarity: rest-pose mm -> world m (scale, turn about Z, centring)
    part_size_m: float
    axes_cam: np.ndarray  # (3, 3) rows: view-corrected part X, Y, Z in the camera frame
    ambient: np.ndarray  # (3,) linear RGB
    lights: list[Light]
    material: Material
    ground: GroundLook
    backdrop: np.ndarray  # (2, 3) linear RGB, top and bottom of the wall gradient
    info: dict = field(default_factory=dict)
    print_look: PrintLook | None = None  # printed part texture (None: the material's flat albedo)


_MATERIALS = {
    # name: (albedo lo, albedo hi, specular range, shininess range)
    "aluminium": ((0.45, 0.45, 0.47), (0.75, 0.75, 0.78), (0.3, 0.7), (20, 80)),
    "steel": ((0.2, 0.2, 0.22), (0.45, 0.45, 0.47), (0.3, 0.8), (30, 120)),
    "anodised": ((0.02, 0.02, 0.02), (0.5, 0.5, 0.5), (0.2, 0.5), (15, 60)),
    "plastic": ((0.02, 0.02, 0.02), (0.9, 0.9, 0.9), (0.05, 0.3), (5, 40)),
    "brass": ((0.45, 0.32, 0.08), (0.75, 0.55, 0.2), (0.3, 0.7), (20, 80)),
}


def _sample_material(rng: np.random.Generator) -> Material:
    name = str(rng.choice(list(_MATERIALS)))
    lo, hi, spec, shin = _MATERIALS[name]
    if name in ("anodised", "plastic"):
        hue = rng.uniform(0, 1, 3)
        albedo = np.asarray(lo) + (np.asarray(hi) - np.asarray(lo)) * hue ** rng.uniform(0.5, 2.0)
    else:
        t = rng.uniform()
        albedo = np.asarray(lo) + (np.asarray(hi) - np.asarray(lo)) * t
    return Material(albedo.astype(float), float(rng.uniform(*spec)), float(rng.uniform(*shin)), name)


def _sample_ground(rng: np.random.Generator, part_size: float) -> GroundLook:
    kind = str(rng.choice(["concrete", "wood", "tiles", "plain"]))
    base = rng.uniform(0.05, 0.7, 3) * rng.uniform(0.4, 1.0)
    other = np.clip(base * rng.uniform(0.5, 1.5, 3) + rng.normal(0, 0.05, 3), 0.01, 0.95)
    scale = float(part_size * rng.uniform(0.4, 2.0)) if kind != "tiles" else float(rng.uniform(0.05, 0.3))
    return GroundLook(
        kind,
        base,
        other,
        scale,
        float(rng.uniform(0, np.pi)),
        int(rng.integers(0, 2**31 - 1)),
        float(rng.uniform(0.0, 0.3)),
    )


def _sample_print(rng: np.random.Generator, part_size: float, base: np.ndarray) -> PrintLook:
    kind = str(rng.choice(["blocks", "stripes", "blotches", "text"]))
    k = int(rng.integers(2, 5))
    palette = rng.uniform(0.0, 1.0, (k, 3)) ** rng.uniform(0.7, 2.2, (k, 1))
    palette[0] = base  # the material colour stays one of the inks
    scale = float(part_size * rng.uniform(0.08, 0.5)) if kind != "text" else float(part_size * rng.uniform(0.01, 0.03))
    direction = rng.normal(size=3)
    return PrintLook(
        kind, palette.astype(float), scale, direction / np.linalg.norm(direction), int(rng.integers(0, 2**31 - 1))
    )


def _look_at(eye: np.ndarray, target: np.ndarray, roll: float) -> np.ndarray:
    """Rotation (rows: camera x, y, z in world) of an OpenCV camera at `eye` looking at `target`, world Z up."""
    # kept: scipy's Rotation has no look-at; the frame is three cross products (synthetic scenes stay bit for bit)
    f = target - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, [0.0, 0.0, 1.0])
    r /= np.linalg.norm(r)
    d = np.cross(f, r)
    c, s = np.cos(roll), np.sin(roll)
    r, d = c * r + s * d, -s * r + c * d
    return np.stack([r, d, f])


def view_corrected_axes(rot_world_to_cam: np.ndarray, model_axes_world: np.ndarray) -> np.ndarray:
    """SCAN_FORMAT.md axes: Z = part up; X = the horizontal model axis closer to parallel with the viewing
    direction, signed away from the camera; Y = Z x X. Returns (3, 3) rows X, Y, Z in the camera frame."""
    forward = rot_world_to_cam[2]  # the optical axis in world coordinates
    z = model_axes_world[2]
    cands = model_axes_world[:2]
    dots = cands @ forward
    k = int(np.argmax(np.abs(dots)))
    x = cands[k] * (1.0 if dots[k] >= 0 else -1.0)
    y = np.cross(z, x)
    return np.stack([x, y, z]) @ rot_world_to_cam.T


def sample_scene(
    rng: np.random.Generator,
    bbox_lo_mm: np.ndarray,
    bbox_hi_mm: np.ndarray,
    width: int,
    height: int,
    cfg: SceneConfig = SceneConfig(),
) -> Scene:
    """Draw a scene for a rest-pose part with bounding box (lo, hi) in millimetres.

    The camera distance d and fill fraction f are drawn first and the part is scaled so its bounding sphere
    (radius r, bbox half-diagonal) projects to f * min(width, height): r = d / sqrt(1 + (2 fx / (f min))^2). If
    that makes the part's largest side leave `part_size_m`, the size is clamped and d recomputed.
    """
    hfov = np.deg2rad(rng.uniform(*cfg.hfov_deg))
    fx = 0.5 * width / np.tan(0.5 * hfov)
    cx = 0.5 * (width - 1) + rng.uniform(-1, 1) * cfg.principal_jitter_px
    cy = 0.5 * (height - 1) + rng.uniform(-1, 1) * cfg.principal_jitter_px
    K = np.array([[fx, 0.0, cx], [0.0, fx, cy], [0.0, 0.0, 1.0]])

    extent = np.asarray(bbox_hi_mm, float) - np.asarray(bbox_lo_mm, float)
    half_diag_mm = 0.5 * float(np.linalg.norm(extent))
    largest_mm = float(extent.max())
    fill = rng.uniform(*cfg.fill)
    k = 2.0 * fx / (fill * min(width, height))
    dist = rng.uniform(*cfg.distance_m)
    radius = dist / np.sqrt(1.0 + k * k)
    scale = radius / half_diag_mm  # metres per mm
    size = np.clip(scale * largest_mm, *cfg.part_size_m)
    scale = size / largest_mm
    radius = scale * half_diag_mm
    dist = radius * np.sqrt(1.0 + k * k)

    turn = rng.uniform(0, 2 * np.pi)
    c, s = np.cos(turn), np.sin(turn)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    rest_to_world = np.hstack([scale * rz, np.zeros((3, 1))])
    centre = np.array([0.0, 0.0, 0.5 * scale * extent[2]])  # bbox centre in the world (part centred on Z)

    elev = np.deg2rad(rng.uniform(*cfg.elevation_deg))
    azim = rng.uniform(0, 2 * np.pi)
    eye_dir = np.array([np.cos(elev) * np.cos(azim), np.cos(elev) * np.sin(azim), np.sin(elev)])
    eye = centre + dist * eye_dir
    rot = _look_at(eye, centre, np.deg2rad(rng.uniform(-1, 1) * cfg.roll_deg))
    # Shift the look-at point within the image plane so the part is not always centred.
    shift = rng.uniform(-1, 1, 2) * cfg.target_jitter * min(width, height) / fx * dist
    eye = eye + shift[0] * rot[0] + shift[1] * rot[1]
    world_to_cam = np.hstack([rot, (-rot @ eye)[:, None]])

    axes_cam = view_corrected_axes(rot, rz.T)  # rows of rz.T: the turned model axes in the world

    key_el = np.deg2rad(rng.uniform(*cfg.key_light_elevation_deg))
    key_az = rng.uniform(0, 2 * np.pi)
    key_dir = np.array([np.cos(key_el) * np.cos(key_az), np.cos(key_el) * np.sin(key_az), np.sin(key_el)])

    def tint() -> np.ndarray:
        """A light's RGB tint: 1 + a normal draw (sigma 0.06) per channel, clipped to [0.8, 1.2]."""
        return np.clip(1.0 + rng.normal(0, 0.06, 3), 0.8, 1.2)

    lights = [Light(rot @ key_dir, tint() * rng.uniform(*cfg.key_intensity), True)]
    fill_dir = -key_dir * np.array([1, 1, -1]) + rng.normal(0, 0.3, 3)
    fill_dir[2] = abs(fill_dir[2]) + 0.2
    fill_dir /= np.linalg.norm(fill_dir)
    lights.append(Light(rot @ fill_dir, tint() * rng.uniform(*cfg.fill_intensity), False))
    ambient = tint() * rng.uniform(*cfg.ambient)
    wall = rng.uniform(0.1, 0.8, 3) * rng.uniform(0.3, 1.0)
    backdrop = np.stack([wall, np.clip(wall * rng.uniform(0.6, 1.2), 0, 1)])

    info = {
        "elevation_deg": float(np.rad2deg(elev)),
        "azimuth_deg": float(np.rad2deg(azim)),
        "distance_m": float(dist),
        "fill": float(fill),
        "turn_deg": float(np.rad2deg(turn)),
        "hfov_deg": float(np.rad2deg(hfov)),
    }
    material, ground = _sample_material(rng), _sample_ground(rng, float(size))
    look = None
    if cfg.print_share > 0:  # its own generator (seeded by the ground's draw): the main stream is untouched
        prng = np.random.default_rng([ground.seed, 7])
        if prng.random() < cfg.print_share:
            look = _sample_print(prng, float(size), material.albedo)
            material = Material(material.albedo, float(prng.uniform(0.0, 0.15)), material.shininess, "printed")
    return Scene(
        width,
        height,
        K,
        world_to_cam,
        float(scale),
        rest_to_world,
        float(size),
        axes_cam,
        ambient,
        lights,
        material,
        ground,
        backdrop,
        info,
        look,
    )
