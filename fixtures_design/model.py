"""The designed fixture and the small geometric helpers its generators share.

A :class:`Fixture` is a build123d solid in the output frame (millimetres; see `fixtures_design.frames`), the faces
of it that are meant to touch the part (``mating_faces``), points sampled where it should touch
(``contact_points``), and the reference it was built from.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum
from typing import Any

import numpy as np
from build123d import Face, Location, Plane, Shape, Solid, Vector, Wire
from OCP.gp import gp_Trsf

from fixtures_design.frames import FrameMap


class FixtureKind(str, Enum):  # noqa: UP042 - StrEnum would change str() and format() of the members
    """The fixtures the designer makes."""

    CORNER = "corner"
    PIN = "pin"
    CRADLE = "cradle"
    NEST = "nest"


@dataclass(frozen=True)
class Seating:
    """How a part is put into its fixture, output frame: the translations the fixture constrains and the way the
    part is pushed home (`fixtures_design.seat.seat_part`).

    directions: (k, 3) orthonormal rows: the part moves in their span only (a corner: its two faces' normals, not
    along the edge; a pin or a nest: any way; a cradle: across its axis). push: (3,) unit vector in that span, the
    way the part is pushed (a corner: into the corner; a pin: onto the flange; a cradle or a nest: down); across it
    the part moves as little as keeps it clear of the mating faces. stops: faces besides the mating faces that end
    the push (a nest's floor, which is not a mating face). standoff_mm: how far the push goes by design beyond the
    clearance (a nest: its ``floor_gap``; 0 for the others), so the seat's bound allows it.
    """

    directions: np.ndarray
    push: np.ndarray
    stops: list[Face] = field(default_factory=list)
    standoff_mm: float = 0.0


@dataclass
class Fixture:
    """A designed fixture, output frame, millimetres.

    solid: the fixture body. mating_faces: its faces that locate the part (each a clearance away from the part
    surface it references). mating_refs: for each mating face, the id of the VB-Rep face it references (-1: the
    part as a whole, e.g. a nest's pocket walls). contact_points: (N, 3) points on the fixture where it should
    touch the part (on the mating faces; for a V cradle on its contact lines). reference: what it was built from
    (a `fixtures_design.references` reference, or a `Footprint` for a nest). fmap: the camera -> output map used.
    params: the generator's parameters. notes: sizes as built (clamped lengths, radii; mm). seating: how the part
    is pushed home into it (`Seating`; None: not stated, `fixtures_design.seat` cannot seat it).
    """

    kind: FixtureKind
    solid: Solid
    mating_faces: list[Face]
    contact_points: np.ndarray
    reference: Any
    fmap: FrameMap
    params: Any
    mating_refs: list[int] = field(default_factory=list)
    notes: dict = field(default_factory=dict)
    seating: Seating | None = None

    @property
    def volume_mm3(self) -> float:
        """The fixture body's volume, mm^3."""
        return float(self.solid.volume)


def unit(v: np.ndarray) -> np.ndarray:
    """``v`` (any shape, last axis the vector) scaled to unit length."""
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def local_plane(origin: np.ndarray, x_dir: np.ndarray, z_dir: np.ndarray) -> Plane:
    """A build123d Plane (output frame, mm) from an origin and two orthogonal directions."""
    z = unit(z_dir)
    x = unit(np.asarray(x_dir, float) - (np.asarray(x_dir, float) @ z) * z)
    return Plane(origin=Vector(*map(float, origin)), x_dir=Vector(*map(float, x)), z_dir=Vector(*map(float, z)))


def place(shape: Shape, plane: Plane) -> Shape:
    """``shape`` built in ``plane``'s local coordinates, moved into the output frame."""
    return shape.moved(Location(plane))


def prism(profile_xy: np.ndarray, z0: float, z1: float) -> Solid:
    """A straight prism: the closed polygon ``profile_xy`` ((K, 2), local mm) extruded from z0 to z1."""
    pts = [Vector(float(x), float(y), float(z0)) for x, y in profile_xy]
    face = Face(Wire.make_polygon(pts, close=True))
    return Solid.extrude(face, Vector(0, 0, float(z1 - z0)))


def faces_facing(
    solid: Shape, normal: np.ndarray, point_on: np.ndarray | None = None, tol_deg: float = 1.0, dist_tol: float = 1e-3
) -> list[Face]:
    """Planar faces of ``solid`` whose outward normal is ``normal`` (and whose plane holds ``point_on``)."""
    n = unit(normal)
    out = []
    for f in solid.faces():
        if f.geom_type.name != "PLANE":
            continue
        c = f.center()
        fn = np.array(tuple(f.normal_at(c)))
        if fn @ n < np.cos(np.radians(tol_deg)):
            continue
        if point_on is not None and abs((np.array(tuple(c)) - point_on) @ n) > dist_tol:
            continue
        out.append(f)
    return out


def sample_face(face: Face, tolerance_mm: float = 0.2, grid: int = 8) -> np.ndarray:
    """(N, 3) points on a face, mm: its tessellation's vertices and triangle centroids, plus a ``grid`` x ``grid``
    sampling of its (u, v) parameter box kept where it lies on the (trimmed) face."""
    verts, tris = face.tessellate(tolerance_mm, 0.2)
    v = np.array([tuple(p) for p in verts])
    t = np.asarray(tris, int).reshape(-1, 3)
    pts = [v, v[t].mean(axis=1)] if len(t) else [v]
    uv = (np.arange(grid) + 0.5) / grid
    on = [tuple(face.position_at(a, b)) for a in uv for b in uv]
    on = [p for p in on if face.is_inside(Vector(*p), 1e-4)]
    if on:
        pts.append(np.array(on))
    return np.concatenate(pts)


def sample_triangles(tri: np.ndarray, n_points: int, seed: int = 0) -> np.ndarray:
    """(n_points, 3) points drawn on the triangles ``tri`` (T, 3, 3), area-weighted, seeded; (0, 3) when they have
    no area."""
    tri = np.asarray(tri, float).reshape(-1, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not len(tri) or not area.sum() > 0:
        return np.zeros((0, 3))
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(tri), n_points, p=area / area.sum())
    a, b = rng.random((2, n_points, 1))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    t = tri[pick]
    return t[:, 0] + a * (t[:, 1] - t[:, 0]) + b * (t[:, 2] - t[:, 0])


def transformed(shape: Shape, m: np.ndarray) -> Shape:
    """``shape`` moved by a (4, 4) rigid transform (rotation + translation, in the shape's units)."""
    trsf = gp_Trsf()
    trsf.SetValues(*(float(x) for x in np.asarray(m, float)[:3].ravel()))
    return shape.moved(Location(trsf))


def common_volume(a: Shape, b: Shape) -> float:
    """Volume (mm^3) of the OCCT boolean common of two shapes (0 when they only touch or are apart)."""
    from OCP.BRepAlgoAPI import BRepAlgoAPI_Common
    from OCP.BRepGProp import BRepGProp
    from OCP.GProp import GProp_GProps

    op = BRepAlgoAPI_Common(a.wrapped, b.wrapped)
    if not op.IsDone():
        raise RuntimeError("OCCT boolean common failed")
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(op.Shape(), props)
    return abs(float(props.Mass()))
