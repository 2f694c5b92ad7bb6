"""Corner locator on a bundled sample scan, reconstructed by the pipeline (samples/bracket_planes_cylinders).

    python -m fixtures_design.examples.corner_on_sample [OUT_DIR]

Reconstructs the scan's VB-Rep (`v2c.pipeline.reconstruct`, learned segmentation), lists its edges and which
qualify as mating references, builds an L block on the best convex intersection edge in the part frame
(millimetres), and writes fixture_corner.step / .stl / _assembly.step (with the reconstructed faces as the part).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from fixtures_design import CornerParams, design_fixture, explain_edges, reconstructed_part, write_fixture
from v2c.pipeline import reconstruct

#: The bundled sample scan used (a bracket of planes and cylinders).
SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "bracket_planes_cylinders"


def main(out_dir: str | Path, sample: str | Path = SAMPLE) -> dict:
    """Design and write the corner locator of ``sample`` into ``out_dir``; its edge id, volume (mm^3), files."""
    vbrep = reconstruct(sample)
    print(explain_edges(vbrep))
    fx = design_fixture(vbrep, "corner", CornerParams(clearance=0.2, wall=8.0, leg=20.0, length=50.0), frame="part")
    files = write_fixture(fx, out_dir, part=reconstructed_part(vbrep, fx.fmap))
    print(f"L block on edge e{fx.reference.edge_id}: {fx.volume_mm3:.0f} mm^3 -> {files.assembly}")
    return {"edge": fx.reference.edge_id, "volume_mm3": fx.volume_mm3, "files": files}


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="v2c_corner_"))
