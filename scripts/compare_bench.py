"""Compare two `v2c bench --json` files per scan on every metric, timings left out (behaviour-preserving changes).

    python scripts/compare_bench.py before.json after.json     # exit 0 when identical, 1 otherwise

Every key under ``rows`` and ``summary`` is compared exactly (NaN equals NaN), except keys that hold wall or CPU
times (names containing "_s", "seconds", "time", "wall", "cpu").
"""

from __future__ import annotations

import json
import math
import sys
from typing import Any

TIMING_MARKERS = ("_s", "seconds", "time", "wall", "cpu")


def is_timing(key: str) -> bool:
    """True for a key that holds a duration (differs run to run by nature)."""
    return any(t in key.lower() for t in TIMING_MARKERS)


def differences(x: Any, y: Any, path: str = "") -> list[tuple[str, Any, Any]]:
    """(path, before, after) for every leaf that differs between two JSON values."""
    if isinstance(x, dict) and isinstance(y, dict):
        out = []
        for k in sorted(set(x) | set(y)):
            if not is_timing(k):
                out += differences(x.get(k), y.get(k), f"{path}/{k}")
        return out
    if isinstance(x, list) and isinstance(y, list) and len(x) == len(y):
        return [d for i, (u, v) in enumerate(zip(x, y)) for d in differences(u, v, f"{path}/{i}")]
    same = x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x) and math.isnan(y))
    return [] if same else [(path, x, y)]


def main(before: str, after: str) -> int:
    a, b = (json.load(open(p)) for p in (before, after))
    diffs = differences(a["rows"], b["rows"], "rows") + differences(a["summary"], b["summary"], "summary")
    print(f"{len(a['rows'])} rows before, {len(b['rows'])} after; {len(diffs)} differences")
    for d in diffs[:40]:
        print("  ", *d)
    return 1 if diffs else 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
