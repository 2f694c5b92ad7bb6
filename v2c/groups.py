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


class UnionFind:
    """Disjoint sets over hashable items (path-halving find, union by the caller's order): `union(a, b)` puts a's
    set under b's root; `groups()` lists the sets of two or more items, each in the order the items were given."""

    def __init__(self, items: Iterable) -> None:
        self._parent = {i: i for i in items}

    def find(self, i: object) -> object:
        """The root of ``i``'s set."""
        parent = self._parent
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def union(self, a: object, b: object) -> None:
        """Join the sets of ``a`` and ``b`` (under b's root)."""
        self._parent[self.find(a)] = self.find(b)

    def members(self, roots: Sequence) -> list:
        """The items whose root is one of ``roots``, in the order the items were given."""
        return [i for i in self._parent if self.find(i) in roots]

    def groups(self) -> list[list]:
        """The sets of two or more items, each in the order the items were given."""
        out: dict = {}
        for i in self._parent:
            out.setdefault(self.find(i), []).append(i)
        return [g for g in out.values() if len(g) > 1]
