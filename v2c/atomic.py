"""Atomic outputs: each file or folder is written under an exclusive temporary name in its destination folder and
renamed into place, so a reader (or a retried task) never sees a half-written output.

The temporary name is keyed by the final name: ``.<name>.v2c-tmp-<pid>-<token><suffix>`` (the suffix is kept,
since OpenCV and OCCT choose the format by it). A writer first removes what earlier, killed attempts at the same
output left under such names (`sweep`), so a task that is retried after its process died leaves no stray files.
One writer per output at a time is assumed (one task per scan).
"""

from __future__ import annotations

import contextlib
import glob
import os
import secrets
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path

#: Marker inside every temporary name (files and folders).
TMP_TAG = ".v2c-tmp-"


def temp_name(final: str | Path, suffix: str | None = None) -> Path:
    """A fresh temporary name next to ``final``, unique to this process and call, ending in ``suffix`` (default:
    the suffix of ``final``)."""
    final = Path(final)
    suffix = final.suffix if suffix is None else suffix
    return final.with_name(f".{final.name}{TMP_TAG}{os.getpid()}-{secrets.token_hex(4)}{suffix}")


def sweep(final: str | Path) -> list[Path]:
    """Remove the temporary files / folders that earlier attempts at ``final`` left behind; returns them."""
    final = Path(final)
    left = [Path(p) for p in glob.glob(str(final.with_name(f".{glob.escape(final.name)}{TMP_TAG}*")))]
    for p in left:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                p.unlink()
    return left


@contextlib.contextmanager
def atomic_file(final: str | Path, suffix: str | None = None) -> Iterator[Path]:
    """Yield an exclusive temporary path next to ``final`` to write (ending in ``suffix``, default that of
    ``final``: writers that pick the format by it need one); on success it is renamed onto ``final`` (replacing
    it), on an exception it is removed and the exception re-raised."""
    final = Path(final)
    sweep(final)
    tmp = temp_name(final, suffix)
    with open(tmp, "x"):  # claim the name exclusively; the writer then overwrites the empty file
        pass
    try:
        yield tmp
        os.replace(tmp, final)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


@contextlib.contextmanager
def atomic_dir(final: str | Path, last: Sequence[str] = ()) -> Iterator[Path]:
    """Yield a fresh temporary folder next to ``final`` to fill; on success it becomes ``final``.

    A missing ``final`` is replaced by one rename (the folder appears complete or not at all). An existing one is
    updated file by file (each an atomic rename; files of it that the new content lacks are kept), with the
    relative paths in ``last`` moved last (completion markers). On an exception the temporary folder is removed.
    """
    final = Path(final)
    final.parent.mkdir(parents=True, exist_ok=True)
    sweep(final)
    tmp = temp_name(final)
    tmp.mkdir()
    try:
        yield tmp
        try:
            os.rename(tmp, final)
        except OSError:  # final exists (and is not empty): merge into it
            if not final.is_dir():
                raise
            _merge(tmp, final, last)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _merge(src: Path, dst: Path, last: Sequence[str]) -> None:
    files = sorted(p.relative_to(src).as_posix() for p in src.rglob("*") if not p.is_dir())
    files = [f for f in files if f not in last] + [f for f in last if f in files]
    for rel in files:
        target = dst / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(src / rel, target)
