"""`v2c bench`: every metric of BENCHMARK.md per ablation on synthetic scans, as a table like the paper's Table 1
(docs/bench.md); ``--suite unseen`` / ``corpus-val``: parts nothing is tuned on (`v2c.bench.suite`); ``--real
DIR``: `v2c to-step` on real frames with regions of interest. ``--stage`` measures one stage alone on the same
scans: ``segmentation`` (the segmenters' instances against the ground-truth faces, `v2c.bench.segmentation`),
``fit`` (the geometry stage on oracle segmentation, `v2c.bench.fit`), ``vbrep`` (Chamfer and edge-type accuracy
per family, `v2c.bench.vbrep`), ``synth`` (the scan generator's speed, `v2c.synth.bench`), ``parts`` (the
feature-based part builder's valid share and speed, `v2c.synth.features.measure`), ``fixtures`` (fixtures designed
with the default settings on reconstructions of generated parts, checked against the true part,
`v2c.bench.fixtures`)."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import click

from v2c.choices import ABLATIONS, DEFAULT_ABLATION, DEFAULT_SEGMENTATION, SEGMENTATION_METHODS
from v2c.cli_support import quiet, verbosity_options
from v2c.commands import executor_config, executor_options, jobs_given, jobs_option

#: What ``--stage`` measures: the whole pipeline (the Table-1 bench), or one stage alone.
STAGES = ("pipeline", "segmentation", "fit", "vbrep", "synth", "parts", "fixtures")

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
@jobs_option
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
    "--real-masks",
    is_flag=True,
    help="With --real: reconstruct each frame with the 'mask' polygon of its --rois entry (the object's outline, "
    "occluders left out) as its mask.png, inside its ROI.",
)
@click.option(
    "-o",
    "--output",
    "--out",
    "out_dir",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Folder where --real writes its STEP files, VB-Reps and figures (default: a temporary folder).",
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
    "--stage",
    default="pipeline",
    show_default=True,
    type=click.Choice(STAGES),
    help="What to measure on the scans (generated, or --scans DIR): pipeline: every metric of the "
    "reconstruction (the table); segmentation: the segmenters alone (instances matched to the gt faces: "
    "precision, recall, type / axis accuracy, mean IoU, seconds per scan); fit: the geometry stage alone on "
    "oracle segmentation (alignment, radius / plane-offset / torus errors, single-thread fit time, per "
    "--ablation); vbrep: Chamfer and edge-type accuracy (matched, strict, coverage) per part family. "
    "Without scans: synth: the scan generator's speed (--n timed scans of --size, --noise, --families); "
    "parts: the feature-based part builder (--n parts of --families: valid share, parts per second). "
    "fixtures: --n generated scans of --families (or, with --suite corpus-train / corpus-val / unseen, the "
    "corpus split's scans), each kind of fixture designed with the default settings on "
    "the reconstruction and checked against the true part (cut rate, touch rate, pin / cradle "
    "qualification).",
)
@click.option(
    "--segmentation-only",
    "seg_only",
    is_flag=True,
    hidden=True,
    help="The same as --stage segmentation (kept for old scripts).",
)
@click.option(
    "--families",
    default=None,
    help="--stage synth / parts / fixtures: part families or groups, comma-separated, as `v2c synth "
    "--families` [default: synth: the procedural families; parts: the feature-based ones; fixtures: train].",
)
@click.option(
    "--clearance-k",
    "clearance_k",
    default=None,
    help="--stage fixtures: k of the default clearance (k x the mating faces' 1-sigma, mm), comma-separated "
    "to measure several  [default: fixtures_design.design.CLEARANCE_K].",
)
@click.option(
    "--fixture-kinds",
    "fixture_kinds",
    default=None,
    help="--stage fixtures: the kinds designed on every scan, comma-separated from corner, pin, cradle, nest "
    "(a nest takes minutes to design and check; corner,pin,cradle measures the rest quickly)  [default: all four].",
)
@click.option(
    "--suite",
    default="family",
    show_default=True,
    type=click.Choice(["family", "unseen", "corpus-val", "corpus-train"]),
    help="family: the generator families (or --cad DIR), as always; unseen: the corpus test split and "
    "the leave-out generator families, which nothing is tuned on; corpus-val: the corpus "
    "validation split, the only one to tune on; corpus-train: the training split (docs/bench.md).",
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
    default=16,
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
@click.option("--force", is_flag=True, help="Replace an existing --json file that v2c did not write (default: refuse).")
@verbosity_options
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
    real_masks: bool,
    out_dir: Path | None,
    figure_dir: Path | None,
    weights: Path | None,
    stage: str,
    seg_only: bool,
    families: str | None,
    clearance_k: str | None,
    fixture_kinds: str | None,
    suite: str,
    views: int,
    corpus_dir: Path | None,
    parts: str | None,
    unseen_families: str | None,
    family_scans: int,
    appearance: str,
    reliability: Path | None,
    force: bool,
    executor: str,
    ray_address: str | None,
) -> None:
    """Benchmark the pipeline on N synthetic scans per segmentation and ablation: Chamfer, primitive alignment,
    face precision / recall, type / axis accuracy, depth error, edge-type accuracy and runtime by stage, printed
    as a Markdown table next to the paper's numbers (docs/bench.md). ``--suite unseen`` measures parts nothing
    is tuned on instead (the CAD corpus test split and the leave-out generator families), per source and size
    band; ``--suite corpus-val`` the corpus validation split. ``--stage`` measures one stage alone instead
    (segmentation, fit, vbrep on the scans; synth, parts: the generators' speed)."""
    from v2c.bench import run
    from v2c.executors import ExecutorError
    from v2c.synth.dataset import SynthError

    def given(name: str) -> bool:
        return jobs_given(ctx, name)

    if seg_only:  # the old spelling of --stage segmentation
        if given("stage") and stage != "segmentation":
            raise click.UsageError(f"--segmentation-only contradicts --stage {stage}")
        stage = "segmentation"
    if families is not None and stage not in ("synth", "parts", "fixtures"):
        raise click.UsageError("--families belongs to --stage synth / parts / fixtures")
    if clearance_k is not None and stage != "fixtures":
        raise click.UsageError("--clearance-k belongs to --stage fixtures")
    if fixture_kinds is not None and stage != "fixtures":
        raise click.UsageError("--fixture-kinds belongs to --stage fixtures")
    if stage != "pipeline":
        for name, flag in (("real_dir", "--real"), ("suite", "--suite"), ("reliability", "--reliability")):
            if given(name) and not (name == "suite" and stage == "fixtures"):
                raise click.UsageError(f"{flag} belongs to --stage pipeline, not --stage {stage}")
    if stage in ("fit", "vbrep", "synth", "parts"):
        for name, flag in (("weights", "--weights"), ("figure_dir", "--figures"), ("no_step", "--no-step")):
            if given(name):
                raise click.UsageError(f"{flag} does not apply to --stage {stage}")
    check_json_output(json_out, force)  # before the work, not after
    progress = not quiet()
    if stage == "fixtures":
        for name, flag in (
            ("scans_dir", "--scans"),
            ("cad_dir", "--cad"),
            ("figure_dir", "--figures"),
            ("no_step", "--no-step"),
            ("ablation", "--ablation"),
            ("views", "--views"),
            ("corpus_dir", "--corpus"),
            ("parts", "--parts"),
            ("unseen_families", "--unseen-families"),
            ("family_scans", "--family-scans"),
            ("appearance", "--appearance"),
        ):
            if given(name):
                raise click.UsageError(f"{flag} does not apply to --stage fixtures (it renders its own scans)")
        if len(segmentation) != 1:
            raise click.UsageError("--stage fixtures takes one --segmentation method")
        if suite != "family" and given("families"):
            raise click.UsageError(f"--families does not apply to --stage fixtures --suite {suite} (a corpus split)")
        _fixtures_stage(
            n=n if suite == "family" or given("n") else None,
            suite=None if suite == "family" else suite,
            seed=seed,
            noise=noise,
            size=size,
            families=_family_names("fixtures", families or "train"),
            segmentation=segmentation[0],
            weights=weights,
            clearance_k=clearance_k,
            kinds=fixture_kinds,
            cache_dir=cache_dir,
            json_out=json_out,
            progress=progress,
        )
        return
    if stage in ("synth", "parts"):
        for name, flag in (("scans_dir", "--scans"), ("cad_dir", "--cad"), ("segmentation", "--segmentation")):
            if given(name):
                raise click.UsageError(f"{flag} does not apply to --stage {stage} (it makes its own parts)")
        _generator_stage(stage, n=n, seed=seed, noise=noise, size=size, families=families, json_out=json_out)
        return
    where = executor_config(executor, ray_address, jobs, jobs_given(ctx))
    if real_dir is not None:
        from v2c.bench import real

        report = real.real_bench(
            real_dir,
            rois or run.DEFAULT_ROIS,
            segmentation,
            out_dir,
            progress=progress,
            masks=real_masks,
            weights=weights,
        )
        click.echo(real.format_table(report))
        click.echo(f"outputs in {report['out_dir']}")
        _write_json(json_out, report)
        return
    order = (*ABLATIONS, "gt")
    if ablation is None:
        ablation = ABLATIONS if suite == "family" and stage in ("pipeline", "fit") else (DEFAULT_ABLATION,)
    if stage in ("fit", "vbrep") and "gt" in ablation:
        raise click.UsageError(f"--ablation gt (the ideal VB-Rep) belongs to --stage pipeline, not {stage}")
    if stage == "fit" and given("segmentation") and segmentation != ("oracle",):
        raise click.UsageError("--stage fit measures the geometry stage on oracle segmentation only")
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
            views=views,
            corpus_dir=corpus_dir,
            parts=parts,
            unseen_families=unseen_families,
            family_scans=family_scans,
            appearance=appearance,
            reliability=reliability,
            progress=progress,
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
        segmentations=("oracle",) if stage == "fit" else segmentation,
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
    if stage in ("segmentation", "fit", "vbrep"):
        try:
            scans = run.prepare_scans(cfg, progress=progress)
        except (ValueError, ExecutorError, SynthError) as e:
            raise click.ClickException(str(e)) from None
        {"segmentation": _segmentation_stage, "fit": _fit_stage, "vbrep": _vbrep_stage}[stage](
            cfg, scans, json_out, progress
        )
        return
    try:
        result = run.run_benchmark(cfg, progress=progress)
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
    views: int,
    corpus_dir: Path | None,
    parts: str | None,
    unseen_families: str | None,
    family_scans: int,
    appearance: str,
    reliability: Path | None,
    progress: bool,
) -> None:
    """``--suite unseen`` / ``corpus-val``: `v2c.bench.suite.run_and_report`."""
    from v2c.bench import run
    from v2c.bench import suite as S

    for flag, given in (("--cad", cad_dir), ("--scans", scans_dir)):
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
        result = S.run_and_report(cfg, progress=progress, echo=click.echo)
    except ValueError as e:
        raise click.ClickException(str(e)) from None
    _reliability(reliability, result, f"suite {suite}, seed {seed}, {len(result['scans'])} scans")
    _write_json(json_out, result)


