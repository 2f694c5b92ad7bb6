"""Open a `v2c to-step` STEP file in FreeCAD with its edge types visible (a FreeCAD macro and module).

FreeCAD's own STEP import keeps the per-edge colours but drops the names (``intersection:0.75:e8``), so the edge
types, confidences and VB-Rep ids are invisible, and free edges become hundreds of anonymous tree objects. This
module reads the STEP text for those names and builds a tidy document:

- ``part``: one Part::Feature holding the whole shape (faces and free edges);
- one group per edge type (``intersection``, ``visibility``, ``occluded``, ``silhouette``), each holding one
  Part::Feature per VB-Rep edge with the properties ``EdgeType``, ``Confidence``, ``EdgeId``, ``StepName`` and
  ``Sigma`` (the 1-sigma position error, a length in mm; absent for a file written before names carried it) and,
  in the GUI, the edge's colour (intersection blue, silhouette red, visibility cyan, occluded green).

Edges are matched to the file's names through their end points (VERTEX_POINT of an EDGE_CURVE, trim points of a
free edge's TRIMMED_CURVE), the curve kind and a circle's radius: millimetres, to ``MATCH_TOL_MM``.

Use, headless: ``V2C_STEP=part.step [V2C_FCSTD=part.FCStd] freecadcmd exporters/freecad_import.py`` prints one
line ``V2C_FREECAD_IMPORT {json}`` (counts per type, unmatched names, edges and faces with their sigma) and saves
the document when V2C_FCSTD is set. In the GUI: Macro > Macros... > this file (asks for the STEP file), or from
FreeCAD's Python console ``exec(open(".../freecad_import.py").read()); open_typed_step("part.step")``. Runs under
FreeCAD's own Python (3.8+), so it imports nothing from v2c; `parse_typed_edges` and `parse_typed_faces` are plain
Python and also run outside FreeCAD.
"""

from __future__ import annotations

import json
import math
import os
import re
import sys
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # aliases for annotations only: FreeCAD's Python (3.8) cannot subscript tuple at run time
    #: A point or vector of the STEP file (millimetres).
    Point = tuple[float, ...]
    #: One curve of a named edge: end points (None when not computable), STEP curve kind, circle radius or None.
    CurveItem = tuple[Point | None, Point | None, str, float | None]

#: Largest distance between matched end points (millimetres; the file writes 1e-12-exact coordinates).
MATCH_TOL_MM = 1e-4
#: Largest difference of matched circle radii (millimetres).
RADIUS_TOL_MM = 1e-4
#: sRGB of each edge type, as `exporters.step.EDGE_COLORS` writes them (tests/test_freecad_import.py checks).
EDGE_COLORS = {
    "intersection": (0.0, 0.0, 1.0),
    "visibility": (0.0, 1.0, 1.0),
    "occluded": (0.0, 1.0, 0.0),
    "silhouette": (1.0, 0.0, 0.0),
}
EDGE_TYPES = tuple(EDGE_COLORS)
MARK = "V2C_FREECAD_IMPORT "

_ENTITY = re.compile(r"#(\d+)\s*=\s*(.*?);\s*(?=#\d+\s*=|ENDSEC;)", re.DOTALL)
#: An edge name of `exporters.step.edge_name`: type, confidence, id, optional 1-sigma position error in mm (files
#: written before it existed have none), optional ``:tangent``.
_NAME = re.compile(
    r"^(intersection|visibility|occluded|silhouette):([0-9.]+):e(\d+)(?::s([0-9]+(?:\.[0-9]*)?))?(?::tangent)?$"
)
#: A face name of `exporters.step.face_name`: primitive type, axis, id, optional 1-sigma position error in mm.
_FACE_NAME = re.compile(r"^([a-z]+):([XYZU-]):f(\d+)(?::s([0-9]+(?:\.[0-9]*)?))?$")


class TypedEdgeRecord:
    """One named edge of the file: type, confidence in [0, 1], VB-Rep edge id, end points (mm), curve kind
    (the STEP entity name, e.g. LINE, CIRCLE, B_SPLINE_CURVE_WITH_KNOTS), a circle's radius (mm) or None, and the
    name's 1-sigma position error (mm) or None when the name has no ``:s`` field."""

    __slots__ = ("confidence", "edge_id", "kind", "name", "p0", "p1", "radius", "sigma_mm", "type")

    def __init__(
        self,
        name: str,
        type_: str,
        confidence: float,
        edge_id: int,
        p0: Point | None,
        p1: Point | None,
        kind: str,
        radius: float | None,
        sigma_mm: float | None = None,
    ) -> None:
        self.name, self.type, self.confidence, self.edge_id = name, type_, confidence, edge_id
        self.p0, self.p1, self.kind, self.radius, self.sigma_mm = p0, p1, kind, radius, sigma_mm

    def as_dict(self) -> dict[str, Any]:
        """The record as a plain dict (slot name -> value), e.g. for JSON."""
        return {s: getattr(self, s) for s in self.__slots__}


