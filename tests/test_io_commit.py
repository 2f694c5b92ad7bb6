"""Output sets that survive SIGKILL (v2c.io_safe, issue 20's must-show): a real writer process committing a set
of 3 files is killed at many random moments, inside the commit included (the committer's test hook sleeps
between its renames), and after each kill (once its committer finished) the folder holds exactly the complete
old set or the complete new set; the committer killed as well leaves a journal that the next writer settles;
broken journals are refused without touching anything; the next run leaves no temporary and no journal."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from v2c.errors import OutputError
from v2c.io_safe import (
    _FAIL_ENV,
    _PAUSE_ENV,
    JOURNAL_PREFIX,
    TMP_TAG,
    OutputSet,
    settle_commits,
    sweep_stale_temporaries,
)

REPO = Path(__file__).resolve().parents[1]
NAMES = ("part.step", "part.vbrep.json", "part.png")

#: The writer: a set of the 3 files with the contents of `content(tag, name)`, each written in 4 chunks 10 ms
#: apart (so a kill can land while temporaries are half-written); prints its phases.
WRITER = """
import sys, time
from pathlib import Path
from v2c.io_safe import OutputSet
out, tag = Path(sys.argv[1]), sys.argv[2]
names = sys.argv[3:]
print("start", flush=True)
with OutputSet() as s:
    for n in names:
        data = (f"{tag} {n} " * 4000).encode()
        with open(s.temp(out / n), "wb") as f:
            for k in range(4):
                f.write(data[k * len(data) // 4 : (k + 1) * len(data) // 4])
                f.flush()
                time.sleep(0.01)
    print("commit", flush=True)
print("done", flush=True)
"""


def content(tag: str, name: str) -> bytes:
    """What the writer puts into ``name`` for ``tag``."""
    return (f"{tag} {name} " * 4000).encode()


def the_set(tag: str) -> dict[str, bytes]:
    return {n: content(tag, n) for n in NAMES}


def visible(folder: Path) -> dict[str, bytes]:
    """{name: content} of the files a user sees (not hidden)."""
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if not p.name.startswith(".")}


def hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def committers(folder: Path) -> list[int]:
    """Pids of running committer processes of sets in ``folder`` (their command line names its journal)."""
    pids = []
    for proc in Path("/proc").iterdir():
        if not proc.name.isdigit():
            continue
        try:
            argv = (proc / "cmdline").read_bytes().split(b"\0")
            state = (proc / "stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z" and b"--commit" in argv and any(a.startswith(str(folder).encode() + b"/") for a in argv):
            pids.append(int(proc.name))
    return pids


def wait_for_committers(folder: Path, timeout: float = 30.0) -> None:
    """Wait until no committer of a set in ``folder`` runs (those of a killed writer run on by design)."""
    end = time.monotonic() + timeout
    while committers(folder):
        assert time.monotonic() < end, f"a committer in {folder} still runs after {timeout} s"
        time.sleep(0.01)


def _env(**extra: str) -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO), **extra)


def _start(out: Path, tag: str, env: dict[str, str]) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-c", WRITER, str(out), tag, *NAMES],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _write_old(out: Path) -> dict[str, bytes]:
    """The visible files become the old set (hidden leftovers of earlier kills stay, for the next run to clear)."""
    out.mkdir(parents=True, exist_ok=True)
    for p in out.iterdir():
        if not p.name.startswith("."):
            p.unlink()
    for n, data in the_set("old").items():
        (out / n).write_bytes(data)
    return visible(out)


def _phase(lines: list[str]) -> str:
    if "done" in lines:
        return "after the commit"
    if "commit" in lines:
        return "in the commit"
    if "start" in lines:
        return "writing temporaries"
    return "starting up"


PAUSE = 0.04  # committer's sleep after each rename: the commit lasts > 3 x PAUSE, so kills land inside it


def test_sigkill_of_the_writer_at_random_moments_leaves_the_old_or_the_new_set(tmp_path: Path) -> None:
    out = tmp_path / "out"
    env = _env(**{_PAUSE_ENV: str(PAUSE)})
    rng = random.Random(20)
    # one undisturbed run: its duration and that of its commit set the kill moments
    _write_old(out)
    t0 = time.perf_counter()
    p = _start(out, "new", env)
    assert p.stdout.readline().strip() == "start"
    assert p.stdout.readline().strip() == "commit"
    t_commit = time.perf_counter()
    assert p.stdout.readline().strip() == "done"
    t_end = time.perf_counter()
    assert p.wait(timeout=30) == 0, p.stderr.read()
    assert visible(out) == the_set("new") and hidden(out) == []
    total, commit = t_end - t0, t_end - t_commit
    assert commit > 3 * PAUSE

    phases: Counter[str] = Counter()
    outcomes: Counter[str] = Counter()
    split_seen = 0
    n_kills = 48
    for k in range(n_kills):
        before = _write_old(out)
        p = _start(out, "new", env)
        lines = []
        if k % 2 == 0:  # anywhere in the run
            time.sleep(rng.uniform(0.0, 1.1 * total))
        else:  # inside the commit: after the writer said "commit", before its commit ends
            while (line := p.stdout.readline().strip()) and line != "commit":
                lines.append(line)
            lines.append(line)
            time.sleep(rng.uniform(0.0, commit))
        p.kill()
        p.wait(timeout=30)
        right_after = visible(out)
        lines += p.stdout.read().split()
        wait_for_committers(out)
        after = visible(out)
        phase = _phase(lines)
        phases[phase] += 1
        assert after in (before, the_set("new")), (k, phase, {n: after.get(n, b"")[:8] for n in NAMES})
        outcomes[f"{phase}: {'new' if after != before else 'old'}"] += 1
        if right_after not in (before, the_set("new")):
            split_seen += 1  # the writer died while its committer was between two renames; it finished them
            assert phase == "in the commit"
    # the next (undisturbed) run: the new set, and nothing of the killed runs left
    r = subprocess.run(
        [sys.executable, "-c", WRITER, str(out), "next", *NAMES], env=_env(), capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, r.stderr
    assert visible(out) == the_set("next")
    assert hidden(out) == []
    print(f"{n_kills} kills: {dict(phases)}; outcomes {dict(outcomes)}; split at the kill, completed: {split_seen}")
    # the kills reached every phase, and some landed between two renames of the committer
    assert phases["in the commit"] >= n_kills // 4 and phases["writing temporaries"] >= 3 and split_seen >= 1
    assert outcomes["in the commit: new"] >= 5  # kills after the journal: the committer completed the set


def test_sigkill_of_writer_and_committer_is_settled_by_the_next_writer(tmp_path: Path) -> None:
    """Both the writer and its committer killed (the committer between its renames): the folder may be split
    for a while; the next `OutputSet` in that folder settles the journal first, so the folder holds the complete
    old or new set before it writes anything, and its own set after."""
    out = tmp_path / "out"
    env = _env(**{_PAUSE_ENV: "0.1"})
    rng = random.Random(21)
    outcomes: Counter[str] = Counter()
    for k in range(12):
        before = _write_old(out)
        p = _start(out, "new", env)
        while (line := p.stdout.readline().strip()) and line != "commit":
            pass
        end = time.monotonic() + 10
        while not (pids := committers(out)):
            assert time.monotonic() < end, "no committer appeared"
            time.sleep(0.002)
        p.kill()
        p.wait(timeout=30)
        time.sleep(rng.uniform(0.0, 0.4))  # its 3 renames take > 0.3 s after its start (~0.1 s)
        for pid in pids:
            os.kill(pid, signal.SIGKILL)
        wait_for_committers(out)
        split = visible(out) not in (before, the_set("new"))
        journals = [n for n in hidden(out) if n.startswith(JOURNAL_PREFIX)]
        assert journals or not split, k  # a split folder always has its journal
        settle_commits(out)  # what the next OutputSet in this folder does first
        after = visible(out)
        assert after in (before, the_set("new")), k
        assert [n for n in hidden(out) if n.startswith(JOURNAL_PREFIX)] == []
        outcomes[f"{'split' if split else 'whole'} -> {'new' if after != before else 'old'}"] += 1
    print(f"writer + committer killed 12 times: {dict(outcomes)}")
    assert outcomes["split -> new"] >= 1  # at least one kill between two renames, rolled forward
    with OutputSet() as s:
        for n in NAMES:
            s.temp(out / n).write_bytes(content("next", n))
    assert visible(out) == the_set("next") and hidden(out) == []


def test_a_failing_rename_puts_the_old_set_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A real failure of the third rename (a folder appeared at its destination): the committer puts the first
    two back; the error names the file and says the previous files stayed."""
    out = tmp_path / "out"
    before = _write_old(out)
    s = OutputSet()
    for n in NAMES:
        s.temp(out / n).write_bytes(content("new", n))
    (out / NAMES[2]).unlink()
    (out / NAMES[2]).mkdir()
    (out / NAMES[2] / "x").write_text("in the way")
    with pytest.raises(OutputError) as err:
        s.commit()
    assert str(err.value).startswith(f"{out / NAMES[2]}: cannot write (Is a directory)")
    assert "previous files were left as they were" in str(err.value)
    assert {n: (out / n).read_bytes() for n in NAMES[:2]} == {n: before[n] for n in NAMES[:2]}
    assert (out / NAMES[2] / "x").read_text() == "in the way"
    assert hidden(out) == []


@pytest.mark.parametrize("fail_after", [0, 1, 2])
def test_a_commit_failing_after_any_rename_leaves_the_old_set(
    fail_after: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "out"
    before = _write_old(out)
    (out / "stale.txt").write_text("of the old set")  # removed by the new set
    before = visible(out)
    monkeypatch.setenv(_FAIL_ENV, str(fail_after))
    with pytest.raises(OutputError, match="No space left on device"), OutputSet() as s:
        for n in NAMES:
            s.temp(out / n).write_bytes(content("new", n))
        s.remove(out / "stale.txt")
    assert visible(out) == before and hidden(out) == []
    monkeypatch.delenv(_FAIL_ENV)
    with OutputSet() as s:
        for n in NAMES[:2]:
            s.temp(out / n).write_bytes(content("new", n))
        s.remove(out / NAMES[2])  # the old figure goes too: a new set without one
        s.remove(out / "stale.txt")
    assert visible(out) == {n: content("new", n) for n in NAMES[:2]} and hidden(out) == []


def test_sigint_during_the_commit_waits_for_the_whole_set(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A real SIGINT to this process while the committer renames (another thread sends it, as a C library's
    thread may receive it): held back until the set is complete, then raised as KeyboardInterrupt."""
    import threading

    out = tmp_path / "out"
    _write_old(out)
    monkeypatch.setenv(_PAUSE_ENV, "0.1")
    s = OutputSet()
    for n in NAMES:
        s.temp(out / n).write_bytes(content("new", n))
    timer = threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT))
    old = signal.signal(signal.SIGINT, signal.default_int_handler)  # Python's own, whatever runs the tests
    try:
        timer.start()
        t0 = time.perf_counter()
        with pytest.raises(KeyboardInterrupt):
            s.commit()
            time.sleep(5)  # not reached when the held-back SIGINT is raised at the end of the commit
        assert time.perf_counter() - t0 < 4
        timer.join()
    finally:
        signal.signal(signal.SIGINT, old)
    assert s.committed and visible(out) == the_set("new") and hidden(out) == []


def _journal_file(out: Path, obj: object) -> Path:
    path = out / f"{JOURNAL_PREFIX}{'0' * 16}.json"
    path.write_text(json.dumps(obj))
    return path


def _tmp_name(dest: str, owner: str = "0123abcd-999999-abcdefgh") -> str:
    return f".{dest}{TMP_TAG}{owner}{Path(dest).suffix}"


def test_a_leftover_journal_is_rolled_forward_or_back(tmp_path: Path) -> None:
    """Journals as a killed committer leaves them: half the renames done (forward), a temporary lost (back, with
    the old files from their links), a rollback half done (back)."""
    out = tmp_path / "out"
    old = _write_old(out)
    new = the_set("new")

    def stage(renamed: int, lost: bool = False, state: str = "commit") -> Path:
        entries = []
        for i, n in enumerate(NAMES):
            bak = _tmp_name(n, "0123abcd-999999-backup00")
            os.link(out / n, out / bak)
            tmp = out / _tmp_name(n)
            tmp.write_bytes(new[n])
            entries.append([tmp.name, n, tmp.stat().st_ino, bak])
            if i < renamed:
                os.replace(tmp, out / n)
            elif lost and i == renamed:
                tmp.unlink()
        return _journal_file(out, {"format": "v2c.commit/1", "state": state, "renames": entries, "removes": []})

    stage(renamed=2)
    assert visible(out) != old and visible(out) != new  # split
    lines = settle_commits(out)
    assert len(lines) == 1 and lines[0].endswith(": committed"), lines
    assert visible(out) == new and hidden(out) == []

    _write_old(out)
    stage(renamed=1, lost=True)
    lines = settle_commits(out)
    assert "rolled back" in lines[0] and "the new file is missing" in lines[0], lines
    assert visible(out) == old and hidden(out) == []

    _write_old(out)
    stage(renamed=2, state="rollback")
    settle_commits(out)
    assert visible(out) == old and hidden(out) == []


@pytest.mark.parametrize(
    "bad",
    ["not json {", "symlink", "fifo", "other format", "slash in a name", "foreign temporary", "dest is a journal"],
)
def test_a_bad_journal_is_removed_and_nothing_else_touched(bad: str, tmp_path: Path) -> None:
    out = tmp_path / "out"
    old = _write_old(out)
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    tmp = out / _tmp_name(NAMES[0])
    tmp.write_bytes(b"new")
    rename = [tmp.name, NAMES[0], tmp.stat().st_ino, None]
    obj: object = {"format": "v2c.commit/1", "state": "commit", "renames": [rename], "removes": []}
    if bad == "other format":
        obj = {**obj, "format": "v2c.commit/9"}
    elif bad == "slash in a name":
        obj = {**obj, "renames": [[tmp.name, "../victim.txt", 1, None]]}
    elif bad == "foreign temporary":  # a name that is not a temporary of its destination: never renamed
        obj = {**obj, "renames": [["part.png", NAMES[0], 1, None]]}
    elif bad == "dest is a journal":
        obj = {**obj, "renames": [[tmp.name, f"{JOURNAL_PREFIX}{'1' * 16}.json", 1, None]]}
    if bad == "symlink":
        (out / f"{JOURNAL_PREFIX}{'0' * 16}.json").symlink_to(tmp_path / "journal_elsewhere.json")
        (tmp_path / "journal_elsewhere.json").write_text(json.dumps(obj))
    elif bad == "fifo":  # never opened for reading: it would wait for a writer forever
        os.mkfifo(out / f"{JOURNAL_PREFIX}{'0' * 16}.json")
    elif bad == "not json {":
        (out / f"{JOURNAL_PREFIX}{'0' * 16}.json").write_text(bad)
    else:
        _journal_file(out, obj)
    lines = settle_commits(out)
    assert len(lines) == 1 and ": bad" in lines[0], lines
    assert visible(out) == old and victim.read_text() == "precious"
    assert hidden(out) == [tmp.name]  # the journal is gone; its would-be temporary is left to the sweep


def test_temporaries_a_journal_names_are_never_swept(tmp_path: Path) -> None:
    """A killed writer's temporaries are swept, unless a journal (whose committer may be at work) names them."""
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    from v2c.io_safe import HOST_ID

    owner = f"{HOST_ID}-{int(dead.stdout)}-abcdefgh"
    out = tmp_path / "out"
    out.mkdir()
    named, loose = out / _tmp_name(NAMES[0], owner), out / _tmp_name(NAMES[0], owner.replace("abcdefgh", "zzzzzzzz"))
    named.write_bytes(b"new")
    loose.write_bytes(b"half")
    _journal_file(
        out,
        {"format": "v2c.commit/1", "state": "commit", "renames": [[named.name, NAMES[0], 1, None]], "removes": []},
    )
    assert sweep_stale_temporaries(out / NAMES[0]) == [loose]
    assert named.exists()


def test_a_set_lives_in_one_folder(tmp_path: Path) -> None:
    s = OutputSet()
    s.temp(tmp_path / "a" / "x.step")
    with pytest.raises(ValueError, match="an output set lives in one folder"):
        s.temp(tmp_path / "b" / "x.json")
    s.discard()
    assert not (tmp_path / "a").exists()
