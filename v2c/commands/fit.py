"""`v2c fit SCAN`: segment a scan, fit one primitive per surface instance (the geometry optimisation stage), print
the primitives and write them as JSON."""

from __future__ import annotations

import json
from pathlib import Path

import click

from v2c.cli_support import max_pixels_option, roi_option, verbosity_options
from v2c.commands import ablation_option, frame_index_option, pick_options, segmentation_option


def _short_params(d: dict) -> str:
    """Compact parameter text: millimetres for lengths, degrees for the cone angle."""
    import numpy as np

    out = []
    for k, v in d["params"].items():
        if k in ("origin",):
            out.append(f"{k}=({', '.join(f'{1000 * x:.1f}' for x in v)}) mm")
        elif k in ("normal", "axis"):
            out.append(f"{k}=({', '.join(f'{x:+.3f}' for x in v)})")
        elif k == "half_angle":
            out.append(f"half_angle={np.rad2deg(v):.2f} deg")
        else:
            out.append(f"{k}={1000 * v:.2f} mm")
    return " ".join(out)


@click.command("fit")
@max_pixels_option
@click.argument("scan_dir", metavar="SCAN", type=click.Path(path_type=str))
@segmentation_option("method")
@ablation_option
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=str),
    default=None,
    help="JSON file to write, or a folder (an existing one, or one ending in /) for fit.json (default: SCAN/fit.json).",
)
@roi_option
@pick_options
@frame_index_option
@click.option("--seed", default=0, show_default=True, help="Seed of the RANSAC sampling.")
@click.option("--force", is_flag=True, help="Replace an existing file that v2c did not write.")
@verbosity_options
def command(
    scan_dir: str,
    method: str,
    ablation: str,
    output: str | None,
    roi: tuple[int, int, int, int] | None,
    seed: int,
    force: bool,
) -> None:
    """Fit primitives to the scan folder SCAN: print type, axis class, parameters, inliers and RMS of each, and
    write them (camera frame, metres) as JSON."""
    from v2c.cli_support import output_file
    from v2c.fit import FitConfig, fit_scan
    from v2c.io_safe import check_replaceable, write_text_atomic
    from v2c.scan import ScanError, load_scan
    from v2c.segment import segment

    base = Path(scan_dir).parent if Path(scan_dir).is_file() else Path(scan_dir)  # a recording: next to it
    out = output_file(output, "fit.json") or base / "fit.json"
    check_replaceable(out, force)  # before the work, not after
    try:
        scan = load_scan(scan_dir, roi=roi)
        seg = segment(scan, method)
    except (ScanError, ValueError, OSError) as e:  # OSError: e.g. a segmenter's missing weights file
        raise click.ClickException(str(e)) from None
    res = fit_scan(scan, seg, FitConfig(seed=seed), ablation)
    from v2c.io_safe import v2c_origin

    data = {"generator": f"{v2c_origin()} fit", **res.to_json()}  # first key: v2c knows the file as its own
    data.update({"scan": str(scan.path), "segmentation": method})
    click.echo(
        f"{len(res.primitives)} primitives, part size {1000 * res.scale:.1f} mm, ablation {ablation}, "
        f"{res.timings['total']:.2f} s"
    )
    click.echo(
        "frame (rows X, Y, Z in camera): "
        + "; ".join("(" + ", ".join(f"{x:+.3f}" for x in row) + ")" for row in res.frame)
    )
    for p in data["primitives"]:
        click.echo(
            f"  #{p['instance']:<3d} {p['type']:<8} axis {p['axis_label'] or '-':<2} "
            f"inliers {p['inliers']:6d}  rms {1000 * p['rms_m']:.2f} mm  {_short_params(p)}"
        )
    write_text_atomic(out, json.dumps(data, indent=1))
    click.echo(f"wrote {out}")
