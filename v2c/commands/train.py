"""`v2c train`: train the segmentation U-Net on `v2c synth` scans and write its weights."""

from __future__ import annotations

from pathlib import Path

import click

from v2c.cli_support import verbosity_options
from v2c.commands import executor_config, executor_options, jobs_given, jobs_option
from v2c.segment.train_config import TrainConfig


@click.command("train")
@click.option(
    "--data",
    "data_dir",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Folder holding `v2c synth` scans (searched recursively for scans with gt/).",
)
@click.option(
    "--recipe",
    type=click.Choice(["base", "stage4", "stage5", "features", "appearance", "stage9", "stage10", "stage13"]),
    default=None,
    help="First generate this training set's missing scans under DATA (MODEL_CARD.md: base = stages "
    "1-3, stage4, stage5 = stages 5-8; features = stage5 plus 1500 scans of the feature-based "
    "training families; appearance = features plus 1500 with random appearance; stage9 = procedural, "
    "feature families, random appearance, corpus training files; stage10 = the same kinds with the procedural "
    "families weighted up, 2,200 scans; stage13 = about 1,000 scans weighted to the corpus training files); "
    "resumable, --jobs processes.",
)
@click.option(
    "-o",
    "--output",
    "--out",
    "out",
    required=True,
    type=click.Path(path_type=str),
    help="Weights file to write (the best checkpoint by validation mIoU), or a folder (an existing one, or one "
    "ending in /) for unet.pt.",
)
@click.option(
    "--force", is_flag=True, help="Replace an existing weights file (never replaced without it: hours of training)."
)
@click.option("--seed", default=0, show_default=True, help="Seed of the weights and of the crop sequence.")
@click.option("--steps", default=TrainConfig.steps, show_default=True, help="Optimiser steps (schedule length).")
@click.option(
    "--stop-step",
    type=int,
    default=None,
    help="Stop after this many steps (a prefix of the --steps schedule; reproduces a capped run).",
)
@click.option("--minutes", type=float, default=None, help="Wall-clock cap in minutes (the schedule is unchanged).")
@click.option(
    "--warmup",
    "warmup_steps",
    default=TrainConfig.warmup_steps,
    show_default=True,
    help="Linear learning-rate warm-up steps.",
)
@click.option("--batch", default=TrainConfig.batch, show_default=True, help="Crops per step.")
@click.option("--crop", "crop_px", default=TrainConfig.crop_px, show_default=True, help="Crop side (pixels).")
@click.option("--lr", default=TrainConfig.lr, show_default=True, help="Peak learning rate.")
@click.option(
    "--cache",
    "cache_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Feature cache folder (default DATA/.cache).",
)
@click.option(
    "--init",
    "init",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="Start from these weights (a second training stage with a fresh schedule).",
)
@click.option("--threads", default=TrainConfig.threads, show_default=True, help="torch CPU threads.")
@click.option("--fp32", is_flag=True, help="Disable bf16 autocast even where the CPU supports it.")
@jobs_option
@verbosity_options
@executor_options
@click.pass_context
def command(
    ctx: click.Context,
    data_dir: Path,
    recipe: str | None,
    out: str,
    force: bool,
    seed: int,
    steps: int,
    stop_step: int | None,
    minutes: float | None,
    warmup_steps: int,
    batch: int,
    crop_px: int,
    lr: float,
    cache_dir: Path | None,
    init: Path | None,
    threads: int,
    fp32: bool,
    jobs: int,
    executor: str,
    ray_address: str | None,
) -> None:
    """Train the segmentation network on the scans under DATA and write OUT (+ OUT.json, the training record).

    --jobs / --executor / --ray-address say where --recipe generates its scans (the training itself runs here)."""
    from v2c.cli_support import output_file
    from v2c.segment.train import train

    weights = output_file(out, "unet.pt")
    for dest in (weights, Path(f"{weights}.json")):  # before the work: a weights file is hours of training
        if (dest.exists() or dest.is_symlink()) and not force:
            raise click.ClickException(f"{dest}: exists; pass --force to replace it (or choose another -o)")
    where = executor_config(executor, ray_address, jobs, jobs_given(ctx))
    if recipe is not None:
        from v2c.executors import ExecutorError
        from v2c.segment.train import RECIPES, generate_training_data
        from v2c.synth.dataset import SynthError

        click.echo(f"generating the {recipe} training set under {data_dir} (missing scans only)")
        try:
            generate_training_data(data_dir, jobs=jobs, recipe=RECIPES[recipe], executor=where)
        except (ExecutorError, SynthError) as e:
            raise click.ClickException(str(e)) from None
    if not data_dir.is_dir():
        raise click.ClickException(f"{data_dir}: no such folder (generate scans with `v2c synth` or --recipe)")
    cfg = TrainConfig(
        steps=steps,
        stop_step=stop_step,
        minutes=minutes,
        warmup_steps=warmup_steps,
        batch=batch,
        crop_px=crop_px,
        lr=lr,
        seed=seed,
        threads=threads,
        bf16=False if fp32 else None,
    )
    try:
        rec = train(data_dir, weights, cfg, cache_dir=cache_dir, init=init, log=lambda m: click.echo(m))
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    best = rec.get("best") or {}
    click.echo(
        f"wrote {weights}: best mIoU {best.get('miou', float('nan')):.3f} at step {best.get('step')}, "
        f"{rec['steps_done']} steps in {rec['minutes']:.1f} min"
    )
