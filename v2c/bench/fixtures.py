"""`v2c bench --stage fixtures`: fixtures designed with the default settings on reconstructions of generated scans,
checked against the true part (docs/fixtures.md, "Measured on generated parts").

For every scan of a chosen set (seed, part families), the scan is reconstructed (learned segmentation by default)
and every fixture kind that finds a reference (corner, pin, cradle, nest) is designed with ``design_fixture``'s
defaults (for each ``clearance_k`` asked, the default being `fixtures_design.design.CLEARANCE_K`), then checked
against the scan's true part (``gt/part.step``):

- **cut**: the common volume of fixture and true part exceeds ``cut_share`` (0.1 %) of the fixture's volume;
- **touch**: the median distance from points on the fixture's mating faces to the true part is at most
  ``touch_mm`` (1 mm; `fixtures_design.verify.check_mating` against the whole part).

Both are measured twice: **camera frame**, the true part where the scan puts it (the fixture judged where the
reconstruction placed it, the scan's depth offset included), and **seated**, the true part first pushed home into
the fixture as a user puts it in (`fixtures_design.seat.seat_part`: a translation along the directions the fixture
constrains until its mating faces hold the part). A seat that moves the part more than ``seat_clearance_factor`` x
the clearance + ``seat_bound_mm`` (+ the design's standoff, a nest's floor gap) is a failed design: it counts as
cutting and not touching.

From the ground truth alone (``gt/primitives.json``, ``gt/faces.png``, ``gt/depth_clean.npy``, ``gt/part.step``) each
scan is marked as having a visible **hole** (a cylinder of at least ``min_visible_px`` pixels showing at least
``min_arc_deg`` of arc, whose seen wall faces away from the camera: concave, and which the true part closes round its
axis: not a flute or a slot's end) and a visible **horizontal cylinder** (a convex one whose axis lies within
``max_tilt_deg`` of horizontal, with room under it for the default cradle: not a housing standing on its base); the
pin and cradle qualification rates are the shares of those scans on which a pin / cradle was designed. The looser
marks (every concave cylinder, every horizontal convex one) are reported beside them (`visible_cylinders`). Scans
are generated once into a cache folder keyed by generator version, noise, size, seed and families.
"""

from __future__ import annotations

import hashlib
import json
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from v2c.bench.cache import default_cache_dir
from v2c.primitives.directions import tangent_basis

KINDS = ("corner", "pin", "cradle", "nest")


def _default_k() -> tuple[float, ...]:
    from fixtures_design.design import CLEARANCE_K

    return (float(CLEARANCE_K),)


@dataclass(frozen=True)
class FixtureBenchConfig:
    """One run of the fixture bench. Lengths in millimetres, angles in degrees, areas in pixels."""

    n: int | None = 20  # scans (with a ``suite``: the first n of its scans, None every one)
    seed: int = 7100  # generator seed (a training seed: never 0, the benchmarks' seed)
    families: tuple[str, ...] = ("block", "shaft", "flange", "knob", "turned", "bracket")  # drawn uniformly
    noise: str = "sensor"
    size: tuple[int, int] = (640, 480)  # (width, height) pixels
    segmentation: str = "learned"
    weights: Path | None = None  # learned segmenter weights (None: the shipped v2c/segment/weights/unet.pt)
    kinds: tuple[str, ...] = KINDS
    clearance_k: tuple[float, ...] = field(default_factory=_default_k)  # k of the default clearance, each measured
    min_confidence: float | None = None  # references' calibrated probability floor (None: design_fixture's default)
    cut_share: float = 0.001  # fraction of the fixture's volume: more common volume with the true part "cuts"
    touch_mm: float = 1.0  # mm: median distance of the mating faces to the true part at most this "touches"
    mating_points: int = 240  # points sampled over all mating faces of a design (at least 2 per face)
    min_visible_px: int = (
        100  # pixels: a gt cylinder (its faces together) smaller than this in faces.png is not "visible"
    )
    min_arc_deg: float = 120.0  # degrees of arc a gt cylinder must show to count (a fillet spans 90)
    max_tilt_deg: float = 30.0  # degrees: a cylinder axis within this of horizontal is "horizontal" (as the cradle)
    hole_min_closure: float = 0.75  # a concave gt cylinder is a hole a pin can take when the true part's material
    # lies just beyond its radius in at least this share of the directions round its axis (fraction; a drilled hole
    # 1, a flute round a knob or a slot's round end at most 0.5: open grooves, no pin enters them)
    probe_mm: float = 0.3  # mm: how far beyond (or inside) a gt cylinder's radius the true part is probed, at least
    probe_rel: float = 0.05  # ... and this share of the radius (fraction)
    probe_directions: int = 36  # directions round the axis probed for a hole's closure (count)
    cache_dir: Path | None = None  # None: v2c.bench.cache.default_cache_dir()
    suite: str | None = None  # a CAD corpus split instead of the generated ``families``: "corpus-train",
    # "corpus-val" (the splits one may look at) or "unseen" (the test split's parts only; its leave-out families are
    # ``families="leave-out"``), rendered as `v2c.bench.suite` renders them (two views per part, the suites' cache)
    seat_clearance_factor: float = 3.0  # a seat moving the true part more than this x the clearance + seat_bound_mm
    seat_bound_mm: float = 2.0  # (mm; + a nest's floor gap) fails the design: the lead's rule for issue 18, not tuned