def _segmentation_stage(cfg: BenchConfig, scans: list[Path], json_out: Path | None, progress: bool) -> None:
    """``--stage segmentation``: the segmenters of ``cfg`` on the scans, scored alone (`v2c.bench.segmentation`)."""
    from v2c.bench import run
    from v2c.bench import segmentation as S

    result = S.run(
        scans,
        list(cfg.segmentations),
        lambda scan, method: run.segment_scan(scan, method, cfg.weights),
        log=(lambda m: click.echo(m, err=True)) if progress else (lambda m: None),
    )
    click.echo(f"{len(scans)} scans, segmentation alone")
    click.echo(S.format_table(result))
    _write_json(json_out, run.jsonable(result))


def _fit_stage(cfg: BenchConfig, scans: list[Path], json_out: Path | None, progress: bool) -> None:
    """``--stage fit``: the geometry stage alone on oracle segmentation, one thread (`v2c.bench.fit`)."""
    from v2c.bench import fit as F
    from v2c.bench import run

    with F.single_thread():
        result = F.fit_benchmark(scans, cfg.ablations, log=(lambda m: click.echo(m, err=True)) if progress else None)
    click.echo(f"{len(scans)} scans, geometry stage alone (oracle segmentation, one thread)")
    click.echo(F.format_table(result["summary"]))
    _write_json(json_out, run.jsonable(result))


