"""`v2c synth OUT`: generate synthetic RGB-D scans with exact ground truth (SCAN_FORMAT.md layout)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING

import click

from v2c.cli_support import quiet, verbosity_options
from v2c.commands import executor_config, executor_options, jobs_given
from v2c.synth.families import FAMILY_GROUPS, FEATURE_FAMILIES, PROCEDURAL_FAMILIES

if TYPE_CHECKING:
    from v2c.synth.dataset import SynthConfig

PROCEDURAL = PROCEDURAL_FAMILIES  # today's default mix
KNOWN_FAMILIES = (*PROCEDURAL_FAMILIES, *FEATURE_FAMILIES, "cad")
NOISE_PROFILES = ("sensor", "paper", "none", "structured_light")
SCAN_NAME = re.compile(r"^scan_\d{5,}$")  # v2c.synth.dataset.scan_name


def _parse_size(ctx: click.Context, param: click.Parameter, value: str) -> tuple[int, int]:
    try:
        w, h = (int(x) for x in value.lower().split("x"))
    except ValueError:
        raise click.BadParameter(f"{value!r} is not WIDTHxHEIGHT (e.g. 640x480)", ctx=ctx, param=param) from None
    if not (16 <= w <= 4096 and 16 <= h <= 4096):
        raise click.BadParameter(f"{value!r}: width and height must be 16..4096 pixels", ctx=ctx, param=param)
    return w, h


def _parse_families(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[str, ...] | None:
    if value is None:
        return None
    given = [v.strip() for v in value.split(",") if v.strip()]
    unknown = [v for v in given if v not in KNOWN_FAMILIES and v not in FAMILY_GROUPS]
    if unknown or not given:
        raise click.BadParameter(
            f"unknown family {', '.join(unknown) or '(none)'}; choose from "
            f"{', '.join(KNOWN_FAMILIES)} or a group {', '.join(FAMILY_GROUPS)}",
            ctx=ctx,
            param=param,
        )
    # Groups expand in place; a family named twice is drawn once (order kept: it fixes which family a draw picks).
    return tuple(dict.fromkeys(f for v in given for f in FAMILY_GROUPS.get(v, (v,))))


def _differences(folder: Path, seed: int, cfg: SynthConfig) -> list[str]:
    """How the complete scan ``folder`` (its gt/meta.json and camera.json) differs from scans of run ``seed``
    with config ``cfg``: "seed 1, not 0", ...; [] when it could be one."""
    from v2c.synth.appearance import FRAMING_VERSION
    from v2c.synth.dataset import GENERATOR

    try:
        meta = json.loads((folder / "gt" / "meta.json").read_text(encoding="utf-8"))
        camera = json.loads((folder / "camera.json").read_text(encoding="utf-8"))
        have = {
            "generator": meta["generator"],
            "seed": meta["seed"],
            "size": f"{camera['width']}x{camera['height']}",
            "noise": meta["noise"]["profile"],
            "appearance": meta.get("appearance", {}).get("mode", "plain"),
            "framing": meta.get("framing", {}).get("mode", "fill"),
            "framing version": meta.get("framing", {}).get("version", 1),
        }
        family = meta["family"]
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError):
        return ["its gt/meta.json or camera.json cannot be read"]
    want = {
        "generator": GENERATOR,
        "seed": seed,
        "size": f"{cfg.width}x{cfg.height}",
        "noise": cfg.noise,
        "appearance": cfg.appearance,
        "framing": cfg.framing,
        # only between two extent framings (a fill scan has none; a different mode is said above)
        "framing version": FRAMING_VERSION if cfg.framing == "extent" == have["framing"] else have["framing version"],
    }
    out = [f"{key} {have[key]}, not {want[key]}" for key in want if have[key] != want[key]]
    if family not in cfg.families:
        out.append(f"family {family}, not one of {','.join(cfg.families)}")
    return out


def _refuse_another_run(out: Path, seed: int, cfg: SynthConfig) -> None:
    """ClickException when ``out`` already holds scans of another run (seed, size, noise, families, look):
    adding to them would mix two sets. The first and the last complete scan are looked at (a run writes one
    config; a resumed or extended run of the same config passes)."""
    try:
        scans = sorted((p for p in out.iterdir() if SCAN_NAME.match(p.name)), key=lambda p: int(p.name[5:]))
    except OSError:  # no folder yet (or not readable: generating into it will say why)
        return
    first = next((p for p in scans if (p / "gt" / "meta.json").is_file()), None)  # the marker of a complete scan
    last = next((p for p in reversed(scans) if (p / "gt" / "meta.json").is_file()), None)
    for folder in dict.fromkeys(p for p in (first, last) if p is not None):
        diff = _differences(folder, seed, cfg)
        if diff:
            raise click.ClickException(
                f"{out}: holds scans of another run ({folder.name}: {'; '.join(diff)}); adding to them would mix "
                "two sets: choose another folder, or pass --force to add to it anyway"
            )


@click.command("synth")
@click.argument("out", type=click.Path(file_okay=False, path_type=Path))
@click.option("--n", "n", type=click.IntRange(min=1), default=10, show_default=True, help="Number of scans.")
@click.option(
    "--seed",
    type=int,
    default=0,
    show_default=True,
    help="Run seed; scan i depends on (seed, i) only, so a seed always gives the same files.",
)
@click.option(
    "--noise",
    type=click.Choice(NOISE_PROFILES),
    default="sensor",
    show_default=True,
    help="Depth noise profile (BENCHMARK.md).",
)
@click.option("--size", default="640x480", show_default=True, callback=_parse_size, help="Image size WxH (pixels).")
@click.option(
    "--cad",
    type=click.Path(exists=True, path_type=Path),
    default=None,
    help="Directory of STEP files (or one STEP file) added as the part family 'cad'.",
)
@click.option(
    "--families",
    default=None,
    callback=_parse_families,
    help=f"Comma-separated part families to draw from: {', '.join(KNOWN_FAMILIES)}, or groups: "
    "procedural (the six above), features (the feature-based training families), train (all "
    "training families), leave-out (never for training: feat_hex, feat_knob, feat_block) "
    "[default: the procedural ones, plus cad with --cad].",
)
@click.option(
    "--jobs",
    type=click.IntRange(min=1),
    default=1,
    show_default=True,
    help="Worker processes (with --executor ray: most scans in flight, default the whole cluster).",
)
@click.option(
    "--start",
    type=click.IntRange(min=0),
    default=0,
    show_default=True,
    help="Index of the first scan (extends a set: scans start..start+n-1).",
)
@click.option(
    "--png-compression",
    type=click.IntRange(0, 9),
    default=1,
    show_default=True,
    help="PNG compression level (9 = smallest files, slower).",
)
@click.option(
    "--preview",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write a PNG with color | depth | labels of the first (up to 4) scans.",
)
@click.option(
    "--print-share",
    type=click.FloatRange(0.0, 1.0),
    default=0.0,
    show_default=True,
    help="Share of scans whose part carries a printed (packaging-like) texture.",
)
@click.option(
    "--appearance",
    type=click.Choice(["plain", "random"]),
    default="plain",
    show_default=True,
    help="random: random, dark and shiny materials, printed art inside faces, clutter beside the part, "
    "textured backgrounds, lights and exposure (docs/synth.md); labels and part depth unchanged.",
)
@click.option(
    "--framing",
    type=click.Choice(["fill", "extent"]),
    default=None,
    help="fill: the bounding sphere fills 0.3-0.7 of the image (as before); extent: the part's extent is "
    "30-70 % of the smaller image side (SCAN_FORMAT.md).  [default: extent with --appearance "
    "random, else fill]",
)
@click.option(
    "--force",
    is_flag=True,
    help="Write into OUT even when it holds scans of another run (other seed, size, noise, families or look).",
)
@verbosity_options
@executor_options
@click.pass_context
def command(
    ctx: click.Context,
    out: Path,
    n: int,
    seed: int,
    noise: str,
    size: tuple[int, int],
    cad: Path | None,
    families: tuple[str, ...] | None,
    jobs: int,
    start: int,
    png_compression: int,
    preview: Path | None,
    print_share: float,
    appearance: str,
    framing: str | None,
    force: bool,
    executor: str,
    ray_address: str | None,
) -> None:
    """Render N synthetic scans of random CAD parts into OUT/scan_XXXXX (color, depth, camera, mask, gt/).

    Each scan is written to a temporary folder and renamed into place. OUT may hold scans of the same run
    (same seed, size, noise, families and look: a resumed or extended run); scans of another run are refused
    unless --force. With --executor ray every scan is one Ray
    task writing into OUT itself: OUT (and --cad) must be on a file system every node shares."""
    from v2c.executors import ExecutorError
    from v2c.synth.dataset import SynthConfig, SynthError, generate_dataset
    from v2c.synth.parts import list_cad_files
    from v2c.synth.scene import SceneConfig

    cad_files: tuple[str, ...] = ()
    if cad is not None:
        files = [cad] if cad.is_file() else list_cad_files(cad)
        if not files:
            raise click.ClickException(f"{cad}: no STEP files (*.step, *.stp) found")
        cad_files = tuple(str(f.resolve()) for f in files)
    if families is None:
        families = PROCEDURAL + (("cad",) if cad_files else ())
    if "cad" in families and not cad_files:
        raise click.ClickException("family 'cad' needs --cad DIR")
    cfg = SynthConfig(
        width=size[0],
        height=size[1],
        noise=noise,
        families=families,
        cad_files=cad_files,
        png_compression=png_compression,
        scene=SceneConfig(print_share=print_share),
        appearance=appearance,
        framing=framing or ("extent" if appearance == "random" else "fill"),
    )
    if not force:
        _refuse_another_run(out, seed, cfg)
    where = executor_config(executor, ray_address, jobs, jobs_given(ctx))
    try:
        folders = generate_dataset(out, n, seed, cfg, jobs=jobs, progress=not quiet(), start=start, executor=where)
    except (ExecutorError, SynthError) as e:
        raise click.ClickException(str(e)) from None
    if preview is not None:
        from v2c.synth.preview import write_preview

        write_preview(folders[:4], preview)
    if not quiet():
        click.echo(f"wrote {len(folders)} scans to {out}")
