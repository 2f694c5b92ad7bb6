"""Feature-based random parts: a base stock followed by a random sequence of named CAD features.

A part is built like a designer builds one: a stock (a sketch of lines and arcs extruded, a revolved profile of
a turned part, polygonal bar stock, a pillow-block body) and then features, each one of `FEATURE_KINDS`, placed on
faces of the current solid (a point of a planar face with a clear disc around it, a full cylindrical face, an
edge between two faces). Every feature is one OCCT operation (boolean, fillet or chamfer); a feature whose operation
fails, leaves an invalid solid (`BRepCheck_Analyzer`), more than one solid, a face that is not a plane, cylinder,
cone, sphere or torus (the types the pipeline knows), or no change at all is skipped and the next one tried. The
part records the kinds it holds (`info["features"]`, with each feature's drawn parameters in
`info["feature_params"]`), which `v2c synth` writes to gt/meta.json under `part`.

Units: millimetres; the rest pose of parts.py (Z up, resting on z = 0, bounding box centred on the Z axis). Every
draw comes from the numpy Generator passed in, so a seed gives the same part.

Feature kinds (the surfaces they add):
  through_hole      cylinder through the part along a face normal (or across a cylinder: a cross hole)
  blind_hole        cylinder of a drawn depth, flat or with a 118-degree drill point (cone)
  counterbore       through hole with a coaxial larger, shallower bore (two cylinders, an annular plane)
  countersink       through hole with a 90-degree conical sink (cone)
  boss              cylinder standing on a planar face
  pocket            rounded-rectangle pocket (planes, corner cylinders), turned at random or along the face axes
  slot              obround slot, blind or through (half cylinders, planes)
  rib               thin wall standing on a planar face
  step              a box cut off one side of the part from its top (two planes)
  groove            annular groove in a full cylindrical face, square (planes, cylinder) or round (torus)
  fillet            constant-radius blend of a line edge between planes (cylinder) or a circle edge (torus)
  chamfer           equal-distance chamfer of such an edge (plane or cone)
  dome              spherical cap on a circular face, larger radius than the face (sphere, a sharp rim)
  ball_end          hemisphere on a circular face, tangent to its cylinder (sphere)
  linear_pattern    a row of 2-5 holes, bosses or slots
  circular_pattern  holes or bosses on a bolt circle, or flutes around a cylinder (knurl-like; concave cylinders)
  union             a box or a half-buried lying cylinder joined to a face
  cut               a tilted box, a lying cylinder (channel) or a sphere (dimple) cut from a face

Families (see families.py for which are left out of training):
  feat_prismatic  sketch of lines and arcs (rectangle, L, T, U or star outline; arcs, rounded corners) extruded
  feat_plate      thin plate stock with hole patterns, slots, pockets
  feat_turned     revolved profile (cylinders, cones, tori from corner arcs), standing or lying on its side
  feat_hex        polygonal bar stock (3-8 sides, mostly hexagons), standing or lying on a flat          [leave-out]
  feat_knob       turned knob: base, taper, domed or ball top, flutes, grooves                           [leave-out]
  feat_block      pillow block: base, housing with bore, counterbored holes                              [leave-out]
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from build123d import (
    Align,
    Axis,
    Box,
    Cone,
    Cylinder,
    Edge,
    Face,
    Location,
    Plane,
    Pos,
    RectangleRounded,
    Rot,
    Shape,
    SlotOverall,
    Solid,
    Sphere,
    Torus,
    Vector,
    Wire,
    extrude,
    revolve,
)
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepClass3d import BRepClass3d_SolidClassifier
from OCP.BRepFilletAPI import BRepFilletAPI_MakeChamfer, BRepFilletAPI_MakeFillet
from OCP.BRepGProp import BRepGProp
from OCP.BRepTools import BRepTools
from OCP.BRepTopAdaptor import BRepTopAdaptor_FClass2d
from OCP.GeomAbs import (
    GeomAbs_Circle,
    GeomAbs_Cone,
    GeomAbs_Cylinder,
    GeomAbs_Line,
    GeomAbs_Plane,
    GeomAbs_Sphere,
    GeomAbs_Torus,
)
from OCP.gp import gp_Dir, gp_Lin, gp_Pnt, gp_Pnt2d
from OCP.GProp import GProp_GProps
from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE, TopAbs_IN, TopAbs_REVERSED, TopAbs_SOLID, TopAbs_WIRE
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape

from v2c.synth.families import FEATURE_FAMILIES
from v2c.synth.parts import RestPart, rest_on_ground

FEATURE_KINDS: tuple[str, ...] = (
    "through_hole",
    "blind_hole",
    "counterbore",
    "countersink",
    "boss",
    "pocket",
    "slot",
    "rib",
    "step",
    "groove",
    "fillet",
    "chamfer",
    "dome",
    "ball_end",
    "linear_pattern",
    "circular_pattern",
    "union",
    "cut",
)
#: Kinds whose operation is an edge blend (slower than a boolean; their count per part is capped).
BLEND_KINDS = ("fillet", "chamfer")
#: Surface types a generated part may hold (the pipeline's primitives).
ANALYTIC_TYPES = {
    GeomAbs_Plane: "plane",
    GeomAbs_Cylinder: "cylinder",
    GeomAbs_Cone: "cone",
    GeomAbs_Sphere: "sphere",
    GeomAbs_Torus: "torus",
}

_C, _MIN, _MAX = Align.CENTER, Align.MIN, Align.MAX
_BASE = (_C, _C, _MIN)


@dataclass(frozen=True)
class FeatureConfig:
    """How features are drawn and checked (lengths in millimetres)."""

    n_features: tuple[int, int] = (4, 8)  # random features tried per part (inclusive), after a family's fixed ones
    max_blends: int = 2  # fillet and chamfer operations per part (each 10-100 ms, the slowest operations)
    max_part_tries: int = 4  # stocks drawn before giving up (a stock that is not a valid solid is re-drawn)
    site_tries: int = 30  # random points tried when looking for a face point with a clear disc around it
    ring_points: int = 12  # points on the disc's rim tested inside the face
    wall_mm: float = 1.5  # material kept between a feature and the boundary of its face, and below blind features
    overshoot_mm: float = 0.5  # tools overshoot the surface they cut, so no coplanar sliver faces are left
    min_size_mm: float = 1.0  # smallest radius, width or depth a feature draws
    max_torus_ratio: float = 0.9  # torus minor / major radius allowed (a STEP reader turns minor > major into a
    # surface of revolution; NOTES.md)
    min_volume_change: float = 1e-6  # relative volume change below which a feature "did nothing" and is skipped


# ---- shape checks ------------------------------------------------------------------------------------------------


def _faces(shape: TopoDS_Shape) -> list:
    out, exp = [], TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        out.append(TopoDS.Face_s(exp.Current()))
        exp.Next()
    return out


def _solids(shape: TopoDS_Shape) -> list:
    out, exp = [], TopExp_Explorer(shape, TopAbs_SOLID)
    while exp.More():
        out.append(TopoDS.Solid_s(exp.Current()))
        exp.Next()
    return out


def volume(shape: TopoDS_Shape) -> float:
    """Volume of `shape`, mm^3."""
    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props)
    return float(props.Mass())


def shape_problem(shape: TopoDS_Shape, cfg: FeatureConfig = FeatureConfig()) -> str | None:
    """Why `shape` is not an acceptable part (None when it is): one solid, BRepCheck-valid, analytic faces only."""
    solids = _solids(shape)
    if len(solids) != 1:
        return f"{len(solids)} solids"
    if not BRepCheck_Analyzer(shape).IsValid():
        return "BRepCheck: invalid"
    for face in _faces(shape):
        surf = BRepAdaptor_Surface(face)
        kind = surf.GetType()
        if kind not in ANALYTIC_TYPES:
            return f"non-analytic face (GeomAbs {int(kind)})"
        if kind == GeomAbs_Torus:
            tor = surf.Torus()
            if tor.MinorRadius() > cfg.max_torus_ratio * tor.MajorRadius():
                return "torus with minor radius near its major radius"
    return None


def face_types(shape: TopoDS_Shape) -> list[str]:
    """Primitive type name of every face (TopExp_Explorer order; non-analytic faces as 'other')."""
    return [ANALYTIC_TYPES.get(BRepAdaptor_Surface(f).GetType(), "other") for f in _faces(shape)]


# ---- the part under construction ---------------------------------------------------------------------------------


@dataclass
class Work:
    """A part being built: the current solid (mm, Z up) and what was done to it."""

    solid: Solid
    family: str
    size: float  # characteristic size of the stock (mm): features draw their sizes relative to it
    info: dict = field(default_factory=dict)  # stock parameters
    features: list[str] = field(default_factory=list)  # kinds applied, in order
    params: list[dict] = field(default_factory=list)  # drawn parameters of each applied feature
    skipped: list[str] = field(default_factory=list)  # "kind: reason" of the features that were skipped
    blends: int = 0
    lying: bool = False  # turn the part onto its side (about X) at the end
    data: dict = field(default_factory=dict)  # family-specific data for the family's own operations

    @property
    def shape(self) -> TopoDS_Shape:
        """The current solid as an OCCT shape (mm, Z up)."""
        return self.solid.wrapped


def _as_solid(shape: Shape | TopoDS_Shape) -> Solid | None:
    """The one solid of ``shape`` as a build123d Solid; None when it holds none or several."""
    raw = shape.wrapped if isinstance(shape, Shape) else shape
    solids = _solids(raw)
    return Solid(solids[0]) if len(solids) == 1 else None


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    """One uniform draw in [lo, hi) as a Python float."""
    return float(rng.uniform(lo, hi))


def _vec(v: gp_Pnt | gp_Dir) -> np.ndarray:
    """(3,) array of an OCCT point or direction (mm for a point)."""
    return np.array([v.X(), v.Y(), v.Z()], float)


# ---- where a feature goes ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Site:
    """A point on a planar face with a clear disc around it (mm). Local frame: z = outward normal."""

    origin: np.ndarray  # (3,) point on the face
    normal: np.ndarray  # (3,) outward unit normal of the face
    xdir: np.ndarray  # (3,) unit in-plane direction (the face plane's own X axis)
    clearance: float  # radius of the disc around `origin` known to lie inside the face
    depth: float  # material depth below `origin` along -normal (min over the centre and 4 rim points)

    def location(self, angle: float = 0.0) -> Location:
        """Placement of the local frame turned by `angle` (radians) about the normal."""
        y = np.cross(self.normal, self.xdir)
        x = math.cos(angle) * self.xdir + math.sin(angle) * y
        return Location(Plane(origin=tuple(self.origin), x_dir=tuple(x), z_dir=tuple(self.normal)))

    def point(self, x: float, y: float, angle: float = 0.0) -> np.ndarray:
        """World point of local (x, y) in the frame turned by `angle`."""
        yd = np.cross(self.normal, self.xdir)
        xd = math.cos(angle) * self.xdir + math.sin(angle) * yd
        yd = np.cross(self.normal, xd)
        return self.origin + x * xd + y * yd


def _hits(shape: TopoDS_Shape, points: list[np.ndarray], direction: np.ndarray) -> list[list[float]]:
    """Sorted distances (mm) from each point along `direction` to where the ray crosses the part's boundary."""
    inter = IntCurvesFace_ShapeIntersector()
    inter.Load(shape, 1e-7)
    d = gp_Dir(*direction)
    out = []
    for p in points:
        inter.Perform(gp_Lin(gp_Pnt(*p), d), 1e-4, 1e9)
        out.append(sorted(inter.WParameter(i) for i in range(1, inter.NbPnt() + 1)))
    return out


