"""VB-Rep -> STEP AP242 (millimetres) with typed edges, and the typed reader.

What the file carries (../shared/SCAN_FORMAT.md, "Output of v2c to-step"):

- analytic faces (PLANE, CYLINDRICAL_SURFACE, CONICAL_SURFACE, SPHERICAL_SURFACE, TOROIDAL_SURFACE) trimmed by
  their VB-Rep loops, faces that share edges in one open shell (SHELL_BASED_SURFACE_MODEL); see
  `exporters.brep`;
- every VB-Rep edge named ``"<type>:<confidence>:e<id>:s<sigma>"`` (confidence with two decimals; sigma the
  1-sigma position error `VEdge.sigma_mm` in millimetres, two significant digits, the field left out when the
  VB-Rep has none; ``":tangent"`` last for a tangent edge), on layer ``edge_<type>`` and coloured by type (sRGB:
  intersection blue, silhouette red, visibility cyan, occluded green);
- every face named ``"<type>:<axis>:f<id>:s<sigma>"`` (axis X, Y, Z, U; ``-`` for a sphere; sigma
  `VFace.sigma_mm` as for edges);
- one product holding one compound: the shells and the free edges (edges on no face) as direct children.

Frames (`exporters.frames`): ``"part"`` (default) puts the recovered axis frame on X/Y/Z with the footprint
origin (centre of the visible geometry's X/Y bounding box, at its lowest Z); ``"camera"`` keeps the camera
frame.
"""

from __future__ import annotations

import contextlib
import re
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.GeomAbs import (
    GeomAbs_BSplineSurface,
    GeomAbs_Cone,
    GeomAbs_Cylinder,
    GeomAbs_Plane,
    GeomAbs_Sphere,
    GeomAbs_SurfaceOfRevolution,
    GeomAbs_Torus,
)
from OCP.Message import Message, Message_Gravity
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS, TopoDS_Face, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape, TopTools_IndexedMapOfShape

from exporters.brep import (
    BuiltBRep,
    bounding_box,
    build_brep,
    drawn_area,
    face_area,
    translate_built,
)
from exporters.brep_config import BrepConfig
from exporters.brep_faces import edges_of
from exporters.brep_outline import edge_candidates, nearest_edge_ids
from exporters.frames import Frame, FrameMap, frame_map
from exporters.xcaf import RGB, ReadSubShape, SubShapeAttrs, read_xcaf_step, write_xcaf_step
from v2c.errors import V2cError
from v2c.io_safe import atomic_write, v2c_origin
from v2c.labels import PrimitiveType
from v2c.vbrep.model import EdgeType

if TYPE_CHECKING:
    from v2c.vbrep.model import VBRep, VEdge, VFace

#: Edge colours by type, sRGB in [0, 1].
EDGE_COLORS: dict[EdgeType, RGB] = {
    EdgeType.INTERSECTION: (0.0, 0.0, 1.0),
    EdgeType.SILHOUETTE: (1.0, 0.0, 0.0),
    EdgeType.VISIBILITY: (0.0, 1.0, 1.0),
    EdgeType.OCCLUDED: (0.0, 1.0, 0.0),
}

#: Surface names of `TypedFace.surface` by OCCT GeomAbs type. A torus whose tube radius exceeds its ring
#: radius comes back from STEP as a surface of revolution ("revolution"), which still counts as a torus.
_SURFACE_NAMES = {
    GeomAbs_Plane: "plane",
    GeomAbs_Cylinder: "cylinder",
    GeomAbs_Cone: "cone",
    GeomAbs_Sphere: "sphere",
    GeomAbs_Torus: "torus",
    GeomAbs_SurfaceOfRevolution: "revolution",
    GeomAbs_BSplineSurface: "bspline",
}

#: Names as written by `edge_name` / `face_name`; the ``:s<sigma>`` field is optional (files written before it
#: existed, and VB-Reps without a sigma, have none).
_EDGE_NAME = re.compile(
    r"^(?P<type>[a-z]+):(?P<conf>[0-9.]+):e(?P<id>\d+)(?::s(?P<sigma>[0-9]+(?:\.[0-9]*)?))?(?P<tangent>:tangent)?$"
)
_FACE_NAME = re.compile(r"^(?P<type>[a-z]+):(?P<axis>[XYZU-]):f(?P<id>\d+)(?::s(?P<sigma>[0-9]+(?:\.[0-9]*)?))?$")

