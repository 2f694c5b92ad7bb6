"""Mating references of a VB-Rep: the intersection edges a fixture may touch.

Only ``intersection`` edges qualify: where two fitted surfaces meet, the reconstruction knows the part's true
boundary. Silhouette, visibility and occluded edges are where the view stops, not where the part does, so a fixture
never references them. Among intersection edges with ``confidence >= min_confidence``:

- **dihedral**: a straight edge between two planes whose normals are perpendicular (within
  ``SelectionConfig.perpendicular_tol_deg``) and which is convex (each face lies behind the other's plane, i.e. the
  material is inside the wedge): a corner locator seats on it.
- **hole** / **boss**: a circle where a cylinder meets a plane whose normal is parallel to the cylinder's axis. A
  hole's wall lies behind the plane (on its material side) and the plane's face lies outside the circle; a boss's
  wall lies in front of the plane (the boss's base) or behind it with the plane's face inside the circle (the boss's
  end cap).
- **boss** also: a circle where a convex cylinder meets a coaxial torus, cone or cylinder (``site`` "shoulder"):
  a shaft's filleted or chamfered end, or a step to a coaxial section. A cradle needs the cylinder's axis, radius
  and the end its seen length starts from, which such a circle gives as well as a plane's; a turned part seldom
  shows a flat end face to the camera.
- **boss** last: a convex cylinder face on its own (``site`` "face", no edge: ``edge_id`` -1), for a shaft whose
  ends the view does not show (its coaxial sections meet at visibility edges, the steps between them hidden). A
  cradle mates with the cylinder's surface, not with an edge: the face gives its axis and radius, and its seen
  length along the axis where the block may lie. Its confidence is the face's raw score (`VFace.confidence`; only
  edges carry a calibrated probability), and such references are tried after every edge reference, so a cylinder
  that has a rim or a shoulder is cradled from it.

Everything here is in the VB-Rep's camera frame (OpenCV: x right, y down, z forward), metres. Plane normals are
oriented outwards, i.e. towards the camera: a face the camera sees has its outward normal facing the viewer.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from v2c.vbrep.model import EdgeType, VBRep, VEdge, VFace


class ReferenceKind(str, Enum):  # noqa: UP042 - StrEnum would change str() and format() of the members
    """What a mating reference is: a convex dihedral edge, a hole's rim or a boss's rim."""

    DIHEDRAL = "dihedral"
    HOLE = "hole"
    BOSS = "boss"


class NoReferenceError(LookupError):
    """No intersection edge qualifies as the reference a fixture needs. The message says what was needed and lists
    every edge of the VB-Rep with its type, confidence and why it was not taken."""


@dataclass(frozen=True)
class SelectionConfig:
    """Thresholds of the reference selection."""

    perpendicular_tol_deg: float = 5.0  # degrees: |angle between plane normals - 90| for a dihedral edge
    coaxial_tol_deg: float = 5.0  # degrees: angle between a cylinder's axis and its rim plane's normal
    min_length_frac: float = 0.05  # fraction of VBRep.scale: shortest usable dihedral edge
    straightness_frac: float = 0.01  # fraction of edge length: max polyline distance from its line (no curve)
    convex_margin_frac: float = 0.01  # fraction of VBRep.scale: margin of the convexity side tests
    min_arc_deg: float = 150.0  # degrees: least angular span of a rim's cylinder face (fillets span ~90)
    min_hole_closure: float = 0.75  # fraction of directions around a hole's rim where its plane face must
    # be found just outside it (a slot's round end, open on one side, falls short)
    rim_probes: tuple[float, ...] = (0.1, 0.2, 0.3)  # fractions of the radius: the plane face is probed at
    # (1 -+ each) x radius around a rim (inside vs outside the circle), to tell a hole from a boss
    land_closure: float = 0.9  # fraction of directions: a hole's land (how far its plane surrounds it, where a
    # pin's flange may rest) reaches out to the largest ring on which the plane face lies in at least this share
    # of the directions, counted from the first such ring (the plane's mesh stops short of the rim, where the depth
    # loses its edge pixels). From the 26 hole rims of the training scans (seed 7100, 24 scans): the ring at 1.05 x
    # radius lay all on the plane on 1 of them (so every other pin got a flange over the opening only); by
    # 1.2-1.3 x radius 25 of 26 rings lay on it in >= 94 % of the directions
    shoulder_axis_tol_rel: float = 0.15  # fraction of the cylinder's radius: how far a torus', cone's or second
    # cylinder's axis may pass from the cylinder's axis (at the circle) for their circle to be a shoulder
    cylinder_faces: bool = True  # convex cylinder faces on their own are boss references too, after every edge
    # reference (``site`` "face"; a shaft whose ends the view does not show)
    reach_bin_frac: float = 0.02  # fraction of VBRep.scale: bin length along a dihedral edge over which each face's
    # reach from the edge is measured (`DihedralReference.reach`)


@dataclass(frozen=True)
class DihedralReference:
    """A convex straight edge between two perpendicular planes (camera frame, metres).

    start, end: (3,) the edge's end points. normals: the two faces' outward unit normals, in the order of ``faces``.
    depths: how far each face reaches away from the edge inside its plane (metres), over the edge's span.
    angle_deg: angle between the two normals (90 for a right-angle edge). reach_at: (k,) centres of the bins along
    the edge (metres from ``start``, `SelectionConfig.reach_bin_frac`); reach: for each face, (k,) how far it
    reaches from the edge in each bin (metres; NaN where the bin holds none of its mesh): a face narrower in
    places than ``depths`` (a ledge, a step rising beside it) is where a locator's leg must stop.
    """

    edge_id: int
    confidence: float
    faces: tuple[int, int]
    start: np.ndarray
    end: np.ndarray
    normals: tuple[np.ndarray, np.ndarray]
    depths: tuple[float, float]
    angle_deg: float
    kind: ReferenceKind = ReferenceKind.DIHEDRAL
    reach_at: np.ndarray = field(default_factory=lambda: np.zeros(0))
    reach: tuple[np.ndarray, np.ndarray] = field(default_factory=lambda: (np.zeros(0), np.zeros(0)))

    @property
    def direction(self) -> np.ndarray:
        """(3,) unit vector from ``start`` to ``end`` (camera frame)."""
        d = self.end - self.start
        return d / np.linalg.norm(d)

    @property
    def length(self) -> float:
        """Edge length (metres)."""
        return float(np.linalg.norm(self.end - self.start))

    @property
    def label(self) -> str:
        """How messages name the reference: its edge (``e12``)."""
        return f"e{self.edge_id}"


@dataclass(frozen=True)
class CircleReference:
    """A circle where a cylinder meets a plane, or a boss's shoulder (camera frame, metres).

    center: (3,) the circle's centre (on the plane). axis: (3,) unit, from the circle into the cylinder's extent
    (into a hole; along a boss's body). radius: metres. plane_normal: (3,) the plane's outward unit normal.
    extent: how far the cylinder face reaches from the circle along ``axis`` (metres; a lower bound of a hole's
    depth or a boss's length, from what the view shows). site: where on the feature the circle is: "rim" (a
    hole's opening), "floor" (a blind hole's bottom), "base" (where a boss stands on the plane), "cap" (a boss's
    end face) or "shoulder" (where a convex cylinder meets a coaxial torus, cone or cylinder; ``plane_face`` is
    then that face and ``plane_normal`` the axis pointing away from the cylinder). land: for a hole's rim, the
    distance from the axis (metres) out to which the plane face surrounds the rim all round (where a pin's flange
    may rest); the radius otherwise.
    """

    edge_id: int
    confidence: float
    kind: ReferenceKind
    cylinder_face: int
    plane_face: int
    center: np.ndarray
    axis: np.ndarray
    radius: float
    plane_normal: np.ndarray
    extent: float
    site: str = "rim"
    land: float = 0.0

    @property
    def label(self) -> str:
        """How messages name the reference: its edge (``e12``), or its cylinder face (``face f3``) for a face's."""
        return f"e{self.edge_id}" if self.edge_id >= 0 else f"face f{self.cylinder_face}"


Reference = DihedralReference | CircleReference


@dataclass
class _Audit:
    """Why each edge was taken or not, for NoReferenceError messages."""

    lines: list[str] = field(default_factory=list)

    def add(self, e: VEdge, verdict: str) -> None:
        kind = (e.curve or {}).get("kind", "-") if e.curve is not None else "-"
        self.lines.append(
            f"  e{e.id}: {EdgeType(e.type).value} conf {e.confidence:.2f} curve {kind} faces "
            f"{tuple(int(f) for f in e.faces)}: {verdict}"
        )

    def add_face(self, f: VFace, verdict: str) -> None:
        self.lines.append(f"  face f{f.id}: {_ptype(f)} conf {f.confidence:.2f}: {verdict}")


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v)