def _vbrep_stage(cfg: BenchConfig, scans: list[Path], json_out: Path | None, progress: bool) -> None:
    """``--stage vbrep``: Chamfer and edge-type accuracy of the reconstruction, per segmentation / ablation and
    per part family (`v2c.bench.vbrep`)."""
    from v2c.bench import run
    from v2c.bench import vbrep as V

    result: dict = {"scans": [str(d) for d in scans], "columns": {}}
    for seg in cfg.segmentations:
        for abl in cfg.ablations:
            rows = []
            for d in scans:
                rows += V.evaluate([str(d)], seg, abl)
                r = rows[-1]
                if progress:
                    click.echo(
                        f"{seg}/{abl} {d.name} {r['family'] or '':8s} chamfer {r['chamfer']:.4f} edge-type acc "
                        f"{r['matched_accuracy']:.3f} (strict {r['accuracy']:.3f}, coverage {r['coverage']:.3f}) "
                        f"{r['t_total']:.1f} s",
                        err=True,
                    )
            fams = sorted({str(r["family"]) for r in rows if r["family"] is not None})
            result["columns"][f"{seg}/{abl}"] = {
                "summary": V.summarize(rows),
                "families": {f: V.summarize([r for r in rows if str(r["family"]) == f]) for f in fams},
                "rows": rows,
            }
    click.echo(f"{len(scans)} scans, VB-Rep metrics")
    click.echo(format_vbrep_table(result))
    _write_json(json_out, run.jsonable(result))


