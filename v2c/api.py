"""Scripting API: a scan folder -> STEP (+ VB-Rep JSON and figure), as `v2c to-step` does it for one scan.

    >>> from v2c.api import scan_to_step
    >>> result = scan_to_step("scans/part_01")          # writes scans/part_01/reconstruction.step
    >>> result.step, result.report.n_faces

`scan_to_step` = `v2c.scan.load_scan` -> `v2c.pipeline.reconstruct` (re-exported here as `reconstruct`, the
one pipeline entry point) -> `exporters.step.write` (millimetres,
part frame by default), then the extras next to the STEP: ``<stem>.vbrep.json`` (the VB-Rep) and
``<stem>.png`` (the result figure of `exporters.figure`). The files are one `v2c.io_safe.OutputSet`: written to
exclusive temporaries in the output folder and committed together, so a failed or interrupted run leaves the
complete previous set (or nothing) and never a new STEP beside an old JSON and figure.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from v2c.choices import DEFAULT_ABLATION, DEFAULT_SEGMENTATION
from v2c.pipeline import PipelineConfig, reconstruct

if TYPE_CHECKING:
    from exporters import Readback, StepReport

__all__ = ["DEFAULT_STEP_NAME", "PipelineConfig", "ScanExport", "expand_scans", "reconstruct", "scan_to_step"]

log = logging.getLogger(__name__)

#: File name of the STEP written into the scan folder when no output is given.
DEFAULT_STEP_NAME = "reconstruction.step"
#: Files whose presence makes a folder a scan folder (SCAN_FORMAT.md).
SCAN_MARKERS = ("camera.json", "depth.png", "depth.npy", "color.png", "color.jpg")


@dataclass
class ScanExport:
    """What `scan_to_step` wrote for one scan. seconds: wall time per step ("load", "reconstruct", "step",
    "extras"); warnings: non-fatal problems (faces rebuilt from their mesh outline, a missing figure, ...);
    readback: the STEP read back through OCCT and compared with the reconstruction (per-face written vs
    reconstructed area, untyped edges, bounding box)."""

    scan: Path
    step: Path
    report: StepReport
    vbrep_json: Path | None = None
    figure: Path | None = None
    warnings: list[str] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    readback: Readback | None = None


def is_scan_dir(path: Path) -> bool:
    """True when ``path`` is a folder holding any of the scan files of SCAN_FORMAT.md."""
    return path.is_dir() and any((path / m).exists() for m in SCAN_MARKERS)


def expand_scans(paths: list[str | Path]) -> list[Path]:
    """Scan folders from command-line paths: a scan folder stays itself; a folder that is not a scan but holds
    scan folders becomes those (sorted by name); anything else is kept, so loading it reports the problem."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir() and not is_scan_dir(p):
            subs = sorted(q for q in p.iterdir() if is_scan_dir(q))
            if subs:
                out.extend(subs)
                continue
        out.append(p)
    return out


def extras_paths(step: Path) -> tuple[Path, Path]:
    """(VB-Rep JSON, figure PNG) written next to a STEP file: ``<stem>.vbrep.json`` and ``<stem>.png``."""
    return step.with_name(step.stem + ".vbrep.json"), step.with_name(step.stem + ".png")


def scan_to_step(
    scan_dir: str | Path,
    out: str | Path | None = None,
    frame: str = "part",
    segmentation: str = DEFAULT_SEGMENTATION,
    extras: bool = True,
    roi: str | tuple[int, int, int, int] | None = None,
    ablation: str = DEFAULT_ABLATION,
    force: bool = False,
    config: PipelineConfig | None = None,
) -> ScanExport:
    """Reconstruct one scan folder and write its STEP (default ``SCAN/reconstruction.step``) and, unless
    ``extras`` is False, the VB-Rep JSON and figure next to it. Raises `v2c.scan.ScanError` for a bad scan and
    whatever the pipeline raises; on any error no STEP is written. force: replace existing files that v2c did
    not write (otherwise `v2c.errors.OutputError`, checked before the pipeline runs). config: every stage's
    settings (`v2c.pipeline.PipelineConfig`; the shipped defaults when None)."""
    from exporters import StepExportError, check_written, result_figure, write
    from v2c.io_safe import OutputSet, check_replaceable
    from v2c.scan import load_scan

    scan_dir = Path(scan_dir)
    out = Path(out) if out is not None else scan_dir / DEFAULT_STEP_NAME
    for dest in (out, *extras_paths(out)) if extras else (out,):  # fail before minutes of work, not after
        check_replaceable(dest, force)
    seconds: dict[str, float] = {}
    t = time.perf_counter()
    scan = load_scan(scan_dir, roi=roi)
    seconds["load"] = time.perf_counter() - t
    log.info(
        "%s: %d x %d px, %d valid pixels, loaded in %.2f s",
        scan_dir,
        scan.width,
        scan.height,
        int(scan.valid.sum()),
        seconds["load"],
    )
    t = time.perf_counter()
    vbrep, seg, _ = reconstruct(scan, segmentation=segmentation, ablation=ablation, config=config, return_stages=True)
    seconds["reconstruct"] = time.perf_counter() - t
    # Committed together on leaving the block; nothing changed on an exception. One task per scan: this process is
    # its outputs' only writer, so a killed attempt's leftovers (on any machine: a retried Ray task) go at once.
    with OutputSet(force=force, single_writer=True) as files:
        t = time.perf_counter()
        tmp = files.temp(out)
        try:
            # straight into the set's own exclusive temporary (a nested one would outlive a killed worker)
            report = write(vbrep, tmp, frame=frame, product=scan_dir.resolve().name or out.stem, atomic=False)
        except StepExportError as exc:  # name the destination, not our temporary
            raise StepExportError(f"{str(exc).replace(str(tmp), str(out))}; nothing written") from None
        report.path = out
        seconds["step"] = time.perf_counter() - t
        log.info("STEP: %d faces, %d edges, %.2f s", report.n_faces, report.n_edges, seconds["step"])
        t = time.perf_counter()
        readback = check_written(vbrep, tmp, report.frame_map)  # what the user gets, read back through OCCT
        readback.path = out
        seconds["readback"] = time.perf_counter() - t
        log.info("%s", readback.summary())
        result = ScanExport(
            scan=scan_dir, step=out, report=report, warnings=list(report.warnings), seconds=seconds, readback=readback
        )
        if extras:
            t = time.perf_counter()
            json_path, png_path = extras_paths(out)
            vbrep.save(files.temp(json_path))
            result.vbrep_json = json_path
            try:
                # drawn from the file as read back: the figure shows what the user got
                drawn = readback.drawn
                result_figure(
                    scan,
                    seg.instances,
                    drawn if drawn is not None else vbrep,
                    files.temp(png_path),
                    source="STEP as written" if drawn is not None else "VB-Rep",
                )
                result.figure = png_path
            except Exception as exc:  # noqa: BLE001 - the figure is a convenience: never lose the STEP over it
                files.forget(png_path)
                files.remove(png_path)  # an old figure would not belong to the new set
                result.warnings.append(f"figure not written ({type(exc).__name__}: {exc})")
            seconds["extras"] = time.perf_counter() - t
    return result
