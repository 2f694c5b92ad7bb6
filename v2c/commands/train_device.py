"""`v2c train-device`: train the segmentation U-Net from packed shards on an accelerator (or the CPU) and write its
checkpoints (`v2c.segment.train_device`, docs/segmentation.md 'Training on an accelerator')."""

from __future__ import annotations

from pathlib import Path

import click

from v2c.cli_support import verbosity_options
from v2c.commands import output_folder_options, refuse_to_replace
from v2c.segment.train_config import TrainConfig


@click.command("train-device")
@click.option(
    "--shards",
    "shards",
    multiple=True,
    required=True,
    type=click.Path(exists=True, path_type=Path),
    help="A folder of shard_*.npz (from `v2c shards`) or one shard file; repeat for more.",
)
@output_folder_options("checkpoints")
@click.option(
    "--init",
    default=None,
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    help="Weights to fine-tune (the net named 'init').",
)
@click.option("--wide", default="", help="Comma-separated widths of a second net trained from scratch ('wide').")
@click.option("--minutes", type=click.FloatRange(min=0.1), default=None, help="Wall-clock budget; fits the schedule.")
@click.option("--steps", type=click.IntRange(min=1), default=20000, show_default=True, help="Schedule length.")
@click.option("--batch", type=click.IntRange(min=1), default=32, show_default=True)
@click.option("--crop", type=click.IntRange(min=32), default=192, show_default=True, help="Crop side in pixels.")
@click.option("--lr", type=click.FloatRange(min=0.0, min_open=True), default=6e-4, show_default=True)
@click.option("--wide-lr-scale", type=click.FloatRange(min=0.0, min_open=True), default=1.0, show_default=True)
@click.option("--warmup", type=click.IntRange(min=0), default=TrainConfig.warmup_steps, show_default=True)
@click.option(
    "--boundary-weight",
    type=click.FloatRange(min=0.0),
    default=TrainConfig.boundary_weight,
    show_default=True,
    help="Weight of the boundary loss against the label loss (every net).",
)
@click.option(
    "--init-boundary-weight",
    type=click.FloatRange(min=0.0),
    default=None,
    help="Also fine-tune a second copy of --init ('init_bw') with this boundary-loss weight.",
)
@click.option("--realisations", type=click.IntRange(min=1), default=2, show_default=True)
@click.option("--workers", type=click.IntRange(min=1), default=16, show_default=True)
@click.option("--val-scans", type=click.IntRange(min=1), default=48, show_default=True)
@click.option("--eval-minutes", type=click.FloatRange(min=0.0), default=1.0, show_default=True)
@click.option("--probe-steps", type=click.IntRange(min=1), default=60, show_default=True)
@click.option("--limit", type=click.IntRange(min=1), default=None, help="Use only the first N packed scans.")
@click.option("--seed", default=0, show_default=True, help="Seed of the weights, crops and noise draws.")
@verbosity_options
def command(
    shards: tuple[Path, ...],
    out: Path,
    init: Path | None,
    wide: str,
    minutes: float | None,
    steps: int,
    batch: int,
    crop: int,
    lr: float,
    wide_lr_scale: float,
    warmup: int,
    boundary_weight: float,
    init_boundary_weight: float | None,
    realisations: int,
    workers: int,
    val_scans: int,
    eval_minutes: float,
    probe_steps: int,
    limit: int | None,
    seed: int,
    force: bool,
) -> None:
    """Train on packed scans, each realised with fresh noise on this machine; the nets train in lock step on the
    same batches and each writes its best checkpoint by validation mIoU into the -o folder."""
    from v2c.segment.train_device import DeviceTrainConfig, load_packed, nets_to_train, train_on_device

    refuse_to_replace(out, "*.pt", "checkpoints", force)
    try:
        widths = tuple(int(v) for v in wide.split(",")) if wide else ()
    except ValueError:
        raise click.BadParameter(f"{wide!r}: expected comma-separated integers", param_hint="--wide") from None
    if init_boundary_weight is not None and not init:
        raise click.BadParameter("needs --init (the weights its net starts from)", param_hint="--init-boundary-weight")
    packed, n_files = load_packed(shards, limit)
    if not packed:
        raise click.BadParameter(f"no packed scans in {', '.join(map(str, shards))}", param_hint="--shards")
    click.echo(f"{len(packed)} packed scans from {n_files} shards")
    cfg = TrainConfig(
        steps=steps,
        minutes=minutes,
        batch=batch,
        crop_px=crop,
        lr=lr,
        warmup_steps=warmup,
        boundary_weight=boundary_weight,
        val_scans=val_scans,
        seed=seed,
    )
    dcfg = DeviceTrainConfig(
        realisations=realisations, workers=workers, probe_steps=probe_steps, eval_minutes=eval_minutes, seed=seed
    )
    copies = ("init_bw",) if init_boundary_weight is not None else ()
    nets = nets_to_train(str(init) if init else None, widths, copies)
    train_on_device(
        packed,
        out,
        nets,
        cfg,
        dcfg,
        lr_scale={"wide": wide_lr_scale},
        log=lambda m: click.echo(m),
        boundary_weight={"init_bw": init_boundary_weight} if init_boundary_weight is not None else None,
    )