def _args(body: str) -> tuple[str, list[str]]:
    """Top-level arguments of an entity body ``NAME(a,b,(c,d),'x,y')`` -> (NAME, [a, b, '(c,d)', "'x,y'"])."""
    head, _, rest = body.partition("(")
    rest = rest[: rest.rfind(")")]
    out, depth, cur, quoted = [], 0, [], False
    for ch in rest:
        if ch == "'":
            quoted = not quoted
        if not quoted:
            if ch == "(":
                depth += 1
            elif ch == ")":
                depth -= 1
            elif ch == "," and depth == 0:
                out.append("".join(cur).strip())
                cur = []
                continue
        cur.append(ch)
    out.append("".join(cur).strip())
    return head.strip(), out


def _ref(text: str) -> int | None:
    """The entity number of a ``#123`` reference, None when ``text`` is not one."""
    m = re.match(r"#(\d+)", text.strip())
    return int(m.group(1)) if m else None


def _unquote(text: str) -> str:
    """A STEP string literal's content (``'it''s'`` -> ``it's``); other text stripped only."""
    text = text.strip()
    return text[1:-1].replace("''", "'") if text.startswith("'") and text.endswith("'") else text


def parse_typed_edges(text: str) -> list[TypedEdgeRecord]:
    """Every edge of a v2c STEP file that carries a typed name (``<type>:<confidence>:e<id>``), as
    `TypedEdgeRecord` objects in file order. ``text``: the STEP file's content."""
    ents = {int(m.group(1)): " ".join(m.group(2).split()) for m in _ENTITY.finditer(text)}

    def point(ref: int | None) -> Point | None:
        """A CARTESIAN_POINT (or a VERTEX_POINT's point) -> its coordinates, mm; None for other entities."""
        name, args = _args(ents.get(ref, ""))
        if name == "VERTEX_POINT":
            return point(_ref(args[1]))
        if name != "CARTESIAN_POINT":
            return None
        return tuple(float(x) for x in args[1].strip("()").split(","))

    def vec(ref: int | None) -> Point | None:
        """DIRECTION -> its ratios; VECTOR -> direction x magnitude."""
        name, args = _args(ents.get(ref, ""))
        if name == "DIRECTION":
            return tuple(float(x) for x in args[1].strip("()").split(","))
        if name == "VECTOR":
            d, mag = vec(_ref(args[1])), float(args[2])
            n = math.sqrt(sum(x * x for x in d)) or 1.0
            return tuple(x / n * mag for x in d)
        return None

    def curve_point(ref: int | None, t: float) -> Point | None:
        """The point at parameter t of a LINE, CIRCLE or clamped B-spline end (None otherwise), mm."""
        name, args = _args(ents.get(ref, ""))
        if name == "LINE":
            p, v = point(_ref(args[1])), vec(_ref(args[2]))
            return tuple(a + t * b for a, b in zip(p, v))
        if name == "CIRCLE":
            _, ax = _args(ents.get(_ref(args[1]), ""))  # AXIS2_PLACEMENT_3D('', centre, axis, ref direction)
            c, z, x = point(_ref(ax[1])), vec(_ref(ax[2])), vec(_ref(ax[3]))
            nz, nx = math.sqrt(sum(a * a for a in z)), math.sqrt(sum(a * a for a in x))
            z, x = tuple(a / nz for a in z), tuple(a / nx for a in x)
            y = (z[1] * x[2] - z[2] * x[1], z[2] * x[0] - z[0] * x[2], z[0] * x[1] - z[1] * x[0])
            r = float(args[2])
            return tuple(ci + r * (math.cos(t) * xi + math.sin(t) * yi) for ci, xi, yi in zip(c, x, y))
        if name.startswith("B_SPLINE_CURVE_WITH_KNOTS"):
            poles = [int(p) for p in re.findall(r"#(\d+)", args[2])]
            knots = [float(k) for k in re.findall(r"[-+0-9.eE]+", args[7])]
            if knots and abs(t - knots[0]) < 1e-9:
                return point(poles[0])
            if knots and abs(t - knots[-1]) < 1e-9:
                return point(poles[-1])
        return None

    def trim(sel: str, basis: int | None) -> Point | None:
        """A trim select: the point at its PARAMETER_VALUE when computable, else its CARTESIAN_POINT (which
        OCCT writes at the edge's vertex, up to the vertex tolerance off the curve)."""
        m = re.search(r"PARAMETER_VALUE\(([-+0-9.eE]+)\)", sel)
        p = curve_point(basis, float(m.group(1))) if m else None
        if p is None:
            refs = [_ref(x) for x in sel.strip("()").split(",") if x.strip().startswith("#")]
            p = point(refs[0]) if refs else None
        return p

    def curve_info(ref: int | None) -> tuple[str, float | None]:
        """The basis curve's STEP entity name (through SURFACE_CURVE, SEAM_CURVE, TRIMMED_CURVE) and a circle's
        radius (mm; None for other curves)."""
        name, args = _args(ents.get(ref, ""))
        if name == "SURFACE_CURVE" or name == "SEAM_CURVE":
            return curve_info(_ref(args[1]))
        if name == "TRIMMED_CURVE":
            return curve_info(_ref(args[1]))
        radius = float(args[2]) if name == "CIRCLE" else None
        return name, radius

    records: list[TypedEdgeRecord] = []
    for body in ents.values():
        kind, args = _args(body)
        if kind not in ("EDGE_CURVE", "GEOMETRIC_CURVE_SET") or not args:
            continue
        m = _NAME.match(_unquote(args[0]))
        if not m:
            continue
        if kind == "EDGE_CURVE":
            p0, p1 = point(_ref(args[1])), point(_ref(args[2]))
            ckind, radius = curve_info(_ref(args[3]))
            items: list[CurveItem] = [(p0, p1, ckind, radius)]
        else:  # a free edge: its curves (TRIMMED_CURVE with CARTESIAN_POINT trims, or a whole curve)
            items = []
            for r in re.findall(r"#(\d+)", args[1]):
                cname, cargs = _args(ents.get(int(r), ""))
                if cname == "TRIMMED_CURVE":
                    p0, p1 = trim(cargs[2], _ref(cargs[1])), trim(cargs[3], _ref(cargs[1]))
                else:
                    p0 = p1 = None
                ckind, radius = curve_info(int(r))
                items.append((p0, p1, ckind, radius))
        sigma = None if m.group(4) is None else float(m.group(4))
        for p0, p1, ckind, radius in items:
            records.append(
                TypedEdgeRecord(
                    _unquote(args[0]), m.group(1), float(m.group(2)), int(m.group(3)), p0, p1, ckind, radius, sigma
                )
            )
    return records


