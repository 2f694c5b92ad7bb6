"""FreeCAD (0.20, headless) import check of a STEP file.

Run as ``V2C_STEP=file.step freecadcmd tests/freecad_check.py``. Prints one line ``V2C_FREECAD_JSON {...}``
with what FreeCAD found:
- ``part``: ``Part.Shape().read`` (OCCT's plain STEP reader inside FreeCAD): face count, unique edge count,
  the ``Part.*`` class name of every face's surface, in file order;
- ``doc``: ``Import.insert`` into a new document (the XCAF import a user gets from File > Import, the path
  that crashes on edge-only products): the top-level objects (one per product) and the same counts over
  their shapes.
Runs under FreeCAD's own Python, so it imports nothing from the project.
"""

import json
import os
import sys
import traceback

MARK = "V2C_FREECAD_JSON "


def _summary(shape):
    return {
        "faces": len(shape.Faces),
        "edges": len(shape.Edges),
        "surfaces": [type(f.Surface).__name__ for f in shape.Faces],
    }


def main():
    path = os.environ.get("V2C_STEP")
    out = {"path": path, "ok": False}
    try:
        import FreeCAD
        import Part

        out["version"] = ".".join(FreeCAD.Version()[:3])
        shape = Part.Shape()
        shape.read(path)
        out["part"] = _summary(shape)
        out["part"]["valid"] = bool(shape.isValid())

        import Import

        doc = FreeCAD.newDocument("v2c_check")
        Import.insert(path, doc.Name)
        # Top-level objects only: a product whose compound holds several shells and free edges is expanded
        # into child objects under one parent, whose shape already holds them all.
        top = [o for o in doc.Objects if not o.InList]
        shapes = [o.Shape for o in top if hasattr(o, "Shape") and not o.Shape.isNull()]
        comp = Part.makeCompound(shapes) if shapes else Part.Shape()
        out["doc"] = _summary(comp) if shapes else {"faces": 0, "edges": 0, "surfaces": []}
        out["doc"]["objects"] = len(top)
        out["doc"]["labels"] = [o.Label for o in top]
        out["doc"]["all_objects"] = len(doc.Objects)
        out["ok"] = True
    except Exception:  # noqa: BLE001 - report any FreeCAD failure as JSON
        out["error"] = traceback.format_exc()
    sys.stdout.write("\n" + MARK + json.dumps(out) + "\n")
    sys.stdout.flush()


main()