#: Significant digits of the sigma field of a name.
SIGMA_DIGITS = 2


# ------------------------------------------------------------------------------------------------ naming
def sigma_field(sigma_mm: float | None) -> str:
    """``":s<sigma>"``: a 1-sigma position error in millimetres with `SIGMA_DIGITS` significant digits, positional
    notation (no exponent, trailing zeros dropped: 0.31, 0.02, 1.2, 120); ``""`` when sigma is None, negative or
    not finite."""
    if sigma_mm is None or not np.isfinite(sigma_mm) or sigma_mm < 0:
        return ""
    text = np.format_float_positional(float(sigma_mm), precision=SIGMA_DIGITS, unique=False, fractional=False, trim="-")
    return f":s{text}"


def edge_name(edge: VEdge) -> str:
    """``"<type>:<confidence>:e<id>:s<sigma>"``, confidence with two decimals, sigma `VEdge.sigma_mm` (mm, see
    `sigma_field`; left out when None); ``":tangent"`` appended last for an intersection edge where its faces meet
    tangentially (G1)."""
    tail = ":tangent" if edge.tangent else ""
    head = f"{EdgeType(edge.type).value}:{float(edge.confidence):.2f}:e{int(edge.id)}"
    return f"{head}{sigma_field(edge.sigma_mm)}{tail}"


def edge_layer(edge_type: EdgeType | str) -> str:
    """``"edge_<type>"``."""
    return f"edge_{EdgeType(edge_type).value}"


def face_name(face: VFace) -> str:
    """``"<type>:<axis>:f<id>:s<sigma>"``; axis X/Y/Z/U, ``-`` when the face has none (sphere); sigma
    `VFace.sigma_mm` (mm, see `sigma_field`; left out when None)."""
    head = f"{PrimitiveType(face.primitive['type']).value}:{face.axis_label or '-'}:f{int(face.id)}"
    return f"{head}{sigma_field(face.sigma_mm)}"


# ------------------------------------------------------------------------------------------------ writing
class StepExportError(V2cError, RuntimeError):
    """The VB-Rep cannot be written as a useful STEP (no face could be built); the message says why."""


@dataclass
class StepReport:
    """What `write` did. seconds: wall time of the whole write (build + XCAF + file), s. frame_map: camera
    metres -> the file's millimetres. face_edges: VFace id -> the VEdge ids its boundary holds in the file;
    copied_edges: VEdge id -> the faces that hold a copy of it of their own (`exporters.brep.BuiltBRep`).
    shape_valid: BRepCheck of the whole assembled shape. fallback_faces: faces bounded by their mesh outline;
    dropped_edges: VEdge ids on no face not written (an outline carries their name, or they lie outside the
    part's box)."""

    path: Path
    frame: Frame
    n_faces: int
    n_edges: int
    free_edges: list[int]
    fallback_faces: list[int]
    skipped_faces: list[int]
    invalid_faces: list[int]
    warnings: list[str]
    seconds: float
    frame_map: FrameMap | None = None
    face_edges: dict[int, set[int]] = field(default_factory=dict)
    copied_edges: dict[int, list[int]] = field(default_factory=dict)
    shape_valid: bool = True
    dropped_edges: list[int] = field(default_factory=list)


@contextmanager
def quiet_occt() -> Iterator[None]:
    """Silence OCCT's default messenger (transfer statistics on stdout) except failures, then restore it."""
    saved = []
    for p in Message.DefaultMessenger_s().Printers():
        saved.append((p, p.GetTraceLevel()))
        p.SetTraceLevel(Message_Gravity.Message_Fail)
    try:
        yield
    finally:
        for p, lvl in saved:
            p.SetTraceLevel(lvl)


def build(
    vbrep: VBRep,
    frame: Frame | str = Frame.PART,
    config: BrepConfig | None = None,
    force_outline: frozenset[int] = frozenset(),
    raw_outline: frozenset[int] = frozenset(),
) -> BuiltBRep:
    """The OCCT topology of a VB-Rep in ``frame`` (millimetres); see `exporters.brep` (``force_outline``,
    ``raw_outline``: `exporters.brep.build_brep`'s).

    Part frame: the footprint origin (`exporters.frames`) is measured on the built faces and edges, so the
    result's bounding box is centred in X and Y and starts at Z = 0 (to 1e-6 mm); ``built.fmap`` maps camera
    metres into it.
    """
    frame = Frame(frame)
    built = build_brep(vbrep, frame_map(vbrep, frame), config, force_outline, raw_outline)
    if frame is Frame.PART and (built.faces or built.edges):
        lo, hi = bounding_box(built.shape)
        shift = -np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
        if np.abs(shift).max() > 1e-6:
            built = translate_built(built, shift)
    return built


