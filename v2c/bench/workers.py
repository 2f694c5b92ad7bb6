"""The per-scan work of `v2c bench`: one scan reconstructed as `v2c to-step --frame camera --no-extras` does it and
scored (`evaluate_scan`), and the executors that run it over many scans (`evaluate_dirs`).

Every scan runs in a process pool (one thread per worker: ``jobs`` workers = ``jobs`` cores) or as one task of a
Ray cluster (``executor`` "ray", `v2c.executors`). Each stage is timed in seconds: load, segment (once per
segmentation method, counted into every ablation), fit and VB-Rep extraction (`v2c.pipeline.reconstruct`) per
ablation, STEP export (`exporters.step.write`); then every metric of `v2c.bench.metrics.scan_metrics`. A worker is
set up once (`warm_up`: imports, learned model), so per-scan times leave out the process start, which
`process_start_seconds` measures once in a fresh interpreter.
"""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from v2c.bench.config import GT, BenchConfig, MetricConfig, executor_of
from v2c.executors import run_tasks

if TYPE_CHECKING:
    from v2c.scan import Scan
    from v2c.segment.types import Segmentation
    from v2c.vbrep.model import VBRep


def limit_threads() -> None:
    """One thread for BLAS/OpenMP, OpenCV and torch in this process (a worker is one core)."""
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = "1"
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass
    import cv2

    cv2.setNumThreads(1)
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def error_text(exc: BaseException) -> str:
    """One line naming an exception and where it was raised: ``Type: message (file.py:line)``, the ``error`` of a
    failed row."""
    tb = traceback.extract_tb(exc.__traceback__)
    where = f" ({Path(tb[-1].filename).name}:{tb[-1].lineno})" if tb else ""
    return f"{type(exc).__name__}: {exc}{where}"


def segment_scan(scan: Scan, method: str, weights: str | Path | None = None) -> Segmentation:
    """`v2c.segment.segment` of one scan; ``weights`` (None: the shipped file) go to the learned segmenter only."""
    from v2c.segment import segment

    return segment(scan, method, **({"weights": weights} if method == "learned" and weights else {}))


def evaluate_scan(
    scan_dir: str | Path,
    segmentations: Sequence[str],
    ablations: Sequence[str],
    metrics: MetricConfig | None = None,
    step: bool = True,
    figure_dir: str | Path | None = None,
    weights: str | None = None,
) -> list[dict[str, Any]]:
    """Rows (one per segmentation x ablation, plus one ``gt`` row if asked) of one scan: every metric and the
    to-step time split by stage (seconds). A failing stage gives a row with ``ok`` False and its ``error``.
    ``figure_dir``: the result figure of the first (segmentation, ablation) goes there as ``<scan>.png``;
    ``weights``: the learned segmenter's weights file (None: the shipped one)."""
    from dataclasses import replace

    from v2c.bench.metrics import scan_metrics, vbrep_from_gt
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan

    metrics = metrics or MetricConfig()
    scan_dir = Path(scan_dir)
    rows: list[dict[str, Any]] = []
    t, c = time.perf_counter(), time.process_time()
    scan = load_scan(scan_dir)
    t_load, c_load = time.perf_counter() - t, time.process_time() - c
    base = {"scan": scan_dir.name, "path": str(scan_dir), "family": scan.gt.meta.get("family") if scan.gt else None}
    if GT in ablations:
        row = {**base, "segmentation": GT, "ablation": GT}
        try:
            # the ideal VB-Rep has no edges: edge-type accuracy is left out, not 0
            row.update(scan_metrics(vbrep_from_gt(scan), scan, replace(metrics, edge_types=False)), ok=True, error=None)
        except Exception as exc:  # noqa: BLE001 - one bad scan must not stop a benchmark
            row.update(ok=False, error=error_text(exc))
        rows.append(row)
    real = [a for a in ablations if a != GT]
    with tempfile.TemporaryDirectory(prefix="v2c-bench-") as tmp:
        for method in segmentations:
            t, c = time.perf_counter(), time.process_time()
            try:
                seg = segment_scan(scan, method, weights)
                seg_error = None
            except Exception as exc:  # noqa: BLE001
                seg, seg_error = None, error_text(exc)
            t_seg, c_seg = time.perf_counter() - t, time.process_time() - c
            for ablation in real:
                row = {**base, "segmentation": method, "ablation": ablation}
                rows.append(row)
                if seg is None:
                    row.update(ok=False, error=f"segment: {seg_error}")
                    continue
                try:
                    c = time.process_time()
                    vbrep = reconstruct(scan, segmentation=seg, ablation=ablation)
                    tim = dict(vbrep.meta.get("timings", {}))
                    split = {
                        "load": t_load,
                        "segment": t_seg,
                        "fit": float(tim.get("fit", math.nan)),
                        "vbrep": float(tim.get("vbrep", math.nan)),
                    }
                    # the pipeline got a ready segmentation: its own "segment" time is ~0; ours is t_seg
                    pipeline_rest = float(tim.get("total", 0.0)) - float(tim.get("segment", 0.0))
                    vbrep.meta.setdefault("timings", {})["segment"] = t_seg
                    if step:
                        from exporters import write

                        t = time.perf_counter()
                        report = write(
                            vbrep,
                            Path(tmp) / f"{scan_dir.name}_{method}_{ablation}.step",
                            frame="camera",
                            product=scan_dir.name,
                        )
                        split["step"] = time.perf_counter() - t
                        row["step_faces"] = report.n_faces
                        row["step_warnings"] = len(report.warnings)
                        # faces bounded by their mesh outline instead of their VB-Rep edges (issue 16)
                        row["step_fallback_faces"] = len(report.fallback_faces)
                    split["to_step"] = t_load + t_seg + pipeline_rest + split.get("step", 0.0)
                    # CPU seconds of the same work: what a free core would take (the machine may be shared)
                    split["to_step_cpu"] = c_load + c_seg + time.process_time() - c
                    if step:
                        row.update(
                            _readback_row(vbrep, Path(tmp) / f"{scan_dir.name}_{method}_{ablation}.step", report)
                        )
                    row.update(scan_metrics(vbrep, scan, metrics, split), ok=True, error=None)
                    if figure_dir is not None and method == segmentations[0] and ablation == real[0]:
                        row["figure"] = _save_figure(scan, seg, vbrep, Path(figure_dir) / f"{scan_dir.name}.png")
                except Exception as exc:  # noqa: BLE001 - a failure is a result of the benchmark, not a crash
                    row.update(ok=False, error=error_text(exc))
    return rows


