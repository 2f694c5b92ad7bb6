"""Appearance and framing randomization of synthetic scans (issue 15 item 3; docs/synth.md "Appearance").

`SynthConfig.appearance = "random"` gives a scan random and dark or shiny materials, printed art drawn with OpenCV
inside the part's face regions (text, stripes, logos, photo-like patches: colour edges inside one surface),
textured or printed grounds, a photo-like backdrop, clutter (simple boxes, cylinders and spheres standing beside
the part, background in the labels), varied lights and exposure. `SynthConfig.framing = "extent"` moves the
camera so the part's image extent (the larger side of its silhouette's bounding box) is a drawn 30-70 % of the
smaller image side (SCAN_FORMAT.md), at a random place in the image.

Both draw from their own generators (`np.random.default_rng([seed, index, stream])`), never from the scan's main
one, so the part, the scene's first draws, the depth noise and the colour noise are those of the plain scan with
the same seed: with `framing` fixed, `appearance` changes the colour only, plus the depth of clutter pixels.
Printed art is albedo, not geometry: it never changes a face id, a label or a depth.

Frames: world = the part's rest frame scaled to metres (Z up, ground z = 0); camera = OpenCV, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from v2c.synth.scene import GroundLook, Light, Material, PrintLook, Scene, _sample_print

APPEARANCES = ("plain", "random")
FRAMINGS = ("fill", "extent")
FRAMING_STREAM = 1501  # third word of the framing generator's seed: [seed, index, FRAMING_STREAM]
APPEARANCE_STREAM = 1502  # and of the appearance generator's
#: Version of the extent framing (`frame_scene`), in the scans' meta and the bench suite cache key of non-plain
#: suites: bump when the camera it places changes. 2: the camera stays above the part (min_sight_elevation_deg).
FRAMING_VERSION = 2


@dataclass(frozen=True)
class FramingConfig:
    """Framing of `framing = "extent"` (SCAN_FORMAT.md: the part's extent 30-70 % of the smaller image side)."""

    extent: tuple[float, float] = (0.32, 0.68)  # drawn silhouette extent / min(width, height); inside 0.3-0.7
    # with a margin for the coarse mesh the extent is measured on
    margin_px: float = 4.0  # the silhouette's bounding box stays this far inside the image
    mesh_deflection_rel: float = 0.004  # chord error of the coarse mesh that is projected, / largest side
    iterations: int = 5  # distance and shift updates (each one a projection of the mesh)
    min_distance_m: float = 0.12  # the camera never comes closer to the part's centre than this
    min_sight_elevation_deg: float = 15.0  # degrees: the camera's height above the part's centre is at least
    # sin(this) x the part centre's depth along the optical axis (the lowest camera elevation of
    # SceneConfig.elevation_deg): placing the part high in the image would otherwise move the camera down to the
    # ground or below it (ground depth readings of a few centimetres)


@dataclass(frozen=True)
class AppearanceConfig:
    """Ranges of `appearance = "random"` (colours linear RGB in [0, 1], sizes in the names)."""

    dark_share: float = 0.25  # share of parts with a dark material (albedo 0.01-0.08)
    shiny_share: float = 0.35  # share of parts with a shiny metal (strong, tight highlights)
    art_share: float = 0.85  # share of parts that carry printed art
    art_face_prob: float = 0.75  # chance that a face of an art-carrying part gets art
    art_min_face_px: int = 120  # faces smaller than this (pixels) get none
    art_items: tuple[int, int] = (1, 4)  # art items per face (inclusive)
    world_print_share: float = 0.2  # share of parts printed in world coordinates (render.print_texture) instead
    clutter: tuple[int, int] = (0, 5)  # clutter objects beside the part (inclusive)
    clutter_size_rel: tuple[float, float] = (0.3, 1.3)  # clutter object size / part size
    clutter_gap_rel: tuple[float, float] = (0.05, 1.5)  # gap between the part's and the object's circles / size
    clutter_tries: int = 40  # placements tried per object (one that could hide the part is refused)
    clutter_kinds: tuple[float, float, float] = (0.5, 0.35, 0.15)  # chances of a box, a cylinder, a sphere
    clutter_print_prob: float = 0.3  # chance that a clutter object is printed (render.print_texture)
    ambient: tuple[float, float] = (0.02, 0.35)
    key_intensity: tuple[float, float] = (0.4, 2.0)
    key_elevation_deg: tuple[float, float] = (15.0, 85.0)  # key light above the ground plane
    fill_intensity: tuple[float, float] = (0.0, 0.8)
    rim_prob: float = 0.4  # chance of a third, shadowless light from behind
    rim_intensity: tuple[float, float] = (0.3, 1.2)
    light_tint_sigma: float = 0.12  # per-channel spread of the lights' colour
    exposure: tuple[float, float] = (0.6, 1.6)  # gain on the linear image (over 1 clips highlights)
    printed_ground_share: float = 0.3  # grounds printed like a poster or a cutting mat
    photo_backdrop_share: float = 0.7  # backdrops that are a photo-like colour field instead of a gradient


@dataclass
class Clutter:
    """One background object standing on the ground (world metres): a box turned about Z, an upright cylinder or
    a sphere."""

    kind: str  # "box" | "cylinder" | "sphere"
    centre: np.ndarray  # (2,) world x, y of its foot
    size: np.ndarray  # box: half extents (3,); cylinder: (radius, height, 0); sphere: (radius, 0, 0)
    angle: float  # box turn about Z (radians)
    material: Material
    print_look: PrintLook | None = None

    @property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """(centre (3,), radius) in the world, metres."""
        if self.kind == "box":
            return np.array([*self.centre, self.size[2]]), float(np.linalg.norm(self.size))
        if self.kind == "cylinder":
            r, h = self.size[0], self.size[1]
            return np.array([*self.centre, 0.5 * h]), float(np.hypot(r, 0.5 * h))
        r = self.size[0]
        return np.array([*self.centre, r]), float(r)


@dataclass
class Appearance:
    """The randomized look of one scan (everything but the geometry of the part)."""

    seed: int  # of the art generator (drawn once, so art is a pure function of the scan seed)
    art: bool  # the part carries OpenCV art inside its faces
    clutter: list[Clutter] = field(default_factory=list)
    backdrop_image: np.ndarray | None = None  # (H, W, 3) float32 linear, None: the scene's gradient
    exposure: float = 1.0
    info: dict = field(default_factory=dict)
    cfg: AppearanceConfig = field(default_factory=AppearanceConfig)


# ------------------------------------------------------------------------------------------------- framing


def project(K: np.ndarray, world_to_cam: np.ndarray, pts_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (n, 2) and depths z (n,) of world points (n, 3) metres."""
    cam = pts_world @ world_to_cam[:, :3].T + world_to_cam[:, 3]
    z = cam[:, 2]
    uv = np.stack([K[0, 0] * cam[:, 0] / z + K[0, 2], K[1, 1] * cam[:, 1] / z + K[1, 2]], axis=1)
    return uv, z


def frame_scene(
    scene: Scene, pts_rest_mm: np.ndarray, rng: np.random.Generator, cfg: FramingConfig = FramingConfig()
) -> tuple[Scene, dict]:
    """Move the camera (its orientation kept) so the part's projected extent is a drawn fraction of the image's
    smaller side and its silhouette box sits at a random place inside the image.

    `pts_rest_mm` (n, 3): points on the part's surface in the rest pose (millimetres), e.g. a coarse mesh's
    vertices. The extent is max(width, height) of their projections' bounding box. Returns the new scene and
    {target_extent, extent, distance_m, version}. Depth along the optical axis scales the extent by about 1 / z, the
    in-plane shift moves it by about f dx / z: a few updates converge to a fraction of a pixel. The shift is limited
    so the camera stays `cfg.min_sight_elevation_deg` above the part's centre (the part then sits lower in the image
    than drawn).
    """
    pts = pts_rest_mm @ scene.rest_to_world[:, :3].T + scene.rest_to_world[:, 3]
    rot = scene.world_to_cam[:, :3]
    eye = -rot.T @ scene.world_to_cam[:, 3]
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    w, h = scene.width, scene.height
    side = float(min(w, h))
    target = float(rng.uniform(*cfg.extent))
    place = rng.uniform(-1.0, 1.0, 2)  # where the box goes within the free room, -1 = left / top edge
    fx, fy = scene.K[0, 0], scene.K[1, 1]
    w2c = scene.world_to_cam
    for _ in range(cfg.iterations):
        uv, _z = project(scene.K, w2c, pts)
        ext = float(max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1])))
        zc = float((centre - eye) @ rot[2])
        z_new = max(zc * ext / (target * side), cfg.min_distance_m)
        eye = eye + rot[2] * (zc - z_new)
        w2c = np.hstack([rot, (-rot @ eye)[:, None]])
        uv, _z = project(scene.K, w2c, pts)
        lo, hi = uv.min(axis=0), uv.max(axis=0)
        room = np.maximum(0.5 * (np.array([w, h]) - (hi - lo)) - cfg.margin_px, 0.0)
        want = 0.5 * np.array([w - 1, h - 1]) + place * room
        du = want - 0.5 * (lo + hi)
        eye = eye - rot[0] * (du[0] * z_new / fx) - rot[1] * (du[1] * z_new / fy)
        eye = _keep_above(eye, rot, centre, cfg.min_sight_elevation_deg)
        w2c = np.hstack([rot, (-rot @ eye)[:, None]])
    uv, _z = project(scene.K, w2c, pts)
    ext = float(max(np.ptp(uv[:, 0]), np.ptp(uv[:, 1]))) / side
    dist = float(np.linalg.norm(centre - eye))
    info = {"target_extent": target, "extent": ext, "distance_m": dist, "version": FRAMING_VERSION}
    return replace(scene, world_to_cam=w2c, info={**scene.info, "distance_m": dist}), info


def _keep_above(eye: np.ndarray, rot: np.ndarray, centre: np.ndarray, min_elevation_deg: float) -> np.ndarray:
    """The camera centre `eye` (world, metres; world-to-camera rotation `rot`) moved along the image's vertical
    (camera -y: the part moves down in the image, its depth along the optical axis unchanged) until its height
    above `centre` is at least sin(min_elevation_deg) x that depth; `eye` itself when it already is."""
    zc = float((centre - eye) @ rot[2])
    need = centre[2] + np.sin(np.deg2rad(min_elevation_deg)) * zc - eye[2]
    rise = -rot[1, 2]  # height gained per metre moved along camera -y (> 0 for a camera looking down, not rolled
    # by 90 degrees)
    if need <= 0.0 or rise <= 1e-9:
        return eye
    return eye - rot[1] * (need / rise)


# ---------------------------------------------------------------------------------------------- appearance


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, np.float32)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _random_material(rng: np.random.Generator, cfg: AppearanceConfig, name: str | None = None) -> Material:
    """A random material: dark, shiny metal or any colour (matte to glossy)."""
    r = rng.random()
    if name == "dark" or (name is None and r < cfg.dark_share):
        albedo = rng.uniform(0.01, 0.08) * rng.uniform(0.7, 1.3, 3)
        return Material(albedo, float(rng.uniform(0.2, 1.0)), float(rng.uniform(10, 300)), "dark")
    if name == "shiny" or (name is None and r < cfg.dark_share + cfg.shiny_share):
        albedo = rng.uniform(0.25, 0.8) * np.clip(1 + rng.normal(0, 0.12, 3), 0.6, 1.3)
        return Material(albedo, float(rng.uniform(0.6, 1.6)), float(rng.uniform(40, 400)), "shiny")
    albedo = rng.uniform(0, 1, 3) ** rng.uniform(0.5, 2.5)
    return Material(albedo, float(rng.uniform(0.0, 0.5)), float(rng.uniform(3, 80)), "colour")


def _photo_field(rng: np.random.Generator, h: int, w: int) -> np.ndarray:
    """(h, w, 3) float32 linear colour field like a defocused photo: a few random colour cells, bicubic upsampled,
    with fine grain and a few hard-edged rectangles (shelves, boxes)."""
    gh, gw = int(rng.integers(2, 9)), int(rng.integers(2, 9))
    small = (rng.uniform(0, 1, (gh, gw, 3)) ** rng.uniform(0.8, 2.2)).astype(np.float32)
    img = cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)
    for _ in range(int(rng.integers(0, 5))):
        x0, y0 = int(rng.integers(0, w)), int(rng.integers(0, h))
        x1, y1 = x0 + int(rng.integers(w // 10 + 1, w // 2 + 2)), y0 + int(rng.integers(h // 10 + 1, h // 2 + 2))
        cv2.rectangle(img, (x0, y0), (x1, y1), tuple(float(v) for v in rng.uniform(0, 1, 3) ** 1.5), -1)
    img += rng.normal(0, 0.02, img.shape).astype(np.float32)
    return np.clip(img, 0.0, 1.0)


def sample_appearance(
    rng: np.random.Generator,
    scene: Scene,
    bbox_lo_mm: np.ndarray,
    bbox_hi_mm: np.ndarray,
    cfg: AppearanceConfig = AppearanceConfig(),
) -> tuple[Scene, Appearance]:
    """Draw a random look for `scene` (material, lights, ground, backdrop, clutter, art, exposure) from `rng`.

    `bbox_lo_mm`, `bbox_hi_mm`: the part's rest-pose bounding box (millimetres), so clutter stands clear of it.
    Returns the scene with its material, lights, ground, backdrop and print replaced, and the extras."""
    size = scene.part_size_m
    corners = np.array(
        [
            [x, y, z]
            for x in (bbox_lo_mm[0], bbox_hi_mm[0])
            for y in (bbox_lo_mm[1], bbox_hi_mm[1])
            for z in (bbox_lo_mm[2], bbox_hi_mm[2])
        ],
        float,
    )
    corners = corners @ scene.rest_to_world[:, :3].T + scene.rest_to_world[:, 3]
    material = _random_material(rng, cfg)
    art = bool(rng.random() < cfg.art_share)
    look = None
    if art and rng.random() < cfg.world_print_share:  # world-space print as well (packaging-like)
        look = _sample_print(rng, size, material.albedo)
    rot = scene.world_to_cam[:, :3]

    def tint() -> np.ndarray:
        """A light's RGB tint: 1 + a normal draw per channel, clipped to [0.5, 1.5]."""
        return np.clip(1.0 + rng.normal(0, cfg.light_tint_sigma, 3), 0.5, 1.5)

    key_el, key_az = np.deg2rad(rng.uniform(*cfg.key_elevation_deg)), rng.uniform(0, 2 * np.pi)
    key_dir = np.array([np.cos(key_el) * np.cos(key_az), np.cos(key_el) * np.sin(key_az), np.sin(key_el)])
    lights = [Light(rot @ key_dir, tint() * rng.uniform(*cfg.key_intensity), True)]
    fill_dir = rng.normal(size=3)
    fill_dir[2] = abs(fill_dir[2]) + 0.2
    lights.append(Light(rot @ (fill_dir / np.linalg.norm(fill_dir)), tint() * rng.uniform(*cfg.fill_intensity), False))
    if rng.random() < cfg.rim_prob:  # from behind the part, seen from the camera
        back = -rot[2] + np.array([0.0, 0.0, rng.uniform(0.2, 1.0)])
        lights.append(Light(rot @ (back / np.linalg.norm(back)), tint() * rng.uniform(*cfg.rim_intensity), False))
    ambient = tint() * rng.uniform(*cfg.ambient)

    kind = str(
        rng.choice(
            ["concrete", "wood", "tiles", "plain", "printed"],
            p=[*([(1 - cfg.printed_ground_share) / 4] * 4), cfg.printed_ground_share],
        )
    )
    base = rng.uniform(0.0, 1.0, 3) ** rng.uniform(0.6, 2.5)
    other = np.clip(base * rng.uniform(0.3, 1.7, 3) + rng.normal(0, 0.1, 3), 0.005, 0.95)
    gscale = float(size * rng.uniform(0.3, 2.5)) if kind != "tiles" else float(rng.uniform(0.02, 0.3))
    gprint = _sample_print(rng, float(size * rng.uniform(0.5, 2.0)), base) if kind == "printed" else None
    ground = GroundLook(
        kind,
        base,
        other,
        gscale,
        float(rng.uniform(0, np.pi)),
        int(rng.integers(0, 2**31 - 1)),
        float(rng.uniform(0.0, 0.6)),
        gprint,
    )
    backdrop_image = _photo_field(rng, scene.height, scene.width) if rng.random() < cfg.photo_backdrop_share else None
    wall = rng.uniform(0.0, 1.0, 3) ** rng.uniform(0.6, 2.0)
    backdrop = np.stack([wall, np.clip(wall * rng.uniform(0.4, 1.3), 0, 1)])
    clutter = _place_clutter(rng, scene, corners, cfg)
    app = Appearance(
        int(rng.integers(0, 2**31 - 1)), art, clutter, backdrop_image, float(rng.uniform(*cfg.exposure)), cfg=cfg
    )
    app.info = {
        "material": material.name,
        "art": art,
        "world_print": look is not None,
        "ground": kind,
        "backdrop": "photo" if backdrop_image is not None else "gradient",
        "lights": len(lights),
        "clutter": [c.kind for c in clutter],
        "exposure": app.exposure,
    }
    if look is not None:
        material = Material(material.albedo, material.specular, material.shininess, "printed")
    scene = replace(
        scene, material=material, lights=lights, ambient=ambient, ground=ground, backdrop=backdrop, print_look=look
    )
    return scene, app


def _place_clutter(rng: np.random.Generator, scene: Scene, corners: np.ndarray, cfg: AppearanceConfig) -> list[Clutter]:
    """Objects on the ground beside the part (world bbox corners (8, 3), metres), clear of its footprint, none
    whose bounding sphere could hide a part pixel (its image disc overlaps the part's image box while it is
    nearer than the part's far side)."""
    size = scene.part_size_m
    part_radius_m = float(np.hypot(corners[:, 0], corners[:, 1]).max())
    uv, z = project(scene.K, scene.world_to_cam, corners)
    plo, phi = uv.min(axis=0), uv.max(axis=0)
    z_far = float(z.max())
    out: list[Clutter] = []
    for _ in range(int(rng.integers(cfg.clutter[0], cfg.clutter[1] + 1))):
        for _try in range(cfg.clutter_tries):
            s = size * rng.uniform(*cfg.clutter_size_rel)
            kind = str(rng.choice(["box", "cylinder", "sphere"], p=list(cfg.clutter_kinds)))
            if kind == "box":
                dims = np.array([rng.uniform(0.2, 0.5), rng.uniform(0.2, 0.5), rng.uniform(0.15, 0.5)]) * s
                foot = float(np.hypot(dims[0], dims[1]))
            elif kind == "cylinder":
                dims = np.array([rng.uniform(0.15, 0.4) * s, rng.uniform(0.3, 1.0) * s, 0.0])
                foot = float(dims[0])
            else:
                dims = np.array([rng.uniform(0.15, 0.35) * s, 0.0, 0.0])
                foot = float(dims[0])
            r = part_radius_m + foot + size * rng.uniform(*cfg.clutter_gap_rel)
            a = rng.uniform(0, 2 * np.pi)
            obj = Clutter(
                kind,
                np.array([r * np.cos(a), r * np.sin(a)]),
                dims,
                float(rng.uniform(0, np.pi)),
                _random_material(rng, cfg),
            )
            if any(np.hypot(*(obj.centre - o.centre)) < foot + o.bounding_sphere[1] for o in out):
                continue
            c, rad = obj.bounding_sphere
            (cu, cv), cz = (v[0] for v in project(scene.K, scene.world_to_cam, c[None]))
            if cz - rad <= 0.05:  # at or behind the camera
                continue
            rpx = scene.K[0, 0] * rad / max(cz - rad, 1e-6)
            if cu + rpx < 0 or cu - rpx > scene.width or cv + rpx < 0 or cv - rpx > scene.height:
                continue  # out of view: no use
            overlaps = (cu + rpx > plo[0]) and (cu - rpx < phi[0]) and (cv + rpx > plo[1]) and (cv - rpx < phi[1])
            if overlaps and cz - rad < z_far:
                continue
            if rng.random() < cfg.clutter_print_prob:
                obj.print_look = _sample_print(rng, s, obj.material.albedo)
            out.append(obj)
            break
    return out


# ----------------------------------------------------------------------------------------------- clutter hits


def intersect_clutter(
    objs: list[Clutter], eye: np.ndarray, dirs_world: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest hit of rays eye + t d (world, unit d (n, 3)) with the clutter: t (n,) metres (inf: none), world
    normals (n, 3) and the object index (n,) (-1: none)."""
    n = len(dirs_world)
    t_best = np.full(n, np.inf)
    nrm = np.zeros((n, 3))
    which = np.full(n, -1, np.int64)
    for k, obj in enumerate(objs):
        # Only rays that cross the object's bounding sphere (an object covers a small part of the image).
        c, r = obj.bounding_sphere
        oc = c - eye
        along = dirs_world @ oc
        cand = np.flatnonzero((along > 0) & (oc @ oc - along * along < r * r))
        if not len(cand):
            continue
        t, nn = _hit_one(obj, eye, dirs_world[cand])
        better = t < t_best[cand]
        sel = cand[better]
        t_best[sel], nrm[sel], which[sel] = t[better], nn[better], k
    return t_best, nrm, which


def _hit_one(obj: Clutter, eye: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = len(d)
    t = np.full(n, np.inf)
    nrm = np.zeros((n, 3))
    o = eye - np.array([*obj.centre, 0.0])
    if obj.kind == "sphere":
        r = obj.size[0]
        oc = o - np.array([0.0, 0.0, r])
        b = d @ oc
        disc = b * b - (oc @ oc - r * r)
        ok = disc > 0
        tt = -b[ok] - np.sqrt(disc[ok])
        good = tt > 0
        idx = np.flatnonzero(ok)[good]
        t[idx] = tt[good]
        nrm[idx] = (oc + d[idx] * t[idx, None]) / r
        return t, nrm
    if obj.kind == "cylinder":
        r, hgt = obj.size[0], obj.size[1]
        a = d[:, 0] ** 2 + d[:, 1] ** 2
        b = d[:, 0] * o[0] + d[:, 1] * o[1]
        c = o[0] ** 2 + o[1] ** 2 - r * r
        with np.errstate(divide="ignore", invalid="ignore"):
            disc = b * b - a * c
            ts = (-b - np.sqrt(np.maximum(disc, 0))) / a
            zs = o[2] + ts * d[:, 2]
            side = (disc > 0) & (ts > 0) & (zs >= 0) & (zs <= hgt)
            tc = (hgt - o[2]) / d[:, 2]
            pc = o[None, :2] + tc[:, None] * d[:, :2]
            cap = (tc > 0) & (np.einsum("ij,ij->i", pc, pc) <= r * r) & (o[2] > hgt)
        t = np.where(side, ts, np.inf)
        t = np.where(cap & (tc < t), tc, t)
        is_cap = cap & (t == tc)
        p = o + d * np.where(np.isfinite(t), t, 0)[:, None]
        nrm = np.where(
            is_cap[:, None], np.array([0.0, 0.0, 1.0]), np.stack([p[:, 0] / r, p[:, 1] / r, np.zeros(n)], axis=1)
        )
        return t, nrm
    # box turned by `angle` about Z, standing on z = 0: slabs in its own frame
    cs, sn = np.cos(obj.angle), np.sin(obj.angle)
    R = np.array([[cs, sn, 0.0], [-sn, cs, 0.0], [0.0, 0.0, 1.0]])  # world -> box
    ob = R @ (o - np.array([0.0, 0.0, obj.size[2]]))
    db = d @ R.T
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (-obj.size - ob) / db
        t2 = (obj.size - ob) / db
    tmin = np.nan_to_num(np.minimum(t1, t2), nan=-np.inf)
    tmax = np.nan_to_num(np.maximum(t1, t2), nan=np.inf)
    t_in = tmin.max(axis=1)
    t_out = tmax.min(axis=1)
    ok = (t_in <= t_out) & (t_in > 0)
    t = np.where(ok, t_in, np.inf)
    axis = tmin.argmax(axis=1)
    nb = np.zeros((n, 3))
    nb[np.arange(n), axis] = -np.sign(db[np.arange(n), axis])
    return t, nb @ R  # box -> world


# ------------------------------------------------------------------------------------------------------- art


def _ink(rng: np.random.Generator) -> tuple[float, float, float]:
    """A random ink colour in sRGB [0, 1] (saturated, dark or light)."""
    c = rng.uniform(0, 1, 3)
    c = c ** rng.uniform(0.3, 3.0)
    if rng.random() < 0.3:  # black or white ink
        c = np.full(3, rng.choice([rng.uniform(0.0, 0.1), rng.uniform(0.85, 1.0)]))
    return tuple(float(v) for v in c)


_FONTS = (
    cv2.FONT_HERSHEY_SIMPLEX,
    cv2.FONT_HERSHEY_DUPLEX,
    cv2.FONT_HERSHEY_COMPLEX,
    cv2.FONT_HERSHEY_TRIPLEX,
    cv2.FONT_HERSHEY_PLAIN,
    cv2.FONT_HERSHEY_SCRIPT_SIMPLEX,
)
_CHARS = "ABCDEFGHJKLMNPRSTUVWXYZ0123456789-/."


def _draw_item(rng: np.random.Generator, canvas: np.ndarray, cover: np.ndarray, box: tuple[int, int, int, int]) -> str:
    """Draw one art item (sRGB colours) into `canvas` (h, w, 3) and mark it in `cover` (h, w) uint8, inside the
    face's bounding box `box` = (x0, y0, x1, y1). Returns its kind."""
    x0, y0, x1, y1 = box
    bw, bh = x1 - x0, y1 - y0
    s = max(min(bw, bh), 4)
    kind = str(rng.choice(["text", "stripes", "logo", "photo"], p=[0.3, 0.25, 0.25, 0.2]))
    cx, cy = int(rng.integers(x0, x1)), int(rng.integers(y0, y1))
    col = _ink(rng)
    layer = np.zeros_like(cover)
    if kind == "text":
        font = _FONTS[int(rng.integers(len(_FONTS)))]
        txt = "".join(rng.choice(list(_CHARS), int(rng.integers(2, 10))))
        scale = max(s * rng.uniform(0.1, 0.35) / 22.0, 0.3)
        thick = int(rng.integers(1, max(2, int(3 * scale)) + 1))
        (tw, th), _ = cv2.getTextSize(txt, font, scale, thick)
        img = np.zeros((th * 2 + 4, tw + 4), np.uint8)
        cv2.putText(img, txt, (2, th + 2), font, scale, 255, thick, cv2.LINE_8)
        ang = float(rng.uniform(-90, 90)) if rng.random() < 0.5 else 0.0
        M = cv2.getRotationMatrix2D((img.shape[1] / 2, img.shape[0] / 2), ang, 1.0)
        M[:, 2] += (cx - img.shape[1] / 2, cy - img.shape[0] / 2)
        layer = cv2.warpAffine(img, M, (cover.shape[1], cover.shape[0]), flags=cv2.INTER_NEAREST)
    elif kind == "stripes":
        ang = rng.uniform(0, np.pi)
        width = max(2, int(s * rng.uniform(0.03, 0.2)))
        period = width * rng.uniform(1.5, 4.0)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        along = (xx - cx) * np.cos(ang) + (yy - cy) * np.sin(ang)
        band = np.mod(along, period) < width
        if rng.random() < 0.5:  # a band of stripes, not the whole face
            across = -(xx - cx) * np.sin(ang) + (yy - cy) * np.cos(ang)
            band &= np.abs(across) < s * rng.uniform(0.1, 0.4)
        layer[y0:y1, x0:x1] = band.astype(np.uint8) * 255
    elif kind == "logo":
        for _ in range(int(rng.integers(1, 4))):
            r = max(2, int(s * rng.uniform(0.05, 0.3)))
            px, py = cx + int(rng.integers(-r, r + 1)), cy + int(rng.integers(-r, r + 1))
            shape = rng.integers(4)
            if shape == 0:
                cv2.circle(layer, (px, py), r, 255, -1 if rng.random() < 0.6 else max(1, r // 4))
            elif shape == 1:
                cv2.ellipse(
                    layer,
                    (px, py),
                    (r, max(1, int(r * rng.uniform(0.3, 1.0)))),
                    float(rng.uniform(0, 180)),
                    0,
                    360,
                    255,
                    -1,
                )
            elif shape == 2:
                k = int(rng.integers(3, 9))
                ang = np.sort(rng.uniform(0, 2 * np.pi, k))
                rad = r * rng.uniform(0.5, 1.0, k)
                poly = np.stack([px + rad * np.cos(ang), py + rad * np.sin(ang)], axis=1).astype(np.int32)
                cv2.fillPoly(layer, [poly], 255)
            else:
                cv2.rectangle(layer, (px - r, py - r // 2), (px + r, py + r // 2), 255, -1)
    else:  # photo-like patch: a colour field in a hard-edged rectangle
        pw, ph = max(3, int(bw * rng.uniform(0.2, 0.7))), max(3, int(bh * rng.uniform(0.2, 0.7)))
        px0, py0 = int(np.clip(cx - pw // 2, 0, cover.shape[1] - 1)), int(np.clip(cy - ph // 2, 0, cover.shape[0] - 1))
        px1, py1 = min(px0 + pw, cover.shape[1]), min(py0 + ph, cover.shape[0])
        photo = _photo_field(rng, py1 - py0, px1 - px0)
        canvas[py0:py1, px0:px1] = np.where(
            cover[py0:py1, px0:px1, None] > 0, canvas[py0:py1, px0:px1], photo ** (1 / 2.2)
        )
        layer[py0:py1, px0:px1] = 255
        cover |= layer
        return kind
    on = layer > 0
    canvas[on] = col
    cover |= layer
    return kind


def draw_art(app: Appearance, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Printed art on the part, drawn with OpenCV in the image and clipped to face regions.

    `faces` (H, W) uint16 face ids (0 = no face). Returns the art's linear albedo (H, W, 3) float32, where it
    applies (H, W) bool (only ever on pixels of one face each: art never crosses a face boundary, so every colour
    edge it makes lies inside one surface), and the kinds drawn. Deterministic given `app.seed`."""
    rng = np.random.default_rng([app.seed, 3])
    cfg = app.cfg
    h, w = faces.shape
    albedo = np.zeros((h, w, 3), np.float32)
    where = np.zeros((h, w), bool)
    kinds: list[str] = []
    if not app.art:
        return albedo, where, kinds
    from scipy import ndimage

    for k, sl in enumerate(ndimage.find_objects(faces.astype(np.int32))):
        if sl is None:
            continue
        mask = faces[sl] == k + 1  # the face within its bounding box
        if int(mask.sum()) < cfg.art_min_face_px or rng.random() > cfg.art_face_prob:
            continue
        bh, bw = mask.shape
        canvas = np.zeros((bh, bw, 3), np.float32)
        cover = np.zeros((bh, bw), np.uint8)
        for _ in range(int(rng.integers(cfg.art_items[0], cfg.art_items[1] + 1))):
            kinds.append(_draw_item(rng, canvas, cover, (0, 0, bw, bh)))
        on = mask & (cover > 0)
        albedo[sl][on] = _srgb_to_linear(canvas[on])
        where[sl] |= on
    return albedo, where, kinds
