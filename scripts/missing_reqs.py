"""Print the requirements of pyproject.toml (dependencies + the dev and ray extras) that the running environment
lacks.

Used by scripts/setup.sh to bring an existing .venv up to date without re-resolving the whole stack: a full
`pip install -e .[dev]` re-installs cadquery-ocp-novtk (build123d's declared dependency, removed on purpose by
scripts/ocp_single.py), which overwrites the shared OCP binary and breaks `import cadquery` for everyone using the
venv until it is repaired. Installing only what is missing leaves the OCP packages alone.

One requirement per line, in pip syntax; nothing printed when all are satisfied. Exit 0.
"""

from __future__ import annotations

import importlib.metadata as md
import sys
import tomllib
from pathlib import Path

from packaging.requirements import Requirement


def missing_requirements(pyproject: Path, extras: tuple[str, ...] = ("dev", "ray")) -> list[str]:
    data = tomllib.loads(pyproject.read_text(encoding="utf-8"))
    project = data["project"]
    reqs = list(project.get("dependencies", []))
    for extra in extras:
        reqs += project.get("optional-dependencies", {}).get(extra, [])
    missing = []
    for text in reqs:
        req = Requirement(text)
        if req.marker is not None and not req.marker.evaluate():
            continue
        try:
            version = md.version(req.name)
        except md.PackageNotFoundError:
            missing.append(text)
            continue
        if req.specifier and not req.specifier.contains(version, prereleases=True):
            missing.append(text)
    return missing


if __name__ == "__main__":
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1]
    for line in missing_requirements(root / "pyproject.toml"):
        print(line)
