"""Edge typing of boundary samples between two faces (or a face and the background).

One rule serves both the extraction (fitted surfaces, noisy depth) and the ground truth (true surfaces; see
`v2c.vbrep.gt_types`); only the tolerances differ. For a sample at pixel s on the boundary between instances a
and b, with unit image normal m pointing from a's side into b's side:

1. **intersection** when both sides are surfaces and the two surfaces (each on its own sheet) cross or come
   closer than ``gap_m`` metres in depth along the rays through s + o m, |o| <= ``band_px``;
2. otherwise the nearer surface at s (the background is infinitely far) is the near face: its edge is
   **visibility** when its contour generator (normal orthogonal to the ray) crosses the image normal through s
   within ``vis_px`` pixels (that crossing is the sample's 3D position), runs along the boundary there (image
   tangents within ``vis_angle_deg``) and projects onto the face's own pixels (within ``vis_face_px``; not onto
   the surface's extension beyond the face), else **silhouette**; the far face, if any, gets an **occluded** edge.

The tolerances are a `TypingRule`; the surfaces, camera and instance map a `SurfaceView`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from v2c.camera import pixel_rays, project
from v2c.primitives.base import Primitive
from v2c.vbrep.lift import project_to_intersection
from v2c.vbrep.raycast import intersect, sheet_depth
from v2c.vbrep.visibility import contour_tangent, find_contour

KIND_INT, KIND_NEAR_A, KIND_NEAR_B = 0, 1, 2


@dataclass
class FaceGeom:
    """A face's surface as the extraction sees it: primitive, sheet (see ambiguity.py), fit residual (metres)."""

    instance: int
    prim: Primitive
    sheet: int = 0
    residual: float = 0.0
    axis_label: str | None = None
    extra: dict = field(default_factory=dict)

    @property
    def curved(self) -> bool:
        """True for every surface but a plane (only curved faces have contour generators)."""
        return self.prim.type != "plane"


@dataclass(frozen=True)
class TypingRule:
    """Tolerances of the edge-type rule (module docstring). The extraction reads them from `VBRepConfig`, the
    ground truth from `GTTypeConfig`."""

    band_px: float  # pixels: half-width of the band across the boundary where the two surfaces may meet
    band_step_px: float  # pixels: spacing of the rays across that band
    gap_m: float  # metres: surfaces closer than this in depth within the band meet
    vis_px: float  # pixels: how far along the image normal a contour generator is searched
    vis_step_px: float  # pixels: step of that search
    vis_bisect: int  # bisection steps refining a crossing found by it
    vis_angle_deg: float  # degrees: the boundary's and the contour's image tangents must lie within this
    vis_face_px: int  # pixels: the contour point must project within this of the face's own pixels
    curve_iters: int  # Gauss-Newton iterations onto the intersection curve
    curve_slack_px: float  # pixels: a point projected onto the curve may move band_px plus this in the image


@dataclass
class SurfaceView:
    """What the rule looks at: the faces (instance id -> `FaceGeom`), intrinsics K (3, 3, pixels), the depth
    window (near, far) of the ray casts (metres) and the (H, W) instance map (None: no face-pixel test)."""

    faces: dict[int, FaceGeom]
    K: np.ndarray
    window: tuple[float, float]
    instances: np.ndarray | None


@dataclass
class SampleTypes:
    """Per-sample result. kind: (N,) KIND_*; vis: (N,) near face's edge is visibility; gap: (N,) smallest depth gap
    of the surfaces in the band (metres, inf with background); angle: (N,) angle between the surface normals
    (radians, NaN with background); p_a, p_b: (N, 3) lifts on a's and b's surfaces at s (NaN for background);
    p_int: (N, 3) points on both surfaces (NaN unless kind is intersection); p_vis: (N, 3) contour points (NaN
    unless vis)."""

    kind: np.ndarray
    vis: np.ndarray
    gap: np.ndarray
    angle: np.ndarray
    p_a: np.ndarray
    p_b: np.ndarray
    p_int: np.ndarray
    p_vis: np.ndarray


def _depths(face: FaceGeom, uv: np.ndarray, K: np.ndarray, window: tuple[float, float]) -> np.ndarray:
    return sheet_depth(intersect(face.prim, pixel_rays(uv, K), window), face.sheet)