def format_vbrep_table(result: dict) -> str:
    """Markdown table of ``--stage vbrep``: one row per column and family, then the column's mean over scans."""
    lines = [
        "| segmentation/ablation | family | scans | Chamfer (max) | edge-type accuracy | strict accuracy | coverage "
        "| seconds per scan (median) |",
        "|" + " --- |" * 8,
    ]
    for col, c in result["columns"].items():
        for fam, s in [*c["families"].items(), ("**all**", c["summary"])]:
            lines.append(
                f"| {col} | {fam} | {s['scans']} | {s['chamfer']:.4f} ({s['chamfer_max']:.4f}) | "
                f"{100 * s['matched_accuracy']:.1f} % | {100 * s['accuracy']:.1f} % | {100 * s['coverage']:.1f} % | "
                f"{s['t_total_median']:.2f} |"
            )
    return "\n".join(lines)


def _generator_stage(
    stage: str,
    *,
    n: int,
    seed: int,
    noise: str,
    size: tuple[int, int],
    families: str | None,
    json_out: Path | None,
) -> None:
    """``--stage synth`` (`v2c.synth.bench.generator_speed`) or ``parts`` (`v2c.synth.features.measure`)."""
    from v2c.synth.families import FEATURE_FAMILIES

    names = None if families is None else _family_names(stage, families)
    if stage == "synth":
        from v2c.synth.bench import format_speed, generator_speed
        from v2c.synth.dataset import SynthConfig

        cfg = SynthConfig(width=size[0], height=size[1], noise=noise, **({"families": names} if names else {}))
        result = generator_speed(cfg, n, seed)
        click.echo(format_speed(result))
    else:
        from v2c.synth.features import measure

        result = measure(n, seed, names or FEATURE_FAMILIES)
        click.echo(format_parts(result))
    _write_json(json_out, result)


def _family_names(stage: str, families: str) -> tuple[str, ...]:
    """``--families``: names or groups (`v2c.synth.families.FAMILY_GROUPS`), comma-separated, expanded; a usage
    error naming what the stage does not know."""
    from v2c.synth.families import FAMILY_GROUPS, FEATURE_FAMILIES, PROCEDURAL_FAMILIES

    known = FEATURE_FAMILIES if stage == "parts" else (*PROCEDURAL_FAMILIES, *FEATURE_FAMILIES)
    given = [f.strip() for f in families.split(",") if f.strip()]
    names = tuple(dict.fromkeys(f for v in given for f in FAMILY_GROUPS.get(v, (v,))))
    bad = [f for f in names if f not in known]
    if bad or not names:
        raise click.BadParameter(
            f"{', '.join(bad) or 'nothing'}: --stage {stage} takes {', '.join(known)} or a group "
            f"{', '.join(FAMILY_GROUPS)}",
            param_hint="--families",
        )
    return names


