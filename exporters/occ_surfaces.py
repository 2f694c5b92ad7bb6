"""Analytic OCCT surfaces from VB-Rep primitive dicts, with closed-form numpy projection and (u, v) maps.

Everything here is in the *output* frame (millimetres, see `exporters.frames`). Each `AnalyticSurface` keeps
its numpy parameters next to its `Geom_Surface`, so points are projected onto it and mapped to its OCCT (u, v)
parameters in closed form, vectorised (no per-point OCCT calls). OCCT parametrisations used (gp_Ax3 = O, X,
Y, Z):

- plane:    P(u, v) = O + u X + v Y                                   (Z = the primitive's normal)
- cylinder: P(u, v) = O + R (cos u X + sin u Y) + v Z
- cone:     P(u, v) = O + (R0 + v sin a)(cos u X + sin u Y) + v cos a Z
            (O on the axis at reference radius R0, Z = the primitive's axis, pointing from the apex towards
            growing radius, a = half_angle)
- sphere:   P(u, v) = O + R cos v (cos u X + sin u Y) + R sin v Z
- torus:    P(u, v) = O + (R + r cos v)(cos u X + sin u Y) + r sin v Z

The u seam (u = 0) of periodic surfaces is put on the side of the axis opposite the face, so a face seen in
one view never straddles it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from OCP.Geom import (
    Geom_ConicalSurface,
    Geom_CylindricalSurface,
    Geom_Plane,
    Geom_SphericalSurface,
    Geom_Surface,
    Geom_ToroidalSurface,
)
from OCP.gp import gp_Ax3, gp_Dir, gp_Pnt

from exporters.frames import FrameMap
from v2c.labels import PrimitiveType

TWO_PI = 2.0 * np.pi


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to unit length."""
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def perpendicular(z: np.ndarray, hint: np.ndarray | None = None) -> np.ndarray:
    """A unit vector orthogonal to unit ``z``: ``hint`` made orthogonal if usable, else any."""
    for cand in ([hint] if hint is not None else []) + list(np.eye(3)[np.argsort(np.abs(z))]):
        x = np.asarray(cand, float) - (np.asarray(cand, float) @ z) * z
        n = np.linalg.norm(x)
        if n > 1e-6:
            return x / n
    raise ValueError("no perpendicular direction")  # unreachable for a unit z


def wrap_near(angle: np.ndarray, center: float) -> np.ndarray:
    """Angles shifted by multiples of 2 pi into [center - pi, center + pi)."""
    return center + np.remainder(np.asarray(angle, float) - center + np.pi, TWO_PI) - np.pi


def _circular_mean(a: np.ndarray) -> float:
    return float(np.arctan2(np.sin(a).mean(), np.cos(a).mean()))


