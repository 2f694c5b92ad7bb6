"""`v2c info SCAN`: load a scan folder, check it, and print what was loaded. Writes nothing."""

from __future__ import annotations

from collections import Counter
from typing import TYPE_CHECKING

import click

from v2c.cli_support import max_pixels_option, roi_option, verbosity_options
from v2c.commands import frame_index_option, pick_options

if TYPE_CHECKING:
    from v2c.scan import Scan


def describe_scan(scan: Scan) -> list[str]:
    """Human-readable lines about a loaded :class:`v2c.scan.Scan` (units: pixels, metres)."""
    import numpy as np

    h, w = scan.height, scan.width
    n = h * w
    has = scan.depth > 0
    lines = [f"scan        {scan.path}"]
    lines.append(f"resolution  {w} x {h} px (width x height)")
    if has.any():
        d = scan.depth[has]
        lines.append(
            f"depth       {float(d.min()):.4f} .. {float(d.max()):.4f} m (median {float(np.median(d)):.4f} m); "
            f"readings on {100.0 * has.sum() / n:.1f} % of pixels"
        )
    depth_file = scan.files.get("depth")
    if scan.files.get("recording") is not None:
        depth_src = f"recording {scan.files['recording'].name} (depth in metres)"
    elif depth_file is not None and depth_file.suffix == ".npy":
        depth_src = f"{depth_file.name} (float metres)"
    else:
        depth_src = f"{depth_file.name if depth_file else 'depth.png'} x {scan.depth_scale:g} m/unit"
    lines.append(f"            source {depth_src}")
    for note in getattr(scan, "notes", []):
        lines.append(f"            note: {note}")
    form = f"camera.json form: {scan.camera_format}"
    if scan.camera_format == "rosbag":
        form = "the recording's camera_info"
    lines.append(f"intrinsics  fx {scan.fx:.3f}  fy {scan.fy:.3f}  cx {scan.cx:.3f}  cy {scan.cy:.3f} px ({form})")
    if abs(float(scan.K[0, 1])) > 0:
        lines.append(f"            skew {float(scan.K[0, 1]):.4f}")
    if scan.mask is not None and getattr(scan, "picked", None):
        lines.append(f"mask        picked: {int(scan.mask.sum())} px ({100.0 * scan.mask.mean():.1f} %); {scan.picked}")
    elif scan.mask is not None:
        lines.append(f"mask        mask.png: {int(scan.mask.sum())} px ({100.0 * scan.mask.mean():.1f} %)")
    else:
        lines.append("mask        none")
    if scan.roi is not None:
        x0, y0, x1, y1 = scan.roi
        lines.append(f"roi         x {x0}..{x1}, y {y0}..{y1} (exclusive ends): {(x1 - x0) * (y1 - y0)} px")
    else:
        lines.append("roi         none")
    valid = scan.valid
    lines.append(f"valid       {int(valid.sum())} px ({100.0 * valid.sum() / n:.1f} %) with depth inside mask/roi")
    if scan.valid.any():
        dv = scan.depth[valid]
        lines.append(f"            valid depth {float(dv.min()):.4f} .. {float(dv.max()):.4f} m")
    gt = scan.gt
    if gt is None:
        lines.append("ground truth  none")
        return lines
    visible = {int(i) for i in gt.visible_face_ids()}
    size = gt.part_size_m
    lines.append(
        f"ground truth  {len(gt.primitives)} faces, {len(visible)} visible; "
        f"part size {'?' if size is None else f'{size:.4f} m'}"
        + (f"; family {gt.meta['family']}" if "family" in gt.meta else "")
    )
    counts: Counter[tuple[str, str]] = Counter()
    counts_vis: Counter[tuple[str, str]] = Counter()
    for i, p in enumerate(gt.primitives):
        key = (str(p.get("type", "?")), str(p.get("axis_label") or "-"))
        counts[key] += 1
        fid = int(p.get("id", i))
        if fid in visible:
            counts_vis[key] += 1
    for (t, a), c in sorted(counts.items()):
        lines.append(f"              {t:<10} axis {a:<2} {c:3d} faces ({counts_vis[(t, a)]} visible)")
    part_px = int((gt.faces > 0).sum())
    lines.append(f"              part pixels {part_px} ({100.0 * part_px / n:.1f} %); step {gt.step_path}")
    return lines


@click.command("info")
@max_pixels_option
@click.argument("scan_dir", metavar="SCAN", type=click.Path(file_okay=True, dir_okay=True, path_type=str))
@roi_option
@pick_options
@frame_index_option
@verbosity_options
def command(scan_dir: str, roi: tuple[int, int, int, int] | None) -> None:
    """Load the scan folder SCAN, check it and print what it holds (resolution, depth, intrinsics, mask/ROI,
    ground truth). Writes nothing."""
    from v2c.scan import ScanError, load_scan

    try:
        scan = load_scan(scan_dir, roi=roi)
    except ScanError as e:
        raise click.ClickException(str(e)) from None
    for line in describe_scan(scan):
        click.echo(line)
