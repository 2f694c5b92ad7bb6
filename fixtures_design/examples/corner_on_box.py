"""Corner locator on the hand-built VB-Rep of a box seen from a corner (`v2c.vbrep.examples.box_corner`).

    python -m fixtures_design.examples.corner_on_box [OUT_DIR]

Lists the box's edges and which qualify as mating references, builds an L block on the best convex edge in the
part frame, and writes fixture_corner.step / .stl / _assembly.step (with the VB-Rep's faces as the part).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from fixtures_design import CornerParams, design_fixture, explain_edges, reconstructed_part, write_fixture
from v2c.vbrep.examples import box_corner


def main(out_dir: str | Path) -> dict:
    vbrep = box_corner()
    print(explain_edges(vbrep, min_confidence=0.9))
    fx = design_fixture(vbrep, "corner", CornerParams(clearance=0.2, wall=8.0, leg=20.0, length=50.0),
                        frame="part", min_confidence=0.9)
    files = write_fixture(fx, out_dir, part=reconstructed_part(vbrep, fx.fmap))
    print(f"L block on edge e{fx.reference.edge_id}: {fx.volume_mm3:.0f} mm^3 -> {files.assembly}")
    return {"edge": fx.reference.edge_id, "volume_mm3": fx.volume_mm3, "files": files}


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="v2c_corner_"))