def _attributes(vbrep: VBRep, built: BuiltBRep) -> list[SubShapeAttrs]:
    """Names of every face (each piece of an outline-bounded face too) and name, layer and colour of every
    edge: the VB-Rep edges, and the outline edges under the VB-Rep edge each was named after."""
    subs = []
    for f in vbrep.faces:
        for shape in built.face_parts.get(f.id, [built.faces[f.id]] if f.id in built.faces else []):
            subs.append(SubShapeAttrs(shape, face_name(f)))

    def edge_attrs(shape: TopoDS_Shape, e: VEdge) -> SubShapeAttrs:
        t = EdgeType(e.type)
        return SubShapeAttrs(shape, edge_name(e), edge_layer(t), EDGE_COLORS[t])

    for e in vbrep.edges:
        for shape in built.edges.get(e.id, []):
            subs.append(edge_attrs(shape, e))
    by_id = {e.id: e for e in vbrep.edges}
    for pairs in built.outline_edges.values():
        for shape, eid in pairs:
            if eid in by_id:
                subs.append(edge_attrs(shape, by_id[eid]))
    # Edges OCCT added itself (the seam ShapeFix puts on a face that closes around a cylinder): named after the
    # nearest VB-Rep edge of their face, as outline segments are, so that no edge of the file goes untyped.
    named = TopTools_IndexedMapOfShape()
    for sub in subs:
        named.Add(sub.shape)
    for f in vbrep.faces:
        parts = built.face_parts.get(f.id, [built.faces[f.id]] if f.id in built.faces else [])
        extra = [edge for face in parts for edge in edges_of(face) if not named.Contains(edge)]
        cands = edge_candidates(vbrep, built.fmap, f.id) if extra and built.fmap is not None else []
        if not cands:
            continue
        for edge, eid in zip(extra, nearest_edge_ids(np.array([_edge_midpoint(e) for e in extra]), cands), strict=True):
            if not named.Contains(edge):  # an edge two pieces share is named once
                subs.append(edge_attrs(edge, by_id[int(eid)]))
                named.Add(edge)
    return subs


def _edge_midpoint(edge: TopoDS_Shape) -> np.ndarray:
    c = BRepAdaptor_Curve(TopoDS.Edge_s(edge))
    return np.array(c.Value(0.5 * (c.FirstParameter() + c.LastParameter())).Coord())