@dataclass
class AnalyticSurface:
    """One analytic surface in the output frame (millimetres, radians); see the module docstring.

    kind: primitive type; origin, x, y, z: the gp_Ax3 placement; radius: R (cylinder, sphere, torus major,
    cone reference radius R0); minor_radius: torus tube radius; half_angle: cone half angle.
    u_center, v_center: the face's parameter centre: `uv` returns periodic parameters within pi of it.
    """

    kind: PrimitiveType
    origin: np.ndarray
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    radius: float = 0.0
    minor_radius: float = 0.0
    half_angle: float = 0.0
    u_center: float = np.pi
    v_center: float = 0.0
    geom: Geom_Surface | None = None

    # ------------------------------------------------------------------ local helpers
    def _local(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        d = np.atleast_2d(np.asarray(p, float)) - self.origin
        return d @ self.x, d @ self.y, d @ self.z

    def _radial(self, lx: np.ndarray, ly: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rho, unit radial direction (N, 3), u angle) of local coordinates; points on the axis get X."""
        rho = np.hypot(lx, ly)
        u = np.arctan2(ly, lx)
        er = np.cos(u)[:, None] * self.x + np.sin(u)[:, None] * self.y
        return rho, er, u

    @property
    def u_periodic(self) -> bool:
        """Whether u is periodic (an angle, period 2 pi): every surface but the plane."""
        return self.kind is not PrimitiveType.PLANE

    @property
    def v_periodic(self) -> bool:
        """Whether v is periodic (an angle, period 2 pi): the torus only."""
        return self.kind is PrimitiveType.TORUS

    # ------------------------------------------------------------------ geometry
    def project(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) millimetres -> (N, 3) closest points on the (untrimmed) surface."""
        return self.evaluate(self.uv(p))

    def uv(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) millimetres -> (N, 2) OCCT (u, v) of the closest surface points, periodic parameters within
        pi of (u_center, v_center)."""
        lx, ly, lz = self._local(p)
        k = self.kind
        if k is PrimitiveType.PLANE:
            return np.stack([lx, ly], 1)
        rho, _, u = self._radial(lx, ly)
        u = wrap_near(u, self.u_center)
        if k is PrimitiveType.CYLINDER:
            v = lz
        elif k is PrimitiveType.CONE:
            sa, ca = np.sin(self.half_angle), np.cos(self.half_angle)
            h_apex = self.radius / np.tan(self.half_angle)  # axial distance apex -> origin
            s = np.maximum(rho * sa + (lz + h_apex) * ca, 0.0)  # distance from the apex along the generator
            v = s - self.radius / sa
        elif k is PrimitiveType.SPHERE:
            v = np.arctan2(lz, rho)
        else:  # torus
            v = wrap_near(np.arctan2(lz, rho - self.radius), self.v_center)
        return np.stack([u, v], 1)

    def evaluate(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) OCCT (u, v) -> (N, 3) millimetres."""
        uv = np.atleast_2d(np.asarray(uv, float))
        u, v = uv[:, 0], uv[:, 1]
        if self.kind is PrimitiveType.PLANE:
            return self.origin + u[:, None] * self.x + v[:, None] * self.y
        er = np.cos(u)[:, None] * self.x + np.sin(u)[:, None] * self.y
        z = self.z[None]
        if self.kind is PrimitiveType.CYLINDER:
            return self.origin + self.radius * er + v[:, None] * z
        if self.kind is PrimitiveType.CONE:
            sa, ca = np.sin(self.half_angle), np.cos(self.half_angle)
            return self.origin + (self.radius + v * sa)[:, None] * er + (v * ca)[:, None] * z
        if self.kind is PrimitiveType.SPHERE:
            return self.origin + self.radius * (np.cos(v)[:, None] * er + np.sin(v)[:, None] * z)
        r, m = self.radius, self.minor_radius
        return self.origin + (r + m * np.cos(v))[:, None] * er + (m * np.sin(v))[:, None] * z

    def normal(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) OCCT (u, v) -> (N, 3) unit normals along dP/du x dP/dv (OCCT's natural normal)."""
        uv = np.atleast_2d(np.asarray(uv, float))
        u, v = uv[:, 0], uv[:, 1]
        if self.kind is PrimitiveType.PLANE:
            return np.repeat(self.z[None], len(uv), 0)
        er = np.cos(u)[:, None] * self.x + np.sin(u)[:, None] * self.y
        z = self.z[None]
        if self.kind is PrimitiveType.CYLINDER:
            n = er
        elif self.kind is PrimitiveType.CONE:
            n = np.cos(self.half_angle) * er - np.sin(self.half_angle) * z
        else:  # sphere, torus: outward from the centre (circle)
            n = np.cos(v)[:, None] * er + np.sin(v)[:, None] * z
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    def unwrap(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) (u, v) along a path with its periodic parameters made continuous (no jumps of a period)."""
        uv = np.array(uv, float)
        if self.u_periodic:
            uv[:, 0] = np.unwrap(uv[:, 0])
        if self.v_periodic:
            uv[:, 1] = np.unwrap(uv[:, 1])
        return uv

    def center_on(self, points: np.ndarray) -> None:
        """Set (u_center, v_center) to the circular means of the face's ``points`` (millimetres)."""
        if len(points) == 0 or self.kind is PrimitiveType.PLANE:
            return
        self.u_center = 0.0
        self.v_center = 0.0
        uv = self.uv(points)
        # Kept in [0, 2 pi) like the parameters OCCT computes itself (e.g. ShapeFix's pcurves).
        self.u_center = float(np.remainder(_circular_mean(uv[:, 0]), TWO_PI))
        if self.v_periodic:
            self.v_center = float(np.remainder(_circular_mean(uv[:, 1]), TWO_PI))


def gp_point(v: np.ndarray) -> gp_Pnt:
    """(3,) -> gp_Pnt."""
    return gp_Pnt(float(v[0]), float(v[1]), float(v[2]))


def gp_direction(v: np.ndarray) -> gp_Dir:
    """(3,) -> gp_Dir (normalised by OCCT)."""
    return gp_Dir(float(v[0]), float(v[1]), float(v[2]))


def make_surface(primitive: dict, fmap: FrameMap, face_points: np.ndarray) -> AnalyticSurface:
    """The surface of a VB-Rep primitive dict (camera frame, metres) in the output frame.

    face_points: (N, 3) camera-frame metres on the face (its mesh); they place the u seam on the far side of
    the axis and centre the returned (u, v). Raises ValueError for unknown types or degenerate parameters.
    """
    kind = PrimitiveType(primitive["type"])
    prm = primitive["params"]
    origin = fmap.points(np.asarray(prm["origin"], float))
    pts = fmap.points(np.asarray(face_points, float).reshape(-1, 3))
    centroid = pts.mean(0) if len(pts) else origin

    if kind is PrimitiveType.PLANE:
        z = unit(fmap.vectors(prm["normal"]))
        # Put the plane origin at the face so (u, v) stay small; x along the output axis most orthogonal to z.
        origin = origin + ((centroid - origin) - ((centroid - origin) @ z) * z)
        x = perpendicular(z, np.eye(3)[int(np.argmin(np.abs(z)))])
        s = AnalyticSurface(kind, origin, x, np.cross(z, x), z)
        s.geom = Geom_Plane(gp_Ax3(gp_point(origin), gp_direction(z), gp_direction(x)))
        return s

    if kind is PrimitiveType.SPHERE:
        radius = fmap.length(prm["radius"])
        if not radius > 0:
            raise ValueError(f"sphere radius {radius} mm")
        away = unit(centroid - origin) if np.linalg.norm(centroid - origin) > 1e-9 else np.array([0.0, 0, 1])
        # Poles 90 degrees away from the face centre, seam behind it.
        z = perpendicular(away, np.eye(3)[int(np.argmin(np.abs(away)))])
        x = -away
        s = AnalyticSurface(kind, origin, x, np.cross(z, x), z, radius=radius)
        s.geom = Geom_SphericalSurface(gp_Ax3(gp_point(origin), gp_direction(z), gp_direction(x)), radius)
        s.center_on(pts)
        return s

    z = unit(fmap.vectors(prm["axis"]))
    radial = (centroid - origin) - ((centroid - origin) @ z) * z
    x = perpendicular(z, -radial if np.linalg.norm(radial) > 1e-9 else None)
    y = np.cross(z, x)

    if kind is PrimitiveType.CYLINDER:
        radius = fmap.length(prm["radius"])
        if not radius > 0:
            raise ValueError(f"cylinder radius {radius} mm")
        # Origin moved along the axis to the face's height keeps v small.
        origin = origin + ((centroid - origin) @ z) * z
        s = AnalyticSurface(kind, origin, x, y, z, radius=radius)
        s.geom = Geom_CylindricalSurface(gp_Ax3(gp_point(origin), gp_direction(z), gp_direction(x)), radius)
    elif kind is PrimitiveType.CONE:
        a = float(prm["half_angle"])
        if not 1e-4 < a < np.pi / 2 - 1e-4:
            raise ValueError(f"cone half angle {a} rad")
        # Reference circle at the face's mean axial distance from the apex (origin = apex in the dict).
        h = max((centroid - origin) @ z, 1e-3)
        r0 = h * np.tan(a)
        s = AnalyticSurface(kind, origin + h * z, x, y, z, radius=r0, half_angle=a)
        s.geom = Geom_ConicalSurface(gp_Ax3(gp_point(s.origin), gp_direction(z), gp_direction(x)), a, r0)
    elif kind is PrimitiveType.TORUS:
        r_major, r_minor = fmap.length(prm["radius"]), fmap.length(prm["minor_radius"])
        if not (r_major > 0 and r_minor > 0):
            raise ValueError(f"torus radii {r_major}, {r_minor} mm")
        s = AnalyticSurface(kind, origin, x, y, z, radius=r_major, minor_radius=r_minor)
        ax3 = gp_Ax3(gp_point(origin), gp_direction(z), gp_direction(x))
        s.geom = Geom_ToroidalSurface(ax3, r_major, r_minor)
    else:  # pragma: no cover - PrimitiveType is exhaustive
        raise ValueError(f"unsupported primitive {kind}")
    s.center_on(pts)
    return s


def distance_to_surface(s: AnalyticSurface, points: np.ndarray) -> np.ndarray:
    """(N,) distances (mm) of points to a surface."""
    return np.linalg.norm(points - s.project(points), axis=1)
