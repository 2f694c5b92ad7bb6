"""Safe outputs: temporary files created exclusively in the destination folder, renamed into place, and sets of
files (STEP + VB-Rep JSON + figure) committed together.

Every file v2c writes goes through here (`atomic_write` for one file, `OutputSet` for several):

- a temporary is made by `tempfile.mkstemp` in the destination's own folder: ``O_CREAT | O_EXCL``, a random
  name, never following a symlink planted under a temporary-looking name, never colliding with a concurrent
  writer;
- the finished temporary is renamed over the destination (`os.replace`: atomic within a folder; a symlink at the
  destination is replaced, never followed), so a reader sees the complete old file or the complete new one;
- an `OutputSet` renames its files in a fixed order with SIGINT held back, after hard-linking the old files
  aside; if any rename fails, the old files are put back, so the folder holds the complete old set or the
  complete new set. On any failure before the commit the temporaries (and folders this set created) are
  removed and the old files were never touched.

Ownership: `v2c` never replaces a file it did not write unless asked to (``--force``; `OutputSet(force=False)`).
Its files say who wrote them: a STEP's FILE_NAME names ``v2c`` as the originating system, a figure PNG carries
the text chunk ``Software: v2c``, a binary STL's header starts with ``v2c``, a JSON starts with
``"format": "v2c.vbrep"`` or ``"generator": "v2c ..."`` (`written_by_v2c`).

A SIGKILL or power loss leaves the old set and possibly hidden temporaries ``.<stem>.<pid>.<random>.tmp<suffix>``;
the next write of the same file removes those whose process is gone (`sweep_stale_temporaries`). The one window
left is a SIGKILL between two renames of one set (a few microseconds): no single-folder rename sequence can close
it.
"""

from __future__ import annotations

import contextlib
import os
import re
import signal
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path
from types import TracebackType
from typing import Self

from v2c.errors import OutputError

#: The mark of a v2c output: STEP originating system, PNG "Software" text, JSON "generator" prefix.
V2C_MARK = "v2c"
#: How many leading bytes of a file `written_by_v2c` reads (the STEP header, the PNG text chunk, the JSON head).
_HEAD_BYTES = 4096


def v2c_origin() -> str:
    """The originating-system / generator text of this v2c: ``"v2c <version>"``."""
    from v2c.version import version

    return f"{V2C_MARK} {version()}"


def written_by_v2c(path: str | Path) -> bool:
    """True when ``path`` is a regular file carrying v2c's mark (module docstring); False for anything else,
    symlinks included."""
    path = Path(path)
    if path.is_symlink() or not path.is_file():
        return False
    try:
        with open(path, "rb") as fp:
            head = fp.read(_HEAD_BYTES)
    except OSError:
        return False
    if head.startswith(b"ISO-10303-21"):
        end = head.find(b"ENDSEC;")
        return f"'{V2C_MARK} ".encode() in head[: end if end > 0 else None]
    if path.suffix.lower() == ".stl":  # a binary STL's 80-byte header: "v2c <version> fixture"
        return head.startswith(V2C_MARK.encode() + b" ")
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return b"tEXtSoftware\x00" + V2C_MARK.encode() in head
    # a JSON whose first key says so: {"format": "v2c.vbrep", ...} or {"generator": "v2c <version> ...", ...}
    return re.match(rb'\s*\{\s*"(format|generator)"\s*:\s*"' + V2C_MARK.encode() + rb"[. ]", head) is not None


def check_replaceable(dest: str | Path, force: bool = False) -> None:
    """OutputError unless ``dest`` is free, or a file v2c wrote, or ``force`` (never a folder)."""
    dest = Path(dest)
    if dest.is_dir() and not dest.is_symlink():
        raise OutputError(f"{dest}: cannot write the output: a folder of that name is in the way")
    if os.path.lexists(dest) and not force and not written_by_v2c(dest):
        what = "a symlink" if dest.is_symlink() else "a file that v2c did not write"
        raise OutputError(f"{dest}: exists and is {what}; pass --force to replace it (or choose another -o)")


def _describe(e: OSError) -> str:
    return e.strerror or type(e).__name__


