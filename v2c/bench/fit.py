"""Geometry-stage benchmark (issue 3): primitive alignment, radius and plane-offset errors, fit time, per ablation,
with oracle segmentation on synthetic scans.

Matching is by instance: with the oracle, instance = ground-truth face (the face that covers most of the
instance's pixels). Definitions (BENCHMARK.md where it has one):
- alignment: min(|a - b|, |a + b|) of the unit axes (plane normal; cylinder, cone, torus axis) of every fitted
  instance whose face has an axis; mean over the scan, then mean over scans.
- radius error: |r_fit - r_gt| of cylinders and spheres, divided by the gt part size (and, also reported, by r_gt).
- torus errors: |R_fit - R_gt| (major) and |r_fit - r_gt| (minor) of tori, divided by the gt radius (and, for
  the minor radius, also reported in millimetres: fillet tubes are a few millimetres).
- plane offset error: distance from the gt face's centroid (noise-free depth, back-projected) to the fitted
  plane, divided by the gt part size.
- fit time: fit_scan's own wall clock and CPU time (normals, RANSAC, aligned fit, edge graph, intersection
  refinement), one thread (BLAS/OpenMP/OpenCV limited to 1), median over scans. On a shared machine the CPU time
  is the fair figure: single-threaded, it is what the wall clock would be on an idle core.
Lengths are divided by gt meta part_size_m (metrics only; the method never reads it).

CLI: ``v2c bench --stage fit --scans DIR --n N [--ablation A,B] [--json OUT]`` (DIR: a scan folder or a folder of
them; without --scans, the bench's generated scans).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from v2c.fit import ABLATIONS, FitConfig, fit_scan
from v2c.primitives import from_dict

if TYPE_CHECKING:
    from v2c.fit.result import FitResult
    from v2c.scan import Scan
    from v2c.segment.types import Segmentation


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """Inside the block BLAS/OpenMP and OpenCV use one thread (the issue's 'one core' timing); restored after."""
    import cv2

    try:
        from threadpoolctl import threadpool_limits

        limits: contextlib.AbstractContextManager = threadpool_limits(1)
    except ImportError:  # timings then depend on OMP_NUM_THREADS / OPENBLAS_NUM_THREADS
        limits = contextlib.nullcontext()
    cv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with limits:
            yield
    finally:
        cv2.setNumThreads(cv_threads)


def scan_dirs(paths: Iterable[str | Path]) -> list[Path]:
    """Scan folders among ``paths``: a folder with camera.json, or the sorted such sub-folders of a folder."""
    out: list[Path] = []
    for p in map(Path, paths):
        if (p / "camera.json").exists():
            out.append(p)
        else:
            out += sorted(q for q in p.iterdir() if (q / "camera.json").exists())
    return out


def _face_of_instances(seg_inst: np.ndarray, faces: np.ndarray) -> dict[int, int]:
    """Instance id -> the 0-based gt face index covering most of its pixels."""
    sel = (seg_inst > 0) & (faces > 0)
    n = int(faces.max()) + 1
    hist = np.bincount(seg_inst[sel].astype(np.int64) * n + faces[sel], minlength=(int(seg_inst.max()) + 1) * n)
    hist = hist.reshape(-1, n)
    return {int(i): int(np.argmax(hist[i])) - 1 for i in np.flatnonzero(hist.sum(axis=1) > 0)}


def scan_metrics(scan: Scan, seg: Segmentation, res: FitResult) -> dict[str, Any]:
    """Per-scan geometry metrics of one FitResult (``res``, fitted on ``seg``) against the scan's ground truth (see
    module docstring): lengths in camera-frame metres, divided by the part size where the name says so."""
    from v2c.camera import backproject

    gt = scan.gt
    size = float(gt.meta["part_size_m"])
    faces = np.asarray(gt.faces).astype(np.int64)
    by_id = {int(p.get("id", k)): p for k, p in enumerate(gt.primitives)}
    match = _face_of_instances(np.asarray(seg.instances), faces)
    clean = backproject(np.asarray(gt.depth_clean, float), np.asarray(scan.K, float))
    align, rad_size, rad_rel, off = [], [], [], []
    tor_major, tor_minor, tor_minor_mm = [], [], []
    for i, p in res.primitives.items():
        g = by_id.get(match.get(i, -1))
        if g is None or g.get("type") not in ("plane", "cylinder", "cone", "sphere", "torus"):
            continue
        gp = from_dict(g)
        if g["type"] != p.type:
            continue
        a, b = p.axis_vector, gp.axis_vector
        if a is not None and b is not None:
            align.append(float(min(np.linalg.norm(a - b), np.linalg.norm(a + b))))
        if p.type in ("cylinder", "sphere"):
            rad_size.append(abs(p.radius - gp.radius) / size)
            rad_rel.append(abs(p.radius - gp.radius) / gp.radius)
        if p.type == "torus":
            tor_major.append(abs(p.radius - gp.radius) / gp.radius)
            tor_minor.append(abs(p.minor_radius - gp.minor_radius) / gp.minor_radius)
            tor_minor_mm.append(1000 * abs(p.minor_radius - gp.minor_radius))
        if p.type == "plane":
            m = (faces == int(g["id"]) + 1) & (gt.depth_clean > 0)
            if m.any():
                c = clean[m].mean(axis=0)
                off.append(abs(float(p.signed_distance(c[None])[0])) / size)
    return {
        "scan": str(scan.path),
        "n_primitives": len(res.primitives),
        "alignment": align,
        "radius_err_size": rad_size,
        "radius_err_rel": rad_rel,
        "plane_offset_err": off,
        "torus_major_err_rel": tor_major,
        "torus_minor_err_rel": tor_minor,
        "torus_minor_err_mm": tor_minor_mm,
        "time_s": float(res.timings["total"]),
        "cpu_s": float(res.timings["total_cpu"]),
        "scale_est_over_gt": float(res.scale / size),
    }


def _summary(rows: Sequence[dict[str, Any]]) -> dict[str, float]:
    def pooled(k: str) -> np.ndarray:
        return np.array([x for r in rows for x in r[k]])

    per_scan_align = [float(np.mean(r["alignment"])) for r in rows if r["alignment"]]
    rad, rel, off = pooled("radius_err_size"), pooled("radius_err_rel"), pooled("plane_offset_err")
    tmaj, tmin, tmm = (
        pooled(k) if all(k in r for r in rows) else np.zeros(0)
        for k in ("torus_major_err_rel", "torus_minor_err_rel", "torus_minor_err_mm")
    )
    return {
        "scans": len(rows),
        "alignment": float(np.mean(per_scan_align)) if per_scan_align else float("nan"),
        "alignment_median_pair": float(np.median(pooled("alignment"))) if len(pooled("alignment")) else float("nan"),
        "pairs": len(pooled("alignment")),
        "radius_err_median_pct_size": 100 * float(np.median(rad)) if len(rad) else float("nan"),
        "radius_err_median_pct_radius": 100 * float(np.median(rel)) if len(rel) else float("nan"),
        "radius_count": len(rad),
        "plane_offset_err_median_pct": 100 * float(np.median(off)) if len(off) else float("nan"),
        "plane_count": len(off),
        "torus_major_err_median_pct": 100 * float(np.median(tmaj)) if len(tmaj) else float("nan"),
        "torus_minor_err_median_pct": 100 * float(np.median(tmin)) if len(tmin) else float("nan"),
        "torus_minor_err_median_mm": float(np.median(tmm)) if len(tmm) else float("nan"),
        "torus_minor_err_max_mm": float(np.max(tmm)) if len(tmm) else float("nan"),
        "torus_major_err_max_pct": 100 * float(np.max(tmaj)) if len(tmaj) else float("nan"),
        "torus_count": len(tmaj),
        "time_median_s": float(np.median([r["time_s"] for r in rows])),
        "time_max_s": float(np.max([r["time_s"] for r in rows])),
        "cpu_median_s": float(np.median([r["cpu_s"] for r in rows])),
        "cpu_max_s": float(np.max([r["cpu_s"] for r in rows])),
        "scale_est_over_gt_median": float(np.median([r["scale_est_over_gt"] for r in rows])),
    }


def fit_benchmark(
    scans: Sequence[str | Path],
    ablations: Sequence[str] = ABLATIONS,
    config: FitConfig | None = None,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Run fit_scan with oracle segmentation on every scan folder for every ablation; ``log`` gets one line per
    scan (alignment and seconds per ablation).

    Returns {"summary": {ablation: {...}}, "rows": {ablation: [per-scan dicts]}}.
    """
    from v2c.scan import load_scan
    from v2c.segment.oracle import segment_oracle

    config = config or FitConfig()
    rows: dict[str, list[dict[str, Any]]] = {a: [] for a in ablations}
    for path in scan_dirs(scans):
        scan = load_scan(path)
        seg = segment_oracle(scan)
        for a in ablations:
            res = fit_scan(scan, seg, config, a)
            rows[a].append(scan_metrics(scan, seg, res))
        if log:
            log(
                f"{path.name}: "
                + "  ".join(
                    f"{a} {np.mean(rows[a][-1]['alignment']) if rows[a][-1]['alignment'] else float('nan'):.4f}"
                    f"/{rows[a][-1]['time_s']:.2f}s"
                    for a in ablations
                )
            )
    return {"summary": {a: _summary(r) for a, r in rows.items() if r}, "rows": rows}


def format_table(summary: dict[str, dict[str, float]]) -> str:
    """Markdown table of the per-ablation summary."""
    head = (
        "| ablation | scans | alignment (mean) | pairs | radius err (median, % size) | radius err (% r) "
        "| plane offset err (median, % size) | torus R / r err (median, % R / % r) "
        "| torus r err (median / max, mm) | fit time median: wall / CPU (s) |"
    )
    lines = [head, "|" + " --- |" * 10]
    for a, s in summary.items():
        lines.append(
            f"| {a} | {s['scans']} | {s['alignment']:.4f} | {s['pairs']} | "
            f"{s['radius_err_median_pct_size']:.2f} | {s['radius_err_median_pct_radius']:.2f} | "
            f"{s['plane_offset_err_median_pct']:.2f} | "
            f"{s.get('torus_major_err_median_pct', float('nan')):.1f} / "
            f"{s.get('torus_minor_err_median_pct', float('nan')):.1f} ({s.get('torus_count', 0)}) | "
            f"{s.get('torus_minor_err_median_mm', float('nan')):.2f} / "
            f"{s.get('torus_minor_err_max_mm', float('nan')):.2f} | "
            f"{s['time_median_s']:.2f} / {s['cpu_median_s']:.2f} |"
        )
    return "\n".join(lines)
