"""Ray-cast rendering of a posed part on a textured ground: face ids, exact clean depth, normals and colour.

Everything is in the camera frame (OpenCV, metres); rays start at the camera centre through pixel centres. The
part mesh gives which face a pixel sees; the depth then comes from intersecting the pixel's ray with that face's
exact primitive (`intersect.py`), so it lies on the primitive up to float64 rounding. Shading is Lambert +
Blinn-Phong in linear RGB with one shadow-casting key light, written out as sRGB.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import cv2
import numpy as np
from embreex import rtcore_scene
from embreex.mesh_construction import TriangleMesh
from pyfastnoiselite.pyfastnoiselite import CellularReturnType, FastNoiseLite, FractalType, NoiseType

from v2c.synth.intersect import intersect_primitive, rows_dot
from v2c.synth.scene import GroundLook, PrintLook, Scene

if TYPE_CHECKING:
    from numpy.typing import DTypeLike

    from v2c.synth.appearance import Appearance

ANALYTIC = ("plane", "cylinder", "cone", "sphere", "torus")
GROUND_SHININESS = 8.0  # Blinn-Phong exponent of the ground


@dataclass(frozen=True)
class RenderConfig:
    """Rendering tolerances (units in the names)."""

    max_shift_factor: float = 20.0  # analytic hit kept within this many mesh deflections of the mesh hit
    # (along the ray: the deflection grows as 1 / cos(incidence) at grazing angles)
    max_range_m: float = 4.0  # farther ground is no reading (and fades into the backdrop)
    shadow_offset_factor: float = 3.0  # shadow rays start this many deflections off the surface
    texture_step_px: int = 2  # ground texture evaluated on this pixel lattice and upsampled


@dataclass
class Render:
    """Noise-free rendering (all (H, W) unless stated)."""

    faces: np.ndarray  # uint16, 1 + face index, 0 = ground/background
    depth: np.ndarray  # float64 metres (z), 0 = no reading; exact on the face primitives
    cos_incidence: np.ndarray  # float32 |cos| of the angle between the pixel ray and the surface normal (0 = none)
    color: np.ndarray  # (H, W, 3) float32 linear RGB, not clipped
    dropped: int  # part pixels whose ray missed the exact surface (grazing silhouettes): set to no reading


def pixel_rays(
    K: np.ndarray, width: int, height: int, index: np.ndarray | None = None, dtype: DTypeLike = np.float64
) -> np.ndarray:
    """Unit ray directions (n, 3) through pixel centres (camera frame), for all pixels in row-major order or for
    the flat pixel indices `index`."""
    if index is None:
        u = np.tile(np.arange(width, dtype=dtype), height)
        v = np.repeat(np.arange(height, dtype=dtype), width)
    else:
        u, v = (index % width).astype(dtype), (index // width).astype(dtype)
    d = np.empty((len(u), 3), dtype)
    d[:, 0] = (u - K[0, 2]) / K[0, 0]
    d[:, 1] = (v - K[1, 2]) / K[1, 1]
    d[:, 2] = 1.0
    d /= np.sqrt(np.einsum("ij,ij->i", d, d))[:, None]
    return d


def _embree_scene(vertices: np.ndarray, triangles: np.ndarray) -> rtcore_scene.EmbreeScene:
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, vertices.astype(np.float32), triangles.astype(np.int32))
    return scene


def render(
    scene: Scene,
    vertices: np.ndarray,
    triangles: np.ndarray,
    face_of_triangle: np.ndarray,
    primitives: list[dict],
    deflection_m: float,
    cfg: RenderConfig = RenderConfig(),
    appearance: Appearance | None = None,
) -> Render:
    """Render the part mesh (camera frame, metres) with exact depth on its primitives.

    `primitives[i]` is face i's primitives.json entry ("type", "params"); `deflection_m` is the mesh's linear
    deflection, which bounds how far an analytic hit may be from the mesh hit. Full-image arrays are kept 1-D
    and float32 where precision allows: numpy here is bound by memory traffic. `appearance` (appearance.py) adds
    printed art inside the faces (albedo only), clutter objects (background: face 0, their own depth), a
    photo-like backdrop and an exposure gain; None renders exactly as before it existed.
    """
    h, w = scene.height, scene.width
    n = h * w
    dirs32 = pixel_rays(scene.K, w, h, dtype=np.float32)
    ebr = _embree_scene(vertices, triangles)
    prim = ebr.run(np.zeros((n, 3), np.float32), dirs32)
    hit = np.flatnonzero(prim >= 0)
    tri = prim[hit]
    face = face_of_triangle[tri].astype(np.int64)

    # Part pixels: mesh hit from the triangle's plane (float64), then the exact primitive hit.
    d = pixel_rays(scene.K, w, h, hit)
    v0 = vertices[triangles[tri, 0]]
    tri_n = np.cross(vertices[triangles[tri, 1]] - v0, vertices[triangles[tri, 2]] - v0)
    tri_n /= np.maximum(np.linalg.norm(tri_n, axis=1, keepdims=True), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_mesh = np.einsum("ij,ij->i", tri_n, v0) / np.einsum("ij,ij->i", tri_n, d)
    t_mesh = np.where(np.isfinite(t_mesh), t_mesh, np.linalg.norm(v0, axis=1))  # degenerate triangles
    tri_n *= -np.sign(np.einsum("ij,ij->i", tri_n, d))[:, None]  # facing the camera
    t = t_mesh.copy()
    nrm = tri_n.copy()
    order = np.argsort(face, kind="stable")
    fids, starts = np.unique(face[order], return_index=True)
    for fid, sel in zip(fids, np.split(order, starts[1:]), strict=True):
        entry = primitives[fid]
        if entry["type"] in ANALYTIC:
            t[sel], nrm[sel] = intersect_primitive(
                entry["type"], entry["params"], d[sel], t_mesh[sel], cfg.max_shift_factor * deflection_m
            )
    # A ray that hits the mesh but misses the exact surface (grazing silhouettes) gets no reading and no face,
    # but is still coloured like the part from the mesh hit.
    missed = ~np.isfinite(t)
    t[missed], nrm[missed] = t_mesh[missed], tri_n[missed]
    good = hit[~missed]

    depth = np.zeros(n)
    faces = np.zeros(n, np.uint16)
    cos_inc = np.zeros(n, np.float32)
    depth[good] = (t * d[:, 2])[~missed]
    faces[good] = face[~missed] + 1
    cos_inc[hit] = np.abs(np.einsum("ij,ij->i", nrm, d))

    # Ground plane z_world = 0, in the camera frame up . p = up . trans.
    rot, trans = scene.world_to_cam[:, :3], scene.world_to_cam[:, 3]
    up = rot[:, 2]
    d_up = rows_dot(dirs32, up.astype(np.float32))
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ground = (up @ trans) / d_up
    ground_mask = (prim < 0) & (t_ground > 0) & np.isfinite(t_ground)
    clutter_px = np.zeros(0, np.int64)
    if appearance is not None and appearance.clutter:
        from v2c.synth.appearance import intersect_clutter

        # Clutter only where the part is not (it is placed so as not to hide the part; this keeps the part's
        # face ids and depth those of the plain scan even where a placement bound was loose).
        free = np.flatnonzero(prim < 0)
        eye = -rot.T @ trans
        t_c, n_c, which = intersect_clutter(appearance.clutter, eye, dirs32[free].astype(np.float64) @ rot)
        t_g = np.where(ground_mask[free], t_ground[free], np.inf)
        near = np.isfinite(t_c) & (t_c < t_g)
        clutter_px, t_c, n_c, which = free[near], t_c[near], n_c[near], which[near]
        ground_mask[clutter_px] = False
    ground = np.flatnonzero(ground_mask)
    z_ground = t_ground[ground] * dirs32[ground, 2]
    in_range = ground[z_ground <= cfg.max_range_m]
    depth[in_range] = z_ground[z_ground <= cfg.max_range_m]
    cos_inc[ground] = np.abs(d_up[ground])
    if len(clutter_px):
        z_c = t_c * dirs32[clutter_px, 2]
        keep = z_c <= cfg.max_range_m
        depth[clutter_px[keep]] = z_c[keep]
        n_cam = n_c @ rot.T  # world -> camera
        cos_inc[clutter_px] = np.abs(np.einsum("ij,ij->i", n_cam, dirs32[clutter_px]))

    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    sphere = (centre, float(np.linalg.norm(vertices - centre, axis=1).max()))
    color = np.zeros((n, 3), np.float32)
    ground_n = -up if (trans @ up) > 0 else up  # facing the camera
    albedo_g = ground_albedo(scene, cfg).reshape(-1, 3)[ground]
    color[ground] = _shade(
        scene,
        ebr,
        dirs32[ground],
        t_ground[ground],
        ground_n,
        albedo_g,
        scene.ground.specular,
        GROUND_SHININESS,
        sphere,
        deflection_m,
        cfg,
    )
    albedo_p = scene.material.albedo
    if scene.print_look is not None:  # printed part: albedo from the world position of each hit
        world_p = (d * t[:, None] - trans) @ rot
        albedo_p = print_texture(scene.print_look, world_p).astype(np.float32)
    if appearance is not None and appearance.art:
        from v2c.synth.appearance import draw_art

        art, on, kinds = draw_art(appearance, faces.reshape(h, w))
        appearance.info["art_kinds"] = sorted(set(kinds))
        appearance.info["art_px"] = int(on.sum())
        sel = on.reshape(-1)[hit]
        albedo_p = np.array(np.broadcast_to(albedo_p, (len(hit), 3)), np.float32)
        albedo_p[sel] = art.reshape(-1, 3)[hit[sel]]
    for k, obj in enumerate(appearance.clutter if appearance is not None else []):
        sel = np.flatnonzero(which == k) if len(clutter_px) else np.zeros(0, np.int64)
        if not len(sel):
            continue
        px = clutter_px[sel]
        alb = obj.material.albedo
        if obj.print_look is not None:
            alb = print_texture(obj.print_look, eye + (dirs32[px].astype(np.float64) @ rot) * t_c[sel, None])
        color[px] = _shade(
            scene,
            ebr,
            dirs32[px],
            t_c[sel],
            n_cam[sel].astype(np.float32),
            alb,
            obj.material.specular,
            obj.material.shininess,
            sphere,
            deflection_m,
            cfg,
        )
    color[hit] = _shade(
        scene,
        ebr,
        d.astype(np.float32),
        t,
        nrm,
        albedo_p,
        scene.material.specular,
        scene.material.shininess,
        sphere,
        deflection_m,
        cfg,
    )
    # Backdrop: a vertical gradient where rays miss everything; far ground fades into it.
    far_mask = prim < 0
    far_mask[in_range] = False
    far_mask[clutter_px] = False
    far = np.flatnonzero(far_mask)
    if len(far):
        s = np.clip(0.5 + 1.5 * d_up[far], 0.0, 1.0)[:, None]
        back = (scene.backdrop[1] * (1 - s) + scene.backdrop[0] * s).astype(np.float32)
        if appearance is not None and appearance.backdrop_image is not None:
            back = appearance.backdrop_image.reshape(-1, 3)[far]
        fade = ground_mask[far][:, None]
        color[far] = np.where(fade, np.float32(0.5) * (color[far] + back), back)
    if appearance is not None:
        color *= np.float32(appearance.exposure)
    return Render(
        faces.reshape(h, w), depth.reshape(h, w), cos_inc.reshape(h, w), color.reshape(h, w, 3), int(missed.sum())
    )


def _shadow_candidates(
    dirs: np.ndarray, t: np.ndarray, light: np.ndarray, sphere: tuple[np.ndarray, float]
) -> np.ndarray:
    """Bool (n,): the shadow ray from t * dirs (float32) towards `light` crosses the part's bounding sphere."""
    c, r = sphere[0].astype(np.float32), np.float32(sphere[1])
    # m = c - p with p = t d: m.l = c.l - t (d.l); |m|^2 = |c|^2 - 2 t (d.c) + t^2 (|d| = 1).
    b = c @ light - t * rows_dot(dirs, light)
    m2 = (c @ c) - np.float32(2.0) * t * rows_dot(dirs, c) + t * t
    return (m2 < r * r) | ((b > 0) & (b * b - (m2 - r * r) > 0))


