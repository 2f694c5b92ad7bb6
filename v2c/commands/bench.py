"""`v2c bench`: every metric of BENCHMARK.md per ablation on synthetic scans, as a table like the paper's Table 1
(docs/bench.md); ``--suite unseen`` / ``corpus-val``: parts nothing is tuned on (`v2c.bench.suite`); ``--real
DIR``: `v2c to-step` on real frames with regions of interest; ``--segmentation-only``: the segmenters alone (their
instances against the ground-truth faces, docs/segmentation.md)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import click

from v2c.choices import ABLATIONS, DEFAULT_ABLATION, DEFAULT_SEGMENTATION, SEGMENTATION_METHODS
from v2c.commands import executor_config, executor_options, jobs_given

if TYPE_CHECKING:
    from v2c.bench.run import BenchConfig


def _csv(allowed: tuple[str, ...]) -> Callable[[click.Context, click.Parameter, str | None], tuple[str, ...] | None]:
    def parse(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[str, ...] | None:
        if value is None:  # an option whose default depends on another (e.g. --ablation on --suite)
            return None
        items = tuple(dict.fromkeys(v.strip() for v in value.split(",") if v.strip()))
        bad = [v for v in items if v not in allowed]
        if bad or not items:
            raise click.BadParameter(
                f"{', '.join(bad) or 'nothing'}: choose from {', '.join(allowed)}", ctx=ctx, param=param
            )
        return items

    return parse


def _size(ctx: click.Context, param: click.Parameter, value: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in value.lower().split("x"))
        if w < 32 or h < 32:
            raise ValueError
    except ValueError:
        raise click.BadParameter(
            f"{value!r}: expected WxH in pixels, e.g. 640x480 (at least 32x32)", ctx=ctx, param=param
        ) from None
    return w, h


@click.command("bench")
@click.option("--n", "n", default=10, show_default=True, type=click.IntRange(1), help="Number of scans.")
@click.option("--seed", default=0, show_default=True, help="Seed of the generated scans.")
@click.option(
    "--noise",
    default="sensor",
    show_default=True,
    type=click.Choice(["sensor", "paper"]),
    help="Noise profile of the generated scans (BENCHMARK.md).",
)
@click.option(
    "--segmentation",
    default=DEFAULT_SEGMENTATION,
    show_default=True,
    callback=_csv(SEGMENTATION_METHODS),
    help="Segmentation method(s), comma-separated: learned, geometric, oracle.",
)
@click.option(
    "--ablation",
    default=None,
    callback=_csv((*ABLATIONS, "gt")),
    help="Ablations, comma-separated; 'gt' adds the ideal VB-Rep built from the ground truth "
    "(the metrics' floor).  [default: full,no-axis,no-int,fit-only; full with --suite unseen or "
    "corpus-val]",
)
@click.option(
    "--cad",
    "cad_dir",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="Render the STEP files of this folder as scans instead of the procedural part families.",
)
@click.option("--size", default="640x480", show_default=True, callback=_size, help="Image size WxH (pixels).")
@click.option(
    "--json",
    "json_out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the summary and every per-scan row here.",
)
@click.option(
    "--jobs",
    default=2,
    show_default=True,
    type=click.IntRange(1),
    help="Worker processes (one thread each); with --executor ray: most scans in flight "
    "[default there: the whole cluster].",
)
@click.option(
    "--scans",
    "scans_dir",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="Use the scan folders in DIR (the first N) instead of generating scans.",
)
@click.option(
    "--cache",
    "cache_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder of generated scans (default $V2C_BENCH_CACHE or ~/.cache/v2c/bench).",
)
@click.option("--no-step", is_flag=True, help="Skip the (timed) STEP export of every reconstruction.")
@click.option(
    "--real",
    "real_dir",
    type=click.Path(exists=True, file_okay=False, path_type=Path),
    default=None,
    help="Instead: reconstruct the real frames in DIR with the regions of interest of --rois, every "
    "--segmentation method, and report faces per side, box angles, can radii, depth RMS, the "
    "share of object pixels within 3 mm of the STEP, runtime (docs/bench.md).",
)
@click.option(
    "--rois",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="ROI file for --real (default: v2c/bench/real_rois.json).",
)
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Where --real writes its STEP files, VB-Reps and figures (default: a temporary folder).",
)
@click.option(
    "--figures",
    "figure_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Write each scan's result figure (first column) and grid.png of the first 12 here.",
)
@click.option(
    "--weights",
    type=click.Path(exists=True, dir_okay=False, path_type=Path),
    default=None,
    help="Weights of the learned segmenter (default: the shipped v2c/segment/weights/unet.pt).",
)
@click.option(
    "--segmentation-only",
    "seg_only",
    is_flag=True,
    help="Instead: score the segmentation alone (its instances matched to the gt faces: precision, "
    "recall, type / axis accuracy, mean IoU, seconds per scan) on the same scans.",
)
@click.option(
    "--suite",
    default="family",
    show_default=True,
    type=click.Choice(["family", "unseen", "corpus-val"]),
    help="family: the generator families (or --cad DIR), as always; unseen: the corpus test split and "
    "the leave-out generator families, which nothing is tuned on; corpus-val: the corpus "
    "validation split, the only one to tune on (docs/bench.md).",
)
@click.option(
    "--views",
    default=2,
    show_default=True,
    type=click.IntRange(1),
    help="--suite unseen / corpus-val: rendered views per corpus part.",
)
@click.option(
    "--corpus",
    "corpus_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="--suite unseen / corpus-val: the CAD corpus folder (default ../shared/data/cad_corpus).",
)
@click.option(
    "--parts",
    default=None,
    help="--suite unseen / corpus-val: only these corpus files of the split, comma-separated, or 'none' "
    "(no corpus scans: only the leave-out families).",
)
@click.option(
    "--unseen-families",
    default=None,
    help="--suite unseen: leave-out generator families, comma-separated, or 'none' (default: "
    "LEAVE_OUT_FAMILIES of v2c.synth.features when it exists).",
)
@click.option(
    "--family-scans",
    default=14,
    show_default=True,
    type=click.IntRange(1),
    help="--suite unseen: scans per leave-out family.",
)
@click.option(
    "--appearance",
    default="plain",
    show_default=True,
    type=click.Choice(["plain", "random"]),
    help="--suite unseen / corpus-val: random renders the scans with appearance and framing "
    "randomization (v2c synth --appearance random; cached apart from plain).",
)
@click.option(
    "--reliability",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Write the reliability diagram (PNG) of the first column's edge confidences here: share of "
    "edges whose type is right against their confidence, raw and calibrated, ECE in the legend.",
)
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@executor_options
@click.pass_context
def command(
    ctx: click.Context,
    n: int,
    seed: int,
    noise: str,
    segmentation: tuple[str, ...],
    ablation: tuple[str, ...],
    cad_dir: Path | None,
    size: tuple[int, int],
    json_out: Path | None,
    jobs: int,
    scans_dir: Path | None,
    cache_dir: Path | None,
    no_step: bool,
    real_dir: Path | None,
    rois: Path | None,
    out_dir: Path | None,
    figure_dir: Path | None,
    weights: Path | None,
    seg_only: bool,
    suite: str,
    views: int,
    corpus_dir: Path | None,
    parts: str | None,
    unseen_families: str | None,
    family_scans: int,
    appearance: str,
    reliability: Path | None,
    quiet: bool,
    executor: str,
    ray_address: str | None,
) -> None:
    """Benchmark the pipeline on N synthetic scans per segmentation and ablation: Chamfer, primitive alignment,
    face precision / recall, type / axis accuracy, depth error, edge-type accuracy and runtime by stage, printed
    as a Markdown table next to the paper's numbers (docs/bench.md). ``--suite unseen`` measures parts nothing
    is tuned on instead (the CAD corpus test split and the leave-out generator families), per source and size
    band; ``--suite corpus-val`` the corpus validation split."""
    from v2c.bench import run
    from v2c.executors import ExecutorError
    from v2c.synth.dataset import SynthError

    where = executor_config(executor, ray_address, jobs, jobs_given(ctx))
    if real_dir is not None:
        from v2c.bench import real

        report = real.real_bench(real_dir, rois or run.DEFAULT_ROIS, segmentation, out_dir, progress=not quiet)
        click.echo(real.format_table(report))
        click.echo(f"outputs in {report['out_dir']}")
        _write_json(json_out, report)
        return
    order = (*ABLATIONS, "gt")
    if ablation is None:
        ablation = ABLATIONS if suite == "family" else (DEFAULT_ABLATION,)
    if suite != "family":
        _suite(
            suite,
            seed=seed,
            noise=noise,
            segmentation=segmentation,
            ablation=tuple(a for a in order if a in ablation),
            cad_dir=cad_dir,
            size=size,
            json_out=json_out,
            jobs=jobs,
            scans_dir=scans_dir,
            cache_dir=cache_dir,
            no_step=no_step,
            figure_dir=figure_dir,
            weights=weights,
            seg_only=seg_only,
            views=views,
            corpus_dir=corpus_dir,
            parts=parts,
            unseen_families=unseen_families,
            family_scans=family_scans,
            appearance=appearance,
            reliability=reliability,
            quiet=quiet,
        )
        return
    if appearance != "plain":
        raise click.UsageError(
            "--appearance belongs to --suite unseen / corpus-val (for the family suite: "
            "v2c synth --appearance random, then --scans DIR)"
        )
    cfg = run.BenchConfig(
        n=n,
        seed=seed,
        noise=noise,
        size=size,
        cad_dir=cad_dir,
        segmentations=segmentation,
        ablations=tuple(a for a in order if a in ablation),
        jobs=jobs,
        cache_dir=cache_dir,
        scans_dir=scans_dir,
        step=not no_step,
        figure_dir=figure_dir,
        weights=weights,
        executor=where.kind,
        ray_address=where.address,
        ray_jobs=where.jobs if where.kind == "ray" else None,
    )
    if seg_only:
        _segmentation_only(cfg, json_out, quiet)
        return
    try:
        result = run.run_benchmark(cfg, progress=not quiet)
    except (ValueError, ExecutorError, SynthError) as e:
        raise click.ClickException(str(e)) from None
    what = (
        f"{len(result['scans'])} {'CAD-part' if cad_dir else 'synthetic'} scans, {noise} noise, "
        f"{size[0]}x{size[1]}, seed {seed}, segmentation {','.join(segmentation)}"
    )
    click.echo(what)
    click.echo(run.format_table(result))
    click.echo(run.format_notes(result))
    _reliability(reliability, result, f"in-family bench, seed {seed}, {len(result['scans'])} scans")
    _write_json(json_out, result)


def _reliability(path: Path | None, result: dict, title: str) -> None:
    """The reliability diagram of the first column's rows (`v2c.bench.run.write_reliability`)."""
    if path is None:
        return
    from v2c.bench import run

    col = result["columns"][0]
    rows = [r for r in result["rows"] if f"{r['segmentation']}/{r['ablation']}" == col]
    click.echo(f"reliability diagram: {run.write_reliability(rows, path, f'{title}, {col}')}")


