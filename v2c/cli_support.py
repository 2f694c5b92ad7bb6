"""What every `v2c` command shares: the error policy, SIGINT, logging levels (``-v``/``-q`` on the group and on
every sub-command, `verbosity_options`), the output-path rule (`output_file`) and the scan-limit option.

Error policy: a `v2c.errors.V2cError` (bad input, an output that cannot be written) and a
`click.ClickException` print ``error: <message>`` and exit 1; Ctrl-C prints ``interrupted`` and exits 130
(whatever was in flight: a SIGINT inside a C extension's import can surface as an ImportError, so a flag set
by our own handler decides); any other exception is a bug of v2c, printed as one line that says so, with
the traceback only under ``-v``. No input makes a traceback.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import click

log = logging.getLogger("v2c")

#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130

_interrupted = False


def was_interrupted() -> bool:
    """True once SIGINT arrived while a `v2c` command ran (see `sigint_flag`)."""
    return _interrupted


def _on_sigint(signum: int, frame: Any) -> None:
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


@contextlib.contextmanager
def sigint_flag() -> Iterator[None]:
    """Inside the block SIGINT sets the flag of `was_interrupted` and raises KeyboardInterrupt as usual."""
    global _interrupted
    _interrupted = False
    try:
        old = signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:  # not the main thread: keep Python's default handler
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def ignore_sigint_from_now_on() -> None:
    """Ignore SIGINT for the rest of the process (after the command finished; only from the main thread)."""
    with contextlib.suppress(ValueError):
        signal.signal(signal.SIGINT, signal.SIG_IGN)


class _BarSafeHandler(logging.StreamHandler):
    """Log lines go above a running tqdm progress bar (`tqdm.write`) instead of through it."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            from tqdm import tqdm

            tqdm.write(self.format(record), file=self.stream)
        except Exception:  # noqa: BLE001 - logging must never raise
            self.handleError(record)


