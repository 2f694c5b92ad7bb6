"""Reliability diagram of the intersection edges of `v2c bench --json` runs, one curve per column and run.

    PYTHONPATH=. python scripts/reliability_figure.py OUT.png "title" LABEL=run.json [LABEL=run.json ...]

Each run's rows carry every edge's type, calibrated and raw confidence and whether it is right (the bench's
``edge_labels``); per run and column (segmentation/ablation) the intersection edges' calibrated confidence is binned
(10 equal-width bins, `v2c.vbrep.calibration.reliability_diagram`), the curve labelled ``LABEL column``.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from v2c.vbrep.calibration import reliability_diagram


def intersection_curves(label: str, path: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per column of the run at ``path``: (calibrated confidence, right) of its intersection edges."""
    result = json.loads(path.read_text())
    curves = {}
    for col in result["columns"]:
        conf, ok = [], []
        for r in result["rows"]:
            lab = r.get("edge_labels")
            if f"{r['segmentation']}/{r['ablation']}" != col or not lab:
                continue
            s = [t == "intersection" for t in lab["type"]]
            conf += [c for c, k in zip(lab["confidence"], s) if k]
            ok += [o for o, k in zip(lab["ok"], s) if k]
        curves[f"{label} {col.split('/')[0]}"] = (np.asarray(conf, float), np.asarray(ok, float))
    return curves


def main(argv: list[str]) -> int:
    """Draw the diagram of the runs named on the command line."""
    if len(argv) < 3 or any("=" not in a for a in argv[2:]):
        print(__doc__.split("\n\n")[1].strip(), file=sys.stderr)
        return 1
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for a in argv[2:]:
        label, path = a.split("=", 1)
        curves.update(intersection_curves(label, Path(path)))
    print(reliability_diagram(curves, argv[0], argv[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