def parse_typed_faces(text: str) -> list[dict[str, Any]]:
    """The named faces of a STEP file's text (``ADVANCED_FACE`` names of `exporters.step.face_name`), one dict per
    face: name, type, axis (None for ``-``), id and sigma_mm (the 1-sigma position error in mm, None when the name
    has no ``:s`` field); sorted by id."""
    out = []
    for m in _ENTITY.finditer(text):
        kind, args = _args(" ".join(m.group(2).split()))
        if kind != "ADVANCED_FACE" or not args:
            continue
        name = _unquote(args[0])
        f = _FACE_NAME.match(name)
        if f:
            sigma = None if f.group(4) is None else float(f.group(4))
            axis = None if f.group(2) == "-" else f.group(2)
            out.append({"name": name, "type": f.group(1), "axis": axis, "id": int(f.group(3)), "sigma_mm": sigma})
    return sorted(out, key=lambda d: d["id"])


def _close(a: Point | None, b: Point | None, tol: float = MATCH_TOL_MM) -> bool:
    """Both points known and within ``tol`` (mm) of each other."""
    return a is not None and b is not None and math.dist(a, b) <= tol


def _kind_of(edge: Any) -> str:
    """The STEP curve kind a FreeCAD edge corresponds to (LINE, CIRCLE, ELLIPSE, or B_SPLINE_CURVE...)."""
    name = type(edge.Curve).__name__
    return {"Line": "LINE", "LineSegment": "LINE", "Circle": "CIRCLE", "Ellipse": "ELLIPSE"}.get(name, name)


def match_edges(
    records: list[TypedEdgeRecord], edges: list[Any]
) -> tuple[list[tuple[TypedEdgeRecord, Any]], list[TypedEdgeRecord]]:
    """Pair every record with one FreeCAD edge: same end points (either direction), same curve kind, same
    radius for circles; each edge used once. Returns ([(record, edge)], [unmatched records])."""
    free = list(edges)
    pairs, missing = [], []
    for rec in records:
        best = None
        for e in free:
            v = e.Vertexes
            a, b = tuple(v[0].Point), tuple(v[-1].Point)
            if not ((_close(a, rec.p0) and _close(b, rec.p1)) or (_close(a, rec.p1) and _close(b, rec.p0))):
                continue
            k = _kind_of(e)
            if rec.kind in ("LINE", "CIRCLE", "ELLIPSE") and k != rec.kind:
                continue
            if rec.radius is not None and abs(e.Curve.Radius - rec.radius) > RADIUS_TOL_MM:
                continue
            best = e
            break
        if best is None:
            missing.append(rec)
        else:
            free.remove(best)
            pairs.append((rec, best))
    return pairs, missing


