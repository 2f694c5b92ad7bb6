"""FreeCAD 0.20 (headless `freecadcmd`) imports our STEP files like OCCT reads them back.

For every hand-built example: the face count, each face's surface class (Part.Plane, Part.Cylinder, Part.Cone,
Part.Sphere, Part.Toroid) and the edge count that FreeCAD finds equal what `exporters.step.read_typed` finds,
both through `Part.Shape.read` and through `Import.insert` (the XCAF import of File > Import, which crashes on
edge-only products), and the import gives exactly one object: the one product.
Skipped only when `freecadcmd` is not installed (scripts/setup.sh installs it when run as root).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from exporters import step

from scenes.revolved import revolved_all_types
from scenes.vbrep import box_corner, cylinder_upright

FREECADCMD = shutil.which("freecadcmd")
SCRIPT = Path(__file__).with_name("freecad_check.py")
MARK = "V2C_FREECAD_JSON "
#: FreeCAD Part surface class of each surface name of `TypedFace.surface`.
FREECAD_SURFACE = {
    "plane": "Plane",
    "cylinder": "Cylinder",
    "cone": "Cone",
    "sphere": "Sphere",
    "torus": "Toroid",
    "revolution": "SurfaceOfRevolution",
}

pytestmark = pytest.mark.skipif(FREECADCMD is None, reason="freecadcmd not installed (scripts/setup.sh as root)")


def freecad_import(path: Path, home: Path) -> dict:
    """Run tests/freecad_check.py on ``path`` in freecadcmd; its JSON result."""
    env = dict(os.environ, V2C_STEP=str(path), HOME=str(home))
    proc = subprocess.run(
        [FREECADCMD, str(SCRIPT)], env=env, capture_output=True, text=True, timeout=180, check=False
    )  # the JSON line says what went wrong
    assert MARK in proc.stdout, f"freecadcmd rc={proc.returncode}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
    return json.loads(proc.stdout.split(MARK, 1)[1].splitlines()[0])


@pytest.mark.parametrize(
    ("name", "make", "frame"),
    [
        ("box_corner", box_corner, "part"),
        ("cylinder_upright", cylinder_upright, "part"),
        ("revolved", revolved_all_types, "part"),
        ("revolved_camera", revolved_all_types, "camera"),
    ],
)
def test_freecad_imports_like_occt(name: str, make, frame: str, tmp_path: Path) -> None:
    vb = make()
    path = tmp_path / f"{name}.step"
    step.write(vb, path, frame=frame)
    occt = step.read_typed(path)
    fc = freecad_import(path, tmp_path)
    assert fc["ok"], fc.get("error")
    assert fc["version"].startswith("0.")
    expected = sorted(FREECAD_SURFACE[f.surface] for f in occt.faces)
    assert sorted(f.primitive["type"] for f in vb.faces) == sorted(f.surface for f in occt.faces)
    for how in ("part", "doc"):
        got = fc[how]
        assert got["faces"] == len(occt.faces) == len(vb.faces), (how, got)
        assert got["edges"] == len(occt.edges) == len(vb.edges), (how, got)
        assert sorted(got["surfaces"]) == expected, (how, got)
    assert fc["part"]["valid"]
    assert fc["doc"]["objects"] == 1 and fc["doc"]["labels"] == [path.stem]


def test_freecad_imports_free_edges(tmp_path: Path) -> None:
    """A product holding faces and free edges imports without crashing, with every edge."""
    vb = box_corner()
    vb.faces[0].mesh_triangles = vb.faces[0].mesh_triangles[:0]  # face 0 cannot be built: its edges are free
    vb.faces[0].loops = [[(0, False), (3, False), (1, True)]]
    path = tmp_path / "free_edges.step"
    report = step.write(vb, path)
    assert report.skipped_faces == [0] and report.free_edges == [3, 4]
    occt = step.read_typed(path)
    fc = freecad_import(path, tmp_path)
    assert fc["ok"], fc.get("error")
    for how in ("part", "doc"):
        assert fc[how]["faces"] == len(occt.faces) == 2
        assert fc[how]["edges"] == len(occt.edges)
    assert fc["doc"]["objects"] == 1
