"""All four fixtures on generated scans whose true part is known, checked against it.

    python -m fixtures_design.examples.fixtures_for_synthetic_scans [OUT_DIR]

Generates three small synthetic scans (`v2c.synth`: a block, a bracket, a shaft), builds each one's ground-truth
VB-Rep (`fixtures_design.testing.vbrep_from_scan`), designs a corner locator and a nest plate for the block, a
locating pin for the bracket's hole and a cradle for the shaft, and measures each against the true part
(gt/part.step): the largest distance from a mating face to the true face it references, and the volume the
fixture shares with the part. Writes every fixture's STEP / STL and an assembly with the true part.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from fixtures_design import check_mating, design_fixture, interference, true_part, write_fixture
from fixtures_design.frames import camera_mm_matrix
from fixtures_design.model import transformed
from fixtures_design.testing import synthetic_scan, true_faces, vbrep_from_scan

#: (family, seed, fixture kinds) of the scans used; seeds picked so each family shows the needed feature.
CASES = (("block", 0, ("corner", "nest")), ("bracket", 0, ("pin",)), ("shaft", 0, ("cradle",)))


def main(out_dir: str | Path) -> list[dict]:
    out_dir = Path(out_dir)
    rows = []
    for family, seed, kinds in CASES:
        scan = synthetic_scan(out_dir / "scans", family, seed)
        vbrep, truth_cam = vbrep_from_scan(scan)
        tol = max(0.5, 0.01 * vbrep.scale * 1000.0)
        for kind in kinds:
            fx = design_fixture(vbrep, kind)
            m = camera_mm_matrix(fx.fmap)
            truth = transformed(truth_cam, m)
            mating = check_mating(fx, truth, true_faces(vbrep, truth_cam, m),
                                  max_points_per_face=10 if kind == "nest" else 40)
            common, frac = interference(fx, truth)
            write_fixture(fx, out_dir / family, part=true_part(scan / "gt" / "part.step", fx.fmap),
                          part_label="true_part")
            rows.append({"scan": f"{family}_{seed}", "kind": kind, "max_mm": mating.max, "tol_mm": tol,
                         "common_mm3": common, "common_frac": frac, "volume_mm3": fx.volume_mm3})
            print(f"{family}_{seed} {kind:6s}: mating faces within {mating.max:.3f} mm (tolerance {tol:.2f}), "
                  f"common volume {common:.3f} mm^3 = {100 * frac:.4f} % of {fx.volume_mm3:.0f} mm^3")
    return rows


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="v2c_fixtures_"))
