"""The report of a `v2c bench` run: per-column summaries of the per-scan rows (`summarise`), the JSON form of a
result (`jsonable`), the Markdown table laid out like the paper's Table 1 (`format_table`: rows = metrics; columns
= ours per segmentation and ablation, then the paper's numbers), the reliability diagram of the edge confidences
and the grid of result figures.

Per column (segmentation, ablation): metrics averaged over scans (BENCHMARK.md), runtime as the median over scans
of the whole to-step time in seconds, with the median of each stage.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from v2c.bench.config import ABLATIONS, GT

#: The paper's Table 1 (BENCHMARK.md): ablation -> metric -> value (fractions for percentages, seconds).
PAPER: dict[str, dict[str, float]] = {
    "full": {
        "chamfer": 0.0628,
        "alignment": 0.0693,
        "precision": 0.881,
        "recall": 0.913,
        "axis_accuracy": 0.945,
        "type_accuracy": 0.992,
        "runtime": 50.0,
    },
    "no-axis": {"chamfer": 0.101, "alignment": 0.251},
    "no-int": {"chamfer": 0.0768, "alignment": 0.0940},
    "fit-only": {"chamfer": 0.0819, "alignment": 0.244},
}

#: Per-scan metrics averaged over scans; failed scans count 0 in the first group, are left out of the second.
ZERO_IF_FAILED = ("precision", "recall", "recall_all", "precision_75", "recall_75", "recall_all_75")
MEAN_OVER_OK = (
    "chamfer",
    "chamfer_all",
    "alignment",
    "type_accuracy",
    "axis_accuracy",
    "depth_error",
    "depth_coverage",
    "edge_type_accuracy",
)
STAGES = ("load", "segment", "fit", "vbrep", "step")
ECE_BINS = 10  # equal-width confidence bins of the expected calibration error


# ----------------------------------------------------------------------------------------------- summaries


def _mean(values: list[float]) -> float:
    """Mean of the finite values (None, NaN and inf left out); NaN when none is left."""
    v = np.array([x for x in values if x is not None], float)
    v = v[np.isfinite(v)]
    return float(v.mean()) if len(v) else float("nan")


def _median(values: list[float]) -> float:
    """Median of the finite values (None, NaN and inf left out); NaN when none is left."""
    v = np.array([x for x in values if x is not None], float)
    v = v[np.isfinite(v)]
    return float(np.median(v)) if len(v) else float("nan")


def summarise(rows: list[dict[str, Any]], process_start_s: float = float("nan")) -> dict[str, Any]:
    """One column's summary: metric means over scans (BENCHMARK.md; precision/recall count a failed scan as 0,
    the other metrics leave it out), type/axis accuracy also pooled over all pairs, runtime medians (to-step
    total and per stage), counts."""
    ok = [r for r in rows if r.get("ok")]
    out: dict[str, Any] = {
        "scans": len(rows),
        "failed": len(rows) - len(ok),
        "errors": sorted({r["error"] for r in rows if not r.get("ok")})[:10],
    }
    for k in ZERO_IF_FAILED:
        out[k] = _mean([r.get(k, np.nan) if r.get("ok") else 0.0 for r in rows])
    for k in MEAN_OVER_OK:
        out[k] = _mean([r.get(k, np.nan) for r in ok])
    pairs = sum(r.get("n_pairs", 0) for r in ok)
    out["type_accuracy_pooled"] = sum(r.get("type_ok", 0) for r in ok) / pairs if pairs else float("nan")
    out["axis_accuracy_pooled"] = sum(r.get("axis_ok", 0) for r in ok) / pairs if pairs else float("nan")
    out["pairs"] = pairs
    far = [r["face_far_max"] for r in ok if r.get("face_far_max") is not None and np.isfinite(r["face_far_max"])]
    out["face_far_max"] = float(max(far)) if far else float("nan")  # the farthest face of any scan (part sizes)
    out["faces_far"] = int(sum(r.get("faces_far", 0) for r in ok))  # faces beyond MetricConfig.far_face_rel
    out["scans_with_far_faces"] = int(sum(1 for r in ok if r.get("faces_far", 0) > 0))
    off = [r["face_off_part_max"] for r in ok if r.get("face_off_part_max") is not None]
    off = [x for x in off if np.isfinite(x)]
    out["face_off_part_max"] = float(max(off)) if off else float("nan")  # the same against the true surface
    out["faces_off_part"] = int(sum(r.get("faces_off_part", 0) for r in ok))
    rt = [r.get("runtime", {}) for r in ok]
    out["runtime"] = _median([x.get("to_step", np.nan) for x in rt])
    out["runtime_mean"] = _mean([x.get("to_step", np.nan) for x in rt])
    out["runtime_cpu"] = _median([x.get("to_step_cpu", np.nan) for x in rt])
    out["runtime_max"] = float(np.max([x.get("to_step", 0.0) for x in rt])) if rt else float("nan")
    out["runtime_stages"] = {s: _median([x.get(s, np.nan) for x in rt]) for s in STAGES}
    fit_sub = sorted({k for x in rt for k in x if k.startswith("fit.") and k != "fit.total"})
    out["runtime_fit_stages"] = {k[4:]: _median([x.get(k, np.nan) for x in rt]) for k in fit_sub}
    out.update(calibration_summary(ok))
    out["process_start_s"] = process_start_s
    out["set_runtime_s"] = (
        process_start_s + float(np.nansum([x.get("to_step", np.nan) for x in rt])) if rt else float("nan")
    )
    return out


def edge_label_arrays(rows: list[dict[str, Any]]) -> dict[str, np.ndarray]:
    """The per-edge labels (`scan_metrics`' ``edge_labels``) of rows, pooled: type, confidence, confidence_raw,
    ok."""
    labs = [r["edge_labels"] for r in rows if r.get("edge_labels")]
    return {
        "type": np.array([t for la in labs for t in la["type"]], object),
        **{k: np.array([v for la in labs for v in la[k]], float) for k in ("confidence", "confidence_raw", "ok")},
    }


def calibration_summary(rows: list[dict[str, Any]], n_bins: int = ECE_BINS) -> dict[str, Any]:
    """Expected calibration error (``n_bins`` equal-width bins, edges pooled over the scans) of the edge
    confidence against the bench's right/wrong label (v2c.bench.vbrep.edge_correctness): ``ece_intersection`` /
    ``ece_all`` of the calibrated confidence, ``*_raw`` of the raw product of factors, ``calibration_edges`` and
    ``intersection_edges`` (counts) and ``intersection_right`` (share right)."""
    from v2c.vbrep.calibration import expected_calibration_error as ece

    a = edge_label_arrays(rows)
    s = a["type"] == "intersection"
    return {
        "ece_intersection": ece(a["confidence"][s], a["ok"][s], n_bins),
        "ece_intersection_raw": ece(a["confidence_raw"][s], a["ok"][s], n_bins),
        "ece_all": ece(a["confidence"], a["ok"], n_bins),
        "ece_all_raw": ece(a["confidence_raw"], a["ok"], n_bins),
        "calibration_edges": len(a["ok"]),
        "intersection_edges": int(s.sum()),
        "intersection_right": float(a["ok"][s].mean()) if s.any() else float("nan"),
    }


def write_reliability(rows: list[dict[str, Any]], path: Path, title: str, n_bins: int = ECE_BINS) -> Path:
    """Reliability diagram (PNG) of rows' pooled edges: intersection edges raw and calibrated, all edges
    calibrated."""
    from v2c.vbrep.calibration import reliability_diagram

    a = edge_label_arrays(rows)
    s = a["type"] == "intersection"
    return reliability_diagram(
        {
            "intersection, raw": (a["confidence_raw"][s], a["ok"][s]),
            "intersection, calibrated": (a["confidence"][s], a["ok"][s]),
            "all edges, raw": (a["confidence_raw"], a["ok"]),
            "all edges, calibrated": (a["confidence"], a["ok"]),
        },
        path,
        title,
        n_bins,
    )


def figure_grid(paths: Sequence[str | Path], out: Path, columns: int = 3, width: int = 480) -> Path | None:
    """Tile result figures (PNG) into one grid image, each scaled to ``width`` pixels; None without figures."""
    import cv2

    tiles = [cv2.imread(str(p)) for p in paths if p]
    tiles = [
        cv2.resize(t, (width, round(t.shape[0] * width / t.shape[1])), interpolation=cv2.INTER_AREA)
        for t in tiles
        if t is not None
    ]
    if not tiles:
        return None
    h = max(t.shape[0] for t in tiles)
    tiles = [np.pad(t, ((0, h - t.shape[0]), (0, 0), (0, 0)), constant_values=255) for t in tiles]
    tiles += [np.full_like(tiles[0], 255)] * (-len(tiles) % columns)
    rows = [np.concatenate(tiles[i : i + columns], 1) for i in range(0, len(tiles), columns)]
    cv2.imwrite(str(out), np.concatenate(rows, 0), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    return out


def jsonable(x: Any) -> Any:
    """``x`` with what JSON cannot hold made plain: dict keys as strings, tuples as lists, paths as strings,
    numpy arrays and scalars as Python values, NaN and inf as None."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None  # JSON has no NaN / inf: an undefined or failed metric
    return x


# ---------------------------------------------------------------------------------------------- the table

#: (row title, summary key, format) of the table, in the paper's order.
TABLE_ROWS: tuple[tuple[str, str, str], ...] = (
    ("Chamfer distance, visible R (lower is better)", "chamfer", "f4"),
    ("Chamfer distance, all of R", "chamfer_all", "f4"),
    ("primitive alignment (lower is better)", "alignment", "f4"),
    ("face precision @ IoU 0.5", "precision", "pct"),
    ("face recall @ IoU 0.5 (gt faces >= 50 px)", "recall", "pct"),
    ("face recall @ IoU 0.5, all gt faces", "recall_all", "pct"),
    ("face precision @ IoU 0.75", "precision_75", "pct"),
    ("face recall @ IoU 0.75 (gt faces >= 50 px)", "recall_75", "pct"),
    ("axis accuracy", "axis_accuracy", "pct"),
    ("type accuracy", "type_accuracy", "pct"),
    ("depth error (median, / part size)", "depth_error", "f4"),
    ("edge-type accuracy", "edge_type_accuracy", "pct"),
    ("farthest face from the measured part points (part sizes, any scan)", "face_far_max", "f4"),
    ("faces farther than 0.05 part sizes (all scans)", "faces_far", "int"),
    ("faces off the true visible surface by over 0.05 part sizes (all scans)", "faces_off_part", "int"),
    ("intersection-edge confidence ECE (10 bins; raw factors)", "ece_intersection", "ece"),
    ("all-edge confidence ECE (10 bins; raw factors)", "ece_all", "ece"),
    ("runtime per scan, median wall (s)", "runtime", "s"),
    ("runtime per scan, median CPU (s)", "runtime_cpu", "s"),
)


def format_value(v: Any, kind: str) -> str:
    """One table cell: ``kind`` "pct" (a fraction as a percentage), "s" (seconds, 2 decimals), "f1" (1 decimal),
    "ece" (3 decimals), "int" or anything else (4 decimals); empty for None, NaN and inf."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if kind == "pct":
        return f"{100 * v:.1f} %"
    if kind == "s":
        return f"{v:.2f}"
    if kind == "f1":
        return f"{v:.1f}"
    if kind == "int":
        return f"{int(v)}"
    if kind == "ece":
        return f"{v:.3f}"
    return f"{v:.4f}"


def column_title(key: str, n_segmentations: int) -> str:
    """The table heading of a column ``"segmentation/ablation"``: the ablation alone when the run has one
    segmentation method, else both; the ``gt`` column is the ideal VB-Rep."""
    seg, abl = key.split("/")
    if seg == GT:
        return "ideal (gt VB-Rep)"
    return abl if n_segmentations == 1 else f"{seg} {abl}"


def format_table(result: dict[str, Any], paper: bool = True) -> str:
    """Markdown table of a `run_benchmark` result: rows = metrics, columns = ours, then the paper's."""
    cols = result["columns"]
    summ = result["summary"]
    n_seg = len({c.split("/")[0] for c in cols if not c.startswith(GT + "/")})
    abl_order = [a for a in ABLATIONS if any(c.endswith("/" + a) for c in cols)]
    heads = [column_title(c, n_seg) for c in cols] + ([f"paper {a}" for a in abl_order] if paper else [])
    lines = ["| metric | " + " | ".join(heads) + " |", "| --- |" + " ---: |" * len(heads)]
    for title, key, kind in TABLE_ROWS:
        cells = [
            format_value(summ[c].get(key), kind) if not (c.startswith(GT) and key.startswith("runtime")) else ""
            for c in cols
        ]
        if kind == "ece":  # calibrated (raw)
            cells = [f"{x} ({format_value(summ[c].get(key + '_raw'), kind)})" if x else "" for x, c in zip(cells, cols)]
        if paper:
            cells += [format_value(PAPER.get(a, {}).get(key), kind) for a in abl_order]
        lines.append(f"| {title} | " + " | ".join(cells) + " |")
    for stage in STAGES:
        cells = [format_value(summ[c].get("runtime_stages", {}).get(stage), "s") for c in cols]
        lines.append(
            f"| &nbsp;&nbsp;{stage} (median s) | " + " | ".join(cells + [""] * (len(heads) - len(cells))) + " |"
        )
    cells = [f"{summ[c]['scans'] - summ[c]['failed']} / {summ[c]['scans']}" for c in cols]
    lines.append("| scans reconstructed / run | " + " | ".join(cells + [""] * (len(heads) - len(cells))) + " |")
    return "\n".join(lines)


def format_notes(result: dict[str, Any]) -> str:
    """Plain-text lines under the table: process start, set runtime, failures."""
    out = [
        (
            f"process start (once per set): {result['process_start_s']:.2f} s; benchmark wall time "
            f"{result['wall_s']:.0f} s"
        )
    ]
    for c in result["columns"]:
        s = result["summary"][c]
        if s["failed"]:
            out.append(f"{c}: {s['failed']} of {s['scans']} failed: " + "; ".join(s["errors"][:3]))
    return "\n".join(out)
