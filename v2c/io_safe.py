"""Safe outputs: every file or folder v2c writes appears complete or not at all, and a set of files (STEP +
VB-Rep JSON + figure) is committed as one: the folder holds the complete old set or the complete new set, even
after a SIGKILL (kill -9, the OOM killer) of the writer at any instant (once its committer, below, finished).

Temporaries. A file (`temp_path`) or folder (`temp_dir`) is first made under an exclusive temporary name in the
destination's own folder, ``.<name>.v2c-tmp-<host>-<pid>-<random><suffix>`` (the suffix of the destination is
kept: writers such as OpenCV and OCCT choose the format by it; host: 8 hex digits of this machine's name). It is
created with ``O_CREAT | O_EXCL`` (`tempfile.mkstemp`) or ``mkdir``, so it never follows a symlink planted under a
temporary-looking name and never collides with a concurrent writer. The finished temporary is renamed over the
destination (`os.replace`: atomic within a folder; a symlink at the destination is replaced, never followed).

Leftovers. A killed writer leaves its temporaries; the next writer of the same destination removes them
(`sweep_stale_temporaries`): those of a process of this machine that no longer runs, those of another machine
once they are an hour old, and, for a caller that is the only writer of the destination (``single_writer``: one
task per output, as the executors run them, `atomic_dir`), all of them, so a task retried on another node cleans
up what its killed attempt left. Temporaries that a commit journal still names are never removed.

Sets (`OutputSet`). Files of one set live in one folder. Its commit:

1. sets the old files aside as hard links (names of the temporary form), records the temporaries' inodes, and
   starts a *committer*: a new Python process in its own session (``python -I -S -c ... --commit JOURNAL``)
   that waits until its standard input closes;
2. writes the *journal* ``.v2c-commit-<random>.json`` (a temporary renamed into place: it appears whole). From
   this instant the new set is decided: the journal lists (temporary, destination, inode, old-file link) for
   each file and the old files to remove;
3. closes the committer's input (or dies: the same end-of-file) and waits for it. The committer renames every
   temporary over its destination in order, removes the files to remove, then the links, then the journal. SIGINT,
   SIGTERM and SIGHUP do not reach it (own session, ignored); it outlives its parent.

So a kill of the writer before step 2 leaves the old set (and temporaries, swept later), after it the committer
completes the new set within milliseconds. Should the committer die too, the journal stays, and the next
`OutputSet` writing into that folder (or any committer started there, or `settle_commits`) settles it first:
under an exclusive lock on the journal (``flock``; a committer at work holds it) it renames what is left, or, when
a temporary is missing and its destination is not the new file (removed by hand), puts the old files back.
A rename that fails (permission, a folder in the way) marks the journal "rollback" (atomically) and puts the
old files back, so a failed commit leaves the old set and says so. A journal that cannot be read as one
(corrupt, a symlink, names outside its folder) is removed and nothing else is touched. A set of one file, and
`atomic_write`, need no journal: one rename is atomic.

Ownership: `v2c` never replaces a file it did not write unless asked to (``--force``; `OutputSet(force=False)`).
Its files say who wrote them: a STEP's FILE_NAME names ``v2c`` as the originating system, a figure PNG carries
the text chunk ``Software: v2c``, a binary STL's header starts with ``v2c``, a JSON starts with
``"format": "v2c.vbrep"`` or ``"generator": "v2c ..."`` (`written_by_v2c`).

Not covered: power loss (files are not fsync'ed; a journal makes no promise about data still in the page cache),
and several processes writing the same set at once (committers settle the journals of a folder oldest first, one
at a time, but which set ends up in place is not defined).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import json
import logging
import os
import re
import secrets
import shutil
import signal
import socket
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Self

from v2c.errors import OutputError

log = logging.getLogger(__name__)

#: The mark of a v2c output: STEP originating system, PNG "Software" text, JSON "generator" prefix.
V2C_MARK = "v2c"
#: How many leading bytes of a file `written_by_v2c` reads (the STEP header, the PNG text chunk, the JSON head).
_HEAD_BYTES = 4096

#: Marker inside every temporary name (files and folders): ``.<name>.v2c-tmp-<host>-<pid>-<random><suffix>``.
TMP_TAG = ".v2c-tmp-"
#: This machine in temporary names: 8 hex digits of its host name (pids are only comparable on one machine).
HOST_ID = hashlib.blake2s(socket.gethostname().encode("utf-8", "replace"), digest_size=4).hexdigest()
#: Age (seconds since the last write) after which a temporary of another machine counts as left behind.
OTHER_HOST_STALE_S = 3600.0
#: Commit journals: ``.v2c-commit-<random>.json`` in the folder of the set.
JOURNAL_PREFIX = ".v2c-commit-"
JOURNAL_FORMAT = "v2c.commit/1"
_JOURNAL_RE = re.compile(rf"^{re.escape(JOURNAL_PREFIX)}[0-9a-f]{{16}}\.json$")
_OWNER_RE = re.compile(r"^([0-9a-f]{8})-(\d+)-([a-z0-9_]+)(\..*)?$")
_MAX_JOURNAL_BYTES = 1 << 20
#: Exit status of a committer that put the old set back (its one-line reason on stderr), and of one that found
#: its journal settled by another process (or never written).
_ROLLED_BACK = 3
_SETTLED_ELSEWHERE = 4
#: Test hooks of the committer (environment): seconds to sleep after each rename; index of the rename after
#: which to fail as a full disk would. Only the tests set them.
_PAUSE_ENV = "V2C_TEST_COMMIT_PAUSE"
_FAIL_ENV = "V2C_TEST_COMMIT_FAIL_AFTER"


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


# --------------------------------------------------------------------------------------------- temporaries


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


def _temp_prefix(dest: Path) -> str:
    return f".{dest.name}{TMP_TAG}{HOST_ID}-{os.getpid()}-"


def temp_path(dest: str | Path, suffix: str | None = None) -> Path:
    """A new, empty, exclusively created temporary file next to ``dest`` (same folder, ending in ``suffix``,
    default that of ``dest``, so writers that choose the format from the name still work). The folder must
    exist."""
    dest = Path(dest)
    if dest.is_dir() and not dest.is_symlink():
        raise OutputError(f"{dest}: cannot write the output: a folder of that name is in the way")
    suffix = dest.suffix if suffix is None else suffix
    try:
        fd, name = tempfile.mkstemp(prefix=_temp_prefix(dest), suffix=suffix, dir=dest.parent)
    except OSError as e:
        raise OutputError(f"{dest.parent}: cannot write into the output folder ({_describe(e)})") from None
    os.close(fd)
    return Path(name)


def temp_dir(dest: str | Path) -> Path:
    """A new, empty, exclusively created temporary folder next to ``dest`` (``mkdir``: never follows a symlink;
    its mode follows the umask, like any folder). The parent folder must exist."""
    dest = Path(dest)
    for _ in range(100):
        tmp = dest.parent / f"{_temp_prefix(dest)}{secrets.token_hex(4)}"
        try:
            tmp.mkdir()
            return tmp
        except FileExistsError:
            continue
        except OSError as e:
            raise OutputError(f"{dest.parent}: cannot write into the output folder ({_describe(e)})") from None
    raise OutputError(f"{dest.parent}: cannot make a temporary folder (every name tried was taken)")


def _is_stale(path: Path, owner: str, single_writer: bool) -> bool:
    """Whether the temporary ``path`` with owner text ``host-pid-random[suffix]`` was left by a writer that is
    gone (module docstring)."""
    m = _OWNER_RE.match(owner)
    if m is None:
        return False
    host, pid = m.group(1), int(m.group(2))
    if host == HOST_ID and pid == os.getpid():
        return False  # this process: in flight
    if single_writer:
        return True
    if host == HOST_ID:
        return not _pid_alive(pid)
    try:
        return time.time() - os.lstat(path).st_mtime > OTHER_HOST_STALE_S
    except OSError:
        return False


def _remove_entry(path: Path) -> bool:
    """Remove a file, a symlink (the link itself) or a folder tree (never following a symlink); True if gone."""
    try:
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path)
        else:
            path.unlink()
    except FileNotFoundError:
        return False
    except OSError:
        return False
    return True


def sweep_stale_temporaries(dest: str | Path, single_writer: bool = False) -> list[Path]:
    """Remove the temporaries (files or folders) of ``dest`` that writers which are gone left in its folder
    (killed by SIGKILL, a lost node; module docstring): ``.<name>.v2c-tmp-<host>-<pid>-<random><suffix>`` of a
    process of this machine that no longer runs, or of another machine older than `OTHER_HOST_STALE_S`; with
    ``single_writer`` (the caller is the only writer of ``dest``) every one but this process's own. Never follows
    a symlink (one planted under such a name is removed as a link); never removes what a commit journal names.
    Returns what was removed."""
    dest = Path(dest)
    prefix = f".{dest.name}{TMP_TAG}"
    try:
        names = [e.name for e in os.scandir(dest.parent) if e.name.startswith(prefix)]
    except OSError:
        return []
    stale = [n for n in names if _is_stale(dest.parent / n, n[len(prefix) :], single_writer)]
    if not stale:
        return []
    protected = _journal_names(dest.parent)  # listed after the owners were found gone: see _journal_names
    removed = []
    for n in stale:
        if n not in protected and _remove_entry(dest.parent / n):
            removed.append(dest.parent / n)
    return removed


# ------------------------------------------------------------------------------------------ commit journals


@dataclass(frozen=True)
class _Rename:
    tmp: str  # names in the journal's folder
    dest: str
    ino: int  # inode of the temporary (the destination's once renamed)
    backup: str | None  # hard link to the old destination; None when there was none


@dataclass(frozen=True)
class _Remove:
    dest: str
    backup: str | None


@dataclass(frozen=True)
class _Journal:
    state: str  # "commit" or "rollback"
    renames: tuple[_Rename, ...]
    removes: tuple[_Remove, ...]

    def to_json(self) -> str:
        """The journal's file content."""
        return json.dumps(
            {
                "format": JOURNAL_FORMAT,
                "state": self.state,
                "renames": [[r.tmp, r.dest, r.ino, r.backup] for r in self.renames],
                "removes": [[r.dest, r.backup] for r in self.removes],
            }
        )

    def names(self) -> set[str]:
        """Every temporary and old-file link it names."""
        out = {r.tmp for r in self.renames}
        out |= {r.backup for r in (*self.renames, *self.removes) if r.backup}
        return out