def _ptype(face: VFace) -> str:
    return str(face.primitive.get("type", "")).lower()


def _face_points(face: VFace) -> np.ndarray:
    return np.asarray(face.mesh_vertices, float).reshape(-1, 3)


def face_samples(face: VFace, subdivisions: int = 4) -> np.ndarray:
    """(N, 3) points spread over a face mesh's triangles (barycentric grid per triangle), camera metres."""
    v = _face_points(face)
    t = np.asarray(face.mesh_triangles, int).reshape(-1, 3)
    if not len(t):
        return v
    k = subdivisions
    ij = np.array([(i, j) for i in range(k + 1) for j in range(k + 1 - i)], float) / k
    bary = np.column_stack([ij, 1.0 - ij.sum(axis=1)])
    return np.einsum("bk,tkd->tbd", bary, v[t]).reshape(-1, 3)


def _off_edge(
    pts: np.ndarray, a: np.ndarray, d: np.ndarray, length: float, margin: float
) -> tuple[np.ndarray, np.ndarray]:
    """(along, distance) of the points ``pts`` (N, 3) beside the segment from ``a`` along unit ``d`` (``length``,
    within ``margin`` of its ends): how far along it each lies and how far from its line (metres)."""
    rel = pts - a
    along = rel @ d
    inside = (along >= -margin) & (along <= length + margin)
    return along[inside], np.linalg.norm(rel[inside] - np.outer(along[inside], d), axis=1)