def _readback_row(vbrep: VBRep, path: Path, report: Any) -> dict[str, Any]:
    """The written STEP read back through OCCT (`exporters.check_written`, issue 16): ``step_area_faces`` (VB-Rep
    faces compared), ``step_area_ok_faces`` (those whose written area is within the read-back's ``area_tol_rel``,
    2 %, of their mesh area, and that OCCT meshes), ``step_unmeshed_faces`` (faces OCCT's mesher draws short),
    ``step_area_share`` (written / reconstructed area over all faces) and
    ``step_box_ratio`` (the file's largest bounding-box extent / the reconstruction's; NaN without either),
    ``step_max_tol_rel`` (the file's largest vertex or edge tolerance in part sizes: the widest gap its
    topology bridges)."""
    from exporters import check_written

    rb = check_written(vbrep, path, report.frame_map)
    ratio = math.nan
    if rb.box_written is not None and rb.box_reconstructed is not None:
        ext_r = float((rb.box_reconstructed[1] - rb.box_reconstructed[0]).max())
        if ext_r > 0:
            ratio = float((rb.box_written[1] - rb.box_written[0]).max()) / ext_r
    return {
        "step_area_faces": len(rb.faces),
        "step_area_ok_faces": len(rb.faces) - len(rb.off_faces()),
        "step_unmeshed_faces": len(rb.unmeshed_faces()),
        "step_area_share": float(rb.area_share),
        "step_box_ratio": ratio,
        "step_max_tol_rel": float(rb.max_tolerance_rel),
    }


def _save_figure(scan: Scan, seg: Segmentation, vbrep: VBRep, path: Path) -> str | None:
    """exporters.figure's result figure (input, segmentation, VB-Rep from the camera and turned); None when it
    cannot be drawn (the figure is a convenience: never lose a benchmark row over it)."""
    try:
        from exporters import result_figure

        path.parent.mkdir(parents=True, exist_ok=True)
        result_figure(scan, seg.instances, vbrep, path)
        return str(path)
    except Exception:  # noqa: BLE001
        return None


def precision_of(segmentations: Sequence[str]) -> str | None:
    """The learned network's arithmetic ("bf16" / "fp32", `v2c.segment.learned.network_precision`) when
    ``segmentations`` use it, else None: written beside every benchmark's figures, which it changes."""
    if "learned" not in segmentations:
        return None
    from v2c.segment.learned import network_precision

    return network_precision()