def _plain_name(x: object) -> bool:
    return isinstance(x, str) and x not in ("", ".", "..") and "/" not in x and "\0" not in x


def _temp_of(name: object, dest: str) -> bool:
    """``name`` is a temporary-form name of ``dest`` (what a journal may rename or remove besides ``dest``)."""
    return _plain_name(name) and str(name).startswith(f".{dest}{TMP_TAG}")


def _parse_journal(data: bytes) -> _Journal | None:
    """The journal in ``data``, or None when it is not one that v2c wrote (any doubt: None)."""
    try:
        obj = json.loads(data.decode("utf-8"))
        if obj.get("format") != JOURNAL_FORMAT or obj.get("state") not in ("commit", "rollback"):
            return None
        renames = tuple(_Rename(t, d, i, b) for t, d, i, b in obj["renames"])
        removes = tuple(_Remove(d, b) for d, b in obj["removes"])
    except (ValueError, TypeError, KeyError, AttributeError, UnicodeDecodeError, RecursionError):
        return None
    dests = [r.dest for r in (*renames, *removes)]
    if len(set(dests)) != len(dests) or not all(_plain_name(d) and not d.startswith(JOURNAL_PREFIX) for d in dests):
        return None
    for r in renames:
        if not (_temp_of(r.tmp, r.dest) and isinstance(r.ino, int) and not isinstance(r.ino, bool)):
            return None
    for r in (*renames, *removes):
        if r.backup is not None and not _temp_of(r.backup, r.dest):
            return None
    return _Journal(obj["state"], renames, removes)