def configure_logging(verbose: int, quiet: bool) -> None:
    """Log level of the ``v2c`` loggers on stderr: INFO (stage progress) by default when stderr is a terminal,
    WARNING when it is not (pipes, logs, tests); INFO with -v, DEBUG with -vv, ERROR with -q."""
    default = logging.INFO if sys.stderr.isatty() else logging.WARNING
    level = logging.ERROR if quiet else {0: default, 1: logging.INFO}.get(verbose, logging.DEBUG)
    handler = _BarSafeHandler(sys.stderr)
    handler.setFormatter(logging.Formatter("%(message)s" if verbose < 2 else "%(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger("v2c")
    root.handlers[:] = [handler]
    root.setLevel(level)
    root.propagate = False


_VERBOSITY = "v2c.verbosity"


def _set_verbosity(ctx: click.Context, param: click.Parameter, value: int | bool) -> None:
    if not value:  # not given on this command: the group's -v / -q (or the default) stay
        return
    state = ctx.meta.setdefault(_VERBOSITY, {})
    state[param.name] = value
    configure_logging(int(state.get("verbose", 0)), bool(state.get("quiet", False)))


def verbosity_options(f: Callable) -> Callable:
    """``-v/--verbose`` (repeatable) and ``-q/--quiet`` on a sub-command: the same as ``v2c -v`` / ``v2c -q``
    before it (``v2c -q bench`` = ``v2c bench -q``). ``-q`` also hides progress bars (`quiet`)."""
    f = click.option(
        "-q",
        "--quiet",
        is_flag=True,
        expose_value=False,
        callback=_set_verbosity,
        help="Only errors on stderr: no progress bar, no stage messages, no warnings (as `v2c -q`).",
    )(f)
    return click.option(
        "-v",
        "--verbose",
        count=True,
        expose_value=False,
        callback=_set_verbosity,
        help="More messages on stderr: -v progress, -vv debug (as `v2c -v`).",
    )(f)


def quiet() -> bool:
    """True under ``-q`` (the group's or the command's): show no progress bar."""
    return logging.getLogger("v2c").level >= logging.ERROR


def output_file(value: str | Path | None, default_name: str) -> Path | None:
    """Where a one-file output goes for ``-o VALUE``: VALUE itself, or ``VALUE/default_name`` when VALUE ends
    with a path separator (``-o new/``: the folder is made) or is an existing folder."""
    if value is None:
        return None
    text = str(value)
    if text.endswith(("/", os.sep)) or Path(text).is_dir():
        return Path(text) / default_name
    return Path(text)


def run_with_error_policy(invoke: Callable[[], Any]) -> int:
    """Run ``invoke`` (click's non-standalone main) under the error policy of this module; the exit status."""
    from v2c.errors import V2cError

    with sigint_flag():
        try:
            rv = invoke()
        except (KeyboardInterrupt, click.exceptions.Abort):
            click.echo("interrupted", err=True)
            return EXIT_INTERRUPTED
        except click.exceptions.Exit as e:
            return int(e.exit_code)
        except click.UsageError as e:  # usage line + "Error: ..." as click prints it, exit 2
            e.show()
            return int(e.exit_code)
        except click.ClickException as e:
            if was_interrupted():
                click.echo("interrupted", err=True)
                return EXIT_INTERRUPTED
            click.echo(f"error: {e.format_message()}", err=True)
            return int(e.exit_code)
        except V2cError as e:
            click.echo(f"error: {e}", err=True)
            return 1
        except Exception as e:  # the last line of defence: never a traceback for the user
            if was_interrupted():
                click.echo("interrupted", err=True)
                return EXIT_INTERRUPTED
            log.debug("traceback of the internal error:", exc_info=True)
            click.echo(f"error: {describe_error(e)}", err=True)
            return 1
    return rv if isinstance(rv, int) else 0


def describe_error(e: BaseException, where: object = None) -> str:
    """One line for an exception: a `V2cError`'s own message; a file-system error's file and reason; anything
    else is a bug of v2c and is called one (``where``: the scan or file it happened on)."""
    from v2c.errors import V2cError

    if isinstance(e, V2cError):
        return str(e)
    if isinstance(e, OSError) and e.filename:
        return f"{e.filename}: {e.strerror or type(e).__name__}"
    at = f"{where}: " if where is not None else ""
    return f"{at}internal error of v2c ({type(e).__name__}: {str(e)[:200]}); please report it (-vv shows the traceback)"


def _parse_roi(ctx: click.Context, param: click.Parameter, value: str | None) -> tuple[int, int, int, int] | None:
    from v2c.scan import ScanError, parse_roi

    try:
        return parse_roi(value)
    except ScanError as e:
        raise click.BadParameter(str(e), ctx=ctx, param=param) from None


def roi_option(f: Callable) -> Callable:
    """``--roi x0,y0,x1,y1``: the region of interest in pixels (x1/y1 exclusive), passed as ``roi``."""
    return click.option(
        "--roi",
        callback=_parse_roi,
        default=None,
        metavar="x0,y0,x1,y1",
        help="Region of interest in pixels (x1, y1 exclusive); restricts the valid pixels. A real "
        "frame needs it or a mask.png.",
    )(f)


def _set_max_pixels(ctx: click.Context, param: click.Parameter, value: int | None) -> None:
    from v2c.scan_checks import scan_limits

    if value is not None:
        ctx.with_resource(scan_limits(max_pixels=value))


def max_pixels_option(f: Callable) -> Callable:
    """``--max-pixels N``: admit images of up to N pixels (width x height) for the rest of the command."""
    from v2c.scan_checks import ScanLimits

    return click.option(
        "--max-pixels",
        type=click.IntRange(min=1),
        default=None,
        expose_value=False,
        callback=_set_max_pixels,
        metavar="N",
        help=f"Largest image in pixels (width x height) to accept; default "
        f"{ScanLimits.max_pixels:,} (2.1 megapixels: 1920x1080 fits).",
    )(f)