def make_dirs(folder: Path) -> list[Path]:
    """Create ``folder`` and missing parents; the folders created, outermost first. OutputError when a parent is
    a file or not writable."""
    folder = Path(folder)
    missing = []
    p = folder
    while not p.exists() and p != p.parent:
        if os.path.lexists(p):  # a broken symlink where a folder should go
            raise OutputError(f"{p}: cannot create the output folder (a broken symlink is in the way)")
        missing.append(p)
        p = p.parent
    if p.exists() and not p.is_dir():
        raise OutputError(f"{p}: cannot write into it: it is a file, not a folder")
    for q in reversed(missing):
        try:
            q.mkdir()
        except FileExistsError:  # a concurrent writer made it
            if not q.is_dir():
                raise OutputError(f"{q}: cannot create the output folder (a file is in the way)") from None
        except OSError as e:
            raise OutputError(f"{q}: cannot create the output folder ({_describe(e)})") from None
    return list(reversed(missing))


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


def sweep_stale_temporaries(dest: Path) -> list[Path]:
    """Remove temporaries of ``dest`` left by a v2c process that no longer runs (killed with SIGKILL, power
    loss): ``.<stem>.<pid>.<random>.tmp<suffix>`` in its folder whose pid is gone. Never follows a symlink (one
    planted under such a name is removed as a link). Returns what was removed."""
    dest = Path(dest)
    pattern = re.compile(rf"^\.{re.escape(dest.stem)}\.(\d+)\.[^/]+\.tmp{re.escape(dest.suffix)}$")
    removed = []
    try:
        entries = list(os.scandir(dest.parent))
    except OSError:
        return removed
    for entry in entries:
        m = pattern.match(entry.name)
        if m and int(m.group(1)) != os.getpid() and not _pid_alive(int(m.group(1))):
            with contextlib.suppress(OSError):
                os.unlink(entry.path)
                removed.append(Path(entry.path))
    return removed


def temp_path(dest: Path) -> Path:
    """A new, empty, exclusively created temporary file next to ``dest`` (same folder, same suffix, so writers
    that choose the format from the name still work): ``.<stem>.<pid>.<random>.tmp<suffix>``. The folder must
    exist."""
    dest = Path(dest)
    if dest.is_dir():
        raise OutputError(f"{dest}: cannot write the output: a folder of that name is in the way")
    try:
        fd, name = tempfile.mkstemp(prefix=f".{dest.stem}.{os.getpid()}.", suffix=f".tmp{dest.suffix}", dir=dest.parent)
    except OSError as e:
        raise OutputError(f"{dest.parent}: cannot write into the output folder ({_describe(e)})") from None
    os.close(fd)
    return Path(name)


def _link_aside(dest: Path, attempts: int = 5) -> Path | None:
    """A hard link to ``dest``'s current file (the link itself for a symlink) under a fresh name in its folder;
    None when there is no such file (or a folder)."""
    for _ in range(attempts):
        if not os.path.lexists(dest) or dest.is_dir():
            return None
        bak = temp_path(dest)
        bak.unlink()  # the name only; os.link never replaces nor follows whatever might appear there meanwhile
        try:
            os.link(dest, bak, follow_symlinks=False)
            return bak
        except FileNotFoundError:
            # a concurrent writer replaced dest between the lookup and the link (Linux link(2) then fails
            # with ENOENT on the old inode): look again
            continue
    raise OutputError(f"{dest}: cannot set the old file aside: it keeps changing (concurrent writers)")


def _unlink_quietly(p: Path) -> None:
    with contextlib.suppress(OSError):
        p.unlink()


