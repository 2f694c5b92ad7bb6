"""The scans of a `v2c bench` run: generated once into a cache folder, or taken from existing scan folders.

Generated scans go into a folder keyed by the generator version, noise profile, image size, seed and CAD files
(`scan_cache_dir`); scan i of a seed is a pure function of (seed, i), so a run of n scans reuses the first n of any
earlier run with the same key and generates only what is missing (`prepare_scans`). The cache lives outside the
repository: ``$V2C_BENCH_CACHE``, else ``~/.cache/v2c/bench``.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
from pathlib import Path

from v2c.bench.config import BenchConfig, executor_of


def default_cache_dir() -> Path:
    """$V2C_BENCH_CACHE, else ~/.cache/v2c/bench."""
    env = os.environ.get("V2C_BENCH_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "v2c" / "bench"


def cad_files(cad_dir: Path | None) -> tuple[str, ...]:
    """Sorted STEP files (.step/.stp, any case) of a folder; () for None."""
    if cad_dir is None:
        return ()
    files = sorted(str(p) for p in Path(cad_dir).iterdir() if p.suffix.lower() in (".step", ".stp"))
    if not files:
        raise ValueError(f"{cad_dir}: no .step/.stp files")
    return tuple(files)


def scan_cache_dir(cfg: BenchConfig) -> Path:
    """The cache folder of a run's scans: named by noise, size and seed, suffixed with a hash of everything that
    changes the scans (generator version, noise, size, seed, CAD file names and sizes)."""
    from v2c.synth.dataset import GENERATOR

    cads = cad_files(cfg.cad_dir)
    key = {
        "generator": GENERATOR,
        "noise": cfg.noise,
        "size": list(cfg.size),
        "seed": cfg.seed,
        "cad": [[Path(f).name, Path(f).stat().st_size] for f in cads],
    }
    digest = hashlib.sha1(json.dumps(key, sort_keys=True).encode()).hexdigest()[:8]
    kind = "cad" if cads else "synth"
    name = f"{kind}_{cfg.noise}_{cfg.size[0]}x{cfg.size[1]}_s{cfg.seed}_{digest}"
    return (cfg.cache_dir or default_cache_dir()) / name


def scan_complete(scan: Path) -> bool:
    """Whether a scan folder was written to the end (the generator writes gt/meta.json last)."""
    return (scan / "gt" / "meta.json").is_file()


def prepare_scans(cfg: BenchConfig, progress: bool = True) -> list[Path]:
    """The n scan folders of a run: from ``scans_dir``, or from the cache (generating the missing ones with
    ``jobs`` processes)."""
    from v2c.bench.fit import scan_dirs

    if cfg.scans_dir is not None:
        dirs = scan_dirs([cfg.scans_dir])[: cfg.n]
        if not dirs:
            raise ValueError(f"{cfg.scans_dir}: no scan folders (folders with camera.json)")
        return dirs
    from v2c.synth.dataset import SynthConfig, generate_dataset, scan_name

    folder = scan_cache_dir(cfg)
    dirs = [folder / scan_name(i) for i in range(cfg.n)]
    missing = [i for i, d in enumerate(dirs) if not scan_complete(d)]
    if missing:
        cads = cad_files(cfg.cad_dir)
        synth = SynthConfig(
            width=cfg.size[0],
            height=cfg.size[1],
            noise=cfg.noise,
            **({"families": ("cad",), "cad_files": cads} if cads else {}),
        )
        start = missing[0]
        if progress:
            print(f"generating scans {start}..{cfg.n - 1} into {folder}", file=sys.stderr)
        generate_dataset(
            folder,
            cfg.n - start,
            cfg.seed,
            synth,
            jobs=max(1, cfg.jobs),
            progress=progress,
            start=start,
            executor=executor_of(cfg),
        )
        (folder / "manifest.json").write_text(
            json.dumps(
                {
                    "seed": cfg.seed,
                    "noise": cfg.noise,
                    "size": list(cfg.size),
                    "cad": list(cads),
                    "n": max(cfg.n, _manifest_n(folder)),
                },
                indent=1,
            )
            + "\n"
        )
    return dirs


def _manifest_n(folder: Path) -> int:
    """The scan count the cache folder's manifest.json records (0 without a readable one)."""
    try:
        return int(json.loads((folder / "manifest.json").read_text())["n"])
    except (OSError, ValueError, KeyError):
        return 0
