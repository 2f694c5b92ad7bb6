"""Write v2c/synth/splits/cad_corpus.csv: the fixed train / validation / test split of ../shared/data/cad_corpus.

A file's split depends on its SHA-1 alone (``int(sha1[:8], 16) % 100``: under 70 train, 70-79 validation, 80 and
over test), so it does not move when files are added or renamed. Run once; the committed list is the reference.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

HEADER = (
    "# Split of ../shared/data/cad_corpus by file: split = int(sha1[:8], 16) % 100 -> <70 train, 70-79 val, "
    ">=80 test.\n"
    "# Fixed once (2026-11-25); never tune on test. Regenerate only with scripts/make_corpus_split.py and say so.\n"
)


def split_of(sha1: str) -> str:
    """The split ("train", "val" or "test") of a file, from its SHA-1 (hex)."""
    k = int(sha1[:8], 16) % 100
    return "train" if k < 70 else ("val" if k < 80 else "test")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--index", type=Path, default=Path("../shared/data/cad_corpus/index.csv"))
    ap.add_argument("--out", type=Path, default=Path("v2c/synth/splits/cad_corpus.csv"))
    args = ap.parse_args()
    rows = sorted(csv.DictReader(args.index.open()), key=lambda r: r["file"])
    lines = [f"{r['file']},{r['sha1']},{split_of(r['sha1'])},{r['n_faces']}\n" for r in rows]
    args.out.write_text(HEADER + "file,sha1,split,n_faces\n" + "".join(lines))


if __name__ == "__main__":
    main()
