"""The settings of a `v2c bench` run and of its metrics: `BenchConfig` (which scans, which columns, where the
per-scan tasks run) and `MetricConfig` (the thresholds of BENCHMARK.md), with the names of the columns.

It imports nothing of the benchmark: the scan cache, the workers, the tables, the metrics and `vbrep.chamfer` read
their settings from here, so none of them needs the coordinator (`run`) or another of them for a setting.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from v2c.choices import ABLATIONS as CHOICE_ABLATIONS
from v2c.choices import SEGMENTATION_METHODS
from v2c.executors import ExecutorConfig
from v2c.labels import AXIS_ALIGN_TOL_DEG

ABLATIONS = CHOICE_ABLATIONS
GT = "gt"  # pseudo-ablation: the ideal VB-Rep built from the ground truth
SEGMENTATIONS = SEGMENTATION_METHODS
NOISES = ("sensor", "paper")


@dataclass(frozen=True)
class MetricConfig:
    """Thresholds of BENCHMARK.md and of the geometric tests of `v2c.bench.metrics` (lengths relative to the
    ground-truth part size where said, pixels of the scan's image, degrees)."""

    n_points: int = 20000  # points in G and in R (BENCHMARK.md)
    seed: int = 0  # seeds G's and R's random draws
    iou_thresholds: tuple[float, ...] = (0.5, 0.75)  # face-matching IoU; the first one feeds type/axis/alignment
    min_gt_px: int = 50  # pixels: ground-truth faces under this count only in recall_all
    axis_tol_deg: float = AXIS_ALIGN_TOL_DEG  # degrees: axis class tolerance against the part axes
    ignore_share: float = 0.5  # predicted faces with more of their pixels on non-analytic gt faces are left out
    visibility_eps_rel: float = 1e-4  # part sizes: a sample counts as seen when no triangle is nearer by more
    max_draw_rounds: int = 8  # rounds of drawing R candidates until n_points visible ones are found
    edge_tol_px: float = 3.0  # pixels: reach of an edge-type record (v2c.bench.vbrep.edge_type_accuracy)
    edge_types: bool = True  # compute edge-type accuracy (needs the scan's exact primitives)
    far_face_rel: float = 0.05  # part sizes: a face with a mesh vertex farther from every measured part point is far


@dataclass(frozen=True)
class BenchConfig:
    """One benchmark run. size: (width, height) pixels; jobs: worker processes (one thread each)."""

    n: int = 10
    seed: int = 0
    noise: str = "sensor"
    size: tuple[int, int] = (640, 480)
    cad_dir: Path | None = None  # render the STEP files of this folder instead of the procedural families
    segmentations: tuple[str, ...] = ("learned",)
    ablations: tuple[str, ...] = ABLATIONS
    jobs: int = 2
    cache_dir: Path | None = None  # None: v2c.bench.cache.default_cache_dir()
    scans_dir: Path | None = None  # use these scan folders instead of generating
    step: bool = True  # export (and time) the STEP file as `v2c to-step` does
    metrics: MetricConfig = field(default_factory=MetricConfig)
    figure_dir: Path | None = None  # result figure per scan (first column) and grid.png of them here
    weights: Path | None = None  # learned segmenter weights (None: the shipped v2c/segment/weights/unet.pt)
    executor: str = "local"  # "local": ``jobs`` processes; "ray": one Ray task per scan (docs/scale.md)
    ray_address: str | None = None  # Ray cluster ("auto", "HOST:PORT"; None: $RAY_ADDRESS or a local instance)
    ray_jobs: int | None = None  # most Ray tasks in flight (None: twice the cluster's CPUs)


def executor_of(cfg: BenchConfig) -> ExecutorConfig:
    """Where a run's per-scan tasks (generation and evaluation) go."""
    if cfg.executor == "ray":
        return ExecutorConfig(kind="ray", address=cfg.ray_address, jobs=cfg.ray_jobs)
    return ExecutorConfig(kind="local", jobs=cfg.jobs)


def columns_of(cfg: BenchConfig) -> list[tuple[str, str]]:
    """(segmentation, ablation) of every column, in the paper's order; the ``gt`` column last."""
    cols = [(s, a) for s in cfg.segmentations for a in cfg.ablations if a != GT]
    if GT in cfg.ablations:
        cols.append((GT, GT))
    return cols
