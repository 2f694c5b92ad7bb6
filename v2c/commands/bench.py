"""`v2c bench`: every metric of BENCHMARK.md per ablation on synthetic scans, as a table like the paper's Table 1
(docs/bench.md); ``--real DIR``: `v2c to-step` on real frames with regions of interest; ``--segmentation-only``:
the segmenters alone (their instances against the ground-truth faces, docs/segmentation.md)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from v2c.commands import executor_config, executor_options, jobs_given


def _csv(allowed: tuple[str, ...]):
    def parse(ctx: click.Context, param: click.Parameter, value: str) -> tuple[str, ...]:
        items = tuple(dict.fromkeys(v.strip() for v in value.split(",") if v.strip()))
        bad = [v for v in items if v not in allowed]
        if bad or not items:
            raise click.BadParameter(f"{', '.join(bad) or 'nothing'}: choose from {', '.join(allowed)}",
                                     ctx=ctx, param=param)
        return items
    return parse


def _size(ctx: click.Context, param: click.Parameter, value: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in value.lower().split("x"))
        if w < 32 or h < 32:
            raise ValueError
    except ValueError:
        raise click.BadParameter(f"{value!r}: expected WxH in pixels, e.g. 640x480 (at least 32x32)",
                                 ctx=ctx, param=param) from None
    return w, h


@click.command("bench")
@click.option("--n", "n", default=10, show_default=True, type=click.IntRange(1), help="Number of scans.")
@click.option("--seed", default=0, show_default=True, help="Seed of the generated scans.")
@click.option("--noise", default="sensor", show_default=True, type=click.Choice(["sensor", "paper"]),
              help="Noise profile of the generated scans (BENCHMARK.md).")
@click.option("--segmentation", default="learned", show_default=True,
              callback=_csv(("learned", "geometric", "oracle")),
              help="Segmentation method(s), comma-separated: learned, geometric, oracle.")
@click.option("--ablation", default="full,no-axis,no-int,fit-only", show_default=True,
              callback=_csv(("full", "no-axis", "no-int", "fit-only", "gt")),
              help="Ablations, comma-separated; 'gt' adds the ideal VB-Rep built from the ground truth "
                   "(the metrics' floor).")
@click.option("--cad", "cad_dir", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="Render the STEP files of this folder as scans instead of the procedural part families.")
@click.option("--size", default="640x480", show_default=True, callback=_size, help="Image size WxH (pixels).")
@click.option("--json", "json_out", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Write the summary and every per-scan row here.")
@click.option("--jobs", default=2, show_default=True, type=click.IntRange(1),
              help="Worker processes (one thread each); with --executor ray: most scans in flight "
                   "[default there: the whole cluster].")
@click.option("--scans", "scans_dir", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="Use the scan folders in DIR (the first N) instead of generating scans.")
@click.option("--cache", "cache_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Folder of generated scans (default $V2C_BENCH_CACHE or ~/.cache/v2c/bench).")
@click.option("--no-step", is_flag=True, help="Skip the (timed) STEP export of every reconstruction.")
@click.option("--real", "real_dir", type=click.Path(exists=True, file_okay=False, path_type=Path), default=None,
              help="Instead: run to-step on the real frames in DIR with the regions of interest of --rois and "
                   "report box angles and can radii.")
@click.option("--rois", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="ROI file for --real (default: v2c/bench/real_rois.json).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Where --real writes its STEP files, VB-Reps and figures (default: a temporary folder).")
@click.option("--figures", "figure_dir", type=click.Path(file_okay=False, path_type=Path), default=None,
              help="Write each scan's result figure (first column) and grid.png of the first 12 here.")
@click.option("--weights", type=click.Path(exists=True, dir_okay=False, path_type=Path), default=None,
              help="Weights of the learned segmenter (default: the shipped v2c/segment/weights/unet.pt).")
@click.option("--segmentation-only", "seg_only", is_flag=True,
              help="Instead: score the segmentation alone (its instances matched to the gt faces: precision, "
                   "recall, type / axis accuracy, mean IoU, seconds per scan) on the same scans.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bar.")
@executor_options
@click.pass_context
def command(ctx: click.Context, n: int, seed: int, noise: str, segmentation: tuple[str, ...],
            ablation: tuple[str, ...], cad_dir: Path | None, size: tuple[int, int], json_out: Path | None, jobs: int, scans_dir: Path | None,
            cache_dir: Path | None, no_step: bool, real_dir: Path | None, rois: Path | None,
            out_dir: Path | None, figure_dir: Path | None, weights: Path | None, seg_only: bool,
            quiet: bool, executor: str, ray_address: str | None) -> None:
    """Benchmark the pipeline on N synthetic scans per segmentation and ablation: Chamfer, primitive alignment,
    face precision / recall, type / axis accuracy, depth error, edge-type accuracy and runtime by stage, printed
    as a Markdown table next to the paper's numbers (docs/bench.md)."""
    from v2c.bench import run
    from v2c.executors import ExecutorError
    from v2c.synth.dataset import SynthError

    where = executor_config(executor, ray_address, jobs, jobs_given(ctx))
    if real_dir is not None:
        report = run.real_frames_report(real_dir, rois or run.DEFAULT_ROIS, segmentation[0], out_dir,
                                        progress=not quiet)
        click.echo(run.format_real_table(report))
        click.echo(f"outputs in {report['out_dir']}")
        _write_json(json_out, report)
        return
    order = ("full", "no-axis", "no-int", "fit-only", "gt")
    cfg = run.BenchConfig(n=n, seed=seed, noise=noise, size=size, cad_dir=cad_dir, segmentations=segmentation,
                          ablations=tuple(a for a in order if a in ablation), jobs=jobs, cache_dir=cache_dir,
                          scans_dir=scans_dir, step=not no_step, figure_dir=figure_dir, weights=weights,
                          executor=where.kind, ray_address=where.address, ray_jobs=where.jobs if
                          where.kind == "ray" else None)
    if seg_only:
        _segmentation_only(cfg, json_out, quiet)
        return
    try:
        result = run.run_benchmark(cfg, progress=not quiet)
    except (ValueError, ExecutorError, SynthError) as e:
        raise click.ClickException(str(e)) from None
    what = f"{len(result['scans'])} {'CAD-part' if cad_dir else 'synthetic'} scans, {noise} noise, " \
           f"{size[0]}x{size[1]}, seed {seed}, segmentation {','.join(segmentation)}"
    click.echo(what)
    click.echo(run.format_table(result))
    click.echo(run.format_notes(result))
    _write_json(json_out, result)


def _segmentation_only(cfg, json_out: Path | None, quiet: bool) -> None:
    """The segmenters of ``cfg`` on its scans, scored alone (`v2c.bench.segmentation`)."""
    from v2c.bench import run
    from v2c.bench import segmentation as S
    from v2c.executors import ExecutorError
    from v2c.synth.dataset import SynthError

    try:
        scans = run.prepare_scans(cfg, progress=not quiet)
    except (ValueError, ExecutorError, SynthError) as e:
        raise click.ClickException(str(e)) from None
    result = S.run(scans, list(cfg.segmentations), lambda scan, method: run.segment_scan(scan, method, cfg.weights),
                   log=(lambda *a: None) if quiet else (lambda m: click.echo(m, err=True)))
    click.echo(f"{len(scans)} scans, segmentation alone")
    click.echo(S.format_table(result))
    _write_json(json_out, run._jsonable(result))


def _write_json(path: Path | None, data: dict) -> None:
    if path is None:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, allow_nan=False) + "\n")
    click.echo(f"wrote {path}")
