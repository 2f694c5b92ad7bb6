"""The CAD corpus split (v2c.synth.corpus) and the training recipe rows that render its train files."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from v2c.synth import corpus
from v2c.synth.families import FAMILY_GROUPS

needs_corpus = pytest.mark.skipif(not corpus.default_corpus_dir().is_dir(), reason="../shared/data/cad_corpus missing")


def test_split_is_disjoint_and_covers_every_row() -> None:
    rows = corpus.read_split()
    assert len(rows) == 147
    by = {k: {p.file for p in rows if p.split == k} for k in corpus.SPLITS}
    assert [len(by[k]) for k in corpus.SPLITS] == [104, 15, 28]
    assert not (by["train"] & by["val"]) and not (by["train"] & by["test"]) and not (by["val"] & by["test"])


def test_unknown_split_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown split 'tests'"):
        corpus.split_files("tests")


@needs_corpus
def test_split_files_are_the_train_rows_only() -> None:
    files = corpus.split_files("train")
    train = {p.file for p in corpus.read_split() if p.split == "train"}
    assert {f.name for f in files} == train and all(f.is_file() for f in files)


def test_changed_file_is_named(tmp_path: Path) -> None:
    (tmp_path / "a.step").write_text("x")
    split = tmp_path / "split.csv"
    split.write_text("file,sha1,split,n_faces\na.step," + "0" * 40 + ",train,4\n")
    with pytest.raises(ValueError, match=r"a\.step: SHA-1 .* expected 0{40}"):
        corpus.split_files("train", tmp_path, split)


@needs_corpus
def test_corpus_train_row_renders_train_files_only(tmp_path: Path) -> None:
    from v2c.segment.train import CORPUS_TRAIN, generate_training_data

    done = generate_training_data(tmp_path, recipe=((96, 72, "none", 2, 5, 0.0, (CORPUS_TRAIN,)),))
    assert [d.parent.name for d in done] == ["96x72_none_corpus-train_s5"] * 2
    train = {p.file for p in corpus.read_split() if p.split == "train"}
    for d in done:
        meta = json.loads((d / "gt" / "meta.json").read_text())
        assert meta["family"] == "cad" and meta["part"]["file"] in train


def test_corpus_train_must_be_a_rows_only_family(tmp_path: Path) -> None:
    from v2c.segment.train import CORPUS_TRAIN, generate_training_data

    row = (96, 72, "none", 1, 5, 0.0, (CORPUS_TRAIN, *FAMILY_GROUPS["features"]))
    with pytest.raises(ValueError, match="must be a row's only family"):
        generate_training_data(tmp_path, recipe=(row,))
