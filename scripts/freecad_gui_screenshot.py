r"""Screenshot of `exporters/freecad_import.py` in the FreeCAD GUI (docs/img/freecad_import.png).

Run under Xvfb with a fresh HOME (FreeCAD's document recovery dialog would wait for a click otherwise):

    SHOT_STEP=part.step SHOT_OUT=/tmp/shot.png HOME=$(mktemp -d) QTWEBENGINE_DISABLE_SANDBOX=1 \
        xvfb-run -a -s "-screen 0 1600x1000x24" freecad scripts/freecad_gui_screenshot.py

Writes SHOT_OUT (the 3D view, 900 x 700) and SHOT_OUT with ``_window`` (the main window: the tree with the
edge groups and the properties of the first intersection edge, selected). Prints ``SHOT_DONE <counts>``.
"""

import os
import sys
import traceback

try:
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "exporters"))
    import FreeCAD
    import freecad_import as fci
    import FreeCADGui
    from PySide import QtGui

    res = fci.open_typed_step(os.environ["SHOT_STEP"])
    doc = FreeCAD.getDocument(res["document"])
    gdoc = FreeCADGui.getDocument(doc.Name)
    gdoc.getObject("part").Transparency = 50
    view = gdoc.activeView()
    view.viewIsometric()
    view.fitAll()
    out = os.environ["SHOT_OUT"]
    view.saveImage(out, 900, 700, "White")
    window = FreeCADGui.getMainWindow()
    window.resize(1400, 900)
    FreeCADGui.Selection.addSelection(next(o for o in doc.Objects if getattr(o, "EdgeType", "") == "intersection"))
    for tree in window.findChildren(QtGui.QTreeWidget):
        tree.expandAll()
    for _ in range(5):
        QtGui.QApplication.processEvents()
    window.grab().save(out.replace(".png", "_window.png"))
    print("SHOT_DONE", res["counts"], flush=True)
    FreeCAD.closeDocument(doc.Name)
    os._exit(0)
except Exception:  # noqa: BLE001 - the GUI swallows exceptions of macros: print and leave
    traceback.print_exc(file=sys.stdout)
    sys.stdout.flush()
    os._exit(1)