def _subdivisions(face: VFace, bin_length: float, most_samples: int = 200_000) -> int:
    """Barycentric subdivisions (`face_samples`) that put a face's samples at most half ``bin_length`` apart along
    its longest triangle edge, with at most about ``most_samples`` samples in all (at least 1)."""
    v = _face_points(face)
    t = np.asarray(face.mesh_triangles, int).reshape(-1, 3)
    if not len(t) or not bin_length > 0:
        return 1
    tri = v[t]
    longest = float(np.linalg.norm(tri - np.roll(tri, 1, axis=1), axis=2).max())
    k = int(np.ceil(2.0 * longest / bin_length))
    cap = int(np.sqrt(2.0 * most_samples / len(t)))
    return max(1, min(k, cap))


def _basis(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing ``axis`` to an orthonormal frame."""
    u = np.cross(axis, [1.0, 0.0, 0.0])
    if np.linalg.norm(u) < 0.1:
        u = np.cross(axis, [0.0, 1.0, 0.0])
    u = _unit(u)
    return u, np.cross(axis, u)


def plane_coords(points: np.ndarray, center: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N, 2) coordinates of points in the plane through ``center`` normal to the unit ``axis`` (``_basis``
    axes)."""
    u, w = _basis(axis)
    rel = np.asarray(points, float) - center
    return np.stack([rel @ u, rel @ w], axis=1)


def _inside_triangles(points: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(P,) bool: which 2D points lie in any of the 2D triangles (T, 3, 2)."""
    if not len(tris):
        return np.zeros(len(points), bool)
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]

    def cross(o: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
        return (p[None, :, 0] - o[None, :, 0]) * (q[:, None, 1] - o[None, :, 1]) - (p[None, :, 1] - o[None, :, 1]) * (
            q[:, None, 0] - o[None, :, 0]
        )

    d1, d2, d3 = cross(a, b, points), cross(b, c, points), cross(c, a, points)
    neg = (d1 < 0) | (d2 < 0) | (d3 < 0)
    pos = (d1 > 0) | (d2 > 0) | (d3 > 0)
    return (~(neg & pos)).any(axis=1)


def outward_plane_normal(face: VFace, trusted: bool = False) -> np.ndarray:
    """Unit normal of a planar face pointing out of the material (towards the camera that sees the face).

    trusted: the primitive's normal is already outward (a VB-Rep read back from a STEP, whose faces face the
    camera); otherwise it is turned towards the camera at the origin.
    """
    n = _unit(face.primitive["params"]["normal"])
    if trusted:
        return n
    pts = _face_points(face)
    c = pts.mean(axis=0) if len(pts) else np.asarray(face.primitive["params"]["origin"], float)
    return -n if n @ c > 0 else n


def _edge_line(e: VEdge, cfg: SelectionConfig) -> tuple[np.ndarray, np.ndarray] | str:
    """End points of a straight edge, or the reason it is not straight."""
    poly = np.asarray(e.polyline, float).reshape(-1, 3)
    curve = e.curve or {}
    if curve.get("kind") == "line":
        o, d = np.asarray(curve["origin"], float), _unit(curve["direction"])
    else:
        if curve.get("kind") not in (None, "intersection") or len(poly) < 2:
            return f"curve is a {curve.get('kind')}, not a line"
        o = poly.mean(axis=0)
        d = np.linalg.svd(poly - o)[2][0]
        off = (poly - o) - np.outer((poly - o) @ d, d)
        span = np.ptp((poly - o) @ d)
        if span <= 0 or np.linalg.norm(off, axis=1).max() > cfg.straightness_frac * span:
            return "polyline is not straight"
    t = (poly - o) @ d
    return o + t.min() * d, o + t.max() * d


def _dihedral(vb: VBRep, e: VEdge, cfg: SelectionConfig) -> DihedralReference | str:
    f0, f1 = (vb.faces[int(i)] for i in e.faces)
    if _ptype(f0) != "plane" or _ptype(f1) != "plane":
        return f"faces are {_ptype(f0)}/{_ptype(f1)}, not two planes"
    trusted = bool(vb.meta.get("outward_normals", False))
    n0, n1 = outward_plane_normal(f0, trusted), outward_plane_normal(f1, trusted)
    angle = float(np.degrees(np.arccos(np.clip(n0 @ n1, -1.0, 1.0))))
    if abs(angle - 90.0) > cfg.perpendicular_tol_deg:
        return f"planes meet at {angle:.1f} deg between normals, not perpendicular"
    line = _edge_line(e, cfg)
    if isinstance(line, str):
        return line
    a, b = line
    length = float(np.linalg.norm(b - a))
    if length < cfg.min_length_frac * vb.scale:
        return f"too short ({length * 1e3:.1f} mm)"
    p0, p1 = _face_points(f0), _face_points(f1)
    if not len(p0) or not len(p1):
        return "a face has no mesh: material side unknown"
    m = 0.5 * (a + b)
    margin = cfg.convex_margin_frac * vb.scale
    s0, s1 = (p0.mean(axis=0) - m) @ n1, (p1.mean(axis=0) - m) @ n0
    if not (s0 < -margin and s1 < -margin):
        return "concave or ambiguous (a face lies in front of the other's plane)"
    d = _unit(b - a)
    n_bins = max(1, int(np.ceil(length / (cfg.reach_bin_frac * vb.scale))))
    bins = np.linspace(0.0, length, n_bins + 1)
    depths, reach = [], []
    for face, pts in ((f0, p0), (f1, p1)):
        _, dist = _off_edge(pts, a, d, length, margin)
        depths.append(float(dist.max()) if len(dist) else 0.0)
        # Per bin, from points over the face's triangles at most half a bin apart (a ground-truth mesh has its
        # vertices at its corners only, a reconstructed one on the pixel grid).
        along, dist = _off_edge(face_samples(face, _subdivisions(face, length / n_bins)), a, d, length, margin)
        k = np.clip(np.searchsorted(bins, along, side="right") - 1, 0, n_bins - 1)
        r = np.full(n_bins, -np.inf)
        np.maximum.at(r, k, dist)
        reach.append(np.where(np.isfinite(r), r, np.nan))
    return DihedralReference(
        e.id,
        float(e.confidence),
        (f0.id, f1.id),
        a,
        b,
        (n0, n1),
        (depths[0], depths[1]),
        angle,
        reach_at=0.5 * (bins[:-1] + bins[1:]),
        reach=(reach[0], reach[1]),
    )


#: Equal sectors around a cylinder's axis in which its face's angular span is counted (10 degrees each).
ARC_SECTORS = 36


def radial_directions(points: np.ndarray, origin: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """(N, 3) unit vectors from the axis (through ``origin`` along unit ``axis``) out to each of ``points``, across
    the axis (camera frame)."""
    q = np.asarray(points, float) - np.asarray(origin, float)
    radial = q - np.outer(q @ axis, axis)
    return radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-12)


def seen_from_outside(points: np.ndarray, radial: np.ndarray) -> bool:
    """Whether a cylinder's seen points (N, 3, camera frame) face the camera at the origin with their outside: the
    median of their radial directions (`radial_directions`) dotted with the direction to the camera is positive. A
    boss (convex) shows the side facing the camera; a hole's wall (concave) its far side."""
    p = np.asarray(points, float)
    to_cam = -p / np.maximum(np.linalg.norm(p, axis=1, keepdims=True), 1e-12)
    return float(np.median(np.sum(radial * to_cam, axis=1))) > 0


def _arc_bins(points: np.ndarray, center: np.ndarray, axis: np.ndarray, nbins: int) -> np.ndarray:
    """The sorted indices of the ``nbins`` equal sectors around ``axis`` (through ``center``) that hold points."""
    xy = plane_coords(points, center, axis)
    return np.unique(np.floor((np.arctan2(xy[:, 1], xy[:, 0]) + np.pi) / (2 * np.pi) * nbins).astype(int) % nbins)


def _circle(vb: VBRep, e: VEdge, cfg: SelectionConfig) -> CircleReference | str:
    faces = [vb.faces[int(i)] for i in e.faces]
    types = sorted(_ptype(f) for f in faces)
    if types != ["cylinder", "plane"]:
        return f"faces are {'/'.join(types)}, not a cylinder and a plane"
    cyl = next(f for f in faces if _ptype(f) == "cylinder")
    pln = next(f for f in faces if _ptype(f) == "plane")
    n = outward_plane_normal(pln, bool(vb.meta.get("outward_normals", False)))
    cp = cyl.primitive["params"]
    axis = _unit(cp["axis"])
    tilt = float(np.degrees(np.arccos(min(1.0, abs(axis @ n)))))
    if tilt > cfg.coaxial_tol_deg:
        return f"cylinder axis {tilt:.1f} deg off the plane normal: not a rim circle"
    curve = e.curve or {}
    if curve.get("kind") == "circle":
        center, radius = np.asarray(curve["center"], float), float(curve["radius"])
    else:
        # The rim circle from the primitives: the cylinder axis meets the plane.
        o = np.asarray(cp["origin"], float)
        po = np.asarray(pln.primitive["params"]["origin"], float)
        center = o + axis * ((po - o) @ n) / (axis @ n)
        radius = float(cp["radius"])
    pc = face_samples(cyl)
    if not len(pc) or not len(pln.mesh_triangles):
        return "a face has no mesh: hole or boss unknown"
    nbins = ARC_SECTORS
    bins_c = _arc_bins(pc, center, axis, nbins)
    span = 360.0 * len(bins_c) / nbins
    if span < cfg.min_arc_deg:
        return f"cylinder face spans {span:.0f} deg around its axis: a fillet or part-round, not a hole or boss"
    h = (pc - center) @ n
    front = bool(np.median(h) > 0)  # the wall stands in front of the plane (outside the material)
    # Probe the plane face just inside and just outside the rim, at the angles the cylinder face covers.
    tri = np.asarray(pln.mesh_triangles, int).reshape(-1, 3)
    v2 = plane_coords(_face_points(pln), center, axis)
    phis = (bins_c + 0.5) * 2 * np.pi / nbins - np.pi
    ring = np.stack([np.cos(phis), np.sin(phis)], axis=1) * radius
    inner = sum(int(_inside_triangles(ring * (1 - f), v2[tri]).sum()) for f in cfg.rim_probes)
    outer = sum(int(_inside_triangles(ring * (1 + f), v2[tri]).sum()) for f in cfg.rim_probes)
    if inner == 0 and outer == 0:
        return "the plane face has no area next to the rim: hole or boss unknown"
    inside = inner > outer  # the plane face covers the disc inside the rim (a cap, or a blind hole's floor)
    if not front and not inside:  # a hole's rim: the plane must surround it (a slot's round end does not)
        phi = (np.arange(nbins) + 0.5) * 2 * np.pi / nbins - np.pi
        full = np.stack([np.cos(phi), np.sin(phi)], axis=1) * radius
        hit = np.zeros(nbins, bool)
        for f in cfg.rim_probes:
            hit |= _inside_triangles(full * (1 + f), v2[tri])
        if hit.mean() < cfg.min_hole_closure:
            return (
                f"the plane surrounds only {100 * hit.mean():.0f}% of the rim: an open arc (a slot's end?), not a hole"
            )
        land, reached = radius, False
        for f in np.arange(1.05, 4.0, 0.05):
            if _inside_triangles(full * f, v2[tri]).mean() >= cfg.land_closure:
                land, reached = f * radius, True
            elif reached:  # the plane's outer edge (or a feature on it)
                break
    else:
        land = radius
    # Wall behind the plane: a hole's rim (plane outside) or a boss's cap (plane inside). Wall in front: a
    # boss's base (plane outside) or a blind hole's floor (plane inside).
    kind = ReferenceKind.BOSS if front != inside else ReferenceKind.HOLE
    into = n if front else -n
    site = {(False, False): "rim", (True, True): "floor", (True, False): "base", (False, True): "cap"}[(front, inside)]
    extent = float(np.abs(h).max())
    return CircleReference(e.id, float(e.confidence), kind, cyl.id, pln.id, center, into, radius, n, extent, site, land)


def _convex_samples(cyl: VFace, origin: np.ndarray, axis: np.ndarray, need: str) -> np.ndarray | str:
    """(N, 3) samples over the mesh of cylinder face ``cyl`` (axis through ``origin`` along unit ``axis``) when it is
    a boss's wall (convex: `seen_from_outside`; a hole's wall shows its far side), else why not (``need``: what
    needs the boss, for the message)."""
    pc = face_samples(cyl)
    if not len(pc) or not len(cyl.mesh_triangles):
        return "the cylinder face has no mesh"
    if not seen_from_outside(pc, radial_directions(pc, origin, axis)):
        return f"the cylinder is concave (a hole's wall): {need} needs a boss"
    return pc


def _short_arc(pc: np.ndarray, center: np.ndarray, axis: np.ndarray, cfg: SelectionConfig) -> str | None:
    """Why a boss's cylinder face (samples ``pc``, axis through ``center``) is none: it spans less than
    ``cfg.min_arc_deg`` around its axis (a fillet or part-round); None when it spans enough."""
    span = 360.0 * len(_arc_bins(pc, center, axis, ARC_SECTORS)) / ARC_SECTORS
    if span < cfg.min_arc_deg:
        return f"cylinder face spans {span:.0f} deg around its axis: a fillet or part-round, not a boss"
    return None


def _shoulder(vb: VBRep, e: VEdge, cfg: SelectionConfig) -> CircleReference | str:
    """A boss reference where a convex cylinder meets a coaxial torus, cone or cylinder (module docstring), or why
    the edge is none. With two cylinders, each is tried and the one seen longer from the circle is taken."""
    faces = [vb.faces[int(i)] for i in e.faces]
    out: list[CircleReference] = []
    why = ""
    for cyl, other in ((faces[0], faces[1]), (faces[1], faces[0])):
        if _ptype(cyl) != "cylinder":
            continue
        r = _shoulder_of(e, cyl, other, cfg)
        if isinstance(r, str):
            why = why or r
        else:
            out.append(r)
    if not out:
        return why or "no cylinder"
    return max(out, key=lambda r: r.extent)


def _shoulder_of(e: VEdge, cyl: VFace, other: VFace, cfg: SelectionConfig) -> CircleReference | str:
    cp = cyl.primitive["params"]
    axis, o, radius = _unit(cp["axis"]), np.asarray(cp["origin"], float), float(cp["radius"])
    op = other.primitive["params"]
    oa, oo = _unit(op["axis"]), np.asarray(op["origin"], float)
    tilt = float(np.degrees(np.arccos(min(1.0, abs(axis @ oa)))))
    if tilt > cfg.coaxial_tol_deg:
        return f"the {_ptype(other)}'s axis is {tilt:.1f} deg off the cylinder's: not a shoulder circle"
    pts = np.asarray(e.polyline, float).reshape(-1, 3)
    if not len(pts):
        return "the edge has no samples"
    center = o + axis * float(np.median((pts - o) @ axis))
    rel = center - oo
    off = float(np.linalg.norm(rel - (rel @ oa) * oa))  # the other axis' distance from the cylinder's at the circle
    if off > cfg.shoulder_axis_tol_rel * radius:
        return f"the {_ptype(other)}'s axis passes {1000 * off:.1f} mm from the cylinder's: not a shoulder circle"
    pc = _convex_samples(cyl, o, axis, "a shoulder")
    if isinstance(pc, str):
        return pc
    short = _short_arc(pc, center, axis, cfg)
    if short is not None:
        return short
    h = (pc - center) @ axis
    into = axis if float(np.median(h)) > 0 else -axis
    extent = float(np.abs(h).max())
    return CircleReference(
        e.id,
        float(e.confidence),
        ReferenceKind.BOSS,
        cyl.id,
        other.id,
        center,
        into,
        radius,
        -into,
        extent,
        "shoulder",
        radius,
    )


def _cylinder_face(f: VFace, cfg: SelectionConfig) -> CircleReference | str:
    """A boss reference on a convex cylinder face itself (module docstring, ``site`` "face"), or why it is none:
    ``axis`` is the fitted axis' direction, ``center`` the point on it where the seen face starts along that
    direction (the smallest projection of its mesh samples), ``extent`` the seen length from there (metres)."""
    cp = f.primitive["params"]
    axis, o, radius = _unit(cp["axis"]), np.asarray(cp["origin"], float), float(cp["radius"])
    pc = _convex_samples(f, o, axis, "a cradle")
    if isinstance(pc, str):
        return pc
    h = (pc - o) @ axis
    center = o + axis * float(h.min())
    short = _short_arc(pc, center, axis, cfg)
    if short is not None:
        return short
    extent = float(h.max() - h.min())
    return CircleReference(
        -1, float(f.confidence), ReferenceKind.BOSS, f.id, -1, center, axis, radius, -axis, extent, "face", radius
    )


def _face_references(
    vb: VBRep, taken: set[int], min_confidence: float, cfg: SelectionConfig, audit: _Audit
) -> list[CircleReference]:
    """Boss references on convex cylinder faces (`_cylinder_face`) that no edge reference already uses (``taken``:
    their cylinder face ids), best first (confidence, then radius); each verdict is added to ``audit``."""
    out = []
    for f in vb.faces:
        if _ptype(f) != "cylinder" or f.id in taken:
            continue
        if f.confidence < min_confidence:
            audit.add_face(f, f"under {min_confidence:.2f}")
            continue
        r = _cylinder_face(f, cfg)
        audit.add_face(f, r if isinstance(r, str) else "qualifies as a boss (its face)")
        if not isinstance(r, str):
            out.append(r)
    out.sort(key=lambda r: (-r.confidence, -r.radius))
    return out


def _select(
    vb: VBRep, wanted: set[ReferenceKind], min_confidence: float, cfg: SelectionConfig
) -> tuple[list[Reference], _Audit]:
    refs: list[Reference] = []
    audit = _Audit()
    for e in vb.edges:
        if EdgeType(e.type) is not EdgeType.INTERSECTION:
            audit.add(e, "not an intersection edge: never a reference")
            continue
        if e.confidence < min_confidence:
            audit.add(e, f"confidence under {min_confidence:.2f}")
            continue
        if len(e.faces) != 2:
            audit.add(e, "does not join two faces")
            continue
        kind = (e.curve or {}).get("kind")
        types = sorted(_ptype(vb.faces[int(i)]) for i in e.faces)
        if types == ["plane", "plane"] and kind in ("line", "intersection", None):
            r: Reference | str = _dihedral(vb, e, cfg)
        elif types == ["cylinder", "plane"]:
            r = _circle(vb, e, cfg)
        elif ReferenceKind.BOSS in wanted and "cylinder" in types and set(types) <= {"cylinder", "torus", "cone"}:
            r = _shoulder(vb, e, cfg)
        else:
            r = f"faces are {'/'.join(types)}: neither a plane/plane line nor a cylinder/plane circle"
        if isinstance(r, str):
            audit.add(e, r)
        elif r.kind not in wanted:
            audit.add(e, f"a {r.kind.value}, not wanted here")
        else:
            audit.add(e, f"qualifies as a {r.kind.value}")
            refs.append(r)
    refs.sort(key=lambda r: (-r.confidence, -(r.length if isinstance(r, DihedralReference) else r.radius)))
    if ReferenceKind.BOSS in wanted and cfg.cylinder_faces:  # after every edge reference
        taken = {r.cylinder_face for r in refs if isinstance(r, CircleReference) and r.kind is ReferenceKind.BOSS}
        refs += _face_references(vb, taken, min_confidence, cfg, audit)
    return refs, audit


def select_references(
    vbrep: VBRep,
    kinds: Iterable[ReferenceKind | str] = tuple(ReferenceKind),
    min_confidence: float = 0.5,
    config: SelectionConfig = SelectionConfig(),
) -> list[Reference]:
    """Mating references of ``vbrep`` of the given kinds, best first (confidence, then length or radius).

    min_confidence: edges with a lower confidence (in [0, 1]) are ignored. Raises :class:`NoReferenceError` when
    none qualifies; its message lists every edge and why it was not taken.
    """
    wanted = {ReferenceKind(k) for k in kinds}
    refs, audit = _select(vbrep, wanted, min_confidence, config)
    if not refs:
        need = " or ".join(sorted(k.value for k in wanted))
        raise NoReferenceError(
            f"no intersection edge{' or cylinder face' if ReferenceKind.BOSS in wanted else ''} with confidence >= "
            f"{min_confidence:.2f} qualifies as a {need} reference; "
            f"the VB-Rep has {len(vbrep.edges)} edges:\n" + "\n".join(audit.lines)
        )
    return refs


def explain_edges(vbrep: VBRep, min_confidence: float = 0.5, config: SelectionConfig = SelectionConfig()) -> str:
    """One line per edge saying whether (and as what) it qualifies as a mating reference, then one per cylinder face
    that no edge reference uses (as a cradle's reference on its own, `_cylinder_face`)."""
    return "\n".join(_select(vbrep, set(ReferenceKind), min_confidence, config)[1].lines)