def _shade(
    scene: Scene,
    ebr: rtcore_scene.EmbreeScene,
    dirs: np.ndarray,
    t: np.ndarray,
    normals: np.ndarray,
    albedo: np.ndarray,
    specular: float,
    shininess: float,
    sphere: tuple[np.ndarray, float],
    deflection_m: float,
    cfg: RenderConfig,
) -> np.ndarray:
    """Linear RGB (n, 3) float32 of surface points t * dirs (dirs (n, 3) float32, t metres): Lambert +
    Blinn-Phong; the key light's shadows are cast by the part.

    `normals` is (n, 3) or one (3,) normal for all points; `albedo` is (n, 3) or one (3,) colour. Everything runs
    in float32 on 1-D arrays where possible (n.h = (n.l + n.v) / |l + v| with |l + v|^2 = 2 + 2 l.v), and shadow
    rays are traced only where they cross the part's bounding sphere: numpy is memory-bound on this machine.
    """
    f32 = np.float32
    t = t.astype(f32)
    normals = np.asarray(normals, f32)
    per_point = normals.ndim == 2
    n_dot_v = -(np.einsum("ij,ij->i", normals, dirs) if per_point else rows_dot(dirs, normals))
    weights_d = np.zeros((len(dirs), len(scene.lights)), f32)
    weights_s = np.zeros((len(dirs), len(scene.lights)), f32)
    for k, light in enumerate(scene.lights):
        ldir = light.direction.astype(f32)
        n_dot_l = rows_dot(normals, ldir) if per_point else np.full(len(dirs), normals @ ldir, f32)
        vis = n_dot_l > 0
        if light.shadow:
            idx = np.flatnonzero(vis & _shadow_candidates(dirs, t, ldir, sphere))
            if len(idx):
                nrm_i = normals[idx] if per_point else normals
                origin = dirs[idx] * t[idx, None] + nrm_i * f32(cfg.shadow_offset_factor * deflection_m)
                ray_dir = np.ascontiguousarray(np.broadcast_to(ldir, (len(idx), 3)))
                occl = ebr.run(origin, ray_dir, query="OCCLUDED")
                vis[idx[occl != -1]] = False  # embree answers -1 for unoccluded rays
        n_dot_h = (n_dot_l + n_dot_v) / np.sqrt(np.maximum(f32(2.0) - f32(2.0) * rows_dot(dirs, ldir), f32(1e-12)))
        lobe = np.exp(f32(shininess) * np.log(np.clip(n_dot_h, f32(1e-6), f32(1.0))))  # exp-log: no denormals
        weights_d[:, k] = np.where(vis, n_dot_l, f32(0.0))
        weights_s[:, k] = np.where(vis, f32(specular) * lobe, f32(0.0))
    colors = np.stack([lt.color for lt in scene.lights]).astype(f32)
    diffuse = np.einsum("nk,kc->nc", weights_d, colors) + scene.ambient.astype(f32)
    return np.asarray(albedo, f32) * diffuse + np.einsum("nk,kc->nc", weights_s, colors)