@contextlib.contextmanager
def _sigint_held() -> Iterator[None]:
    """Hold SIGINT back (pending, delivered after the block) so Ctrl-C cannot split a commit."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


class OutputSet:
    """Files written to temporaries and committed together (all new or all old).

        with OutputSet() as out:
            step.write(vbrep, out.temp(step_path))
            vbrep.save(out.temp(json_path))
            out.remove(png_path)          # a stale file of the old set that the new set has not
        # committed here; on an exception inside the block nothing was changed

    ``commit`` (called on a clean exit of the block) renames in the order the temporaries were asked for.
    """

    def __init__(self, force: bool = True) -> None:
        """force: replace existing destinations whoever wrote them; False refuses any that v2c did not write
        (`check_replaceable`)."""
        self.force = force
        self._pending: list[tuple[Path, Path]] = []  # (temporary, destination)
        self._remove: list[Path] = []
        self._made_dirs: list[Path] = []
        self.committed = False

    def temp(self, dest: str | Path) -> Path:
        """An exclusive temporary for ``dest`` (its folder is created when missing); write the file there."""
        dest = Path(dest)
        if any(d == dest for _, d in self._pending):
            raise ValueError(f"{dest}: asked for twice in one output set")
        check_replaceable(dest, self.force)
        self._made_dirs += make_dirs(dest.parent)
        sweep_stale_temporaries(dest)
        tmp = temp_path(dest)
        self._pending.append((tmp, dest))
        return tmp

    def forget(self, dest: str | Path) -> None:
        """Drop ``dest`` from the set (its temporary is removed): e.g. a writer failed and the rest may go on."""
        dest = Path(dest)
        for tmp, d in [p for p in self._pending if p[1] == dest]:
            _unlink_quietly(tmp)
            self._pending.remove((tmp, d))

    def remove(self, dest: str | Path) -> None:
        """Remove ``dest`` at the commit if it exists (a file of the old set that the new set does not have)."""
        self._remove.append(Path(dest))

    @property
    def destinations(self) -> list[Path]:
        """The destinations written so far (in the order their temporaries were made)."""
        return [d for _, d in self._pending]

    def discard(self) -> None:
        """Remove the temporaries and the folders this set created (when empty); the old files stay."""
        for tmp, _ in self._pending:
            _unlink_quietly(tmp)
        self._pending.clear()
        for d in reversed(self._made_dirs):
            with contextlib.suppress(OSError):
                d.rmdir()
        self._made_dirs.clear()

    def commit(self, _after_rename: Callable[[int], None] | None = None) -> None:
        """Rename every temporary over its destination, in order, as one step (module docstring).

        ``_after_rename(i)`` is a test hook called after the i-th rename (to simulate a failure mid-commit).
        """
        backups: dict[Path, Path] = {}  # destination -> hard link to its old file
        changed: list[Path] = []
        try:
            with _sigint_held():
                try:
                    # one file alone needs no backup: os.replace keeps the old file until the new one is in place
                    single = len(self._pending) + len(self._remove) == 1
                    for dest in [] if single else self.destinations + self._remove:
                        if dest not in backups and (bak := _link_aside(dest)) is not None:
                            backups[dest] = bak
                    for i, (tmp, dest) in enumerate(self._pending):
                        os.replace(tmp, dest)
                        changed.append(dest)
                        if _after_rename is not None:
                            _after_rename(i)
                    for dest in self._remove:
                        if dest in backups and dest not in changed:
                            os.unlink(dest)
                            changed.append(dest)
                except BaseException:
                    for dest in changed:  # put the old set back
                        if dest in backups:
                            os.replace(backups.pop(dest), dest)
                        else:
                            _unlink_quietly(dest)
                    raise
            self.committed = True
        except OSError as e:
            raise OutputError(
                f"{e.filename or self.destinations[0]}: cannot write ({_describe(e)}); the previous "
                "files were left as they were"
            ) from None
        finally:
            for bak in backups.values():
                _unlink_quietly(bak)
            if self.committed:
                self._pending.clear()
                self._made_dirs.clear()
            else:
                self.discard()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.commit()
        else:
            self.discard()


@contextlib.contextmanager
def atomic_write(dest: str | Path) -> Iterator[Path]:
    """Yield an exclusive temporary next to ``dest``; on a clean exit it is renamed over ``dest``, on an exception
    removed (``dest`` untouched)."""
    with OutputSet() as out:
        yield out.temp(dest)


def write_bytes_atomic(dest: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``dest`` atomically (`atomic_write`); returns ``dest``."""
    dest = Path(dest)
    with atomic_write(dest) as tmp:
        tmp.write_bytes(data)
    return dest


def write_text_atomic(dest: str | Path, text: str) -> Path:
    """Write UTF-8 ``text`` to ``dest`` atomically (`atomic_write`); returns ``dest``."""
    return write_bytes_atomic(dest, text.encode("utf-8"))