def cache_folder(cfg: FixtureBenchConfig) -> Path:
    """The cache folder of a run's scans: ``fixtures_<noise>_<W>x<H>_s<seed>_<digest>`` (digest: generator version,
    noise, size, seed, families)."""
    from v2c.synth.dataset import GENERATOR

    key = {
        "generator": GENERATOR,
        "noise": cfg.noise,
        "size": list(cfg.size),
        "seed": cfg.seed,
        "families": list(cfg.families),
    }
    digest = hashlib.sha1(json.dumps(key, sort_keys=True).encode()).hexdigest()[:8]
    name = f"fixtures_{cfg.noise}_{cfg.size[0]}x{cfg.size[1]}_s{cfg.seed}_{digest}"
    return (cfg.cache_dir or default_cache_dir()) / name


FIXTURE_SUITES = ("corpus-train", "corpus-val", "unseen")  # `FixtureBenchConfig.suite`'s values


def prepare_scans(cfg: FixtureBenchConfig, log: Callable[[str], None] | None = None) -> list[Path]:
    """The ``n`` scan folders of a run, rendering the missing ones (one process; scan i is a function of
    (seed, i, families)); with ``cfg.suite`` the corpus split's scans as `v2c.bench.suite` plans them (a part
    that cannot be rendered is left out and logged)."""
    from v2c.bench.cache import scan_complete
    from v2c.synth.dataset import SynthConfig, generate_scan, scan_name

    if cfg.suite is not None:
        from v2c.bench.config import BenchConfig
        from v2c.bench.suite import CORPUS, SuiteConfig, plan_scans, render_missing

        if cfg.suite not in FIXTURE_SUITES:
            raise ValueError(f"suite {cfg.suite!r}: expected one of {', '.join(FIXTURE_SUITES)}")
        bench = BenchConfig(noise=cfg.noise, size=cfg.size, cache_dir=cfg.cache_dir, ablations=("full",))
        planned, _ = plan_scans(SuiteConfig(suite=cfg.suite, bench=bench, families=()))
        planned = [s for s in planned if s.source == CORPUS][: cfg.n]
        errors = render_missing(planned, jobs=1, progress=log is not None)
        for label, err in errors.items():
            if log:
                log(f"{label}: not rendered: {err}")
        return [s.path for s in planned if s.label not in errors]
    if cfg.n is None:
        raise ValueError("n: generated families need a number of scans (None is for a suite's every scan)")
    folder = cache_folder(cfg)
    synth = SynthConfig(width=cfg.size[0], height=cfg.size[1], noise=cfg.noise, families=tuple(cfg.families))
    dirs = []
    for i in range(cfg.n):
        d = folder / scan_name(i)
        if not scan_complete(d):
            if log:
                log(f"rendering {d}")
            folder.mkdir(parents=True, exist_ok=True)
            generate_scan(folder, cfg.seed, i, synth)
        dirs.append(d)
    return dirs