def _depth_along(shape: TopoDS_Shape, points: list[np.ndarray], direction: np.ndarray) -> float:
    """Smallest distance (mm) from each of `points` (on the boundary) along `direction` into the material to the
    next boundary crossing: the material thickness below a face point."""
    best = math.inf
    for ws in _hits(shape, points, direction):
        ws = [w for w in ws if w > 1e-4]
        best = min(best, ws[0] if ws else 0.0)
    return best


def _planar_faces(shape: TopoDS_Shape, min_nz: float) -> list[tuple]:
    out = []
    for face in _faces(shape):
        surf = BRepAdaptor_Surface(face)
        if surf.GetType() != GeomAbs_Plane:
            continue
        pln = surf.Plane()
        n = _vec(pln.Axis().Direction())
        # Outward normal: X x Y of the plane's frame (minus the axis for a left-handed frame, as on the end faces
        # of a revolved solid), flipped for a reversed face.
        if (face.Orientation() == TopAbs_REVERSED) != (not pln.Position().Direct()):
            n = -n
        if n[2] < min_nz:
            continue
        props = GProp_GProps()
        BRepGProp.SurfaceProperties_s(face, props)
        out.append((face, surf, n, _vec(pln.XAxis().Direction()), float(props.Mass())))
    return out


def find_site(
    w: Work, rng: np.random.Generator, radius: float, cfg: FeatureConfig, min_nz: float = -0.5, up_only: bool = False
) -> Site | None:
    """A random point of a planar face of `w` whose disc of `radius` + wall (mm) lies inside the face.

    Faces are drawn by area; `min_nz` excludes faces looking down (the part rests on them), `up_only` keeps faces
    whose normal is +Z. None if no such point is found in `cfg.site_tries` draws.
    """
    faces = _planar_faces(w.shape, 0.999 if up_only else min_nz)
    if not faces:
        return None
    area = np.array([f[4] for f in faces])
    prob = area / area.sum()
    clear = radius + cfg.wall_mm
    classifiers: dict[int, BRepTopAdaptor_FClass2d] = {}
    ring = [(math.cos(t), math.sin(t)) for t in np.linspace(0, 2 * math.pi, cfg.ring_points, endpoint=False)]
    for _ in range(cfg.site_tries):
        k = int(rng.choice(len(faces), p=prob))
        face, surf, n, xdir, _ = faces[k]
        umin, umax, vmin, vmax = BRepTools.UVBounds_s(face)
        if umax - umin <= 2 * clear or vmax - vmin <= 2 * clear:
            rng.random(2)  # keep the number of draws per try fixed
            continue
        u, v = rng.uniform(umin + clear, umax - clear), rng.uniform(vmin + clear, vmax - clear)
        cls = classifiers.setdefault(k, BRepTopAdaptor_FClass2d(face, 1e-7))
        if cls.Perform(gp_Pnt2d(u, v)) != TopAbs_IN:
            continue
        if any(cls.Perform(gp_Pnt2d(u + clear * c, v + clear * s)) != TopAbs_IN for c, s in ring):
            continue
        origin = _vec(surf.Value(u, v))
        rim = [origin + radius * (c * xdir + s * np.cross(n, xdir)) for c, s in ring[:: max(1, len(ring) // 4)]]
        depth = _depth_along(w.shape, [origin, *rim], -n)
        if depth <= cfg.wall_mm:
            continue
        return Site(origin, n, xdir, clear, depth)
    return None


@dataclass(frozen=True)
class CylSite:
    """A full (360 degree) or partial cylindrical face (mm): axis point, unit axis, radius, axial extent."""

    centre: np.ndarray  # (3,) point on the axis at axial parameter 0
    axis: np.ndarray  # (3,) unit axis
    radius: float
    v_range: tuple[float, float]  # axial extent of the face along `axis` from `centre`
    u_range: tuple[float, float]  # angular extent (radians)
    xdir: np.ndarray  # (3,) unit radial direction at u = 0
    ydir: np.ndarray  # (3,) unit radial direction at u = pi / 2
    outer: bool  # material inside the cylinder (a shaft), not outside (a hole)

    @property
    def full(self) -> bool:
        """Whether the face goes all the way round (360 degrees)."""
        return self.u_range[1] - self.u_range[0] > 2 * math.pi - 1e-6

    def radial(self, u: float) -> np.ndarray:
        """(3,) unit radial direction at angle ``u`` (radians) from `xdir` towards `ydir`."""
        return math.cos(u) * self.xdir + math.sin(u) * self.ydir


def cylinder_sites(shape: TopoDS_Shape, outer_only: bool = True) -> list[CylSite]:
    """Cylindrical faces of `shape` (outer ones: material inside the cylinder)."""
    out = []
    for face in _faces(shape):
        surf = BRepAdaptor_Surface(face)
        if surf.GetType() != GeomAbs_Cylinder:
            continue
        cyl = surf.Cylinder()
        # Material inside the cylinder when the outward normal points away from the axis: the surface normal
        # does for a right-handed frame, and the face's orientation may flip it.
        outer = (face.Orientation() != TopAbs_REVERSED) == cyl.Position().Direct()
        if outer_only and not outer:
            continue
        umin, umax, vmin, vmax = BRepTools.UVBounds_s(face)
        ax = cyl.Position()
        out.append(
            CylSite(
                _vec(ax.Location()),
                _vec(ax.Direction()),
                float(cyl.Radius()),
                (vmin, vmax),
                (umin, umax),
                _vec(ax.XDirection()),
                _vec(ax.YDirection()),
                outer,
            )
        )
    return out


@dataclass(frozen=True)
class DiscSite:
    """A planar face bounded by one full circle and nothing else (mm): the end of a cylinder."""

    centre: np.ndarray
    normal: np.ndarray  # outward
    radius: float


def disc_sites(shape: TopoDS_Shape, min_nz: float = -0.5) -> list[DiscSite]:
    """Planar faces that are full discs (one wire of one circular edge), looking no further down than `min_nz`."""
    out = []
    for face, _surf, n, _, _ in _planar_faces(shape, min_nz):
        wires, exp = 0, TopExp_Explorer(face, TopAbs_WIRE)
        while exp.More():
            wires += 1
            exp.Next()
        # A revolved disc also holds a seam and a degenerate edge at the axis: only real boundary edges count.
        edges = [e for e in _edges(face) if not BRep_Tool.Degenerated_s(e) and not BRep_Tool.IsClosed_s(e, face)]
        if wires != 1 or len(edges) != 1:
            continue
        curve = BRepAdaptor_Curve(edges[0])
        if curve.GetType() != GeomAbs_Circle:
            continue
        circ = curve.Circle()
        centre, radius = _vec(circ.Location()), float(circ.Radius())
        # An end of a cylinder, not the floor of a hole: just outside the rim, just above the disc, is air.
        radial = _vec(circ.XAxis().Direction())
        probe = centre + radius * (1 + 1e-3) * radial + n * min(1e-2, 1e-3 * radius)
        classifier = BRepClass3d_SolidClassifier(shape, gp_Pnt(*probe), 1e-7)
        if classifier.State() == TopAbs_IN:
            continue
        out.append(DiscSite(centre, n, radius))
    return out


def _edges(shape: TopoDS_Shape) -> list:
    out, exp = [], TopExp_Explorer(shape, TopAbs_EDGE)
    while exp.More():
        out.append(TopoDS.Edge_s(exp.Current()))
        exp.Next()
    return out


# ---- tools in a site's local frame (z = outward normal, z = 0 on the face) ---------------------------------------


def _cyl(r: float, z0: float, z1: float) -> Solid:
    return Pos(0, 0, z0) * Cylinder(r, z1 - z0, align=_BASE)


def _cone(r0: float, r1: float, z0: float, z1: float) -> Solid:
    return Pos(0, 0, z0) * Cone(r0, r1, z1 - z0, align=_BASE)


def _hole_tool(w: Work, r: float, cfg: FeatureConfig) -> Solid:
    """A cylinder from above the face through everything below it (length: twice the part's size)."""
    return _cyl(r, -4 * w.size - 10 * cfg.overshoot_mm, cfg.overshoot_mm)


def _radial_site(w: Work, rng: np.random.Generator, r: float, cfg: FeatureConfig) -> tuple[Location, float] | None:
    """A local frame on an outer cylinder face (z = outward radial, for cross holes) and the material depth."""
    cands = [
        c
        for c in cylinder_sites(w.shape)
        if c.radius > 2 * r + cfg.wall_mm and c.v_range[1] - c.v_range[0] > 2 * (r + cfg.wall_mm)
    ]
    if not cands:
        return None
    c = cands[int(rng.integers(len(cands)))]
    for _ in range(cfg.site_tries // 3):
        u = _u(rng, *c.u_range)
        v = _u(rng, c.v_range[0] + r + cfg.wall_mm, c.v_range[1] - r - cfg.wall_mm)
        radial = c.radial(u)
        origin = c.centre + v * c.axis + c.radius * radial
        # Only where the face really is (a partial face, or a hole already there): a ray from just outside must
        # cross the boundary at the surface point, and the material below it must be thicker than the wall.
        ws = _hits(w.shape, [origin + radial], -radial)[0]
        if len(ws) >= 2 and abs(ws[0] - 1.0) < 1e-6 and ws[1] - ws[0] > 2 * cfg.wall_mm:
            return Location(Plane(origin=tuple(origin), x_dir=tuple(c.axis), z_dir=tuple(radial))), ws[1] - ws[0]
    return None


# ---- the feature kinds -------------------------------------------------------------------------------------------
# Each takes the work, the generator and the config, and returns (new shape, drawn parameters) or None when the
# feature does not apply to this part (no room for it); an OCCT failure raises.

FeatureResult = tuple[Shape | TopoDS_Shape, dict] | None


def _hole_radius(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> float:
    return max(cfg.min_size_mm, _u(rng, 0.025, 0.07) * w.size)


def f_through_hole(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A through hole of radius 2.5-7 % of the part size (mm): along the normal of a planar face, or in
    30 % of draws across an outer cylinder when the part has one (a cross hole)."""
    r = _hole_radius(w, rng, cfg)
    if rng.random() < 0.3:  # a cross hole through a cylinder
        rs = _radial_site(w, rng, r, cfg)
        if rs is not None:
            return w.solid - rs[0] * _hole_tool(w, r, cfg), {"radius": r, "on": "cylinder"}
    site = find_site(w, rng, r, cfg)
    if site is None:
        return None
    return w.solid - site.location() * _hole_tool(w, r, cfg), {"radius": r, "on": "plane"}


def f_blind_hole(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A blind hole (radius as `f_through_hole`) 30-75 % of the material below the wall deep (less the
    drill point), flat-bottomed or with a 118-degree drill point (cone); in 30 % of draws radial into an outer
    cylinder when the part has one (a set-screw hole)."""
    r = _hole_radius(w, rng, cfg)
    drill_point = bool(rng.random() < 0.5)
    tip = r / math.tan(math.radians(59.0)) if drill_point else 0.0
    frac = _u(rng, 0.3, 0.75)
    frame, room, on = None, 0.0, "plane"
    if rng.random() < 0.3:  # a radial hole in a cylinder (a set-screw hole)
        rs = _radial_site(w, rng, r, cfg)
        if rs is not None:
            frame, room, on = rs[0], rs[1], "cylinder"
    if frame is None:
        site = find_site(w, rng, r, cfg)
        if site is None:
            return None
        frame, room = site.location(), site.depth
    depth = frac * (room - cfg.wall_mm) - tip
    if depth < cfg.min_size_mm:
        return None
    tool = _cyl(r, -depth, cfg.overshoot_mm)
    if drill_point:
        tool = tool + _cone(0.0, r, -depth - tip, -depth)
    return w.solid - frame * tool, {"radius": r, "depth": depth, "drill_point": drill_point, "on": on}


def f_counterbore(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A through hole with a coaxial bore 1.5-2 times its radius, 20-50 % of the material depth deep
    (two cylinders and the annular plane between them)."""
    r = _hole_radius(w, rng, cfg)
    rc = r * _u(rng, 1.5, 2.0)
    site = find_site(w, rng, rc, cfg)
    if site is None:
        return None
    depth = _u(rng, 0.2, 0.5) * site.depth
    if depth < cfg.min_size_mm:
        return None
    tool = _hole_tool(w, r, cfg) + _cyl(rc, -depth, cfg.overshoot_mm)
    return w.solid - site.location() * tool, {"radius": r, "counterbore_radius": rc, "counterbore_depth": depth}


def f_countersink(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A through hole with a 90-degree conical sink whose rim radius is 1.5-2 times the hole's (cone)."""
    r = _hole_radius(w, rng, cfg)
    rs = r * _u(rng, 1.5, 2.0)
    site = find_site(w, rng, rs, cfg)
    if site is None or rs - r > 0.5 * site.depth:
        return None
    o = cfg.overshoot_mm
    # 90-degree sink: the radius grows by the depth; the cone continues `o` above the face.
    tool = _hole_tool(w, r, cfg) + _cone(r, rs + o, -(rs - r), o)
    return w.solid - site.location() * tool, {"radius": r, "sink_radius": rs, "half_angle_deg": 45.0}


def f_boss(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A cylinder of radius 6-18 % and height 8-35 % of the part size standing on a planar face."""
    r = max(cfg.min_size_mm * 2, _u(rng, 0.06, 0.18) * w.size)
    h = max(cfg.min_size_mm, _u(rng, 0.08, 0.35) * w.size)
    site = find_site(w, rng, r, cfg)
    if site is None:
        return None
    return w.solid + site.location() * _cyl(r, 0.0, h), {"radius": r, "height": h}


def f_pocket(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A rounded-rectangle pocket 15-40 % by 10-30 % of the part size, 20-60 % of the material below the
    wall deep; turned by a multiple of 90 degrees (60 % of draws) or at random about the face normal."""
    a, b = _u(rng, 0.15, 0.4) * w.size, _u(rng, 0.1, 0.3) * w.size
    rc = _u(rng, 0.1, 0.4) * min(a, b)
    site = find_site(w, rng, 0.5 * math.hypot(a, b), cfg)
    if site is None:
        return None
    depth = _u(rng, 0.2, 0.6) * (site.depth - cfg.wall_mm)
    if depth < cfg.min_size_mm:
        return None
    angle = 0.5 * math.pi * int(rng.integers(4)) if rng.random() < 0.6 else _u(rng, 0, math.pi)
    tool = Pos(0, 0, -depth) * extrude(RectangleRounded(a, b, rc), depth + cfg.overshoot_mm)
    return w.solid - site.location(angle) * tool, {"length": a, "width": b, "corner_radius": rc, "depth": depth}


def f_slot(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """An obround slot 5-15 % of the part size wide, through the part (30 % of draws) or blind."""
    width = max(2 * cfg.min_size_mm, _u(rng, 0.05, 0.15) * w.size)
    length = width + _u(rng, 0.1, 0.4) * w.size
    site = find_site(w, rng, 0.5 * length, cfg)
    if site is None:
        return None
    through = bool(rng.random() < 0.3)
    depth = 4 * w.size if through else _u(rng, 0.2, 0.6) * (site.depth - cfg.wall_mm)
    if depth < cfg.min_size_mm:
        return None
    angle = 0.5 * math.pi * int(rng.integers(4)) if rng.random() < 0.6 else _u(rng, 0, math.pi)
    tool = Pos(0, 0, -depth) * extrude(SlotOverall(length, width), depth + cfg.overshoot_mm)
    return w.solid - site.location(angle) * tool, {"length": length, "width": width, "depth": depth, "through": through}


def f_rib(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A thin wall (3-8 % of the part size thick, 10-30 % high) standing on a planar face."""
    length = _u(rng, 0.2, 0.5) * w.size
    thick = max(cfg.min_size_mm, _u(rng, 0.03, 0.08) * w.size)
    height = _u(rng, 0.1, 0.3) * w.size
    site = find_site(w, rng, 0.5 * math.hypot(length, thick), cfg)
    if site is None:
        return None
    angle = 0.5 * math.pi * int(rng.integers(4)) if rng.random() < 0.7 else _u(rng, 0, math.pi)
    tool = Box(length, thick, height, align=_BASE)
    return w.solid + site.location(angle) * tool, {"length": length, "thickness": thick, "height": height}


def f_step(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A box cut off one side of the part (along X or Y) from its top: 15-40 % of the width, 20-60 % of
    the height (two planes)."""
    bb = w.solid.bounding_box()
    lo, hi = np.array([bb.min.X, bb.min.Y, bb.min.Z]), np.array([bb.max.X, bb.max.Y, bb.max.Z])
    k = int(rng.integers(2))  # cut along X or Y
    side = 1 if rng.random() < 0.5 else -1
    span = hi[k] - lo[k]
    width = _u(rng, 0.15, 0.4) * span
    depth = _u(rng, 0.2, 0.6) * (hi[2] - lo[2])
    o = cfg.overshoot_mm
    ext = hi - lo + 4 * o
    size = ext.copy()
    size[k] = width + o
    size[2] = depth + o
    centre = 0.5 * (lo + hi)
    centre[k] = (hi[k] - width + 0.5 * (width + o)) if side > 0 else (lo[k] + width - 0.5 * (width + o))
    centre[2] = hi[2] - depth + 0.5 * (depth + o)
    tool = Pos(*centre) * Box(*size)
    return w.solid - tool, {"axis": "XY"[k], "side": side, "width": width, "depth": depth}


def f_groove(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """An annular groove in a full outer cylinder: square (planes and a cylinder) or, in 35 % of draws,
    round (a torus tube centred on the surface, an O-ring groove)."""
    cands = [c for c in cylinder_sites(w.shape) if c.full and c.radius > 3 * cfg.wall_mm]
    if not cands:
        return None
    c = cands[int(rng.integers(len(cands)))]
    v0, v1 = c.v_range
    width = min(_u(rng, 0.15, 0.4) * (v1 - v0), 0.2 * w.size)
    depth = _u(rng, 0.1, 0.3) * c.radius
    if v1 - v0 < width + 2 * cfg.wall_mm or min(width, depth) < 0.5 * cfg.min_size_mm:
        return None
    v = _u(rng, v0 + cfg.wall_mm + 0.5 * width, v1 - cfg.wall_mm - 0.5 * width)
    loc = Location(Plane(origin=tuple(c.centre + v * c.axis), x_dir=tuple(c.xdir), z_dir=tuple(c.axis)))
    o = cfg.overshoot_mm
    if rng.random() < 0.35:  # round (O-ring) groove: a torus tube centred on the surface
        rt = min(0.5 * width, depth)
        tool = Torus(c.radius, rt)
        params = {"shape": "round", "radius": c.radius, "tube_radius": rt}
    else:
        ring = Cylinder(c.radius + o, width, align=(_C, _C, _C)) - Cylinder(
            c.radius - depth, width + 2 * o, align=(_C, _C, _C)
        )
        tool = ring
        params = {"shape": "square", "radius": c.radius, "width": width, "depth": depth}
    return w.solid - loc * tool, params


def _edge_faces(shape: TopoDS_Shape) -> TopTools_IndexedDataMapOfShapeListOfShape:
    m = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, m)
    return m


def _face_span(face: TopoDS_Face) -> float:
    """Second-largest side of the face's bounding box (mm): a rough width of the face."""
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib

    box = Bnd_Box()
    BRepBndLib.Add_s(face, box)
    lo, hi = box.CornerMin(), box.CornerMax()
    return float(sorted([hi.X() - lo.X(), hi.Y() - lo.Y(), hi.Z() - lo.Z()])[1])


def blend_edges(shape: TopoDS_Shape) -> list[tuple]:
    """Edges whose blend stays analytic: (edge, face1, face2, kind, limit mm) where kind is 'line' (between two
    non-parallel planes: a fillet is a cylinder, a chamfer a plane) or 'circle' (a plane and a coaxial cylinder or
    cone: a torus or a cone), and limit bounds the blend size by the faces' widths and the circle radius."""
    out = []
    m = _edge_faces(shape)
    for i in range(1, m.Extent() + 1):
        edge = TopoDS.Edge_s(m.FindKey(i))
        faces = [TopoDS.Face_s(f) for f in m.FindFromIndex(i)]
        if len(faces) != 2 or faces[0].IsSame(faces[1]):
            continue  # seam or free edge
        curve = BRepAdaptor_Curve(edge)
        s1, s2 = BRepAdaptor_Surface(faces[0]), BRepAdaptor_Surface(faces[1])
        t1, t2 = s1.GetType(), s2.GetType()
        limit = min(_face_span(faces[0]), _face_span(faces[1]))
        if curve.GetType() == GeomAbs_Line and t1 == GeomAbs_Plane and t2 == GeomAbs_Plane:
            n1, n2 = _vec(s1.Plane().Axis().Direction()), _vec(s2.Plane().Axis().Direction())
            if abs(n1 @ n2) > math.cos(math.radians(15)):
                continue  # nearly tangent planes: a blend would be a sliver
            out.append((edge, faces[0], faces[1], "line", limit))
        elif curve.GetType() == GeomAbs_Circle and {t1, t2} in (
            {GeomAbs_Plane, GeomAbs_Cylinder},
            {GeomAbs_Plane, GeomAbs_Cone},
        ):
            circ = curve.Circle()
            ax = _vec(circ.Axis().Direction())
            other = s2 if t1 == GeomAbs_Plane else s1
            oax = other.Cylinder().Axis() if other.GetType() == GeomAbs_Cylinder else other.Cone().Axis()
            if abs(_vec(oax.Direction()) @ ax) < 1 - 1e-9:
                continue
            out.append((edge, faces[0], faces[1], "circle", min(limit, float(circ.Radius()))))
    return out


def _blend(w: Work, rng: np.random.Generator, cfg: FeatureConfig, chamfer: bool) -> FeatureResult:
    cands = blend_edges(w.shape)
    if not cands:
        return None
    edge, _, _, kind, limit = cands[int(rng.integers(len(cands)))]
    size = _u(rng, 0.08, 0.3) * limit
    if size < cfg.min_size_mm * 0.5:
        return None
    if chamfer:
        mk = BRepFilletAPI_MakeChamfer(w.shape)
        mk.Add(size, edge)
    else:
        mk = BRepFilletAPI_MakeFillet(w.shape)
        mk.Add(size, edge)
    mk.Build()
    if not mk.IsDone():
        raise RuntimeError("blend failed")
    return mk.Shape(), {("distance" if chamfer else "radius"): size, "edge": kind}


def f_fillet(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A constant-radius fillet of a line or circle edge of `blend_edges` (a cylinder or a torus)."""
    return _blend(w, rng, cfg, chamfer=False)


def f_chamfer(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """An equal-distance chamfer of a line or circle edge of `blend_edges` (a plane or a cone)."""
    return _blend(w, rng, cfg, chamfer=True)


def _cap(w: Work, rng: np.random.Generator, cfg: FeatureConfig, ball: bool) -> FeatureResult:
    discs = disc_sites(w.shape)
    if not discs:
        return None
    d = discs[int(rng.integers(len(discs)))]
    R = d.radius
    rs = R if ball else R * _u(rng, 1.15, 2.5)
    h = rs - math.sqrt(max(rs * rs - R * R, 0.0))  # cap height above the disc
    o = cfg.overshoot_mm
    loc = Location(Plane(origin=tuple(d.centre), z_dir=tuple(d.normal)))
    # The sphere cut at the disc's plane: its base circle is the disc's rim.
    cap = (Pos(0, 0, h - rs) * Sphere(rs)) & Box(2 * rs + 2 * o, 2 * rs + 2 * o, h + o, align=_BASE)
    return w.solid + loc * cap, {"sphere_radius": rs, "disc_radius": R, "height": h}


def f_dome(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A spherical cap on a disc face (the end of a cylinder), its sphere radius 1.15-2.5 times the
    disc's: a sharp rim."""
    return _cap(w, rng, cfg, ball=False)


def f_ball_end(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A hemisphere on a disc face with the disc's radius, tangent to its cylinder."""
    return _cap(w, rng, cfg, ball=True)


def _pattern_member(
    w: Work, rng: np.random.Generator, cfg: FeatureConfig
) -> tuple[str, float, float, Callable[[float], Solid]]:
    """One member feature of a pattern: (kind, clearance radius mm, radius of its cylinder faces mm,
    builder(material depth mm) -> the member's tool in the site's local frame)."""
    kind = str(rng.choice(["through_hole", "blind_hole", "boss", "slot"]))
    r = max(cfg.min_size_mm, _u(rng, 0.02, 0.05) * w.size)
    if kind == "through_hole":
        return kind, r, r, lambda depth: _hole_tool(w, r, cfg)
    if kind == "blind_hole":
        frac = _u(rng, 0.3, 0.7)
        return kind, r, r, lambda depth: _cyl(r, -frac * (depth - cfg.wall_mm), cfg.overshoot_mm)
    if kind == "boss":
        h = _u(rng, 0.05, 0.2) * w.size
        return kind, 1.5 * r, 1.5 * r, lambda depth: _cyl(1.5 * r, 0.0, h)
    length, width = 4 * r, 1.6 * r  # a short slot along the local X axis
    frac = _u(rng, 0.3, 0.7)
    return (
        kind,
        2 * r,
        0.5 * width,
        lambda depth: (
            Pos(0, 0, -frac * (depth - cfg.wall_mm))
            * extrude(SlotOverall(length, width), frac * (depth - cfg.wall_mm) + cfg.overshoot_mm)
        ),
    )


def f_linear_pattern(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A row of 2-5 equal members (`_pattern_member`: through or blind holes, bosses, slots) on one planar
    face, at a pitch of 2.6-5 times a member's clearance radius."""
    kind, rc, radius, build = _pattern_member(w, rng, cfg)
    n = int(rng.integers(2, 6))
    pitch = rc * 2 * _u(rng, 1.3, 2.5)
    half = 0.5 * (n - 1) * pitch
    site = find_site(w, rng, half + rc, cfg)
    if site is None:
        return None
    angle = 0.5 * math.pi * int(rng.integers(4)) if rng.random() < 0.7 else _u(rng, 0, math.pi)
    centres = [site.point(-half + i * pitch, 0.0, angle) for i in range(n)]
    depth = _depth_along(w.shape, centres, -site.normal)
    if depth <= 2 * cfg.wall_mm:
        return None
    frame = site.location(angle)
    tools = [frame * (Pos(-half + i * pitch, 0, 0) * build(depth)) for i in range(n)]
    new = w.solid + tools if kind == "boss" else w.solid - tools
    return new, {"of": kind, "count": n, "pitch": pitch, "member_radius": radius}


def f_circular_pattern(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """Holes, bosses or slots on a bolt circle of one planar face (3-8 members), or flutes around a
    full outer cylinder when the part has one (6-18 concave cylinders; share ``w.data['flute_share']`` of draws,
    default 40 %)."""
    cyls = [
        c
        for c in cylinder_sites(w.shape)
        if c.full and c.radius > 4 * cfg.wall_mm and c.v_range[1] - c.v_range[0] > 2 * cfg.wall_mm
    ]
    if cyls and rng.random() < w.data.get("flute_share", 0.4):  # flutes around a cylinder (knurl-like when many)
        c = cyls[int(rng.integers(len(cyls)))]
        n = int(rng.integers(6, 19))
        rf = min(_u(rng, 0.3, 0.8) * math.pi * c.radius / n, 0.3 * c.radius)
        v0, v1 = c.v_range
        o = cfg.overshoot_mm
        loc = Location(Plane(origin=tuple(c.centre), x_dir=tuple(c.xdir), z_dir=tuple(c.axis)))
        tools = []
        for i in range(n):
            a = 2 * math.pi * i / n
            tools.append(
                loc
                * (
                    Pos(c.radius * math.cos(a), c.radius * math.sin(a), v0 - o)
                    * Cylinder(rf, v1 - v0 + 2 * o, align=_BASE)
                )
            )
        return w.solid - tools, {"of": "flute", "count": n, "member_radius": rf, "circle_radius": c.radius}
    kind, rc, radius, build = _pattern_member(w, rng, cfg)
    n = int(rng.integers(3, 9))
    rb = max(rc / math.sin(math.pi / n) * _u(rng, 1.2, 2.0), 2 * rc)
    site = find_site(w, rng, rb + rc, cfg)
    if site is None:
        return None
    phase = _u(rng, 0, 2 * math.pi)
    pts = [
        site.point(rb * math.cos(phase + 2 * math.pi * i / n), rb * math.sin(phase + 2 * math.pi * i / n))
        for i in range(n)
    ]
    depth = _depth_along(w.shape, pts, -site.normal)
    if depth <= 2 * cfg.wall_mm:
        return None
    frame = site.location()
    tools = [
        frame
        * (
            Pos(rb * math.cos(phase + 2 * math.pi * i / n), rb * math.sin(phase + 2 * math.pi * i / n), 0)
            * Rot(0, 0, math.degrees(phase + 2 * math.pi * i / n))
            * build(depth)
        )
        for i in range(n)
    ]
    new = w.solid + tools if kind == "boss" else w.solid - tools
    return new, {"of": kind, "count": n, "circle_radius": rb, "member_radius": radius}


def f_union(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A box or a half-buried lying cylinder joined to a planar face (15-40 % of the part size long)."""
    a = _u(rng, 0.15, 0.4) * w.size
    site = find_site(w, rng, 0.5 * a, cfg)
    if site is None:
        return None
    angle = _u(rng, 0, math.pi) if rng.random() < 0.4 else 0.5 * math.pi * int(rng.integers(4))
    if rng.random() < 0.5:
        b, h = _u(rng, 0.3, 1.0) * a, _u(rng, 0.1, 0.3) * w.size
        tool = Box(a, b, h, align=_BASE)
        params = {"primitive": "box", "size": [a, b, h]}
    else:  # a lying cylinder half buried in the face (axis in the face plane)
        r = _u(rng, 0.15, 0.35) * a
        tool = Rot(0, 90, 0) * Cylinder(r, a, align=(_C, _C, _C))
        params = {"primitive": "cylinder", "radius": r, "length": a}
    return w.solid + site.location(angle) * tool, params


def f_cut(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """A tilted box (a bevelled notch), a lying cylinder (a channel) or a sphere (a dimple) cut 15-50 % of
    the material below the wall deep into a planar face."""
    choice = str(rng.choice(["box", "cylinder", "sphere"]))
    a = _u(rng, 0.15, 0.4) * w.size
    site = find_site(w, rng, 0.5 * a, cfg)
    if site is None:
        return None
    depth = _u(rng, 0.15, 0.5) * (site.depth - cfg.wall_mm)
    if depth < cfg.min_size_mm:
        return None
    angle = _u(rng, 0, math.pi)
    if choice == "box":  # a box tilted about its long axis: a bevelled notch with unaligned planes
        tilt = _u(rng, 10, 35)
        tool = Pos(0, 0, -depth) * Rot(tilt, 0, 0) * Box(a, a, a, align=_BASE)
        params = {"primitive": "box", "size": a, "tilt_deg": tilt, "depth": depth}
    elif choice == "cylinder":  # a channel: a lying cylinder whose lowest line is `depth` below the face
        r = max(depth, _u(rng, 0.5, 1.0) * 0.5 * a)
        tool = Pos(0, 0, r - depth) * Rot(0, 90, 0) * Cylinder(r, 4 * w.size, align=(_C, _C, _C))
        params = {"primitive": "cylinder", "radius": r, "depth": depth}
    else:  # a spherical dimple of chord radius a / 2
        c = 0.5 * a
        rs = (c * c + depth * depth) / (2 * depth)
        tool = Pos(0, 0, rs - depth) * Sphere(rs)
        params = {"primitive": "sphere", "radius": rs, "depth": depth}
    return w.solid - site.location(angle) * tool, params


FEATURES: dict[str, Callable[[Work, np.random.Generator, FeatureConfig], FeatureResult]] = {
    "through_hole": f_through_hole,
    "blind_hole": f_blind_hole,
    "counterbore": f_counterbore,
    "countersink": f_countersink,
    "boss": f_boss,
    "pocket": f_pocket,
    "slot": f_slot,
    "rib": f_rib,
    "step": f_step,
    "groove": f_groove,
    "fillet": f_fillet,
    "chamfer": f_chamfer,
    "dome": f_dome,
    "ball_end": f_ball_end,
    "linear_pattern": f_linear_pattern,
    "circular_pattern": f_circular_pattern,
    "union": f_union,
    "cut": f_cut,
}
assert tuple(FEATURES) == FEATURE_KINDS


def apply_feature(
    w: Work,
    kind: str,
    rng: np.random.Generator,
    cfg: FeatureConfig = FeatureConfig(),
    op: Callable[[Work, np.random.Generator, FeatureConfig], FeatureResult] | None = None,
) -> dict | None:
    """Try feature `kind` on `w`; on success replace `w.solid`, record it and return its parameters.

    `op` replaces the kind's own operation (a family's fixed feature recorded under a standard kind). A feature
    that does not apply (no room), whose OCCT operation fails, or whose result is not an acceptable part
    (`shape_problem`) or equals the input is skipped: `w` is unchanged, the reason is appended to `w.skipped` and
    None returned.
    """
    if kind in BLEND_KINDS and w.blends >= cfg.max_blends:
        w.skipped.append(f"{kind}: blend budget used")
        return None
    try:
        out = (op or FEATURES[kind])(w, rng, cfg)
    except Exception as exc:  # noqa: BLE001 - an OCCT boolean/blend failure: skip this feature, try the next
        w.skipped.append(f"{kind}: OCCT failed ({type(exc).__name__})")
        return None
    if out is None:
        w.skipped.append(f"{kind}: no room")
        return None
    new, params = out
    solid = _as_solid(new)
    problem = shape_problem(solid.wrapped, cfg) if solid is not None else "not one solid"
    if problem is None:
        before, after = volume(w.shape), volume(solid.wrapped)
        if abs(after - before) <= cfg.min_volume_change * before:
            problem = "no change"
    if problem is not None:
        w.skipped.append(f"{kind}: {problem}")
        return None
    if kind in BLEND_KINDS:
        w.blends += 1
    w.solid = solid
    w.features.append(kind)
    record = {"kind": kind, **params}
    w.params.append(record)
    return record


# ---- stocks ------------------------------------------------------------------------------------------------------


def _round_corners(
    pts: list[np.ndarray],
    rng: np.random.Generator,
    p_round: float,
    p_chamfer: float,
    size_frac: tuple[float, float] = (0.1, 0.35),
    sharp: tuple[int, ...] = (),
) -> list[tuple]:
    """Closed 2-D outline -> segments: ("line", a, b) or ("arc", a, mid, b); some corners rounded by a tangent arc
    or cut by a chamfer of a drawn size (fraction of the shorter adjacent side). Corners in `sharp` stay sharp."""
    n = len(pts)
    ins: list[np.ndarray] = []  # point where the outline enters corner i
    outs: list[np.ndarray] = []  # point where it leaves corner i
    arcs: list[np.ndarray | None] = []
    for i in range(n):
        p, prev, nxt = pts[i], pts[i - 1], pts[(i + 1) % n]
        a, b = p - prev, nxt - p
        la, lb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
        a, b = a / la, b / lb
        turn = math.acos(float(np.clip(a @ b, -1, 1)))  # exterior angle
        roll = rng.random()
        frac = _u(rng, *size_frac)
        if i in sharp or turn < math.radians(10) or roll >= p_round + p_chamfer:
            ins.append(p)
            outs.append(p)
            arcs.append(None)
            continue
        # Tangent length: frac (< 0.5) of half the shorter side, so the two blends of one side never overlap.
        t = frac * 0.5 * min(la, lb)
        t1, t2 = p - a * t, p + b * t
        ins.append(t1)
        outs.append(t2)
        if roll < p_round:
            r = t / math.tan(0.5 * turn)
            bis = b - a
            bis /= np.linalg.norm(bis)
            # The centre lies on the side the outline turns to, along (b - a) from the corner, at r / cos(turn / 2).
            centre = p + bis * (r / math.cos(0.5 * turn))
            mid = centre + (p - centre) / np.linalg.norm(p - centre) * r
            arcs.append(mid)
        else:
            arcs.append(None)
    segs: list[tuple] = []
    for i in range(n):
        if not np.allclose(ins[i], outs[i]):
            segs.append(("arc", ins[i], arcs[i], outs[i]) if arcs[i] is not None else ("line", ins[i], outs[i]))
        segs.append(("line", outs[i], ins[(i + 1) % n]))
    return segs


def _edges_2d(segs: list[tuple], plane: str = "XY") -> list[Edge]:
    def v(p: np.ndarray) -> Vector:
        return Vector(p[0], p[1], 0.0) if plane == "XY" else Vector(p[0], 0.0, p[1])

    out = []
    for s in segs:
        if s[0] == "line":
            out.append(Edge.make_line(v(s[1]), v(s[2])))
        else:
            out.append(Edge.make_three_point_arc(v(s[1]), v(s[2]), v(s[3])))
    return out


def _bulge(segs: list[tuple], rng: np.random.Generator, p: float) -> list[tuple]:
    """Replace some straight segments by circular arcs through the same end points (bulging out or in)."""
    out = []
    for s in segs:
        if s[0] == "line" and rng.random() < p:
            a, b = s[1], s[2]
            d = b - a
            length = float(np.linalg.norm(d))
            normal = np.array([d[1], -d[0]]) / length  # right of the direction: outward for a CCW outline
            mid = 0.5 * (a + b) + normal * _u(rng, -0.12, 0.2) * length
            out.append(("arc", a, mid, b))
        else:
            out.append(s)
    return out


def _outline(rng: np.random.Generator, L: float, W: float) -> tuple[str, list[np.ndarray]]:
    """A counter-clockwise outline centred near the origin: rectangle, L, T, U or a star-shaped polygon."""
    kind = str(rng.choice(["rect", "L", "T", "U", "star"], p=[0.35, 0.2, 0.15, 0.15, 0.15]))
    a, b = _u(rng, 0.3, 0.6), _u(rng, 0.3, 0.6)
    if kind == "rect":
        pts = [(0, 0), (L, 0), (L, W), (0, W)]
    elif kind == "L":
        pts = [(0, 0), (L, 0), (L, a * W), (b * L, a * W), (b * L, W), (0, W)]
    elif kind == "T":
        c0, c1 = 0.5 * L * (1 - b), 0.5 * L * (1 + b)
        pts = [(c0, 0), (c1, 0), (c1, a * W), (L, a * W), (L, W), (0, W), (0, a * W), (c0, a * W)]
    elif kind == "U":
        c0, c1 = 0.5 * L * (1 - b), 0.5 * L * (1 + b)
        pts = [(0, 0), (L, 0), (L, W), (c1, W), (c1, a * W), (c0, a * W), (c0, W), (0, W)]
    else:
        n = int(rng.integers(5, 9))
        # Star-shaped (so simple): evenly spread directions jittered by up to 30 % of their spacing.
        ang = (np.arange(n) + rng.uniform(-0.3, 0.3, n)) * 2 * math.pi / n
        rad = rng.uniform(0.6, 1.0, n)
        pts = [(0.5 * L * r * math.cos(t), 0.5 * W * r * math.sin(t)) for r, t in zip(rad, ang, strict=True)]
    arr = [np.array(p, float) for p in pts]
    centre = 0.5 * (np.min(arr, axis=0) + np.max(arr, axis=0))
    return kind, [p - centre for p in arr]


def stock_extrude(rng: np.random.Generator, L: float, W: float, H: float) -> tuple[Solid, dict]:
    """A sketch of lines and arcs (outline of `_outline`, corners rounded or chamfered, sides bulged) extruded by H
    (mm) along +Z from z = 0."""
    kind, pts = _outline(rng, L, W)
    segs = _round_corners(pts, rng, p_round=0.35, p_chamfer=0.15)
    segs = _bulge(segs, rng, 0.25 if kind in ("rect", "star") else 0.0)
    face = Face(Wire(_edges_2d(segs)))
    solid = extrude(face, H)
    arcs = sum(s[0] == "arc" for s in segs)
    return _as_solid(solid), {
        "stock": "extrude",
        "outline": kind,
        "L": L,
        "W": W,
        "H": H,
        "segments": len(segs),
        "arcs": arcs,
    }


def stock_polygon(rng: np.random.Generator, n: int, across_flats: float, length: float) -> tuple[Solid, dict]:
    """Regular n-gon bar of `across_flats` (mm) standing along +Z from 0 to `length`, one side normal to -Y."""
    R = 0.5 * across_flats / math.cos(math.pi / n)
    theta0 = -0.5 * math.pi + math.pi / n  # vertices at +-180/n about -Y: a flat faces -Y
    pts = [
        np.array([R * math.cos(theta0 + 2 * math.pi * k / n), R * math.sin(theta0 + 2 * math.pi * k / n)])
        for k in range(n)
    ]
    segs = [("line", pts[k], pts[(k + 1) % n]) for k in range(n)]
    solid = extrude(Face(Wire(_edges_2d(segs))), length)
    return _as_solid(solid), {"stock": "polygon", "sides": n, "across_flats": across_flats, "length": length}


def _revolve_profile(
    pts: list[np.ndarray], rng: np.random.Generator, p_round: float, p_chamfer: float
) -> tuple[Solid, int]:
    """Revolve a closed (r, z) outline whose first and last points lie on the axis (r = 0) about Z."""
    # Corners on the axis are kept sharp (a blend there would leave the axis); the rest may be rounded.
    segs = _round_corners(pts, rng, p_round, p_chamfer, size_frac=(0.1, 0.4), sharp=(0, len(pts) - 1))
    fixed = []
    for s in segs:  # snap end points on the axis to exactly r = 0 (a revolved edge near the axis is degenerate)
        fixed.append(tuple(np.where(np.abs(x) < 1e-9, 0.0, x) if isinstance(x, np.ndarray) else x for x in s))
    solid = revolve(Face(Wire(_edges_2d(fixed, plane="XZ"))), Axis.Z, 360)
    return _as_solid(solid), sum(s[0] == "arc" for s in fixed)


def stock_turned(
    rng: np.random.Generator,
    n_steps: int,
    r_range: tuple[float, float],
    h_range: tuple[float, float],
    taper: float = 0.3,
) -> tuple[Solid, dict]:
    """A turned profile: `n_steps` sections of random radius and height (mm), joined by shoulders or tapers
    (cones), corners rounded (tori) or chamfered (cones); revolved about Z, base at z = 0."""
    radii = rng.uniform(*r_range, n_steps)
    heights = rng.uniform(*h_range, n_steps)
    pts = [np.array([0.0, 0.0])]
    z = 0.0
    for i in range(n_steps):
        r = float(radii[i])
        if i == 0:
            pts.append(np.array([r, 0.0]))
        elif rng.random() < taper:  # a taper: the previous section's top goes straight to this radius
            z += 0.3 * heights[i]
        else:
            pts.append(np.array([r, z]))
        z += float(heights[i])
        pts.append(np.array([r, z]))
    pts.append(np.array([0.0, z]))
    # Drop collinear points (two sections of equal radius) so every corner is a real corner.
    keep = [pts[0]]
    for i in range(1, len(pts) - 1):
        a, b = pts[i] - keep[-1], pts[i + 1] - pts[i]
        if abs(a[0] * b[1] - a[1] * b[0]) > 1e-9 * (np.linalg.norm(a) * np.linalg.norm(b) + 1e-12):
            keep.append(pts[i])
    keep.append(pts[-1])
    solid, arcs = _revolve_profile(keep, rng, 0.3, 0.25)
    return solid, {"stock": "turned", "sections": n_steps, "radii": radii.tolist(), "height": z, "arcs": arcs}


def stock_pillow_block(rng: np.random.Generator) -> tuple[Solid, dict, dict]:
    """Pillow-block body (mm): base plate along X, a housing cylinder along Y on a pedestal, a bore through it.

    Returns the solid, its parameters and the hole sites' data (base top z, hole x positions)."""
    L = _u(rng, 80, 150)
    Wb = _u(rng, 25, 50)
    Hb = _u(rng, 8, 18)
    Rh = _u(rng, 0.18, 0.28) * L
    Wh = _u(rng, 0.7, 1.0) * Wb
    Hc = Hb + Rh * _u(rng, 0.5, 1.1)  # housing axis height
    Rb = _u(rng, 0.45, 0.7) * Rh
    ped = _u(rng, 1.4, 2.0) * Rh
    base = Box(L, Wb, Hb, align=_BASE)
    pedestal = Box(ped, Wh, Hc, align=_BASE)
    housing = Pos(0, 0, Hc) * Rot(90, 0, 0) * Cylinder(Rh, Wh, align=(_C, _C, _C))
    body = base + pedestal + housing
    body = body - Pos(0, 0, Hc) * Rot(90, 0, 0) * Cylinder(Rb, Wb + 10, align=(_C, _C, _C))
    return (
        _as_solid(body),
        {
            "stock": "pillow_block",
            "L": L,
            "W": Wb,
            "base_height": Hb,
            "housing_radius": Rh,
            "axis_height": Hc,
            "bore_radius": Rb,
        },
        {"L": L, "ped": ped, "Hb": Hb, "Wb": Wb},
    )


# ---- families ----------------------------------------------------------------------------------------------------

# Relative weights of the random features per family (kinds that cannot apply just get skipped).
_W_PRISMATIC = {
    "through_hole": 3,
    "blind_hole": 2,
    "counterbore": 2,
    "countersink": 1,
    "boss": 2,
    "pocket": 2,
    "slot": 2,
    "rib": 1,
    "step": 1.5,
    "groove": 0.5,
    "fillet": 2,
    "chamfer": 2,
    "dome": 0.5,
    "ball_end": 0.3,
    "linear_pattern": 1.5,
    "circular_pattern": 1,
    "union": 1,
    "cut": 1.5,
}
_W_PLATE = {
    **_W_PRISMATIC,
    "step": 0.5,
    "rib": 1.5,
    "union": 0.5,
    "linear_pattern": 2.5,
    "circular_pattern": 2,
    "boss": 1,
    "groove": 0.2,
}
_W_TURNED = {
    "through_hole": 2,
    "blind_hole": 2,
    "counterbore": 1,
    "countersink": 1,
    "boss": 0.5,
    "pocket": 0.5,
    "slot": 1,
    "rib": 0.3,
    "step": 1,
    "groove": 3,
    "fillet": 1.5,
    "chamfer": 2,
    "dome": 1.5,
    "ball_end": 1,
    "linear_pattern": 0.5,
    "circular_pattern": 2.5,
    "union": 0.5,
    "cut": 1,
}


def _draw_kinds(rng: np.random.Generator, weights: dict[str, float], cfg: FeatureConfig) -> list[str]:
    names = list(weights)
    p = np.array([weights[k] for k in names], float)
    n = int(rng.integers(cfg.n_features[0], cfg.n_features[1] + 1))
    return [names[int(i)] for i in rng.choice(len(names), size=n, p=p / p.sum())]


def _fam_prismatic(rng: np.random.Generator, cfg: FeatureConfig) -> tuple[Work, list[str]]:
    L = _u(rng, 50, 130)
    W = _u(rng, 0.4, 1.0) * L
    H = _u(rng, 10, 45)
    solid, info = stock_extrude(rng, L, W, H)
    return Work(solid, "feat_prismatic", min(L, W), info), _draw_kinds(rng, _W_PRISMATIC, cfg)


def _fam_plate(rng: np.random.Generator, cfg: FeatureConfig) -> tuple[Work, list[str]]:
    L = _u(rng, 60, 150)
    W = _u(rng, 0.35, 0.9) * L
    H = _u(rng, 4, 12)
    solid, info = stock_extrude(rng, L, W, H)
    kinds = ["linear_pattern" if rng.random() < 0.5 else "circular_pattern", *_draw_kinds(rng, _W_PLATE, cfg)]
    return Work(solid, "feat_plate", min(L, W), info), kinds


def _fam_turned(rng: np.random.Generator, cfg: FeatureConfig) -> tuple[Work, list[str]]:
    n = int(rng.integers(2, 5))
    solid, info = stock_turned(rng, n, (8, 35), (8, 35))
    size = 2 * max(info["radii"])
    w = Work(solid, "feat_turned", size, info, lying=bool(rng.random() < 0.35))
    return w, _draw_kinds(rng, _W_TURNED, cfg)


def _fam_hex(rng: np.random.Generator, cfg: FeatureConfig) -> tuple[Work, list[str]]:
    n = 6 if rng.random() < 0.6 else int(rng.choice([3, 4, 5, 8]))
    af = _u(rng, 20, 60)
    length = _u(rng, 0.4, 2.5) * af
    solid, info = stock_polygon(rng, n, af, length)
    w = Work(solid, "feat_hex", af, info, lying=bool(rng.random() < 0.5))
    # Bar stock is drilled along its axis more often than not (a nut, a spacer, a standoff).
    kinds = (["through_hole"] if rng.random() < 0.5 else []) + _draw_kinds(rng, _W_PRISMATIC, cfg)
    return w, kinds


def _fam_knob(rng: np.random.Generator, cfg: FeatureConfig) -> tuple[Work, list[str]]:
    rb = _u(rng, 12, 35)
    hb = _u(rng, 6, 20)
    rt = rb * _u(rng, 0.5, 0.9)
    ht = _u(rng, 6, 25)
    top = float(hb + 0.3 * ht + ht)
    pts = [
        np.array([0.0, 0.0]),
        np.array([rb, 0.0]),
        np.array([rb, hb]),
        np.array([rt, hb + 0.3 * ht]),
        np.array([rt, top]),
        np.array([0.0, top]),
    ]
    solid, arcs = _revolve_profile(pts, rng, 0.4, 0.2)
    info = {"stock": "knob", "base_radius": rb, "top_radius": rt, "height": top, "arcs": arcs}
    # The top first (it needs the full top disc), then a groove (it needs a full cylinder), then the flutes.
    kinds = ["dome" if rng.random() < 0.6 else "ball_end"]
    if rng.random() < 0.5:
        kinds.append("groove")
    kinds.append("circular_pattern")
    kinds += _draw_kinds(
        rng,
        {"through_hole": 1, "blind_hole": 1.5, "chamfer": 1, "fillet": 1, "groove": 1, "circular_pattern": 0.5},
        replace(cfg, n_features=(1, 3)),
    )
    return Work(solid, "feat_knob", 2 * rb, info, data={"flute_share": 0.8}), kinds


def _fam_block(rng: np.random.Generator, cfg: FeatureConfig) -> tuple[Work, list[str]]:
    solid, info, holes = stock_pillow_block(rng)
    w = Work(solid, "feat_block", holes["Wb"], info, data=holes)
    kinds = [
        "block_counterbores",
        *_draw_kinds(
            rng,
            {"fillet": 2, "chamfer": 2, "blind_hole": 1, "slot": 0.5, "through_hole": 1, "cut": 0.5},
            replace(cfg, n_features=(1, 4)),
        ),
    ]
    return w, kinds


def _block_counterbores(w: Work, rng: np.random.Generator, cfg: FeatureConfig) -> FeatureResult:
    """Two or four counterbored holes in the pillow block's base, outside the pedestal (counts as `counterbore`)."""
    h = w.data
    r = _u(rng, 0.08, 0.14) * h["Wb"]
    rc = r * _u(rng, 1.5, 1.9)
    depth = _u(rng, 0.2, 0.45) * h["Hb"]
    x_lo, x_hi = 0.5 * h["ped"] + rc + cfg.wall_mm, 0.5 * h["L"] - rc - cfg.wall_mm
    if x_hi <= x_lo or 2 * (rc + cfg.wall_mm) > h["Wb"]:
        return None
    x = _u(rng, x_lo, x_hi)
    ys = [0.0] if rng.random() < 0.5 or 4 * (rc + cfg.wall_mm) > h["Wb"] else [-0.25 * h["Wb"], 0.25 * h["Wb"]]
    o = cfg.overshoot_mm
    tools = []
    for sx in (-1, 1):
        for y in ys:
            tools.append(Pos(sx * x, y, h["Hb"]) * (_cyl(r, -h["Hb"] - o, o) + _cyl(rc, -depth, o)))
    return w.solid - tools, {"radius": r, "counterbore_radius": rc, "counterbore_depth": depth, "count": len(tools)}


_FAMILY_BUILDERS: dict[str, Callable[[np.random.Generator, FeatureConfig], tuple[Work, list[str]]]] = {
    "feat_prismatic": _fam_prismatic,
    "feat_plate": _fam_plate,
    "feat_turned": _fam_turned,
    "feat_hex": _fam_hex,
    "feat_knob": _fam_knob,
    "feat_block": _fam_block,
}
assert tuple(_FAMILY_BUILDERS) == FEATURE_FAMILIES


def build_work(family: str, rng: np.random.Generator, cfg: FeatureConfig = FeatureConfig()) -> Work:
    """A valid feature part of `family` before its rest pose (stock re-drawn if invalid, up to max_part_tries)."""
    if family not in _FAMILY_BUILDERS:
        raise ValueError(f"unknown feature family {family!r}; choose from {', '.join(FEATURE_FAMILIES)}")
    last = "no try"
    for _ in range(cfg.max_part_tries):
        try:
            w, kinds = _FAMILY_BUILDERS[family](rng, cfg)
        except Exception as exc:  # noqa: BLE001 - an OCCT failure on the stock: draw another
            last = f"stock failed ({type(exc).__name__}: {exc})"
            continue
        problem = "no solid" if w.solid is None else shape_problem(w.shape, cfg)
        if problem is not None:
            last = f"stock: {problem}"
            continue
        for kind in kinds:
            if kind == "block_counterbores":
                apply_feature(w, "counterbore", rng, cfg, op=_block_counterbores)
            else:
                apply_feature(w, kind, rng, cfg)
        return w
    raise RuntimeError(f"could not build a valid {family} part in {cfg.max_part_tries} tries: {last}")


def make_feature_part(family: str, rng: np.random.Generator, cfg: FeatureConfig = FeatureConfig()) -> RestPart:
    """A random feature-based part of `family` in the rest pose of parts.py (mm, Z up, on z = 0, centred)."""
    w = build_work(family, rng, cfg)
    shape = w.shape
    if w.lying:  # on its side: the stock axis (Z) becomes horizontal; a polygon's flat (-Y) faces down
        shape = (Rot(90, 0, 0) * w.solid).wrapped
    shape, box = rest_on_ground(shape)
    problem = shape_problem(shape, cfg)
    if problem is not None:  # every step was checked; this guards the final turn and move
        raise RuntimeError(f"{family} part invalid after its rest pose: {problem}")
    info = {
        **w.info,
        "features": list(w.features),
        "feature_params": w.params,
        "skipped": list(w.skipped),
        "lying": w.lying,
    }
    return RestPart(shape, family, box, info)


# ---- validity and speed ------------------------------------------------------------------------------------------


def measure(
    n: int, seed: int, families: tuple[str, ...] = FEATURE_FAMILIES, cfg: FeatureConfig = FeatureConfig()
) -> dict:
    """Build `n` parts in this process (family i % len(families), generator [seed, i]) and report the valid share
    (built, one BRepCheck-valid solid of analytic faces in its rest pose), parts per CPU second and per wall
    second, the feature kinds applied and why the skipped features were skipped."""
    import time
    from collections import Counter

    valid, kinds, per_family, skipped = 0, Counter(), Counter(), Counter()
    n_features = []
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for i in range(n):
        family = families[i % len(families)]
        try:
            part = make_feature_part(family, np.random.default_rng([seed, i]), cfg)
        except RuntimeError:
            continue
        valid += 1
        per_family[family] += 1
        kinds.update(part.info["features"])
        n_features.append(len(part.info["features"]))
        # Why features were skipped, by cause ("no room", "OCCT failed", "BRepCheck: invalid", "non-analytic", ...).
        skipped.update(reason.split(": ", 1)[1].split(" (")[0] for reason in part.info["skipped"])
    cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
    return {
        "parts": n,
        "valid": valid,
        "valid_share": valid / n,
        "parts_per_cpu_s": n / cpu,
        "parts_per_wall_s": n / wall,
        "mean_features": float(np.mean(n_features)) if n_features else 0.0,
        "kinds": dict(sorted(kinds.items())),
        "valid_per_family": dict(per_family),
        "features_applied": int(sum(kinds.values())),
        "features_skipped": dict(skipped.most_common()),
    }
