"""Generate synthetic scans in the folder layout of SCAN_FORMAT.md.

Scan i of a run is a pure function of (seed, i): its generator is `np.random.default_rng([seed, i])`, so the same
seed gives byte-identical files whatever the number of worker processes.

Depth files use DEPTH_SCALE = 0.0001 m per unit (0.1 mm; uint16 reaches 6.5535 m, beyond the 4 m range kept).
gt/depth_clean.png is quantised to that unit like depth.png; gt/depth_clean.npy keeps the exact float32 metres
(the 0.05 mm quantisation of the PNG would exceed the 1e-4 part-size exactness of the ground truth).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from v2c.executors import ExecutorConfig, run_tasks
from v2c.io_safe import atomic_dir
from v2c.labels import IGNORE, axis_class, label_of
from v2c.synth import appearance as appearance_mod
from v2c.synth import noise as noise_mod
from v2c.synth import occ, parts
from v2c.synth.families import FEATURE_FAMILIES
from v2c.synth.render import ANALYTIC, RenderConfig, render
from v2c.synth.scene import SceneConfig, sample_scene

GENERATOR = "v2c.synth/1"
DEPTH_SCALE = 1e-4  # metres per depth unit in depth.png and gt/depth_clean.png
#: Written last into a scan folder: its presence marks a complete scan (resuming runs look for it).
COMPLETE_MARKER = "gt/meta.json"


#: Failed scans named in a SynthError's message (the rest are counted): a broken worker pool fails every scan.
MAX_FAILURES_SHOWN = 5


class SynthError(RuntimeError):
    """Scans of a run that could not be generated (the others were); the message names the first few and why."""


@dataclass(frozen=True)
class SynthConfig:
    """One generator run (sizes in pixels, deflections relative to the part size)."""

    width: int = 640
    height: int = 480
    noise: str = "sensor"
    families: tuple[str, ...] = tuple(parts.FAMILIES)  # drawn uniformly; "cad" draws one of `cad_files`; the
    # feature-based families (families.FEATURE_FAMILIES) go to features.py
    cad_files: tuple[str, ...] = ()  # STEP files (paths) of the family "cad"
    linear_deflection_rel: float = 0.002  # tessellation chord error / part size
    angular_deflection_rad: float = 0.5
    png_compression: int = 1  # cv2 PNG level 0-9 (fixed, so files are reproducible)
    scene: SceneConfig = field(default_factory=SceneConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    appearance: str = "plain"  # "plain": today's look; "random": appearance.py (materials, printed art inside
    # faces, clutter, backgrounds, lights; colour and clutter depth only, from its own generator)
    framing: str = "fill"  # "fill": the bounding sphere fills 0.3-0.7 of the image (today); "extent": the
    # part's silhouette extent is 30-70 % of the smaller image side (SCAN_FORMAT.md), camera moved to match
    appearance_cfg: appearance_mod.AppearanceConfig = field(default_factory=appearance_mod.AppearanceConfig)
    framing_cfg: appearance_mod.FramingConfig = field(default_factory=appearance_mod.FramingConfig)


def scan_name(index: int) -> str:
    """Folder name of scan `index` inside the output directory."""
    return f"scan_{index:05d}"


def _pick_part(rng: np.random.Generator, cfg: SynthConfig) -> parts.RestPart:
    family = cfg.families[int(rng.integers(len(cfg.families)))]
    if family == "cad":
        if not cfg.cad_files:
            raise ValueError("family 'cad' needs STEP files (--cad DIR)")
        return parts.load_cad(Path(cfg.cad_files[int(rng.integers(len(cfg.cad_files)))]))
    if family in FEATURE_FAMILIES:
        from v2c.synth import features  # imported here: runs of the procedural families never need it

        return features.make_feature_part(family, rng)
    return parts.make_procedural(family, rng)


def face_labels(primitives: list[dict], axes_cam: np.ndarray) -> list[dict]:
    """Add `axis_label` and the 18-class `label` to primitives.json entries (in place; returned)."""
    for p in primitives:
        kind = p["type"]
        if kind not in ANALYTIC:
            p["axis_label"], p["label"] = None, IGNORE
        elif kind == "sphere":
            p["axis_label"], p["label"] = None, label_of("sphere", None)
        else:
            axis = p["params"]["normal"] if kind == "plane" else p["params"]["axis"]
            cls = axis_class(np.asarray(axis), axes_cam)
            p["axis_label"], p["label"] = cls.value, label_of(kind, cls)
    return primitives


def _write_png(path: Path, image: np.ndarray, level: int) -> None:
    if not cv2.imwrite(str(path), image, [cv2.IMWRITE_PNG_COMPRESSION, level]):
        raise OSError(f"{path}: could not write the PNG")


def _write_json(path: Path, obj: Any) -> None:
    """Write ``obj`` as JSON (sorted keys, indented) to ``path``."""
    path.write_text(json.dumps(obj, sort_keys=True, indent=1) + "\n")


def _to_units(depth_m: np.ndarray) -> np.ndarray:
    return np.clip(np.round(depth_m / DEPTH_SCALE), 0, 65535).astype(np.uint16)


def generate_scan(out_dir: Path, seed: int, index: int, cfg: SynthConfig = SynthConfig()) -> Path:
    """Render scan `index` of run `seed` into out_dir/scan_XXXXX and return that folder.

    The files are written into a temporary folder next to it (`v2c.io_safe.atomic_dir`), renamed into place when
    complete: a killed or retried generator leaves no half-written scan."""
    with atomic_dir(Path(out_dir) / scan_name(index), last=(COMPLETE_MARKER,)) as folder:
        _render_scan_into(folder, seed, index, cfg)
    return Path(out_dir) / scan_name(index)


def _render_scan_into(folder: Path, seed: int, index: int, cfg: SynthConfig) -> None:
    rng = np.random.default_rng([seed, index])
    rest = _pick_part(rng, cfg)
    lo, hi = rest.bbox
    scene = sample_scene(rng, lo, hi, cfg.width, cfg.height, cfg.scene)
    extra_meta: dict = {}
    if cfg.framing not in appearance_mod.FRAMINGS:
        raise ValueError(f"unknown framing {cfg.framing!r} (choose from {', '.join(appearance_mod.FRAMINGS)})")
    if cfg.appearance not in appearance_mod.APPEARANCES:
        raise ValueError(f"unknown appearance {cfg.appearance!r} (choose from {', '.join(appearance_mod.APPEARANCES)})")
    if cfg.framing == "extent":  # own generators: the main stream (part, noise) stays that of the plain scan
        size_mm = float(np.max(np.asarray(hi) - np.asarray(lo)))
        coarse = occ.tessellate(
            rest.shape,
            occ.faces_of(rest.shape),
            cfg.framing_cfg.mesh_deflection_rel * size_mm,
            cfg.angular_deflection_rad,
        )
        scene, info = appearance_mod.frame_scene(
            scene, coarse.vertices, np.random.default_rng([seed, index, appearance_mod.FRAMING_STREAM]), cfg.framing_cfg
        )
        extra_meta["framing"] = {"mode": "extent", **info}
    look = None
    if cfg.appearance == "random":
        scene, look = appearance_mod.sample_appearance(
            np.random.default_rng([seed, index, appearance_mod.APPEARANCE_STREAM]), scene, lo, hi, cfg.appearance_cfg
        )
    rot, trans = scene.world_to_cam[:, :3], scene.world_to_cam[:, 3]
    rest_to_cam_mm = 1000.0 * np.hstack(
        [rot @ scene.rest_to_world[:, :3], (rot @ scene.rest_to_world[:, 3] + trans)[:, None]]
    )

    gt = folder / "gt"
    gt.mkdir(parents=True, exist_ok=True)
    step_path = gt / "part.step"
    occ.write_step(occ.transform_shape(rest.shape, rest_to_cam_mm), step_path)
    shape = occ.read_step(step_path)  # face order and surfaces exactly as a reader of part.step sees them
    faces = occ.faces_of(shape)
    primitives = [dict(id=i, pixel_value=i + 1, **occ.face_primitive(f, 1e-3)) for i, f in enumerate(faces)]
    face_labels(primitives, scene.axes_cam)
    deflection_mm = cfg.linear_deflection_rel * scene.part_size_m * 1000.0
    mesh = occ.tessellate(shape, faces, deflection_mm, cfg.angular_deflection_rad)
    ren = render(
        scene,
        mesh.vertices * 1e-3,
        mesh.triangles,
        mesh.face_of_triangle,
        primitives,
        deflection_mm * 1e-3,
        cfg.render,
        look,
    )
    if look is not None:
        extra_meta["appearance"] = {"mode": "random", **look.info}

    lut = np.zeros(len(primitives) + 1, np.uint8)
    lut[1:] = [p["label"] for p in primitives]
    labels = lut[ren.faces]
    depth = noise_mod.apply_depth_noise(cfg.noise, ren.depth, ren.cos_incidence, rng)
    color = noise_mod.finish_color(ren.color, rng, cfg.noise)

    level = cfg.png_compression
    _write_png(folder / "color.png", cv2.cvtColor(color, cv2.COLOR_RGB2BGR), level)
    _write_png(folder / "depth.png", _to_units(depth), level)
    _write_png(folder / "mask.png", np.where(ren.faces > 0, 255, 0).astype(np.uint8), level)
    _write_json(
        folder / "camera.json",
        {"width": cfg.width, "height": cfg.height, "K": scene.K.tolist(), "depth_scale": DEPTH_SCALE},
    )
    _write_png(gt / "faces.png", ren.faces, level)
    _write_png(gt / "labels.png", labels, level)
    _write_png(gt / "depth_clean.png", _to_units(ren.depth), level)
    np.save(gt / "depth_clean.npy", ren.depth.astype(np.float32))
    _write_json(gt / "primitives.json", primitives)
    meta = {
        "generator": GENERATOR,
        "seed": int(seed),
        "index": int(index),
        "family": rest.family,
        "part": rest.info,
        "noise": {"profile": cfg.noise, "params": noise_mod.noise_params(cfg.noise)},
        "part_size_m": scene.part_size_m,
        "axes_cam": scene.axes_cam.tolist(),
        "depth_scale": DEPTH_SCALE,
        "scene": {**scene.info, "material": scene.material.name, "ground": scene.ground.kind},
        "mesh_deflection_m": deflection_mm * 1e-3,
        "dropped_pixels": ren.dropped,
        "units": "camera frame (OpenCV), metres; part.step in millimetres",
        **extra_meta,  # only with appearance / framing other than the defaults (default files unchanged)
    }
    _write_json(folder / COMPLETE_MARKER, _plain(meta))


def _plain(obj: Any) -> Any:
    """JSON-ready copy: numpy scalars/arrays to Python numbers/lists."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_plain(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _worker_init() -> None:
    cv2.setNumThreads(1)
    occ.silence_occt()