def open_typed_step(path: str, doc: Any = None) -> dict[str, Any]:
    """Import the STEP file ``path`` into ``doc`` (a new document when None): the part, and one group per edge
    type of Part::Feature edges with their EdgeType, Confidence, EdgeId, StepName and (when the name has it) Sigma
    properties. Returns a summary dict: the document name, counts per type, the names that matched no edge, the
    edges with their properties (sigma_mm None without the field) and the named faces (`parse_typed_faces`)."""
    import FreeCAD
    import Part

    with open(path, encoding="utf-8", errors="replace") as fp:
        text = fp.read()
    records, faces = parse_typed_edges(text), parse_typed_faces(text)
    shape = Part.Shape()
    shape.read(path)
    if doc is None:
        doc = FreeCAD.newDocument(re.sub(r"\W", "_", os.path.splitext(os.path.basename(path))[0]) or "v2c")
    part = doc.addObject("Part::Feature", "part")
    part.Shape = shape
    pairs, missing = match_edges(records, shape.Edges)
    groups = {}
    counts = {t: 0 for t in EDGE_TYPES}
    for rec, edge in pairs:
        grp = groups.get(rec.type)
        if grp is None:
            grp = groups[rec.type] = doc.addObject("App::DocumentObjectGroup", rec.type)
        obj = doc.addObject("Part::Feature", f"e{rec.edge_id}_{rec.type}")
        obj.Label = rec.name
        obj.Shape = edge
        obj.addProperty("App::PropertyString", "EdgeType", "v2c", "VB-Rep edge type").EdgeType = rec.type
        obj.addProperty("App::PropertyFloat", "Confidence", "v2c", "confidence in [0, 1]").Confidence = rec.confidence
        obj.addProperty("App::PropertyInteger", "EdgeId", "v2c", "VB-Rep edge id").EdgeId = rec.edge_id
        obj.addProperty("App::PropertyString", "StepName", "v2c", "name in the STEP file").StepName = rec.name
        if rec.sigma_mm is not None:  # files written before the sigma field have none
            obj.addProperty("App::PropertyLength", "Sigma", "v2c", "1-sigma position error (mm)").Sigma = rec.sigma_mm
        grp.addObject(obj)
        counts[rec.type] += 1
        if FreeCAD.GuiUp:
            obj.ViewObject.LineColor = EDGE_COLORS[rec.type]
            obj.ViewObject.LineWidth = 3.0
    for t, grp in groups.items():
        grp.Label = f"{t} ({counts[t]})"
    doc.recompute()
    edges = [
        {
            "object": o.Name,
            "type": o.EdgeType,
            "confidence": o.Confidence,
            "id": o.EdgeId,
            "sigma_mm": o.Sigma.Value if hasattr(o, "Sigma") else None,
            "length": o.Shape.Length,
        }
        for o in doc.Objects
        if hasattr(o, "EdgeType")
    ]
    return {
        "document": doc.Name,
        "counts": counts,
        "named": len(records),
        "missing": [r.name for r in missing],
        "part_faces": len(shape.Faces),
        "part_edges": len(shape.Edges),
        "edges": edges,
        "faces": faces,
        "groups": sorted(g.Label for g in groups.values()),
    }


def main() -> None:
    """Entry point of freecadcmd and of the GUI macro: opens V2C_STEP (or the file a dialog asks for in the GUI),
    saves the document to V2C_FCSTD when set, prints one ``V2C_FREECAD_IMPORT {json}`` line."""
    import FreeCAD

    path = os.environ.get("V2C_STEP")
    if not path and FreeCAD.GuiUp:
        from PySide import QtGui

        path, _ = QtGui.QFileDialog.getOpenFileName(None, "Open a v2c STEP file", "", "STEP (*.step *.stp)")
    if not path:
        print("freecad_import: set V2C_STEP=<file.step>", file=sys.stderr)
        return
    out = {"path": path, "ok": False}
    try:
        out.update(open_typed_step(path))
        save = os.environ.get("V2C_FCSTD")
        if save:
            FreeCAD.getDocument(out["document"]).saveAs(save)
        out["ok"] = True
    except Exception as exc:  # noqa: BLE001 - reported in the JSON line for the caller
        out["error"] = f"{type(exc).__name__}: {exc}"
    print(MARK + json.dumps(out), flush=True)


def _under_freecad() -> bool:
    """Whether this runs under FreeCAD (its ``FreeCAD`` module imports)."""
    try:
        import FreeCAD  # noqa: F401
    except ImportError:
        return False
    return True


# The GUI's macro runner executes the file as __main__; freecadcmd imports it as a module named after the file,
# so there V2C_STEP says it is being run rather than imported by another script.
if (__name__ == "__main__" or (__name__ == "freecad_import" and os.environ.get("V2C_STEP"))) and _under_freecad():
    main()