def _cylinders(primitives: list[dict]) -> list[tuple[np.ndarray, np.ndarray, float, list[int]]]:
    """The gt cylinder faces grouped by surface (a generated cylinder is often split into several faces): one
    (unit axis, origin, radius (m), pixel values) per distinct (axis line, radius), to 1e-5 m."""
    groups: list[tuple[np.ndarray, np.ndarray, float, list[int]]] = []
    for p in primitives:
        if p["type"] != "cylinder":
            continue
        axis = np.asarray(p["params"]["axis"], float)
        axis /= np.linalg.norm(axis)
        origin, radius = np.asarray(p["params"]["origin"], float), float(p["params"]["radius"])
        for a, o, r, vals in groups:
            off = (origin - o) - ((origin - o) @ a) * a
            if abs(r - radius) < 1e-6 and abs(abs(a @ axis) - 1) < 1e-6 and np.linalg.norm(off) < 1e-5:
                vals.append(int(p["pixel_value"]))
                break
        else:
            groups.append((axis, origin, radius, [int(p["pixel_value"])]))
    return groups


def _arc_deg(radial: np.ndarray, axis: np.ndarray) -> float:
    """Degrees of arc around ``axis`` that the unit radial directions (N, 3) cover (360 minus the largest gap)."""
    u = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(axis, u)
    ang = np.sort(np.degrees(np.arctan2(radial @ v, radial @ u)))
    gaps = np.diff(np.concatenate([ang, [ang[0] + 360.0]]))
    return float(360.0 - gaps.max())


def _inside_probe(step_path: Path) -> Callable[[np.ndarray], np.ndarray]:
    """A test of points (N, 3, the STEP's frame, mm) against the solid of ``step_path``: True where strictly
    inside (OCCT's solid classifier)."""
    from OCP.BRepClass3d import BRepClass3d_SolidClassifier
    from OCP.gp import gp_Pnt
    from OCP.TopAbs import TopAbs_IN

    from v2c.synth.occ import read_step

    cls = BRepClass3d_SolidClassifier(read_step(step_path))

    def inside(p: np.ndarray) -> np.ndarray:
        out = np.zeros(len(p), bool)
        for k, q in enumerate(np.asarray(p, float)):  # loop over the probes (a few dozen per cylinder)
            cls.Perform(gp_Pnt(*map(float, q)), 1e-6)
            out[k] = cls.State() == TopAbs_IN
        return out

    return inside


def _ring(axis: np.ndarray, n: int) -> np.ndarray:
    """(n, 3) unit directions perpendicular to ``axis``, evenly round it."""
    u, v = tangent_basis(axis)
    phi = 2 * np.pi * np.arange(n) / n
    return np.outer(np.cos(phi), u) + np.outer(np.sin(phi), v)


