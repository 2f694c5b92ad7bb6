"""Grouping helpers shared by the stages."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np


def groups_sharing_keys(keys: Sequence[Iterable]) -> list[np.ndarray]:
    """Connected groups of items, two items being connected when they share a key (directly or through other
    items): union-find over ``keys[i]``, the keys of item i. Returns arrays of item indices, each ascending, in
    the order of their first item."""
    lab = list(range(len(keys)))

    def find(i: int) -> int:
        while lab[i] != i:
            lab[i] = lab[lab[i]]
            i = lab[i]
        return i

    first: dict = {}
    for i, ks in enumerate(keys):
        for k in ks:
            if k in first:
                lab[find(i)] = find(first[k])
            else:
                first[k] = i
    roots = np.array([find(i) for i in range(len(keys))], dtype=int)
    return [np.flatnonzero(roots == r) for r in dict.fromkeys(roots.tolist())]
