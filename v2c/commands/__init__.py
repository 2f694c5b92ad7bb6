"""Sub-commands of `v2c`; each module defines `command` (a click command). Heavy imports go inside the function.

`executor_options` and `jobs_option` add the options of the batch commands (to-step, synth, bench, train) that say
where their one-task-per-scan work runs and how much of it at once (`v2c.executors`, docs/scale.md). The flags
every command shares, and what they mean, are in docs/cli.md (tests/test_cli_flags.py checks them). `pick_options`
adds ``--pick`` and ``--point`` to the commands that read a scan (with ``--roi``; `v2c.pick`), `frame_index_option`
``--frame-index`` (which frame of a recording, `v2c.recordings`)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from v2c.choices import ABLATIONS, DEFAULT_ABLATION, DEFAULT_SEGMENTATION, SEGMENTATION_METHODS


def executor_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """Add ``--executor local|ray`` and ``--ray-address`` (parameters ``executor`` and ``ray_address``)."""
    f = click.option(
        "--ray-address",
        "ray_address",
        default=None,
        metavar="auto|HOST:PORT",
        help="Ray cluster to run on with --executor ray: 'auto' = the one `ray start` runs on this "
        "machine, HOST:PORT = its head node [default: $RAY_ADDRESS, else a new local instance].",
    )(f)
    return click.option(
        "--executor",
        type=click.Choice(["local", "ray"]),
        default="local",
        show_default=True,
        help="Where the per-scan tasks run: local processes, or a Ray cluster (needs "
        "`pip install 'v2c[ray]'`; docs/scale.md).",
    )(f)


#: ``--jobs`` of every batch command when not given: one worker process (locally; the whole cluster on Ray).
DEFAULT_JOBS = 1


def jobs_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--jobs N``: worker processes, one default for every batch command (`DEFAULT_JOBS`)."""
    return click.option(
        "--jobs",
        default=DEFAULT_JOBS,
        show_default=True,
        type=click.IntRange(1),
        help="Worker processes (one thread each); with --executor ray: most scans in flight "
        "[default there: the whole cluster].",
    )(f)


def executor_config(executor: str, ray_address: str | None, jobs: int | None = 1, jobs_given: bool = True) -> Any:
    """The `v2c.executors.ExecutorConfig` of the options; on Ray an unset --jobs means the whole cluster.

    Raises click.UsageError for --ray-address without --executor ray, ClickException when Ray is missing."""
    from v2c.executors import ExecutorConfig, ExecutorError, ray_module

    if executor != "ray":
        if ray_address is not None:
            raise click.UsageError("--ray-address needs --executor ray")
        return ExecutorConfig(kind="local", jobs=jobs)
    try:
        ray_module()  # fail before any work, with the install hint
    except ExecutorError as e:
        raise click.ClickException(str(e)) from None
    return ExecutorConfig(kind="ray", address=ray_address, jobs=jobs if jobs_given else None)


def jobs_given(ctx: click.Context, name: str = "jobs") -> bool:
    """Whether the user set the option ``name`` (rather than leaving its default)."""
    return ctx.get_parameter_source(name) not in (None, click.core.ParameterSource.DEFAULT)


def segmentation_option(dest: str = "segmentation") -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``--segmentation`` as every reconstructing command takes it: one list of methods, one default
    (`v2c.choices`); the value reaches the command's ``dest`` parameter."""
    return click.option(
        "--segmentation",
        dest,
        default=DEFAULT_SEGMENTATION,
        show_default=True,
        type=click.Choice(SEGMENTATION_METHODS),
        help="Where the surface instances come from (oracle needs a synthetic scan's gt/).",
    )


def ablation_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--ablation``: the geometry stage's ablation of the paper's Table 2 (`v2c.choices.ABLATIONS`)."""
    return click.option(
        "--ablation",
        default=DEFAULT_ABLATION,
        show_default=True,
        type=click.Choice(ABLATIONS),
        help="full: shared axis frame + intersection refinement; no-axis / no-int drop one; fit-only both.",
    )(f)


def _parse_point(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[int, int] | None:
    from v2c.pick import PickError, parse_point

    try:
        return parse_point(value)
    except PickError as e:
        raise click.BadParameter(str(e), ctx=ctx, param=param) from None


def pick_options(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--pick auto|centre|none`` and ``--point X,Y`` on a command that reads a scan (and has ``--roi``): the
    command body runs inside `v2c.pick.pick_request`, so `v2c.scan.load_scan` picks the object of a cluttered frame
    that has no mask.png and no ROI. --point or --pick centre together with --roi is a usage error."""

    @functools.wraps(f)
    def run(*args: Any, pick: str, point: tuple[int, int] | None, **kwargs: Any) -> Any:
        from v2c.pick import PickRequest, pick_request

        if kwargs.get("roi") is not None and (point is not None or pick == "centre"):
            raise click.UsageError("--roi and --point/--pick centre both say where the part is: give one")
        with pick_request(PickRequest(mode=pick, point=point)):
            return f(*args, **kwargs)

    run = click.option(
        "--point",
        callback=_parse_point,
        default=None,
        metavar="X,Y",
        help="Pick the object under this pixel (column, row) of a frame with no mask.png and no --roi: the "
        "support plane is dropped and the depth-connected object there becomes the mask.",
    )(run)
    return click.option(
        "--pick",
        type=click.Choice(["auto", "centre", "none"]),
        default="auto",
        show_default=True,
        help="A frame with no mask.png and no --roi: auto = pick the object under the image centre (or --point) "
        "when the frame is a large scene on a support plane; centre = always; none = the whole frame.",
    )(run)


def _set_frame_index(ctx: click.Context, param: click.Parameter, value: int | None) -> None:
    from v2c.recordings import recording_frame

    if value is not None:
        ctx.with_resource(recording_frame(value))


def frame_index_option(f: Callable[..., Any]) -> Callable[..., Any]:
    """``--frame-index N``: which colour+depth pair of a recording (a .bag given as SCAN) to read, for the rest of
    the command (`v2c.recordings.recording_frame`); not ``--frame``, which is to-step's output frame."""
    return click.option(
        "--frame-index",
        type=click.IntRange(min=0),
        default=None,
        expose_value=False,
        callback=_set_frame_index,
        metavar="N",
        help="SCAN is a recording (.bag): read its N-th complete colour+depth pair [default: 0, the first].",
    )(f)


def output_folder_options(what: str) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """``-o/--output/--out FOLDER`` (parameter ``out``, a `Path`, required) and ``--force`` for a command that
    writes a set of ``what`` (e.g. "shards") into a folder; `refuse_to_replace` checks them."""

    def wrap(f: Callable[..., Any]) -> Callable[..., Any]:
        f = click.option("--force", is_flag=True, help=f"Write into a folder that already holds {what} (replaced).")(f)
        return click.option(
            "-o",
            "--output",
            "--out",
            "out",
            required=True,
            type=click.Path(file_okay=False, path_type=Path),
            help=f"Folder for the {what} (made when missing).",
        )(f)

    return wrap


def refuse_to_replace(out: Path, pattern: str, what: str, force: bool) -> None:
    """Stop (click error) when ``out`` already holds files matching ``pattern`` and ``force`` is not given."""
    if not force and out.is_dir() and any(out.glob(pattern)):
        raise click.ClickException(f"{out}: holds {what}; pass --force to replace them (or choose another -o)")