def _journal_paths(folder: Path) -> list[Path]:
    """The commit journals in ``folder``, oldest first."""
    try:
        entries = [e for e in os.scandir(folder) if _JOURNAL_RE.match(e.name)]
    except OSError:
        return []

    def age(e: os.DirEntry) -> float:
        try:
            return e.stat(follow_symlinks=False).st_mtime
        except OSError:
            return 0.0

    return [Path(e.path) for e in sorted(entries, key=lambda e: (age(e), e.name))]


def _journal_names(folder: Path) -> set[str]:
    """Names the journals in ``folder`` list (read without the lock). A sweep lists them *after* it found a
    temporary's writer gone: a writer writes its journal before it can die with one, so none is missed."""
    names: set[str] = set()
    for path in _journal_paths(folder):
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
        except OSError:
            continue
        try:
            regular = stat.S_ISREG(os.fstat(fd).st_mode)
            journal = _parse_journal(os.read(fd, _MAX_JOURNAL_BYTES)) if regular else None
        except OSError:
            journal = None
        finally:
            os.close(fd)
        if journal is not None:
            names |= journal.names()
    return names


def _ino(path: Path) -> int | None:
    try:
        return os.lstat(path).st_ino
    except OSError:
        return None


def _write_journal(path: Path, journal: _Journal) -> None:
    """Write ``journal`` to ``path`` whole (an exclusive temporary renamed into place)."""
    tmp = temp_path(path)
    try:
        tmp.write_text(journal.to_json(), encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        _unlink_quietly(tmp)
        raise


def _lock(fd: int) -> None:
    with contextlib.suppress(OSError):  # a file system without locks: go on unlocked (one committer per set)
        fcntl.flock(fd, fcntl.LOCK_EX)


def _open_locked(path: Path) -> int | None:
    """An fd of the journal ``path``, exclusively locked, or None when it is gone (settled by someone else).
    Raises OSError(ELOOP) for a symlink."""
    for _ in range(100):
        try:
            fd = os.open(path, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK)
        except FileNotFoundError:
            return None
        if not stat.S_ISREG(os.fstat(fd).st_mode):  # a FIFO or device under a journal's name: never read
            os.close(fd)
            raise OSError(errno.EINVAL, "not a regular file", str(path))
        _lock(fd)
        try:
            if os.path.samestat(os.fstat(fd), os.lstat(path)):
                return fd
        except OSError:
            pass
        os.close(fd)  # replaced (marked "rollback") or removed while we waited: look again
    return None


@dataclass
class _Outcome:
    state: str  # "gone", "bad", "committed", "rolled back", "stuck"
    message: str = ""


def _settle(path: Path, after_rename: Callable[[int, Path], None] | None = None) -> _Outcome:
    """Settle the journal ``path``: complete its set, or put the old set back (module docstring)."""
    try:
        fd = _open_locked(path)
    except OSError as e:
        if e.errno in (errno.ELOOP, errno.EINVAL):  # a symlink (never followed), a FIFO, ...: not ours
            _unlink_quietly(path)
            return _Outcome("bad", f"{path}: not a regular file, removed")
        return _Outcome("stuck", f"{path}: cannot open the commit journal ({_describe(e)})")
    if fd is None:
        return _Outcome("gone")
    fds = [fd]
    try:
        try:
            journal = _parse_journal(os.read(fd, _MAX_JOURNAL_BYTES))
        except OSError as e:
            return _Outcome("stuck", f"{path}: cannot read the commit journal ({_describe(e)})")
        if journal is None:
            log.warning("%s: not a commit journal of v2c; removed without acting on it", path)
            _unlink_quietly(path)
            return _Outcome("bad", f"{path}: not a commit journal of v2c")
        folder = path.parent
        message = ""
        if journal.state == "commit":
            lost = [
                r.tmp for r in journal.renames if not os.path.lexists(folder / r.tmp) and _ino(folder / r.dest) != r.ino
            ]
            if lost:
                message = f"{folder / lost[0]}: the new file is missing; the previous files were put back"
            else:
                message = _roll_forward(folder, journal, after_rename)
                if not message:
                    for r in (*journal.renames, *journal.removes):
                        if r.backup:
                            _unlink_quietly(folder / r.backup)
                    _unlink_quietly(path)
                    return _Outcome("committed")
            with contextlib.suppress(OSError):  # unmarked, a later settle would try to go forward again
                fds.append(_mark_rollback(path, journal))
        errors = _roll_back(folder, journal)
        if errors:
            return _Outcome("stuck", f"{message or errors[0]}; the previous files could not all be put back")
        _unlink_quietly(path)
        return _Outcome("rolled back", message or f"{path}: an interrupted rollback, finished")
    finally:
        for f in fds:
            os.close(f)


def _roll_forward(folder: Path, journal: _Journal, after_rename: Callable[[int, Path], None] | None) -> str:
    """Rename what is left of the set into place and remove the files to remove; "" or why it failed."""
    dest = folder
    try:
        for i, r in enumerate(journal.renames):
            dest = folder / r.dest
            if os.path.lexists(folder / r.tmp):
                os.replace(folder / r.tmp, dest)
            if after_rename is not None:
                after_rename(i, dest)
        for r in journal.removes:
            dest = folder / r.dest
            if os.path.lexists(dest):
                os.unlink(dest)
    except OSError as e:
        return f"{dest}: cannot write ({_describe(e)}); the previous files were left as they were"
    return ""


def _mark_rollback(path: Path, journal: _Journal) -> int:
    """Replace the journal by its "rollback" version (locked before it appears); the new fd."""
    marked = _Journal("rollback", journal.renames, journal.removes)
    tmp = temp_path(path)
    try:
        tmp.write_text(marked.to_json(), encoding="utf-8")
        fd = os.open(tmp, os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC)
        _lock(fd)
        try:
            os.replace(tmp, path)
        except OSError:
            os.close(fd)
            raise
        return fd
    finally:
        _unlink_quietly(tmp)  # gone once renamed


def _roll_back(folder: Path, journal: _Journal) -> list[str]:
    """Put the old files back and remove the new ones and the temporaries (each step repeatable); errors."""
    errors = []
    for r in (*journal.renames, *journal.removes):
        dest = folder / r.dest
        try:
            if r.backup is not None and os.path.lexists(folder / r.backup):
                os.replace(folder / r.backup, dest)
                _unlink_quietly(folder / r.backup)  # still there when it already was the destination's file
            elif r.backup is None and isinstance(r, _Rename) and _ino(dest) == r.ino:
                os.unlink(dest)  # the new file where there was none
            if isinstance(r, _Rename):
                _unlink_quietly(folder / r.tmp)
        except OSError as e:
            errors.append(f"{dest}: {_describe(e)}")
    return errors


def settle_commits(folder: str | Path) -> list[str]:
    """Settle every commit journal left in ``folder`` (oldest first; waits for a committer at work on one) and
    remove journal temporaries of writers that are gone; the outcome of each, as lines. `OutputSet` calls this
    for its folder before it writes there."""
    folder = Path(folder)
    lines = []
    for path in _journal_paths(folder):
        outcome = _settle(path)
        lines.append(f"{path}: {outcome.state}" + (f": {outcome.message}" if outcome.message else ""))
    prefix = f".{JOURNAL_PREFIX}"
    try:
        names = [e.name for e in os.scandir(folder) if e.name.startswith(prefix) and TMP_TAG in e.name]
    except OSError:
        names = []
    for n in names:
        if _is_stale(folder / n, n.split(TMP_TAG, 1)[1], single_writer=False):
            _unlink_quietly(folder / n)
    return lines


def _test_hook() -> Callable[[int, Path], None] | None:
    """The committer's test hook from the environment (`_PAUSE_ENV`, `_FAIL_ENV`); None outside the tests."""
    pause, fail = os.environ.get(_PAUSE_ENV), os.environ.get(_FAIL_ENV)
    if not pause and not fail:
        return None

    def hook(i: int, dest: Path) -> None:
        if pause:
            time.sleep(float(pause))
        if fail and i == int(fail):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(dest))

    return hook


