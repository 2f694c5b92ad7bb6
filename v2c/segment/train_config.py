"""Training schedule of the segmentation U-Net (torch-free, so the `v2c` command line starts fast)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TrainConfig:
    """Training schedule, augmentation and validation of the segmentation U-Net (units in the comments)."""

    steps: int = 1800  # optimiser steps (the schedule length)
    stop_step: int | None = None  # stop after this many steps (a reproducible prefix of the schedule)
    minutes: float | None = None  # wall-clock cap (minutes); the best checkpoint so far is kept
    batch: int = 8  # crops per step
    crop_px: int = 160  # square crop side (pixels)
    lr: float = 2e-3  # peak AdamW learning rate
    weight_decay: float = 1e-4
    warmup_steps: int = 200
    final_lr_frac: float = 0.03  # cosine decays to lr * final_lr_frac
    boundary_weight: float = 1.0  # weight of the boundary BCE against the label CE
    boundary_pos_weight: float = 3.0  # BCE pos_weight of boundary pixels
    class_weight_power: float = 0.3  # class weights = frequency^-power, normalised to mean 1 over present classes
    flip: bool = True  # random horizontal mirrors (label-safe, see data.CachedScans.crop)
    val_scans: int = 24  # held-out cached scans for the checkpoint metric (evenly spread over the sorted list)
    eval_every: int = 500  # steps between validation + checkpoint
    seed: int = 0
    threads: int = 1  # torch CPU threads (1 is faster than 2 on a loaded 2-core machine)
    bf16: bool | None = None  # None = when the CPU supports it
