"""Every fixture that qualifies on the bundled sample scans, checked against each scan's true part.

    python -m fixtures_design.examples.fixtures_for_samples [OUT_DIR]

For each scan in samples/ (generated scans: gt/part.step holds the true part, camera frame, millimetres):
reconstructs its VB-Rep (`v2c.pipeline.reconstruct`, learned segmentation), tries the four fixture kinds (corner
locator, locating pin, cradle, nest plate; a kind whose reference the part does not offer is reported and
skipped), and measures each fixture against the true part moved into the fixture's output frame: the largest
distance from a mating face to the part, and the volume the fixture shares with the part. Writes every
fixture's STEP / STL and an assembly with the true part into OUT_DIR/<scan>/.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from fixtures_design import (
    FixtureKind,
    NoReferenceError,
    check_mating,
    design_fixture,
    interference,
    true_part,
    write_fixture,
)
from v2c.pipeline import reconstruct

#: The bundled sample scans (each a scan folder with gt/part.step).
SAMPLES = Path(__file__).resolve().parents[2] / "samples"


def main(out_dir: str | Path, samples: str | Path = SAMPLES) -> list[dict]:
    """Design, check and write every qualifying fixture of every sample scan; one row per fixture (mm, mm^3)."""
    out_dir = Path(out_dir)
    rows = []
    for scan_dir in sorted(p for p in Path(samples).iterdir() if (p / "gt" / "part.step").exists()):
        vbrep = reconstruct(scan_dir)
        for kind in FixtureKind:
            try:
                fx = design_fixture(vbrep, kind)
            except NoReferenceError as exc:
                print(f"{scan_dir.name} {kind.value:6s}: none ({str(exc).splitlines()[0].rstrip(':')})")
                continue
            truth = true_part(scan_dir / "gt" / "part.step", fx.fmap)
            mating = check_mating(fx, truth, max_points_per_face=10 if kind is FixtureKind.NEST else 40)
            common, frac = interference(fx, truth)
            write_fixture(fx, out_dir / scan_dir.name, part=truth, part_label="true_part")
            rows.append(
                {
                    "scan": scan_dir.name,
                    "kind": kind.value,
                    "max_mm": mating.max,
                    "common_mm3": common,
                    "common_frac": frac,
                    "volume_mm3": fx.volume_mm3,
                }
            )
            print(
                f"{scan_dir.name} {kind.value:6s}: mating faces within {mating.max:.3f} mm of the true part, "
                f"common volume {common:.3f} mm^3 = {100 * frac:.4f} % of {fx.volume_mm3:.0f} mm^3"
            )
    return rows


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="v2c_fixtures_"))