def _committer_main(argv: Sequence[str]) -> int:
    """The committer (``--commit JOURNAL``): wait for the end of standard input (the writer closed it or died),
    then settle the folder's journals, oldest first, this one in its turn. Exit 0 (committed), `_ROLLED_BACK`
    (the reason on stderr) or `_SETTLED_ELSEWHERE`."""
    if len(argv) != 2 or argv[0] != "--commit":
        print("usage: _committer_main --commit JOURNAL (started by OutputSet.commit)", file=sys.stderr)
        return 2
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(sig, signal.SIG_IGN)
    with contextlib.suppress(OSError, ValueError):
        sys.stdin.buffer.read()
    journal = Path(argv[1])
    outcome = _Outcome("gone")  # settled by another process (or never written: the writer died before)
    for path in _journal_paths(journal.parent):  # oldest first: a later set wins, as it would have anyway
        if path == journal:
            outcome = _settle(journal, _test_hook())
        else:
            _settle(path)
    if outcome.state == "committed":
        return 0
    if outcome.state == "gone":
        return _SETTLED_ELSEWHERE
    with contextlib.suppress(OSError):
        print(outcome.message, file=sys.stderr)
    return _ROLLED_BACK


def _committer_command(journal: Path) -> list[str] | None:
    """The command line of a committer for ``journal``; None when this interpreter cannot start one (embedded
    Python, e.g. in FreeCAD): the writer then renames itself, and a kill in the middle leaves the journal for the
    next writer in the folder to settle."""
    exe = sys.executable
    if not exe or not os.path.basename(exe).lower().startswith(("python", "pypy")):
        return None
    root = str(Path(__file__).resolve().parents[1])  # this very v2c, whatever $PYTHONPATH says (-I ignores it)
    code = f"import sys; sys.path.insert(0, {root!r}); from v2c.io_safe import _committer_main; "
    code += "sys.exit(_committer_main(sys.argv[1:]))"
    return [exe, "-I", "-S", "-c", code, "--commit", str(journal)]


