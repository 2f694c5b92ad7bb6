"""Retired: the fixture clearance measurement is ``v2c bench --stage fixtures`` (`v2c.bench.fixtures`). This
wrapper passes its old options on:

    PYTHONPATH=. python scripts/fixture_clearance.py --seed 7100 --n 20 --k 0,1,2,3

is ``v2c bench --stage fixtures --seed 7100 --n 20 --clearance-k 0,1,2,3 --families procedural``.
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    """Parse the old options and run `v2c bench --stage fixtures` with them."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=7100)
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--k", default="0,1,2,3")
    ap.add_argument("--families", default="procedural")
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    from v2c.cli import main as cli

    args = ["bench", "--stage", "fixtures", "--seed", str(a.seed), "--n", str(a.n), "--clearance-k", a.k]
    args += ["--families", a.families] + (["--json", a.json] if a.json else [])
    return cli.main(args, standalone_mode=False) or 0


if __name__ == "__main__":
    sys.exit(main())
