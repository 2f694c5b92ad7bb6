"""`v2c to-step SCAN...`: reconstruct scans and write STEP AP242 files with typed edges (docs/step.md)."""

from __future__ import annotations

import os
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING

import click

from v2c.cli_support import max_pixels_option, quiet, roi_option, verbosity_options
from v2c.commands import executor_config, executor_options, frame_index_option, pick_options, segmentation_option

if TYPE_CHECKING:
    from v2c.api import ScanExport
    from v2c.pick import PickRequest


def _output_for(scan: Path, out: Path | None, batch: bool) -> Path | None:
    """Where one scan's STEP goes: -o as given for one scan; for several (or -o DIR/ or an existing folder), -o
    is a folder of <name>.step."""
    if out is None:
        from v2c.recordings import is_recording

        return scan.with_suffix(".step") if is_recording(scan) else None  # next to a recording, not inside it
    if batch or out.is_dir():
        return out / f"{scan.resolve().name}.step"
    return out


def _to_step_task(
    scan: Path,
    out: Path | None,
    batch: bool,
    frame: str,
    segmentation: str,
    extras: bool,
    roi: tuple[int, int, int, int] | None,
    force: bool = False,
    pick: PickRequest | None = None,
    frame_index: int = 0,
) -> ScanExport:
    """One scan's task (here, in a pool or on a Ray worker): reads SCAN (picking its object as ``pick`` says,
    `v2c.pick`; a recording's pair ``frame_index``), writes its outputs, returns the small `v2c.api.ScanExport`
    record."""
    from v2c.api import scan_to_step
    from v2c.pick import PickRequest, pick_request
    from v2c.recordings import recording_frame

    # in this task's process, which may not be the command's
    with pick_request(pick or PickRequest()), recording_frame(frame_index):
        return scan_to_step(
            scan,
            _output_for(scan, out, batch),
            frame=frame,
            segmentation=segmentation,
            extras=extras,
            roi=roi,
            force=force,
        )


@click.command("to-step")
@max_pixels_option
@click.argument("scans", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    "out",
    type=click.Path(path_type=str),
    default=None,
    help="STEP file (one scan), or folder: an existing one, one ending in / (made when missing), or "
    "several scans; <scan name>.step each. Default: SCAN/reconstruction.step.",
)
@click.option("--force", is_flag=True, help="Replace existing files that v2c did not write.")
@click.option(
    "--frame",
    type=click.Choice(["part", "camera"]),
    default="part",
    show_default=True,
    help="part: recovered axes on X/Y/Z, origin at the bottom centre of the visible part; "
    "camera: the camera frame. Millimetres either way.",
)
@segmentation_option()
@click.option("--no-extras", is_flag=True, help="Write only the STEP, not the VB-Rep JSON and figure.")
@roi_option
@pick_options
@frame_index_option
@verbosity_options
@executor_options
def command(
    scans: tuple[Path, ...],
    out: str | None,
    frame: str,
    segmentation: str,
    no_extras: bool,
    roi: tuple[int, int, int, int] | None,
    force: bool,
    executor: str,
    ray_address: str | None,
) -> None:
    """Reconstruct each SCAN folder (or every scan folder inside a folder) and write its STEP.

    One failing scan does not stop the others; the exit status is non-zero if any failed. The scans run one at a
    time here (no --jobs: each uses the cores it can); with --executor ray each scan is one Ray task: workers read
    the scan folders (and write next to them or under -o) at the same paths, so those must be on a file system
    every node shares.
    """
    from tqdm import tqdm

    from v2c.api import expand_scans
    from v2c.cli_support import describe_error, log, was_interrupted
    from v2c.executors import ExecutorError, run_tasks
    from v2c.pick import current_pick
    from v2c.recordings import current_frame_index

    where = executor_config(executor, ray_address)
    paths = expand_scans(list(scans))
    batch = len(paths) > 1
    # click's Path would drop a trailing separator: "-o new/" must still mean a folder
    into_folder = batch or (out is not None and out.endswith(("/", os.sep)))
    out = Path(out) if out is not None else None
    if batch and out is not None:
        if out.exists() and not out.is_dir():
            raise click.ClickException(f"{out}: -o must be a folder when several scans are given")
        names = [p.name for p in paths]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise click.ClickException(
                f"scans with the same folder name ({', '.join(dup)}) would write "
                f"the same {out}/<name>.step; give them separately"
            )
    task = partial(
        _to_step_task,
        out=out,
        batch=into_folder,
        frame=frame,
        segmentation=segmentation,
        extras=not no_extras,
        roi=roi,
        force=force,
        pick=current_pick(),
        frame_index=current_frame_index(),
    )
    try:
        results = run_tasks(task, paths, where)
    except ExecutorError as e:
        raise click.ClickException(str(e)) from None
    done, failed = [], []
    bar = tqdm(total=len(paths), desc="to-step", unit="scan", disable=not batch or quiet(), leave=False)
    if where.kind == "local":  # one at a time, in order: name the scan being worked on
        bar.set_postfix_str(paths[0].name)
    for scan, res, exc in results:
        bar.update()
        if where.kind == "local" and bar.n < len(paths):
            bar.set_postfix_str(paths[bar.n].name)
        if exc is not None:  # one failing scan does not stop the rest
            if was_interrupted():  # Ctrl-C inside a C extension can surface as another exception
                raise KeyboardInterrupt from exc
            log.debug("%s failed: %s", scan, exc)
            msg = describe_error(exc, scan)
            failed.append((scan, msg))
            if batch:
                tqdm.write(f"error: {msg}")
            continue
        done.append(res)
        r = res.report
        outline = f", {len(r.fallback_faces)} bounded by their mesh outline" if r.fallback_faces else ""
        tqdm.write(
            f"{res.step}: {r.n_faces} faces{outline}, {r.n_edges} edges ({len(r.free_edges)} free), "
            f"written in {r.seconds:.2f} s"
        )
        if res.readback is not None:
            tqdm.write(f"  {res.readback.summary()}")
        for w in res.warnings:
            tqdm.write(f"  warning: {w}")
    bar.close()
    if not batch and failed:
        raise click.ClickException(failed[0][1])
    if batch:
        tail = f", {len(failed)} failed:" if failed else "."
        click.echo(f"{len(done)} of {len(paths)} scans written{tail}")
        for _, msg in failed:
            click.echo(f"  {msg}")
        if failed:
            raise click.ClickException(f"{len(failed)} of {len(paths)} scans failed")