def _near_region(instances: np.ndarray, inst: int, uv: np.ndarray, r: int) -> np.ndarray:
    """(N,) bool: an instance pixel lies within ``r`` pixels (8-neighbourhood) of each image point."""
    h, w = instances.shape
    u0, v0 = np.rint(uv[:, 0]).astype(int), np.rint(uv[:, 1]).astype(int)
    out = np.zeros(len(uv), bool)
    for du in range(-r, r + 1):
        for dv in range(-r, r + 1):
            u, v = np.clip(u0 + du, 0, w - 1), np.clip(v0 + dv, 0, h - 1)
            out |= instances[v, u] == inst
    return out


def classify_samples(
    uv: np.ndarray, normal: np.ndarray, a: int, b: int, view: SurfaceView, rule: TypingRule
) -> SampleTypes:
    """Type the samples ``uv`` (N, 2, pixels) of the boundary between instances ``a`` and ``b`` (0 or an instance
    missing from ``view.faces`` = background); ``normal`` (N, 2) unit image vectors from a's side into b's side."""
    faces, K, window = view.faces, view.K, view.window
    band_px = rule.band_px
    uv = np.asarray(uv, float).reshape(-1, 2)
    normal = np.asarray(normal, float).reshape(-1, 2)
    n = len(uv)
    fa, fb = faces.get(a), faces.get(b)
    nan3 = np.full((n, 3), np.nan)
    rays = pixel_rays(uv, K)
    za = _depths(fa, uv, K, window) if fa else np.full(n, np.inf)
    zb = _depths(fb, uv, K, window) if fb else np.full(n, np.inf)
    p_a = rays * za[:, None] if fa else nan3.copy()
    p_b = rays * zb[:, None] if fb else nan3.copy()
    kind = np.where(za <= zb, KIND_NEAR_A, KIND_NEAR_B).astype(np.int8)
    gap = np.full(n, np.inf)
    angle = np.full(n, np.nan)
    p_int = nan3.copy()
    if fa and fb:
        offs = np.arange(-band_px, band_px + 1e-9, rule.band_step_px)
        q = (uv[:, None, :] + offs[None, :, None] * normal[:, None, :]).reshape(-1, 2)
        g = (_depths(fa, q, K, window) - _depths(fb, q, K, window)).reshape(n, len(offs))
        cross = (np.signbit(g[:, :-1]) != np.signbit(g[:, 1:])).any(1)
        gap = np.where(cross, 0.0, np.abs(g).min(1))
        is_int = gap < rule.gap_m
        kind[is_int] = KIND_INT
        if is_int.any():
            x0 = 0.5 * (p_a[is_int] + p_b[is_int])
            p_int[is_int] = project_to_intersection(
                fa.prim, fb.prim, x0, rule.curve_iters, K, band_px + rule.curve_slack_px
            )
            x = p_int[is_int]
            cosang = np.abs(np.einsum("ij,ij->i", fa.prim.normal(x), fb.prim.normal(x)))
            angle[is_int] = np.arccos(np.clip(cosang, 0.0, 1.0))
    vis = np.zeros(n, bool)
    p_vis = nan3.copy()
    for near, face, sign in ((KIND_NEAR_A, fa, 1.0), (KIND_NEAR_B, fb, -1.0)):
        sel = np.nonzero(kind == near)[0]
        if face is None or not face.curved or len(sel) == 0:
            continue
        res = find_contour(
            face.prim,
            face.sheet,
            uv[sel],
            sign * normal[sel],
            K,
            window,
            rule.vis_px,
            rule.vis_step_px,
            rule.vis_bisect,
        )
        vis[sel] = res.found
        hit = sel[res.found]
        if len(hit):
            # the boundary must run along the contour: its image tangent within vis_angle of the contour's (a
            # boundary that merely crosses a contour line near its end, e.g. a cylinder's base arc, is not one)
            q = res.points[res.found]
            t3 = contour_tangent(face.prim, q)
            eps = 1e-4 * np.linalg.norm(q, axis=1, keepdims=True)
            ti = project(q + eps * t3, K) - project(q, K)
            ti /= np.maximum(np.linalg.norm(ti, axis=1, keepdims=True), 1e-15)
            tb = np.stack([-normal[hit, 1], normal[hit, 0]], 1)
            ok = np.abs(np.einsum("ij,ij->i", ti, tb)) >= np.cos(np.deg2rad(rule.vis_angle_deg))
            if view.instances is not None:  # ... and the contour point is on the face (not the surface's extension)
                ok &= _near_region(view.instances, face.instance, project(q, K), rule.vis_face_px)
            p_vis[hit[ok]] = q[ok]
            vis[hit[~ok]] = False
    return SampleTypes(kind, vis, gap, angle, p_a, p_b, p_int, p_vis)