def ground_albedo(scene: Scene, cfg: RenderConfig) -> np.ndarray:
    """(H, W, 3) float32 linear albedo of the ground plane seen through every pixel (also behind the part),
    evaluated every `texture_step_px` pixels and bilinearly upsampled (the texture is smooth at that scale)."""
    step = cfg.texture_step_px
    hs, ws = -(-scene.height // step), -(-scene.width // step)
    u = np.arange(ws) * step + 0.5 * (step - 1)
    v = np.arange(hs) * step + 0.5 * (step - 1)
    K = scene.K
    uu, vv = np.meshgrid((u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1])
    rays = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)], axis=1)
    rot, trans = scene.world_to_cam[:, :3], scene.world_to_cam[:, 3]
    up = rot[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.abs((up @ trans) / rows_dot(rays, up))  # rays above the horizon get a mirrored point: unused
    t = np.minimum(np.nan_to_num(t, nan=0.0, posinf=0.0), 1e3)
    world = np.einsum("ij,jk->ik", rays * t[:, None] - trans, rot)
    tex = ground_texture(scene.ground, world[:, 0], world[:, 1]).astype(np.float32).reshape(hs, ws, 3)
    tex = cv2.resize(tex, (ws * step, hs * step), interpolation=cv2.INTER_LINEAR)
    return tex[: scene.height, : scene.width]


def ground_texture(look: GroundLook, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Procedural albedo (n, 3) of the ground at world coordinates (x, y) in metres."""
    if look.kind == "printed" and look.print_look is not None:  # a poster or cutting mat (appearance.py)
        return print_texture(look.print_look, np.stack([x, y, np.zeros_like(x)], axis=1))
    c, s = np.cos(look.angle), np.sin(look.angle)
    u = (c * x + s * y) / look.scale_m
    v = (-s * x + c * y) / look.scale_m
    noise = FastNoiseLite(look.seed)
    noise.noise_type = NoiseType.NoiseType_OpenSimplex2
    noise.fractal_type = FractalType.FractalType_FBm
    noise.fractal_octaves = 4
    noise.frequency = 1.0
    if look.kind == "wood":
        warp = _fbm(noise, u * 0.3, v * 2.0)
        rings = 0.5 + 0.5 * np.sin(2 * np.pi * (v * 1.5 + 1.5 * warp))
        mix = rings**3
    elif look.kind == "tiles":
        grout = np.minimum(np.abs(u - np.round(u)), np.abs(v - np.round(v))) < 0.03
        checker = (np.floor(u) + np.floor(v)) % 2
        mix = np.where(grout, 1.0, 0.15 * checker + 0.1 * _fbm(noise, u * 8, v * 8))
    elif look.kind == "concrete":
        mix = 0.5 + 0.5 * _fbm(noise, u * 2, v * 2)
    else:
        mix = 0.15 * (0.5 + 0.5 * _fbm(noise, u, v))
    mix = np.clip(mix, 0.0, 1.0)[:, None]
    return look.color_a * (1 - mix) + look.color_b * mix


def print_texture(look: PrintLook, p: np.ndarray) -> np.ndarray:
    """Albedo (n, 3) of a printed part at world points p (n, 3), metres: flat inks with sharp edges."""
    q = p / look.scale_m
    noise = FastNoiseLite(look.seed)
    noise.frequency = 1.0
    k = len(look.palette)
    along = q @ look.direction
    if look.kind == "blocks":
        noise.noise_type = NoiseType.NoiseType_Cellular
        noise.cellular_return_type = CellularReturnType.CellularReturnType_CellValue
        v = 0.5 + 0.5 * np.asarray(noise.gen_from_coords(q.T.astype(np.float32)), float)
    elif look.kind == "stripes":
        v = (np.floor(along) % k + 0.5) / k
    else:
        noise.noise_type = NoiseType.NoiseType_OpenSimplex2
        noise.fractal_type = FractalType.FractalType_FBm
        noise.fractal_octaves = 3
        v = 0.5 + 0.5 * np.asarray(
            noise.gen_from_coords((q * (0.05 if look.kind == "text" else 1.0)).T.astype(np.float32)), float
        )
        v = np.clip((v - 0.5) * 2.5 + 0.5, 0.0, 0.999)
    idx = np.clip((v * k).astype(int), 0, k - 1)
    if look.kind == "text":  # lines of fine marks on the regions of ink 1 and up
        marks = (np.sin(2 * np.pi * along) > 0.3) & (np.sin(7.3 * np.pi * (q @ np.roll(look.direction, 1))) > 0)
        idx = np.where(marks & (idx > 0), (idx + 1) % k, 0)
    return look.palette[idx]


def _fbm(noise: FastNoiseLite, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    coords = np.stack([u, v]).astype(np.float32)
    return np.asarray(noise.gen_from_coords(coords), float)