# -------------------------------------------------------------------------------------------------- sets


def _link_aside(dest: Path, attempts: int = 5) -> Path | None:
    """A hard link to ``dest``'s current file (the link itself for a symlink) under a fresh temporary name in
    its folder; None when there is no such file (or a folder)."""
    for _ in range(attempts):
        if not os.path.lexists(dest) or (dest.is_dir() and not dest.is_symlink()):
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
    """Hold SIGINT back until the end of the block, so Ctrl-C cannot split a commit: blocked in this thread and
    only recorded by Python (another thread may receive it), then handed to the previous handler."""
    if threading.current_thread() is not threading.main_thread():
        yield  # Python runs signal handlers in the main thread only: no KeyboardInterrupt can arrive here
        return
    got: list[int] = []
    old_handler = signal.signal(signal.SIGINT, lambda signum, frame: got.append(signum))
    old_mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old_mask)
        signal.signal(signal.SIGINT, old_handler if old_handler is not None else signal.SIG_DFL)
        if got:
            signal.raise_signal(signal.SIGINT)


class OutputSet:
    """Files of one folder written to temporaries and committed together (all new or all old, even after
    SIGKILL: module docstring).

        with OutputSet() as out:
            step.write(vbrep, out.temp(step_path))
            vbrep.save(out.temp(json_path))
            out.remove(png_path)          # a stale file of the old set that the new set has not
        # committed here; on an exception inside the block nothing was changed

    ``commit`` (called on a clean exit of the block) renames in the order the temporaries were asked for.
    """

    def __init__(self, force: bool = True, single_writer: bool = False) -> None:
        """force: replace existing destinations whoever wrote them; False refuses any that v2c did not write
        (`check_replaceable`). single_writer: the caller is the only writer of these files (one task per
        output, e.g. a task the executors may retry on another node): every temporary of them that another
        process left is removed (`sweep_stale_temporaries`)."""
        self.force = force
        self.single_writer = single_writer
        self._folder: Path | None = None
        self._pending: list[tuple[Path, Path]] = []  # (temporary, destination)
        self._remove: list[Path] = []
        self._made_dirs: list[Path] = []
        self.committed = False

    def _enter_folder(self, dest: Path) -> None:
        folder = Path(os.path.abspath(dest.parent))
        if self._folder is None:
            self._made_dirs += make_dirs(folder)
            settle_commits(folder)  # a set an earlier writer left half-committed comes first
            self._folder = folder
        elif folder != self._folder:
            raise ValueError(f"{dest}: an output set lives in one folder ({self._folder})")

    def temp(self, dest: str | Path) -> Path:
        """An exclusive temporary for ``dest`` (its folder is created when missing); write the file there."""
        dest = Path(dest)
        if any(d == dest for _, d in self._pending):
            raise ValueError(f"{dest}: asked for twice in one output set")
        check_replaceable(dest, self.force)
        self._enter_folder(dest)
        sweep_stale_temporaries(dest, self.single_writer)
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
        dest = Path(dest)
        self._enter_folder(dest)
        self._remove.append(dest)

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

    def commit(self) -> None:
        """Rename every temporary over its destination, in order, as one step (module docstring). OutputError
        (the old set left in place) when it fails."""
        removes = [d for d in dict.fromkeys(self._remove) if d not in self.destinations]
        try:
            with _sigint_held():
                if len(self._pending) + len(removes) <= 1:  # one rename (or unlink) is atomic by itself
                    for tmp, dest in self._pending:
                        os.replace(tmp, dest)
                    for dest in removes:
                        if os.path.lexists(dest):
                            os.unlink(dest)
                else:
                    self._commit_journaled(removes)
                self.committed = True  # before a held-back SIGINT is handed on, at the end of the block
        except OSError as e:
            if isinstance(e, OutputError):
                raise
            raise OutputError(
                f"{e.filename or self.destinations[0]}: cannot write ({_describe(e)}); the previous "
                "files were left as they were"
            ) from None
        finally:
            if self.committed:
                self._pending.clear()
                self._made_dirs.clear()
            else:
                self.discard()

    def _commit_journaled(self, removes: list[Path]) -> None:
        """Steps 1-3 of the module docstring."""
        assert self._folder is not None
        path = self._folder / f"{JOURNAL_PREFIX}{secrets.token_hex(8)}.json"
        renames: list[_Rename] = []
        backups: list[Path | None] = []
        reason, rc = "", None
        try:
            for dest in self.destinations + removes:
                backups.append(_link_aside(dest))
            for (tmp, dest), bak in zip(self._pending, backups, strict=False):
                renames.append(_Rename(tmp.name, dest.name, os.lstat(tmp).st_ino, bak.name if bak else None))
            gone = [
                _Remove(d.name, b.name if b else None) for d, b in zip(removes, backups[len(renames) :], strict=True)
            ]
            committer = self._start_committer(path)
            try:
                _write_journal(path, _Journal("commit", tuple(renames), tuple(gone)))  # the commit point
            finally:
                if committer is not None:  # end of its input: go (without a journal: nothing to do)
                    _, err = committer.communicate()
                    rc = committer.returncode
                    if rc == _ROLLED_BACK and err.strip():
                        reason = err.decode("utf-8", "replace").strip().splitlines()[-1]
            # the committer's verdict; else (it died, could not start, found the journal settled by another
            # process) this process settles what is left and looks at the files
            outcome = _settle(path) if rc not in (0, _ROLLED_BACK) else _Outcome("gone")
            reason = reason or outcome.message
        finally:
            if not os.path.lexists(path):  # a journal still there needs them to put the old set back
                for bak in backups:  # none is left after a settled journal; these are of a set without one
                    if bak is not None:
                        _unlink_quietly(bak)
        if rc == 0 or outcome.state == "committed":
            return
        if rc == _ROLLED_BACK or outcome.state != "gone" or not self._in_place(renames, removes):
            raise OutputError(
                reason or f"{self.destinations[0]}: not written; the previous files were left as they were"
            )

    def _in_place(self, renames: list[_Rename], removes: list[Path]) -> bool:
        """Whether the folder holds this set (its new files, none of those to remove)."""
        assert self._folder is not None
        return all(_ino(self._folder / r.dest) == r.ino for r in renames) and not any(map(os.path.lexists, removes))

    @staticmethod
    def _start_committer(journal: Path) -> subprocess.Popen | None:
        command = _committer_command(journal)
        if command is None:
            return None
        try:
            return subprocess.Popen(
                command,
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.PIPE,
                start_new_session=True,  # no terminal's Ctrl-C, no kill of our process group reaches it
                close_fds=True,
            )
        except OSError as e:
            log.debug("no committer process (%s); renaming in this process", e)
            return None

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