def write(
    vbrep: VBRep,
    path: str | Path,
    frame: Frame | str = Frame.PART,
    product: str | None = None,
    config: BrepConfig | None = None,
    atomic: bool = True,
) -> StepReport:
    """Write a VB-Rep as STEP AP242 (millimetres) to ``path``, atomically (temporary file + rename; with
    ``atomic=False`` straight into ``path``, for a caller that passes its own exclusive temporary).

    frame: "part" (recovered axis frame, footprint origin) or "camera". product: the product name (default:
    the file stem). Returns a `StepReport`; faces that could not be built are reported there, not raised,
    unless none could: then `StepExportError` and nothing is written.
    """
    t0 = time.perf_counter()
    path = Path(path)
    frame = Frame(frame)
    cfg = config or BrepConfig()
    built = build(vbrep, frame, cfg)
    if not built.faces:
        # A product of edges alone is useless and crashes FreeCAD 0.20's import: refuse rather than write it.
        detail = "; ".join(built.warnings[:3]) or "the VB-Rep has no faces"
        raise StepExportError(f"{path}: no face could be built ({detail})")
    target = atomic_write(path) if atomic else contextlib.nullcontext(path)
    with target as tmp, quiet_occt():  # exclusive temporary in the folder, renamed into place
        write_xcaf_step(
            tmp, built.shape, product or path.stem, _attributes(vbrep, built), originating_system=v2c_origin()
        )
        # The file must hold what was built: OCCT's reader heals faces (and may split one, losing its name).
        # Faces the round trip changed, or left for OCCT's mesher to draw short, are written again from their mesh
        # outline; an outline face the mesher draws short is written again from its outline unsimplified (a
        # feat_block wall of 6,539 mm² drawn at 4,525: whole so)
        deflection = cfg.roundtrip_mesh_deflection_rel * max(built.fmap.length(vbrep.scale), 1.0)
        outlined = frozenset(built.fallback_faces)
        loops = frozenset(built.built_area) - outlined
        areas, drawn = written_face_areas(tmp, deflection, cfg.roundtrip_mesh_angle_rad)
        tol = cfg.roundtrip_tol_rel
        changed = frozenset(
            fid
            for fid, a in built.built_area.items()
            if abs(areas.get(fid, 0.0) - a) > tol * a
            or (fid in loops and drawn.get(fid, 0.0) < (1 - tol) * areas.get(fid, 0.0))
        )
        raw = frozenset(fid for fid in outlined if fid in areas and drawn.get(fid, 0.0) < (1 - tol) * areas[fid])
        if changed or raw:
            built = build(vbrep, frame, cfg, force_outline=changed, raw_outline=raw)
            write_xcaf_step(
                tmp, built.shape, product or path.stem, _attributes(vbrep, built), originating_system=v2c_origin()
            )
    invalid = [fid for fid, face in built.faces.items() if not BRepCheck_Analyzer(face).IsValid()]
    shape_valid = BRepCheck_Analyzer(built.shape).IsValid()
    warnings = list(built.warnings) + [f"face {fid}: fails BRepCheck" for fid in invalid]
    if not shape_valid and not invalid:
        warnings.append("the assembled shape fails BRepCheck")
    return StepReport(
        path=path,
        frame=frame,
        n_faces=len(built.faces),
        n_edges=len(built.edges),
        free_edges=built.free_edges,
        fallback_faces=built.fallback_faces,
        skipped_faces=built.skipped_faces,
        invalid_faces=invalid,
        warnings=warnings,
        seconds=time.perf_counter() - t0,
        frame_map=built.fmap,
        face_edges=built.face_edges,
        copied_edges=built.copied_edges,
        shape_valid=shape_valid,
        dropped_edges=built.dropped_edges,
    )


# ------------------------------------------------------------------------------------------------ reading
def faces_by_id(faces: list[ReadSubShape]) -> dict[int, list[TopoDS_Face]]:
    """VFace id -> the faces (all pieces) named after it, of faces read back by `exporters.xcaf.read_xcaf_step`;
    unnamed faces are left out."""
    out: dict[int, list[TopoDS_Face]] = {}
    for f in faces:
        fid = parse_face_name(f.name)[0]
        if fid is not None:
            out.setdefault(fid, []).append(TopoDS.Face_s(f.shape))
    return out


def written_face_areas(
    path: str | Path, deflection: float, angle_rad: float
) -> tuple[dict[int, float], dict[int, float]]:
    """VFace id -> the area (mm²) of the faces named after it in a STEP written by `write` (all pieces), and
    VFace id -> the area of their triangulation by OCCT's mesher at ``deflection`` (mm) and ``angle_rad``."""
    by_id = faces_by_id(read_xcaf_step(path).faces)
    areas = {fid: sum(face_area(f) for f in fs) for fid, fs in by_id.items()}
    drawn = {fid: sum(drawn_area(f, deflection, angle_rad) for f in fs) for fid, fs in by_id.items()}
    return areas, drawn


def _edge_type(text: str | None) -> EdgeType | None:
    try:
        return EdgeType(text) if text else None
    except ValueError:
        return None


def _type_of_color(rgb: RGB | None, tol: float = 0.02) -> EdgeType | None:
    if rgb is None:
        return None
    for t, c in EDGE_COLORS.items():
        if max(abs(a - b) for a, b in zip(rgb, c)) <= tol:
            return t
    return None


@dataclass(frozen=True)
class TypedFace:
    """A face read back. surface: "plane", "cylinder", "cone", "sphere", "torus", "revolution", "bspline" or
    "other"; name: its STEP name; type, axis, id: parsed from the name (None when it does not parse); sigma_mm:
    the name's 1-sigma position error in millimetres (None when the name has no ``:s`` field)."""

    surface: str
    name: str | None
    type: PrimitiveType | None
    axis: str | None
    id: int | None
    sigma_mm: float | None = None