def visible_cylinders(scan: Any, cfg: FixtureBenchConfig) -> dict[str, bool]:
    """From a scan's ground truth, the cylinders a pin or a cradle could take, among those seen (at least
    ``min_visible_px`` pixels of ``gt/faces.png`` showing ``min_arc_deg`` of arc):

    - ``hole``: a concave cylinder (its seen wall faces away from the camera: the median over its pixels of the
      radial direction dotted with the direction to the camera) that the true part closes round its axis: at the
      seen wall's median height, material just beyond the radius in ``hole_min_closure`` of the directions. A
      drilled, blind or counterbored hole; not a flute round a knob, a groove or a slot's end;
    - ``horizontal_cylinder``: a convex cylinder whose axis is within ``max_tilt_deg`` of horizontal (up = the
      part's Z, meta axes_cam) and whose underside leaves room for the default cradle (`_free_underside`): a shaft,
      a boss standing out sideways; not a housing standing on or through a base plate, whose plate the cradle's
      block would cut;
    - ``hole_any`` / ``horizontal_cylinder_any``: the same without the true part's closure / free underside (the
      bench's marks before 2026-11-27 evening: every concave cylinder, every horizontal convex one).

    The true part is probed at ``max(probe_mm, probe_rel x radius)`` beyond or inside the radius (gt/part.step, the
    camera frame in mm)."""
    from fixtures_design.references import radial_directions, seen_from_outside
    from v2c.camera import backproject

    gt = scan.gt
    up = np.asarray(gt.meta["axes_cam"], float)[2]
    up /= np.linalg.norm(up)
    pts = backproject(gt.depth_clean, scan.K)
    out = {"hole": False, "horizontal_cylinder": False, "hole_any": False, "horizontal_cylinder_any": False}
    inside: Callable[[np.ndarray], np.ndarray] | None = None
    for axis, origin, radius, vals in _cylinders(gt.primitives):
        pix = np.isin(gt.faces, vals) & (gt.depth_clean > 0)
        if int(pix.sum()) < cfg.min_visible_px:
            continue
        q = pts[pix] - origin
        radial = radial_directions(pts[pix], origin, axis)
        if _arc_deg(radial, axis) < cfg.min_arc_deg:  # a fillet (90 deg), not a hole or a boss
            continue
        convex = seen_from_outside(pts[pix], radial)  # a boss shows the side facing the camera
        horizontal = abs(float(axis @ up)) <= np.sin(np.radians(cfg.max_tilt_deg))
        if convex and not horizontal:
            continue
        out["hole_any" if not convex else "horizontal_cylinder_any"] = True
        inside = inside or _inside_probe(Path(gt.step_path))
        r_mm = 1000.0 * radius
        delta = max(cfg.probe_mm, cfg.probe_rel * r_mm)
        centre = 1000.0 * (origin + float(np.median(q @ axis)) * axis)  # on the axis, at the seen wall's height
        if not convex:
            ring = _ring(axis, cfg.probe_directions)
            closure = float(np.mean(inside(centre + (r_mm + delta) * ring)))
            out["hole"] |= closure >= cfg.hole_min_closure
        else:
            out["horizontal_cylinder"] |= _free_underside(inside, axis, up, pts[pix], origin, r_mm, delta, cfg)
    return out


def _free_underside(
    inside: Callable[[np.ndarray], np.ndarray],
    axis: np.ndarray,
    up: np.ndarray,
    seen: np.ndarray,
    origin: np.ndarray,
    r_mm: float,
    delta: float,
    cfg: FixtureBenchConfig,
) -> bool:
    """Whether the true part leaves room under a convex cylinder for the default cradle (`CradleParams`' U block:
    the groove's wrap and the wall below and beside it, ``delta`` mm clear of the cylinder): no probe of that
    region is inside the part, at three heights along the seen wall (``seen``: its points, metres), and the part
    has material just inside the cylinder's lowest line (it is the part's own surface, not a hole's far wall)."""
    from fixtures_design.cradle import CradleParams, cradle_axes, u_block_extent

    x_ax, y_ax, _ = cradle_axes(axis, up)
    w, y_top, y_bottom = u_block_extent(r_mm, CradleParams())
    xs, ys = np.meshgrid(np.linspace(-w, w, 9), np.linspace(y_bottom, y_top, 5))
    keep = np.hypot(xs, ys) > r_mm + delta
    grid = np.outer(xs[keep], x_ax) + np.outer(ys[keep], y_ax)
    heights = 1000.0 * np.percentile((seen - origin) @ axis, [20, 50, 80])
    base = 1000.0 * origin
    probes = np.concatenate([base + h * axis + grid for h in heights])
    body = base + heights[1] * axis - (r_mm - delta) * y_ax
    return bool(inside(body[None])[0] and not inside(probes).any())


