"""`v2c reconstruct SCAN`: segmentation -> geometry optimisation -> VB-Rep; writes the VB-Rep JSON and the result
figure (docs/vbrep.md)."""

from __future__ import annotations

from pathlib import Path

import click

from v2c.cli_support import max_pixels_option, roi_option, verbosity_options
from v2c.commands import ablation_option, frame_index_option, pick_options, segmentation_option


@click.command("reconstruct")
@max_pixels_option
@click.argument("scan_dir", metavar="SCAN", type=click.Path(path_type=Path))
@segmentation_option("method")
@ablation_option
@click.option(
    "-o",
    "--output",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder for reconstruction.vbrep.json and reconstruction.png (default: SCAN).",
)
@click.option("--no-figure", is_flag=True, help="Write only the VB-Rep JSON.")
@click.option("--force", is_flag=True, help="Replace existing files that v2c did not write.")
@roi_option
@pick_options
@frame_index_option
@verbosity_options
def command(
    scan_dir: Path,
    method: str,
    ablation: str,
    out_dir: Path | None,
    no_figure: bool,
    force: bool,
    roi: tuple[int, int, int, int] | None,
) -> None:
    """Reconstruct the VB-Rep of the scan folder SCAN: write reconstruction.vbrep.json (camera frame, metres)
    and reconstruction.png (input, segmentation, VB-Rep from the camera and from a turned view)."""
    from exporters import result_figure
    from v2c.io_safe import check_replaceable
    from v2c.pipeline import reconstruct
    from v2c.scan import ScanError, load_scan

    try:
        scan = load_scan(scan_dir, roi=roi)
    except ScanError as e:
        raise click.ClickException(str(e)) from None
    if out_dir is None and scan.files.get("recording") is not None:
        out_dir = scan_dir.parent  # a recording is a file: write next to it
    for dest in ("reconstruction.vbrep.json", "reconstruction.png"):  # before the work, not after
        check_replaceable((out_dir or scan_dir) / dest, force)
    try:
        vbrep, seg, _ = reconstruct(scan, segmentation=method, ablation=ablation, return_stages=True)
    except ScanError as e:
        raise click.ClickException(str(e)) from None
    except (ValueError, FileNotFoundError) as e:  # oracle without gt/, learned without weights
        raise click.ClickException(str(e) if str(scan_dir) in str(e) else f"{scan_dir}: {e}") from None
    if not vbrep.faces:  # a VB-Rep without faces is no reconstruction: say so and write nothing
        raise click.ClickException(
            f"{scan_dir}: no face could be reconstructed ({len(seg.labels) - 1} surface "
            f"instances segmented); nothing written"
        )
    from v2c.io_safe import OutputSet

    out = out_dir or scan_dir
    json_path, png = out / "reconstruction.vbrep.json", out / "reconstruction.png"
    with OutputSet(force=force) as files:  # JSON and figure committed together
        vbrep.save(files.temp(json_path))
        if not no_figure:
            result_figure(scan, seg.instances, vbrep, files.temp(png))
    counts = {t: len(vbrep.edges_of_type(t)) for t in ("intersection", "visibility", "silhouette", "occluded")}
    click.echo(
        f"{json_path}: {len(vbrep.faces)} faces, {len(vbrep.edges)} edges "
        f"({', '.join(f'{n} {t}' for t, n in counts.items())}), {len(vbrep.vertices)} vertices; "
        f"{vbrep.meta['timings']['total']:.2f} s"
    )
    if not no_figure:
        click.echo(f"{png}")