@dataclass(frozen=True)
class TypedEdge:
    """An edge read back with its type three ways: from its name, its layer and its colour (sRGB).

    n_faces: how many faces of the file use it (2 for an intersection edge shared by its faces). tangent: the name
    says its faces meet tangentially (G1). sigma_mm: the name's 1-sigma position error in millimetres (None when
    the name has no ``:s`` field, as in files written before it existed).
    """

    name: str | None
    id: int | None
    type: EdgeType | None
    confidence: float | None
    layer: str | None
    layer_type: EdgeType | None
    color: RGB | None
    color_type: EdgeType | None
    n_faces: int
    tangent: bool = False
    sigma_mm: float | None = None


@dataclass
class TypedStep:
    """A STEP file read back: its products, its shape, every unique face and edge (named or not)."""

    path: Path
    products: list[str]
    shape: TopoDS_Shape
    faces: list[TypedFace] = field(default_factory=list)
    edges: list[TypedEdge] = field(default_factory=list)

    @property
    def typed_edges(self) -> list[TypedEdge]:
        """The edges whose name carries a VB-Rep edge type."""
        return [e for e in self.edges if e.type is not None]

    def edge(self, edge_id: int) -> list[TypedEdge]:
        """Every edge named with VB-Rep edge id ``edge_id`` (more than one where ShapeFix split it)."""
        return [e for e in self.edges if e.id == edge_id]


def _sigma(text: str | None) -> float | None:
    return None if text is None else float(text)


def parse_edge_name(name: str | None) -> tuple[int | None, EdgeType | None, float | None, float | None, bool]:
    """(id, type, confidence, sigma_mm, tangent) of an edge name written by `edge_name`, with or without the
    ``:s<sigma>`` field (sigma_mm None without it); (None, None, None, None, False) when it does not parse."""
    m = _EDGE_NAME.match(name or "")
    if not m:
        return None, None, None, None, False
    return int(m["id"]), _edge_type(m["type"]), float(m["conf"]), _sigma(m["sigma"]), m["tangent"] is not None


def parse_face_name(name: str | None) -> tuple[int | None, PrimitiveType | None, str | None, float | None]:
    """(id, primitive type, axis, sigma_mm) of a face name written by `face_name`, with or without the
    ``:s<sigma>`` field; axis None for ``-``; all None when it does not parse."""
    m = _FACE_NAME.match(name or "")
    if not m:
        return None, None, None, None
    try:
        ptype = PrimitiveType(m["type"])
    except ValueError:
        ptype = None
    return int(m["id"]), ptype, (None if m["axis"] == "-" else m["axis"]), _sigma(m["sigma"])


def read_typed(path: str | Path) -> TypedStep:
    """Read a STEP written by `write` (or any STEP) back: faces with surface type and name, edges with type
    from name, layer and colour. Raises `exporters.xcaf.XcafError` for an unreadable file."""
    path = Path(path)
    with quiet_occt():
        rs = read_xcaf_step(path)
    ancestors = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(rs.shape, TopAbs_EDGE, TopAbs_FACE, ancestors)
    out = TypedStep(path=path, products=rs.products, shape=rs.shape)
    for f in rs.faces:
        kind = BRepAdaptor_Surface(TopoDS.Face_s(f.shape)).GetType()
        fid, ptype, axis, fsig = parse_face_name(f.name)
        out.faces.append(TypedFace(_SURFACE_NAMES.get(kind, "other"), f.name, ptype, axis, fid, fsig))
    for e in rs.edges:
        eid, etype, conf, esig, _ = parse_edge_name(e.name)
        n = 0
        if ancestors.Contains(e.shape):
            faces = ancestors.FindFromKey(e.shape)
            uniq: list[TopoDS_Shape] = []
            for face in faces:
                if not any(face.IsSame(u) for u in uniq):
                    uniq.append(face)
            n = len(uniq)
        layer = next((lay for lay in e.layers if lay.startswith("edge_")), e.layers[0] if e.layers else None)
        layer_type = _edge_type(layer[len("edge_") :]) if layer and layer.startswith("edge_") else None
        out.edges.append(
            TypedEdge(
                e.name,
                eid,
                etype,
                conf,
                layer,
                layer_type,
                e.color,
                _type_of_color(e.color),
                n,
                (e.name or "").endswith(":tangent"),
                esig,
            )
        )
    return out


__all__ = [
    "EDGE_COLORS",
    "Frame",
    "FrameMap",
    "StepExportError",
    "StepReport",
    "TypedEdge",
    "TypedFace",
    "TypedStep",
    "build",
    "edge_layer",
    "edge_name",
    "face_name",
    "parse_edge_name",
    "parse_face_name",
    "read_typed",
    "sigma_field",
    "write",
]
