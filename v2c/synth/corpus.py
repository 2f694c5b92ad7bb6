"""The CAD corpus (``../shared/data/cad_corpus``) and its fixed split by file (issue 15 item 1).

The split is committed in ``v2c/synth/splits/cad_corpus.csv`` (by file SHA-1: 70 % train, 10 % validation, 20 %
test; `scripts/make_corpus_split.py`). Training may render the **train** files (`v2c train --recipe`), thresholds
are chosen on **val**, and **test** is only measured (`v2c bench --suite unseen`). It lives with the generator
because both training and the benchmark read it.
"""

from __future__ import annotations

import csv
import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

SPLIT_FILE = Path(__file__).with_name("splits") / "cad_corpus.csv"
SPLITS: tuple[str, ...] = ("train", "val", "test")


def default_corpus_dir() -> Path:
    """``$V2C_SHARED_DATA/cad_corpus``, else ``../shared/data/cad_corpus`` next to the repository."""
    env = os.environ.get("V2C_SHARED_DATA")
    root = Path(env) if env else Path(__file__).resolve().parents[2].parent / "shared" / "data"
    return root / "cad_corpus"


@dataclass(frozen=True)
class CorpusPart:
    """One row of the split file: file name, SHA-1 (hex), split, face count."""

    file: str
    sha1: str
    split: str
    n_faces: int


def read_split(path: Path = SPLIT_FILE) -> list[CorpusPart]:
    """The committed corpus split (``#`` lines are comments), sorted by file name."""
    lines = [ln for ln in Path(path).read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    out = []
    for r in csv.DictReader(lines):
        try:
            out.append(CorpusPart(r["file"], r["sha1"], r["split"], int(r["n_faces"])))
        except (KeyError, ValueError) as exc:
            raise ValueError(f"{path}: bad row {r} (expected file,sha1,split,n_faces): {exc}") from None
    return sorted(out, key=lambda p: p.file)


def checked_files(rows: list[CorpusPart], corpus_dir: Path | None = None, path: Path = SPLIT_FILE) -> list[Path]:
    """The files of ``rows`` in the corpus folder (``corpus_dir``, default `default_corpus_dir`), each checked: it
    exists and has the SHA-1 the split ``path`` was made from. Raises ValueError naming the file or folder."""
    folder = Path(corpus_dir or default_corpus_dir())
    if not folder.is_dir():
        raise ValueError(
            f"{folder}: CAD corpus not found (expected ../shared/data/cad_corpus; v2c bench: --corpus DIR)"
        )
    out = []
    for p in rows:
        f = folder / p.file
        if not f.is_file():
            raise ValueError(f"{f}: listed in {Path(path).name} ({p.split} split) but missing")
        got = hashlib.sha1(f.read_bytes()).hexdigest()
        if got != p.sha1:
            raise ValueError(f"{f}: SHA-1 {got}, expected {p.sha1} from {Path(path).name} (file changed?)")
        out.append(f)
    return out


def split_files(split: str, corpus_dir: Path | None = None, path: Path = SPLIT_FILE) -> list[Path]:
    """The checked files (`checked_files`) of one split of ``path``."""
    if split not in SPLITS:
        raise ValueError(f"{path}: unknown split {split!r} (expected one of {', '.join(SPLITS)})")
    return checked_files([p for p in read_split(path) if p.split == split], corpus_dir, path)
