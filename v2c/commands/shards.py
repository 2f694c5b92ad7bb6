"""`v2c shards`: pack generated training scans into shards for training on an accelerator (docs/segmentation.md)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from v2c.cli_support import verbosity_options
from v2c.commands import output_folder_options, refuse_to_replace


@click.command("shards")
@click.argument("data", type=click.Path(exists=True, file_okay=False, path_type=Path))
@output_folder_options("shards")
@click.option(
    "--max-mb",
    type=click.FloatRange(min=1.0),
    default=None,
    help="Largest shard in MiB [default: ShardConfig.max_shard_mb, 48: one shard per call of the device tool].",
)
@verbosity_options
def command(data: Path, out: Path, max_mb: float | None, force: bool) -> None:
    """Pack the `v2c synth` scans under DATA into shard_XXX.npz files in the -o folder (colour as WebP, clean
    depth, faces, labels; noise and features are drawn again on the training machine), families interleaved."""
    from dataclasses import replace

    from v2c.segment.shards import ShardConfig, interleaved_scans, write_shards

    refuse_to_replace(out, "shard_*.npz", "shards", force)
    scans = interleaved_scans(data)
    if not scans:
        raise click.BadParameter(f"no scans with gt/ under {data}: expected `v2c synth` output", param_hint="DATA")
    cfg = ShardConfig() if max_mb is None else replace(ShardConfig(), max_shard_mb=max_mb)
    written = write_shards(scans, data, out, cfg)
    index = json.loads((out / "shards.json").read_text())["shards"]  # write_shards' list of each shard's scans
    for s in written:
        click.echo(f"{s}: {s.stat().st_size / 2**20:.1f} MiB, {len(index[s.name])} scans")
