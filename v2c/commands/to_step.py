"""`v2c to-step SCAN...`: reconstruct scans and write STEP AP242 files with typed edges (docs/step.md)."""

from __future__ import annotations

import os
from pathlib import Path

import click

from v2c.cli_support import max_pixels_option


def _roi_option(ctx: click.Context, param: click.Parameter, value: str | None):
    from v2c.scan import ScanError, parse_roi

    try:
        return parse_roi(value)
    except ScanError as e:
        raise click.BadParameter(str(e), ctx=ctx, param=param) from None


def _output_for(scan: Path, out: Path | None, batch: bool) -> Path | None:
    """Where one scan's STEP goes: -o as given for one scan; for several (or -o DIR/ or an existing folder), -o
    is a folder of <name>.step."""
    if out is None:
        return None
    if batch or out.is_dir():
        return out / f"{scan.resolve().name}.step"
    return out


@click.command("to-step")
@max_pixels_option
@click.argument("scans", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("-o", "--output", "out", type=click.Path(path_type=str), default=None,
              help="STEP file (one scan), or folder: an existing one, one ending in / (made when missing), or "
                   "several scans; <scan name>.step each. Default: SCAN/reconstruction.step.")
@click.option("--force", is_flag=True, help="Replace existing files that v2c did not write.")
@click.option("--frame", type=click.Choice(["part", "camera"]), default="part", show_default=True,
              help="part: recovered axes on X/Y/Z, origin at the bottom centre of the visible part; "
                   "camera: the camera frame. Millimetres either way.")
@click.option("--segmentation", type=click.Choice(["learned", "geometric", "oracle"]), default="learned",
              show_default=True, help="Segmentation of the pipeline (oracle needs a synthetic scan's gt/).")
@click.option("--no-extras", is_flag=True, help="Write only the STEP, not the VB-Rep JSON and figure.")
@click.option("--roi", callback=_roi_option, default=None, metavar="X0,Y0,X1,Y1",
              help="Restrict the reconstruction to this pixel box (x1/y1 exclusive).")
def command(scans: tuple[Path, ...], out: str | None, frame: str, segmentation: str, no_extras: bool,
            roi: tuple[int, int, int, int] | None, force: bool) -> None:
    """Reconstruct each SCAN folder (or every scan folder inside a folder) and write its STEP.

    One failing scan does not stop the others; the exit status is non-zero if any failed.
    """
    from tqdm import tqdm

    from v2c.api import expand_scans, scan_to_step
    from v2c.cli_support import describe_error, log, was_interrupted

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
            raise click.ClickException(f"scans with the same folder name ({', '.join(dup)}) would write "
                                       f"the same {out}/<name>.step; give them separately")
    done, failed = [], []
    bar = tqdm(paths, desc="to-step", unit="scan", disable=not batch, leave=False)
    for scan in bar:
        bar.set_postfix_str(scan.name)
        try:
            res = scan_to_step(scan, _output_for(scan, out, into_folder), frame=frame, segmentation=segmentation,
                               extras=not no_extras, roi=roi, force=force)
        except Exception as exc:  # one failing scan must not stop the rest
            if was_interrupted():  # Ctrl-C inside a C extension can surface as another exception
                raise KeyboardInterrupt from exc
            log.debug("%s failed:", scan, exc_info=True)
            msg = describe_error(exc, scan)
            failed.append((scan, msg))
            if batch:
                tqdm.write(f"error: {msg}")
            continue
        done.append(res)
        r = res.report
        outline = f", {len(r.fallback_faces)} bounded by their mesh outline" if r.fallback_faces else ""
        tqdm.write(f"{res.step}: {r.n_faces} faces{outline}, {r.n_edges} edges ({len(r.free_edges)} free), "
                   f"written in {r.seconds:.2f} s")
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
