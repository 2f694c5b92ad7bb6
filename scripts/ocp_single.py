"""Check that exactly one distribution owns the `OCP/` package (the OpenCASCADE bindings), and restore it through
pip when another one crept in.

Why: cadquery 2.8.0 requires `cadquery-ocp` (bindings built with VTK) and build123d 0.12.0 requires
`cadquery-ocp-novtk` (the same OCCT 7.9.3 bindings without VTK). Both write the same files into
`site-packages/OCP/`; whichever is unpacked last wins the shared `OCP/OCP.cpython-*.so`. If it is the no-VTK one,
`import cadquery` fails (cadquery.occ_impl.shapes imports OCP.IVtkOCC), and uninstalling either distribution later
deletes files the other one needs. No version pin avoids it: both are hard requirements of the pinned packages.

scripts/setup.sh settles it before pip resolves anything: it installs a files-less stand-in named
`cadquery-ocp-novtk` (scripts/shims/cadquery-ocp-novtk), so build123d's requirement is met and the no-VTK wheel is
never installed; `cadquery-ocp` (a strict superset: the same 642 OCP modules plus the 4 IVtk ones) owns OCP/ alone,
build123d runs on it unchanged, and `pip check` is clean. Nothing is deleted from site-packages by hand.

This script checks that state. With --fix, a second owner that got in anyway (e.g. `pip install
cadquery-ocp-novtk` by hand, or a venv of an older recipe) is removed with `pip uninstall`, and `cadquery-ocp` is
then reinstalled (same version, --no-deps) when any of its OCP/ files is missing or differs from its RECORD;
--hashes checks those hashes even when no second owner was found.

Usage: python scripts/ocp_single.py [--fix] [--hashes]. Exit 0 when exactly one OCP distribution remains.
Runs with the venv's interpreter (it inspects the environment it runs in).
"""

from __future__ import annotations

import base64
import hashlib
import importlib.metadata as md
import subprocess
import sys
from pathlib import Path

KEEP = "cadquery-ocp"


def _norm(name: str) -> str:
    return name.lower().replace("_", "-").replace(".", "-")


def ocp_distributions() -> dict[str, md.Distribution]:
    """Installed distributions that list files under OCP/ (normalised name -> distribution)."""
    out: dict[str, md.Distribution] = {}
    for d in md.distributions():
        files = d.files or []
        if any(str(f).startswith("OCP/") for f in files):
            out[_norm(d.metadata["Name"])] = d
    return out


def _hash(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 22), b""):
            h.update(block)
    return "sha256=" + base64.urlsafe_b64encode(h.digest()).rstrip(b"=").decode()


def mismatched_files(dist: md.Distribution) -> list[str]:
    """OCP/ files of `dist` whose content is missing or differs from its RECORD (skips .pyc)."""
    bad = []
    for f in dist.files or []:
        s = str(f)
        if not s.startswith("OCP/") or f.hash is None or s.endswith(".pyc"):
            continue
        p = Path(f.locate())
        if not p.is_file() or _hash(p) != f"{f.hash.mode}={f.hash.value}":
            bad.append(s)
    return bad


def main(argv: list[str]) -> int:
    fix, hashes = "--fix" in argv, "--hashes" in argv
    dists = ocp_distributions()
    if KEEP not in dists:
        print(
            f"[ocp] {KEEP} is not installed (found: {sorted(dists) or 'none'}); cadquery 2.8.0 needs it",
            file=sys.stderr,
        )
        return 1
    keep = dists[KEEP]
    others = {n: d for n, d in dists.items() if n != KEEP}
    if others and not fix:
        print(
            f"[ocp] {len(dists)} distributions own OCP/: {sorted(dists)}; run scripts/ocp_single.py --fix",
            file=sys.stderr,
        )
        return 1
    for name, d in others.items():
        print(f"[ocp] uninstalling {name} {d.version} (pip); {KEEP} is checked and reinstalled below if it lost files")
        subprocess.run([sys.executable, "-m", "pip", "uninstall", "-q", "-y", name], check=True)
    if others or hashes:
        bad = mismatched_files(keep)
        if bad:
            print(f"[ocp] {len(bad)} OCP/ files differ from {KEEP} {keep.version} (e.g. {bad[0]}): reinstalling it")
            subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "pip",
                    "install",
                    "-q",
                    "--no-deps",
                    "--force-reinstall",
                    f"{KEEP}=={keep.version}",
                ],
                check=True,
            )
            md_dists = ocp_distributions()
            bad = mismatched_files(md_dists[KEEP])
            if bad:
                print(f"[ocp] still {len(bad)} mismatched OCP/ files after reinstall", file=sys.stderr)
                return 1
    left = ocp_distributions()
    if list(left) != [KEEP]:
        print(f"[ocp] expected only {KEEP} to own OCP/, found {sorted(left)}", file=sys.stderr)
        return 1
    print(f"[ocp] one OCP distribution: {KEEP} {left[KEEP].version}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