def warm_up(segmentations: Sequence[str], weights: str | None = None) -> None:
    """Import what `v2c to-step` needs and load the learned model, so that per-scan times leave out the process
    start (measured once by `process_start_seconds`)."""
    import exporters.step  # noqa: F401
    import v2c.pipeline
    import v2c.vbrep.extract  # noqa: F401

    if "learned" in segmentations:
        from v2c.segment import learned

        path = weights or str(learned.DEFAULT_WEIGHTS)
        if learned.weights_available(Path(path)):
            learned._model(path)


def _worker_init(segmentations: Sequence[str] = (), weights: str | None = None) -> None:
    """Set up a worker process once: one thread per library, `v2c to-step`'s imports and model loaded."""
    limit_threads()
    with contextlib.suppress(Exception):  # a failing import is reported by the scan that needs it
        warm_up(segmentations, weights)
    limit_threads()  # again, for torch imported by the warm-up


def _worker(args: tuple) -> list[dict[str, Any]]:
    """One task of `evaluate_dirs`: `evaluate_scan` of the arguments packed in ``args``."""
    return evaluate_scan(*args)


def process_start_seconds(segmentations: Sequence[str], weights: str | None = None) -> float:
    """Wall time (s) of a fresh interpreter importing what `v2c to-step` needs (the CLI, the pipeline, the STEP
    writer, the segmenters used; the learned model loaded when its weights exist): the once-per-set start."""
    code = ["import v2c.cli, v2c.pipeline, exporters.step, v2c.fit, v2c.vbrep.extract"]
    for m in segmentations:
        if m == "learned":
            path = repr(weights or "")
            code.append(
                "from v2c.segment import learned as L\n"
                f"p = {path} or str(L.DEFAULT_WEIGHTS)\n"
                "if L.weights_available(p): L._model(p)"
            )
        elif m in ("geometric", "oracle"):
            code.append(f"import v2c.segment.{m}")
    t = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-c", "\n".join(code)],
        check=False,
        capture_output=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    return time.perf_counter() - t if proc.returncode == 0 else float("nan")


def evaluate_dirs(
    cfg: BenchConfig,
    dirs: Sequence[Path],
    progress: bool = True,
    figure_dirs: Sequence[Path | None] | None = None,
    desc: str = "bench",
) -> list[dict[str, Any]]:
    """`evaluate_scan` of every scan folder in a process pool of ``cfg.jobs`` workers (one thread each); the rows
    in the order of ``dirs``. A scan that raises anywhere (even while loading, or a worker that dies) gives
    failed rows naming the error: it never stops the run. ``figure_dirs``: the figure folder per scan (default:
    ``cfg.figure_dir`` for all)."""
    from tqdm import tqdm

    weights = str(cfg.weights) if cfg.weights else None
    if figure_dirs is None:
        figure_dirs = [cfg.figure_dir] * len(dirs)
    tasks = [
        (str(d), tuple(cfg.segmentations), tuple(cfg.ablations), cfg.metrics, cfg.step, str(f) if f else None, weights)
        for d, f in zip(dirs, figure_dirs, strict=True)
    ]
    rows: list[dict[str, Any]] = []
    where = executor_of(cfg)
    # local jobs > 1: spawned processes, a clean interpreter per worker (no forked torch / OCCT state)
    results = run_tasks(_worker, tasks, where, initializer=_worker_init, initargs=(tuple(cfg.segmentations), weights))
    if where.kind == "local" and cfg.jobs <= 1:
        _worker_init(cfg.segmentations, weights)
    bar = tqdm(total=len(tasks), unit="scan", desc=desc, disable=not progress)
    for task, scan_rows, exc in results:
        # a failed task (a worker that died, e.g. a crash inside OCCT; an unreadable scan): failed rows
        rows += scan_rows if exc is None else failed_rows(task, error_text(exc))
        bar.update()
    bar.close()
    order = {str(d): i for i, d in enumerate(dirs)}
    rows.sort(key=lambda r: order.get(r["path"], 0))
    return rows


def failed_rows(task: tuple, error: str) -> list[dict[str, Any]]:
    """The rows of a scan whose whole task failed (``task`` as `evaluate_dirs` packs it: scan folder,
    segmentations, ablations, ...): one per column, ``ok`` False, all naming ``error``."""
    path, segs, abls = Path(task[0]), task[1], task[2]
    base = {"scan": path.name, "path": str(path), "ok": False, "error": error}
    out = [{**base, "segmentation": s, "ablation": a} for s in segs for a in abls if a != GT]
    if GT in abls:
        out.append({**base, "segmentation": GT, "ablation": GT})
    return out