def _suite(
    suite: str,
    *,
    seed: int,
    noise: str,
    segmentation: tuple[str, ...],
    ablation: tuple[str, ...],
    cad_dir: Path | None,
    size: tuple[int, int],
    json_out: Path | None,
    jobs: int,
    scans_dir: Path | None,
    cache_dir: Path | None,
    no_step: bool,
    figure_dir: Path | None,
    weights: Path | None,
    seg_only: bool,
    views: int,
    corpus_dir: Path | None,
    parts: str | None,
    unseen_families: str | None,
    family_scans: int,
    appearance: str,
    reliability: Path | None,
    quiet: bool,
) -> None:
    """``--suite unseen`` / ``corpus-val``: `v2c.bench.suite.run_and_report`."""
    from v2c.bench import run
    from v2c.bench import suite as S

    for flag, given in (("--cad", cad_dir), ("--scans", scans_dir), ("--segmentation-only", seg_only)):
        if given:
            raise click.UsageError(f"{flag} belongs to --suite family, not --suite {suite}")
    fams = None
    if unseen_families is not None:
        fams = (
            ()
            if unseen_families.strip().lower() == "none"
            else tuple(dict.fromkeys(f.strip() for f in unseen_families.split(",") if f.strip()))
        )
    names = None
    if parts:
        names = (
            ()
            if parts.strip().lower() == "none"
            else tuple(dict.fromkeys(p.strip() for p in parts.split(",") if p.strip()))
        )
    bench = run.BenchConfig(
        seed=seed,
        noise=noise,
        size=size,
        segmentations=segmentation,
        ablations=ablation,
        jobs=jobs,
        cache_dir=cache_dir,
        step=not no_step,
        figure_dir=figure_dir,
        weights=weights,
    )
    cfg = S.SuiteConfig(
        suite=suite,
        bench=bench,
        corpus_dir=corpus_dir,
        views=views,
        parts=names,
        families=fams,
        family_scans=family_scans,
        appearance=appearance,
    )
    try:
        result = S.run_and_report(cfg, progress=not quiet, echo=click.echo)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    _reliability(reliability, result, f"suite {suite}, seed {seed}, {len(result['scans'])} scans")
    _write_json(json_out, result)


def _segmentation_only(cfg: BenchConfig, json_out: Path | None, quiet: bool) -> None:
    """The segmenters of ``cfg`` on its scans, scored alone (`v2c.bench.segmentation`)."""
    from v2c.bench import run
    from v2c.bench import segmentation as S
    from v2c.executors import ExecutorError
    from v2c.synth.dataset import SynthError

    try:
        scans = run.prepare_scans(cfg, progress=not quiet)
    except (ValueError, ExecutorError, SynthError) as e:
        raise click.ClickException(str(e)) from None
    result = S.run(
        scans,
        list(cfg.segmentations),
        lambda scan, method: run.segment_scan(scan, method, cfg.weights),
        log=(lambda *a: None) if quiet else (lambda m: click.echo(m, err=True)),
    )
    click.echo(f"{len(scans)} scans, segmentation alone")
    click.echo(S.format_table(result))
    _write_json(json_out, run.jsonable(result))


def _write_json(path: Path | None, data: dict) -> None:
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n")
    click.echo(f"wrote {path}")
