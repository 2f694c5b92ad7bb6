"""STEP AP242 with per-sub-shape names, layers and colours through OCCT's XCAF document, and reading them
back.

Kept generic (no VB-Rep types): `write_xcaf_step` takes a shape and a list of `SubShapeAttrs`;
`read_xcaf_step` returns every unique face and edge of the file with whatever name, layer and colour came
back. Colours are sRGB triples in [0, 1] (converted with ``Quantity_TOC_sRGB`` both ways; plain RGB would be
taken as linear).

Measured pitfalls this module handles (../shared/NOTES.md): the sub-shape-name static exists only once the
STEP CAF controller is initialised, and setting an unknown static fails silently, so every static set is
checked; readers need ``read.stepcaf.subshapes.name`` too; attributes are only read after ``IsAttribute`` says
they are there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from OCP.APIHeaderSection import APIHeaderSection_MakeHeader
from OCP.IFSelect import IFSelect_RetDone
from OCP.Interface import Interface_Static
from OCP.Quantity import Quantity_Color, Quantity_TOC_sRGB
from OCP.STEPCAFControl import STEPCAFControl_Controller, STEPCAFControl_Reader, STEPCAFControl_Writer
from OCP.STEPControl import STEPControl_AsIs
from OCP.TCollection import TCollection_ExtendedString, TCollection_HAsciiString
from OCP.TDataStd import TDataStd_Name
from OCP.TDF import TDF_Label, TDF_LabelSequence
from OCP.TDocStd import TDocStd_Document
from OCP.TopAbs import TopAbs_COMPOUND, TopAbs_EDGE, TopAbs_FACE
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS_Iterator, TopoDS_Shape
from OCP.TopTools import TopTools_IndexedMapOfShape
from OCP.XCAFApp import XCAFApp_Application
from OCP.XCAFDoc import (
    XCAFDoc_ColorCurv,
    XCAFDoc_ColorGen,
    XCAFDoc_ColorSurf,
    XCAFDoc_DocumentTool,
    XCAFDoc_LayerTool,
)

from v2c.errors import V2cError

#: STEP schema written (AP242 DIS, the OCCT name of AP242).
SCHEMA = "AP242DIS"

RGB = tuple[float, float, float]


class XcafError(V2cError, RuntimeError):
    """The STEP file could not be written or read with its attributes."""


@dataclass(frozen=True)
class SubShapeAttrs:
    """Attributes of one sub-shape (face or edge) of the written shape.

    color: sRGB in [0, 1]; written as a curve colour for edges and a surface colour for faces.
    """

    shape: TopoDS_Shape
    name: str
    layer: str | None = None
    color: RGB | None = None


@dataclass(frozen=True)
class ReadSubShape:
    """A face or edge read back: its shape, and the name, layers and sRGB colour found for it (or None)."""

    shape: TopoDS_Shape
    name: str | None
    layers: tuple[str, ...]
    color: RGB | None


@dataclass
class ReadStep:
    """What `read_xcaf_step` found: the product names, its shape, and every unique face and edge."""

    products: list[str]
    shape: TopoDS_Shape
    faces: list[ReadSubShape]
    edges: list[ReadSubShape]


def _set_int(name: str, value: int) -> None:
    if not Interface_Static.SetIVal_s(name, value):
        raise XcafError(f"OCCT static {name!r} is not registered (controller not initialised?)")


def _set_str(name: str, value: str) -> None:
    if not Interface_Static.SetCVal_s(name, value):
        raise XcafError(f"OCCT static {name!r} could not be set to {value!r}")


def _new_document() -> TDocStd_Document:
    doc = TDocStd_Document(TCollection_ExtendedString("MDTV-XCAF"))
    XCAFApp_Application.GetApplication_s().InitDocument(doc)
    return doc


def _color(rgb: RGB) -> Quantity_Color:
    r, g, b = (float(c) for c in rgb)
    return Quantity_Color(r, g, b, Quantity_TOC_sRGB)


def write_xcaf_step(
    path: str | Path,
    shape: TopoDS_Shape,
    product: str,
    subshapes: list[SubShapeAttrs],
    originating_system: str | None = None,
) -> None:
    """Write ``shape`` as one product named ``product`` with the sub-shape attributes to a STEP AP242 file.

    originating_system: written into the header's FILE_NAME (default: OCCT's own text).

    Lengths are written as millimetres (the shape must already be in millimetres). Raises XcafError when a
    sub-shape is not part of ``shape`` or the writer fails.
    """
    doc = _new_document()
    main = doc.Main()
    st = XCAFDoc_DocumentTool.ShapeTool_s(main)
    ct = XCAFDoc_DocumentTool.ColorTool_s(main)
    lt = XCAFDoc_DocumentTool.LayerTool_s(main)
    root = st.AddShape(shape, False)
    TDataStd_Name.Set_s(root, TCollection_ExtendedString(product, True))  # True: the str arrives as UTF-8 bytes
    for sub in subshapes:
        label = st.AddSubShape(root, sub.shape)
        if label.IsNull():
            raise XcafError(f"sub-shape {sub.name!r} is not part of the shape")
        TDataStd_Name.Set_s(label, TCollection_ExtendedString(sub.name, True))
        if sub.color is not None:
            kind = XCAFDoc_ColorCurv if sub.shape.ShapeType() == TopAbs_EDGE else XCAFDoc_ColorSurf
            ct.SetColor(label, _color(sub.color), kind)
        if sub.layer is not None:
            lt.SetLayer(label, TCollection_ExtendedString(sub.layer, True))

    STEPCAFControl_Controller.Init_s()
    writer = STEPCAFControl_Writer()
    _set_int("write.stepcaf.subshapes.name", 1)
    _set_str("write.step.schema", SCHEMA)
    _set_str("write.step.unit", "MM")
    _set_int("write.surfacecurve.mode", 1)
    writer.SetNameMode(True)
    writer.SetColorMode(True)
    writer.SetLayerMode(True)
    if not writer.Transfer(doc, STEPControl_AsIs):
        raise XcafError("STEPCAFControl_Writer.Transfer failed")
    if originating_system:  # FILE_NAME's originating system: how `v2c` knows a file is its own
        header = APIHeaderSection_MakeHeader(writer.ChangeWriter().Model())
        header.SetOriginatingSystem(TCollection_HAsciiString(originating_system))
    if writer.Write(str(path)) != IFSelect_RetDone:
        raise XcafError(f"{path}: STEP write failed")


# ------------------------------------------------------------------------------------------------ reading
def _name_of(label: TDF_Label) -> str | None:
    if label.IsNull() or not label.IsAttribute(TDataStd_Name.GetID_s()):
        return None
    attr = TDataStd_Name()
    if not label.FindAttribute(TDataStd_Name.GetID_s(), attr):
        return None
    return attr.Get().ToExtString()


def _color_of(ct: object, shape: TopoDS_Shape, kinds: tuple) -> RGB | None:
    col = Quantity_Color()
    for kind in kinds:
        if ct.GetColor(shape, kind, col):
            r, g, b = col.Values(Quantity_TOC_sRGB)
            return (round(r, 4), round(g, 4), round(b, 4))
    return None


def _layers_by_shape(st: object, lt: object) -> list[tuple[TopoDS_Shape, str]]:
    """(shape, layer name) pairs: the reader hangs layers on the sub-shape labels, so walk the layers."""
    out = []
    layers = TDF_LabelSequence()
    lt.GetLayerLabels(layers)
    for i in range(1, layers.Length() + 1):
        lab = layers.Value(i)
        name = TCollection_ExtendedString()
        if not lt.GetLayer(lab, name):
            continue
        shapes = TDF_LabelSequence()
        XCAFDoc_LayerTool.GetShapesOfLayer_s(lab, shapes)
        for j in range(1, shapes.Length() + 1):
            out.append((st.GetShape_s(shapes.Value(j)), name.ToExtString()))
    return out


def read_xcaf_step(path: str | Path) -> ReadStep:
    """Read a STEP file with names, colours and layers of its sub-shapes (see `ReadStep`)."""
    path = Path(path)
    if not path.is_file():
        raise XcafError(f"{path}: no such file")
    STEPCAFControl_Controller.Init_s()
    reader = STEPCAFControl_Reader()
    _set_int("read.stepcaf.subshapes.name", 1)
    reader.SetNameMode(True)
    reader.SetColorMode(True)
    reader.SetLayerMode(True)
    if reader.ReadFile(str(path)) != IFSelect_RetDone:
        raise XcafError(f"{path}: not a readable STEP file")
    doc = _new_document()
    if not reader.Transfer(doc):
        raise XcafError(f"{path}: STEP transfer failed")
    main = doc.Main()
    st = XCAFDoc_DocumentTool.ShapeTool_s(main)
    ct = XCAFDoc_DocumentTool.ColorTool_s(main)
    lt = XCAFDoc_DocumentTool.LayerTool_s(main)
    roots = TDF_LabelSequence()
    st.GetFreeShapes(roots)
    labels = [roots.Value(i) for i in range(1, roots.Length() + 1)]
    if not labels:
        raise XcafError(f"{path}: no shape in the file")
    products = [_name_of(lab) or "" for lab in labels]
    shape = st.GetShape_s(labels[0]) if len(labels) == 1 else reader.ChangeReader().OneShape()
    layered = _layers_by_shape(st, lt)
    transfer = reader.ChangeReader().WS().TransferReader()

    def own(
        s: TopoDS_Shape,
        m: TopTools_IndexedMapOfShape,
        layers: dict[int, list[str]],
        colors: tuple,
    ) -> tuple[str | None, tuple[str, ...], RGB | None]:
        name = None
        for root in labels:
            sub = TDF_Label()
            if st.FindSubShape(root, s, sub):
                name = _name_of(sub)
                break
        return name, tuple(layers.get(m.FindIndex(s), ())), _color_of(ct, s, colors)

    def indexed(kind: object) -> tuple[TopTools_IndexedMapOfShape, dict[int, list[str]]]:
        m = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(shape, kind, m)
        layers: dict[int, list[str]] = {}
        for s, name in layered:
            idx = m.FindIndex(s)
            if idx > 0:
                layers.setdefault(idx, []).append(name)
        return m, layers

    # Free edges come back inside one compound each (their GEOMETRIC_CURVE_SET), which holds their attributes:
    # its name only on the STEP entity, its colour and layer on the compound.
    emap, elayers = indexed(TopAbs_EDGE)
    cmap = TopTools_IndexedMapOfShape()
    for comp in _sub_compounds(shape):
        cmap.Add(comp)
    clayers: dict[int, list[str]] = {}
    for s, name in layered:
        if cmap.FindIndex(s) > 0:
            clayers.setdefault(cmap.FindIndex(s), []).append(name)
    inherited: dict[int, tuple[str | None, tuple[str, ...], RGB | None]] = {}
    for i in range(1, cmap.Extent() + 1):
        comp = cmap.FindKey(i)
        name, layers, color = own(comp, cmap, clayers, (XCAFDoc_ColorCurv, XCAFDoc_ColorGen))
        name = name or _entity_name(transfer, comp)
        inner = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(comp, TopAbs_EDGE, inner)
        for j in range(1, inner.Extent() + 1):
            inherited[emap.FindIndex(inner.FindKey(j))] = (name, layers, color)

    edges = []
    for i in range(1, emap.Extent() + 1):
        s = emap.FindKey(i)
        name, layers, color = own(s, emap, elayers, (XCAFDoc_ColorCurv, XCAFDoc_ColorGen))
        up = inherited.get(i, (None, (), None))
        edges.append(ReadSubShape(s, name or up[0], layers or up[1], color or up[2]))
    fmap, flayers = indexed(TopAbs_FACE)
    faces = [
        ReadSubShape(fmap.FindKey(i), *own(fmap.FindKey(i), fmap, flayers, (XCAFDoc_ColorSurf,)))
        for i in range(1, fmap.Extent() + 1)
    ]
    return ReadStep(products, shape, faces, edges)


def _sub_compounds(shape: TopoDS_Shape) -> list[TopoDS_Shape]:
    """Compounds nested (at any depth) inside ``shape``, not ``shape`` itself (TopExp does not list them)."""
    out = []
    it = TopoDS_Iterator(shape)
    while it.More():
        child = it.Value()
        if child.ShapeType() == TopAbs_COMPOUND:
            out.append(child)
            out.extend(_sub_compounds(child))
        it.Next()
    return out


def _entity_name(transfer: object, shape: TopoDS_Shape) -> str | None:
    """The name of the STEP entity a shape was read from (empty names give None)."""
    ent = transfer.EntityFromShapeResult(shape, 1)
    if ent is None or not hasattr(ent, "Name") or ent.Name() is None:
        return None
    return ent.Name().ToCString() or None