def evaluate_scan(
    scan_dir: Path, cfg: FixtureBenchConfig, log: Callable[[str], None] | None = None, vbrep: Any = None
) -> dict:
    """One scan: its reconstruction, every kind at every k designed and checked. Returns ``{"scan", "family",
    "hole", "horizontal_cylinder", "seconds_reconstruct", "designs": [...]}``; a design row has kind, k, ok
    (False: no reference, with ``error``), clearance (mm), sigma_mm (what the clearance came from, `_design_sigma`),
    probability, cut_mm3, cut_share, cuts, mating_median_mm, mating_max_mm, touches (camera frame), and seated:
    seat_move_mm (the translation (3,), output frame mm), seat_mm (its length), seat_push_mm, seat_bound_mm, seat_ok,
    seat_reason, seat_overlap_mm, seated_cut_mm3, seated_cut_share, seated_mating_median_mm, seated_mating_max_mm
    (None when the seat failed), seated_cuts, seated_touches.
    ``vbrep``: the scan's reconstruction when already made."""
    from fixtures_design.assembly import true_part
    from fixtures_design.design import design_fixture
    from fixtures_design.model import transformed
    from fixtures_design.references import NoReferenceError
    from fixtures_design.run import ground_height
    from fixtures_design.seat import SeatConfig, seat_part
    from fixtures_design.verify import check_mating, interference
    from v2c.bench.workers import segment_scan
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan

    scan = load_scan(scan_dir)
    t0 = time.perf_counter()
    if vbrep is None:
        vbrep = reconstruct(scan, segment_scan(scan, cfg.segmentation, cfg.weights))
    row: dict[str, Any] = {
        "scan": str(scan_dir),
        "family": scan.gt.meta.get("family"),
        **visible_cylinders(scan, cfg),
        "seconds_reconstruct": time.perf_counter() - t0,
        "designs": [],
    }
    ground = ground_height(scan, vbrep)
    valid = scan.valid
    points = scan.points()[valid]  # what the depth shows of the part: designs holding it are refused
    clean = scan.gt.depth_clean
    both = valid & (clean > 0)
    # The scan's depth offset over the part (diagnostic, from the ground truth): median of depth - clean depth.
    row["depth_bias_mm"] = float(1000.0 * np.median((scan.depth - clean)[both])) if both.any() else None
    parts: dict[tuple, Any] = {}
    seat_cfg = SeatConfig(bound_clearance_factor=cfg.seat_clearance_factor, bound_mm=cfg.seat_bound_mm)
    extra = {} if cfg.min_confidence is None else {"min_confidence": cfg.min_confidence}
    for kind in cfg.kinds:
        for k in cfg.clearance_k:
            d: dict[str, Any] = {"kind": kind, "k": float(k)}
            try:
                fx = design_fixture(
                    vbrep, kind, None, clearance_k=float(k), ground_height=ground, points=points, **extra
                )
            except (NoReferenceError, ValueError) as exc:
                d.update(ok=False, error=str(exc).splitlines()[0][:300])
                row["designs"].append(d)
                continue
            key = (tuple(np.round(fx.fmap.rotation, 12).ravel()), tuple(np.round(fx.fmap.origin, 12)))
            if key not in parts:
                parts[key] = true_part(scan.gt.step_path, fx.fmap)
            tp = parts[key]
            vol, share = interference(fx, tp)
            per_face = max(2, cfg.mating_points // max(1, len(fx.mating_faces)))
            m = check_mating(fx, tp, None, max_points_per_face=per_face)
            ref = fx.reference if kind != "nest" else None  # a nest's reference is its footprint
            d.update(
                ok=True,
                clearance=float(fx.params.clearance),
                sigma_mm=_design_sigma(vbrep, kind, ref),
                probability=None if ref is None else float(ref.confidence),
                edge=None if ref is None else int(ref.edge_id),
                cut_mm3=float(vol),
                cut_share=float(share),
                cuts=bool(share > cfg.cut_share),
                mating_median_mm=m.median,
                mating_max_mm=m.max,
                touches=bool(m.median <= cfg.touch_mm),
            )
            seat = seat_part(fx, tp, seat_cfg)
            s_vol = s_share = s_median = s_max = None  # a failed seat is not measured: it cuts and does not touch
            if seat.ok:
                move = np.eye(4)
                move[:3, 3] = seat.move
                seated = transformed(tp, move)
                s_vol, s_share = interference(fx, seated)
                s_m = check_mating(fx, seated, None, max_points_per_face=per_face)
                s_median, s_max = s_m.median, s_m.max
            d.update(
                seat_move_mm=[float(x) for x in seat.move],
                seat_mm=seat.move_mm,
                seat_push_mm=seat.push_mm,
                seat_bound_mm=seat.bound_mm,
                seat_ok=seat.ok,
                seat_reason=seat.reason,
                seat_overlap_mm=seat.overlap_mm,
                seated_cut_mm3=s_vol,
                seated_cut_share=s_share,
                seated_mating_median_mm=s_median,
                seated_mating_max_mm=s_max,
                seated_cuts=bool(s_share is None or s_share > cfg.cut_share),
                seated_touches=bool(s_median is not None and s_median <= cfg.touch_mm),
            )
            row["designs"].append(d)
            if log:
                log(
                    f"{Path(scan_dir).name} {row['family']} {kind} k={k:g}: clearance {d['clearance']:.2f} mm, "
                    f"sigma {_f(d['sigma_mm'])} mm, cut {100 * share:.2f} %, mating median {m.median:.2f} mm; "
                    + (
                        f"seat {seat.move_mm:.2f} mm, seated cut {100 * s_share:.2f} %, mating median {s_median:.2f} mm"
                        if seat.ok
                        else f"seat FAILED ({seat.reason})"
                    )
                )
    return row


def _design_sigma(vbrep: Any, kind: str, ref: Any) -> float | None:
    """The 1-sigma (mm) a design's default clearance came from: a nest's faces' median, a pin's hole radius
    (`fixtures_design.design.HOLE_RADIUS_SIGMA_MM`), else the mating faces' largest."""
    from fixtures_design.design import HOLE_RADIUS_SIGMA_MM, mating_sigma_mm, outline_sigma_mm

    if ref is None:
        return outline_sigma_mm(vbrep)
    return HOLE_RADIUS_SIGMA_MM if kind == "pin" else mating_sigma_mm(vbrep, ref)


def _f(v: float | None) -> str:
    return "-" if v is None else f"{v:.2f}"


def summarise(rows: list[dict], cfg: FixtureBenchConfig) -> dict[str, Any]:
    """Per k, per kind and over all kinds: designs, cut and touch rates (shares of the designs) in the camera frame
    and seated (a failed seat counts as cutting and not touching), failed seats, the median seat and clearance
    (mm), and for pin / cradle the scans that qualify (visible hole / horizontal cylinder) and the share
    of them with a design."""
    out: dict[str, Any] = {}
    qual = {"pin": "hole", "cradle": "horizontal_cylinder"}
    for k in cfg.clearance_k:
        per: dict[str, Any] = {}
        for kind in (*cfg.kinds, "all"):
            ds = [
                d for r in rows for d in r["designs"] if d["k"] == float(k) and d["ok"] and kind in (d["kind"], "all")
            ]
            s: dict[str, Any] = {
                "designs": len(ds),
                "cut_rate": float(np.mean([d["cuts"] for d in ds])) if ds else None,
                "touch_rate": float(np.mean([d["touches"] for d in ds])) if ds else None,
                "median_clearance_mm": float(np.median([d["clearance"] for d in ds])) if ds else None,
                "seated_cut_rate": float(np.mean([d["seated_cuts"] for d in ds])) if ds else None,
                "seated_touch_rate": float(np.mean([d["seated_touches"] for d in ds])) if ds else None,
                "seat_failures": sum(not d["seat_ok"] for d in ds),
                "median_seat_mm": float(np.median([d["seat_mm"] for d in ds])) if ds else None,
            }
            if kind in qual:
                scans = [r for r in rows if r[qual[kind]]]
                hit = [
                    r for r in scans if any(d["ok"] and d["kind"] == kind and d["k"] == float(k) for d in r["designs"])
                ]
                s.update(qualifying_scans=len(scans), designed_on=len(hit))
                s["qualification_rate"] = len(hit) / len(scans) if scans else None
                # the marks before the true part's closure / free underside were checked (visible_cylinders)
                loose = [r for r in rows if r.get(f"{qual[kind]}_any", r[qual[kind]])]
                s["qualifying_scans_any"] = len(loose)
                s["designed_on_any"] = sum(
                    any(d["ok"] and d["kind"] == kind and d["k"] == float(k) for d in r["designs"]) for r in loose
                )
            per[kind] = s
        out[f"{float(k):g}"] = per
    return out


def run(cfg: FixtureBenchConfig, log: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Prepare the scans, evaluate each, summarise. JSON-able: ``config``, ``weights_sha1``, ``summary`` (per k,
    per kind), ``rows`` (per scan), ``wall_s``."""
    t0 = time.perf_counter()
    dirs = prepare_scans(cfg, log)
    rows = []
    for d in dirs:
        try:
            rows.append(evaluate_scan(d, cfg, log))
        except Exception as exc:  # noqa: BLE001 - a failing reconstruction is one row, not the end of the run
            if log:
                log(f"{d.name}: {type(exc).__name__}: {exc}")
            rows.append({"scan": str(d), "error": f"{type(exc).__name__}: {exc}", "designs": []})
    ok = [r for r in rows if "error" not in r]
    conf = {k: (str(v) if isinstance(v, Path) else v) for k, v in cfg.__dict__.items()}
    return {
        "config": conf,
        "weights_sha1": weights_sha1(cfg.weights),
        "scans": len(rows),
        "failed_scans": len(rows) - len(ok),
        "summary": summarise(ok, cfg),
        "rows": rows,
        "wall_s": time.perf_counter() - t0,
    }


def weights_sha1(weights: Path | None) -> str | None:
    """SHA-1 of the learned segmenter's weights file (the shipped one when None), None if it cannot be read."""
    if weights is None:
        import v2c.segment

        weights = Path(v2c.segment.__file__).parent / "weights" / "unet.pt"
    try:
        return hashlib.sha1(Path(weights).read_bytes()).hexdigest()
    except OSError:
        return None


def format_table(result: dict[str, Any]) -> str:
    """Markdown table: one row per k and kind (and all kinds): designs, cut and touch rates in the camera frame and
    seated, failed seats, median seat and clearance, pin / cradle qualification (holes a pin can take, cylinders
    with room for a cradle; and every concave / horizontal convex cylinder, `visible_cylinders`)."""
    lines = [
        "| k | kind | designs | cut rate | touch rate | seated cut rate | seated touch rate | failed seats | "
        "median seat (mm) | median clearance (mm) | qualifying scans | designed on | "
        "every concave / horizontal convex cylinder: scans | designed on |",
        "|" + " --- |" * 14,
    ]
    for k, per in result["summary"].items():
        for kind, s in per.items():
            q = "" if "qualifying_scans" not in s else str(s["qualifying_scans"])
            on = q_any = on_any = ""
            if "qualifying_scans" in s and s["qualification_rate"] is not None:
                on = f"{s['designed_on']} ({100 * s['qualification_rate']:.0f} %)"
            if s.get("qualifying_scans_any"):
                q_any = str(s["qualifying_scans_any"])
                on_any = f"{s['designed_on_any']} ({100 * s['designed_on_any'] / s['qualifying_scans_any']:.0f} %)"
            lines.append(
                f"| {k} | {'**all**' if kind == 'all' else kind} | {s['designs']} | {_pct(s['cut_rate'])} | "
                f"{_pct(s['touch_rate'])} | {_pct(s['seated_cut_rate'])} | {_pct(s['seated_touch_rate'])} | "
                f"{s['seat_failures']} | {_f(s['median_seat_mm'])} | {_f(s['median_clearance_mm'])} | {q} | {on} | "
                f"{q_any} | {on_any} |"
            )
    return "\n".join(lines)


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.1f} %"


def stderr_log(message: str) -> None:
    """Progress line to stderr."""
    print(message, file=sys.stderr, flush=True)