# ----------------------------------------------------------------------------------------------- folders


@contextlib.contextmanager
def atomic_dir(final: str | Path, last: Sequence[str] = ()) -> Iterator[Path]:
    """Yield a fresh temporary folder next to ``final`` to fill; on success it becomes ``final``.

    A missing ``final`` is replaced by one rename (the folder appears complete or not at all). An existing one is
    updated file by file (each an atomic rename; files of it that the new content lacks are kept), with the
    relative paths in ``last`` moved last (completion markers). On an exception the temporary folder is removed.
    The caller is the only writer of ``final`` (one task per output): what earlier, killed attempts left next to
    it, on this machine or another, is removed first (`sweep_stale_temporaries` with ``single_writer``).
    """
    final = Path(final)
    make_dirs(final.parent)
    sweep_stale_temporaries(final, single_writer=True)
    tmp = temp_dir(final)
    try:
        yield tmp
        try:
            os.rename(tmp, final)
        except OSError:  # final exists (and is not empty): merge into it
            if final.is_symlink() or not final.is_dir():
                raise
            _merge(tmp, final, last)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _merge(src: Path, dst: Path, last: Sequence[str]) -> None:
    files = sorted(p.relative_to(src).as_posix() for p in src.rglob("*") if not p.is_dir())
    files = [f for f in files if f not in last] + [f for f in last if f in files]
    for rel in files:
        target = dst / rel
        for parent in reversed(target.relative_to(dst).parents[:-1]):  # never write through a planted symlink
            if (dst / parent).is_symlink():
                raise OutputError(f"{dst / parent}: a symlink where a folder of the output should be")
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(src / rel, target)