def _fixtures_stage(
    *,
    n: int | None,
    suite: str | None,
    seed: int,
    noise: str,
    size: tuple[int, int],
    families: tuple[str, ...],
    segmentation: str,
    weights: Path | None,
    clearance_k: str | None,
    kinds: str | None,
    cache_dir: Path | None,
    json_out: Path | None,
    progress: bool,
) -> None:
    """``--stage fixtures``: `v2c.bench.fixtures.run` on --n scans of --families, or on a corpus split's scans
    (``--suite corpus-train`` / ``corpus-val`` / ``unseen``: the first --n, or every one)."""
    from v2c.bench import fixtures as F
    from v2c.bench import run

    extra: dict = {}
    if kinds is not None:
        chosen = tuple(dict.fromkeys(k.strip() for k in kinds.split(",") if k.strip()))
        wrong = [k for k in chosen if k not in F.KINDS]
        if wrong or not chosen:
            raise click.BadParameter(
                f"{kinds!r}: expected kinds from {', '.join(F.KINDS)}, comma-separated", param_hint="--fixture-kinds"
            )
        extra["kinds"] = chosen
    if clearance_k is not None:
        try:
            ks = tuple(dict.fromkeys(float(k) for k in clearance_k.split(",") if k.strip()))
            if not ks or min(ks) < 0:
                raise ValueError
        except ValueError:
            raise click.BadParameter(
                f"{clearance_k!r}: expected numbers >= 0, comma-separated (e.g. 0,1,2)", param_hint="--clearance-k"
            ) from None
        extra["clearance_k"] = ks
    cfg = F.FixtureBenchConfig(
        n=n,
        suite=suite,
        seed=seed,
        families=families,
        noise=noise,
        size=size,
        segmentation=segmentation,
        weights=weights,
        cache_dir=cache_dir,
        **extra,
    )
    result = F.run(cfg, F.stderr_log if progress else None)
    sha = result["weights_sha1"]
    what = f"the {suite} split's corpus parts" if suite else ", ".join(families)
    click.echo(
        f"{result['scans']} scans of {what} ({result['failed_scans']} failed), seed {seed}, {noise} "
        f"noise, {size[0]}x{size[1]}, segmentation {segmentation}"
        + (f" (weights sha1 {sha[:10]})" if segmentation == "learned" and sha else "")
    )
    click.echo(F.format_table(result))
    _write_json(json_out, run.jsonable(result))


def format_parts(r: dict) -> str:
    """Lines of a `v2c.synth.features.measure` result: valid share, speed, features applied and skipped."""
    kinds = ", ".join(f"{k} {c}" for k, c in r["kinds"].items())
    skipped = ", ".join(f"{k} {c}" for k, c in r["features_skipped"].items()) or "none"
    return "\n".join(
        [
            f"{r['parts']} parts: {r['valid']} valid ({100 * r['valid_share']:.1f} %), {r['parts_per_cpu_s']:.2f} "
            f"parts per CPU second, {r['parts_per_wall_s']:.2f} per wall second, {r['mean_features']:.2f} "
            "features per part",
            f"valid per family: {', '.join(f'{k} {c}' for k, c in r['valid_per_family'].items())}",
            f"features applied ({r['features_applied']}): {kinds}",
            f"features skipped: {skipped}",
        ]
    )


def check_json_output(path: Path | None, force: bool) -> None:
    """Refuse (`v2c.errors.OutputError`) a --json file that exists and that v2c did not write, unless ``force``."""
    if path is not None:
        from v2c.io_safe import check_replaceable

        check_replaceable(path, force)


def _write_json(path: Path | None, data: dict) -> None:
    """Write ``data`` atomically, its first key ``generator`` (the mark by which v2c knows the file as its own)."""
    if path is None:
        return
    from v2c.io_safe import v2c_origin, write_text_atomic

    marked = {"generator": f"{v2c_origin()} bench", **{k: v for k, v in data.items() if k != "generator"}}
    write_text_atomic(path, json.dumps(marked, indent=1, allow_nan=False) + "\n")
    click.echo(f"wrote {path}")