def _job(args: tuple[Path, int, int, SynthConfig]) -> Path:
    return generate_scan(*args)


def generate_dataset(
    out_dir: Path,
    n: int,
    seed: int,
    cfg: SynthConfig = SynthConfig(),
    jobs: int = 1,
    progress: bool = True,
    start: int = 0,
    executor: str | ExecutorConfig = "local",
) -> list[Path]:
    """Generate scans start..start+n-1 of run `seed` into `out_dir` and return their folders in index order.

    executor: "local" (``jobs`` processes; 1 = this process) or an `v2c.executors.ExecutorConfig` (e.g. a Ray
    cluster; its own jobs apply). A scan that fails does not stop the others: `SynthError` names every failed scan
    once the rest are written. Raises `v2c.executors.ExecutorError` (nothing written) when the executor cannot
    be used.
    """
    from tqdm import tqdm

    out_dir = Path(out_dir)
    where = executor if isinstance(executor, ExecutorConfig) else ExecutorConfig(kind=executor, jobs=jobs)
    tasks = [(out_dir, seed, i, cfg) for i in range(start, start + n)]
    results = run_tasks(_job, tasks, where, initializer=_worker_init)
    out_dir.mkdir(parents=True, exist_ok=True)
    if where.kind == "local" and (where.jobs or 1) <= 1:
        occ.silence_occt()
    done: dict[int, Path] = {}
    failed: list[str] = []
    with tqdm(total=n, unit="scan", disable=not progress) as bar:
        for task, path, exc in results:
            if exc is None:
                done[task[2]] = path
            else:
                failed.append(f"{scan_name(task[2])}: {type(exc).__name__}: {exc}")
            bar.update()
    if failed:
        shown = sorted(failed)[:MAX_FAILURES_SHOWN]
        more = f"; and {len(failed) - len(shown)} more" if len(failed) > len(shown) else ""
        raise SynthError(f"{len(failed)} of {n} scans failed ({out_dir}): " + "; ".join(shown) + more)
    return [done[i] for i in sorted(done)]
