"""The synthetic depth-noise profiles against the real frames: local noise std vs depth, its growth with the patch
size (spatial correlation), the depth step, hole and flying-pixel shares, side by side.

    PYTHONPATH=$PWD python scripts/sensor_stats.py [--real ../shared/data/real] [--n 6] [--seed 9000]
        [--plot docs/img/sensor_std_vs_z.png] [--json stats.json] [--fit]

Real: the frames of v2c/bench/real_rois.json, loaded with the depth clean-up off. Noise figures use every complete,
edge-free patch of the whole frame (table, boxes, cans, walls; `v2c.synth.noise_stats.patch_noise`); hole share
inside each frame's ROI; flying-pixel share over the readings near depth edges of the whole frame. The five
YCB-Video frames (Asus Xtion, 1 mm depth unit) are pooled; the LineMOD frame (Kinect v1) is listed apart.

Synthetic, for every profile compared: ``--n`` scans of `v2c synth` (seed ``--seed``, a validation seed; the scans
are rendered into a temporary folder and deleted), measured the same way (hole share inside the part's bounding
box); and a fronto-parallel plane at the depths of the real bins (`plane_sweep`), since the synthetic scans stand
0.4-1.2 m away and the real noise is seen out to 3 m.

How the `structured_light` parameters were fitted (docs/synth.md): the white and correlated coefficients and the
correlation length by matching the real patch-size profile (5-21 px patches at 0.8-1.0 m) on the plane (``--fit``
runs that grid search); the depth
unit from the frames' distinct values; the flying-pixel probability from the flying share.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from v2c.bench.real import DEFAULT_ROIS, load_frames
from v2c.depth_clean import depth_clean
from v2c.scan import load_scan
from v2c.synth import noise as noise_mod
from v2c.synth.dataset import SynthConfig, generate_scan
from v2c.synth.noise_stats import (
    NoiseStatsConfig,
    binned_std,
    flying_share,
    hole_share,
    patch_noise,
    quantum_near,
)

PROFILES = ("sensor", "structured_light")
#: patch sides (pixels) of the patch-size profile, and the depth band (metres) it is measured in
PATCH_SIDES = (5, 7, 11, 15, 21)
PROFILE_BAND_M = (0.8, 1.0)
#: image size of the plane sweep (pixels) and the focal length of the YCB frames (pixels)
PLANE_SIZE = (640, 480)
#: the grid of `fit_structured_light`: correlation length (pixels), white and correlated coefficients (1/m)
FIT_LENGTHS_PX = (2.0, 3.0, 4.0)
FIT_WHITE = (0.0003, 0.0004, 0.0005)
FIT_CORRELATED = (0.0012, 0.0016, 0.002, 0.0024)


def real_stats(data: Path, rois: Path, cfg: NoiseStatsConfig) -> dict:
    """Per-frame and pooled statistics of the real frames."""
    frames, z_ycb, s_ycb, z_lm, s_lm, depths_ycb = [], [], [], [], [], []
    for name, spec in load_frames(rois).items():
        with depth_clean("off"):
            scan = load_scan(data / name, roi=tuple(spec["roi"]))
        d, roi = scan.depth.astype(np.float64), scan.roi_mask()
        z, s = patch_noise(d, None, cfg)
        zm = float(np.median(d[roi & (d > 0)]))
        frames.append(
            {
                "frame": name,
                "z_roi_m": zm,
                "patch_std_roi_mm": 1000 * float(np.median(patch_noise(d, roi, cfg)[1])),
                "quantum_mm": 1000 * quantum_near(d, zm, cfg),
                "hole_share_roi": hole_share(d, roi),
                "hole_share_frame": hole_share(d, np.ones_like(roi)),
                "flying_share": flying_share(d, np.ones_like(roi), cfg),
            }
        )
        if name.startswith("ycb_video"):
            z_ycb.append(z)
            s_ycb.append(s)
            depths_ycb.append(d)
        else:
            z_lm.append(z)
            s_lm.append(s)
    return {
        "frames": frames,
        "bins_xtion": binned_std(np.concatenate(z_ycb), np.concatenate(s_ycb), cfg),
        "bins_kinect": binned_std(np.concatenate(z_lm), np.concatenate(s_lm), cfg) if z_lm else [],
        "patch_profile_xtion": patch_profile(depths_ycb, cfg),
    }


def patch_profile(depths: list[np.ndarray], cfg: NoiseStatsConfig) -> list[float]:
    """Median patch std (mm) for each side of PATCH_SIDES over the patches in PROFILE_BAND_M."""
    out = []
    for side in PATCH_SIDES:
        c = NoiseStatsConfig(**{**cfg.__dict__, "patch_px": side})
        zs, ss = zip(*(patch_noise(d, None, c) for d in depths), strict=True)
        z, s = np.concatenate(zs), np.concatenate(ss)
        sel = (z > PROFILE_BAND_M[0]) & (z < PROFILE_BAND_M[1])
        out.append(1000 * float(np.median(s[sel])) if sel.any() else float("nan"))
    return out


def plane_sweep(profile: str, depths_m: list[float], seed: int) -> list[np.ndarray]:
    """One noisy fronto-parallel plane (PLANE_SIZE) per depth, facing the camera."""
    w, h = PLANE_SIZE
    out = []
    for i, z in enumerate(depths_m):
        rng = np.random.default_rng([seed, i])
        out.append(noise_mod.apply_depth_noise(profile, np.full((h, w), z), np.ones((h, w)), rng))
    return out


def synth_stats(profile: str, n: int, seed: int, z_bins: list[float], cfg: NoiseStatsConfig) -> dict:
    """Statistics of ``n`` synthetic scans of ``profile`` and of its plane sweep."""
    tmp = Path(tempfile.mkdtemp(prefix="v2c-sensor-stats-"))
    try:
        zs, ss, rows = [], [], []
        for i in range(n):
            scan = load_scan(generate_scan(tmp, seed, i, SynthConfig(noise=profile)))
            d = scan.depth.astype(np.float64)
            z, s = patch_noise(d, None, cfg)
            zs.append(z)
            ss.append(s)
            part = scan.gt.depth_clean > 0
            part &= scan.gt.faces > 0
            ys, xs = np.nonzero(part)
            box = np.zeros_like(part)
            box[ys.min() : ys.max() + 1, xs.min() : xs.max() + 1] = True
            zm = float(np.median(scan.gt.depth_clean[part]))
            rows.append(
                {
                    "z_part_m": zm,
                    "quantum_mm": 1000 * quantum_near(d, zm, cfg),
                    "hole_share_box": hole_share(d, box),
                    "flying_share": flying_share(d, np.ones_like(part), cfg),
                }
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    planes = plane_sweep(profile, z_bins, seed)
    sweep = []
    for z, d in zip(z_bins, planes, strict=True):
        sweep.append((z, 1000 * float(np.median(patch_noise(d, None, cfg)[1]))))
    prof_planes = plane_sweep(profile, [float(np.mean(PROFILE_BAND_M))] * 2, seed)
    return {
        "scans": rows,
        "bins": binned_std(np.concatenate(zs), np.concatenate(ss), cfg),
        "plane_sweep": sweep,
        "patch_profile": patch_profile(prof_planes, cfg),
    }


def fit_structured_light(real_profile: list[float], seed: int, cfg: NoiseStatsConfig) -> list[tuple]:
    """The grid search behind `StructuredLightNoise`: [(RMS relative error against ``real_profile``, length px,
    white coeff, correlated coeff, profile mm)] best first, each on a plane at the middle of PROFILE_BAND_M."""
    from dataclasses import replace

    base = noise_mod.StructuredLightNoise()
    w, h = PLANE_SIZE
    z = float(np.mean(PROFILE_BAND_M))
    target = np.asarray(real_profile)
    out = []
    for length in FIT_LENGTHS_PX:
        for white in FIT_WHITE:
            for corr in FIT_CORRELATED:
                c = replace(
                    base,
                    correlated_length_px=length,
                    correlated_coeff_per_m=corr,
                    sensor=replace(base.sensor, sigma_coeff_per_m=white),
                )
                d = noise_mod.apply_structured_light(
                    np.full((h, w), z), np.ones((h, w)), np.random.default_rng(seed), c
                )
                prof = np.asarray(patch_profile([d], cfg))
                out.append((float(np.sqrt(np.mean((prof / target - 1) ** 2))), length, white, corr, prof.round(2)))
    return sorted(out, key=lambda t: t[0])


def z2_fit(bins: list[tuple], quantum_m: float, min_z: float = 1.0) -> tuple[float, float]:
    """(coefficient c of std = c z^2 in 1/m, after removing the quantisation's q^2/12; log-log slope of std vs z
    over the bins at or beyond ``min_z`` metres)."""
    z = np.array([b[0] for b in bins])
    s = np.array([b[2] for b in bins])
    s_noise = np.sqrt(np.maximum(s**2 - quantum_m**2 / 12, 0))
    c = float(np.sum(s_noise * z**2) / np.sum(z**4))
    far = z >= min_z
    slope = float(np.polyfit(np.log(z[far]), np.log(s_noise[far]), 1)[0]) if far.sum() >= 2 else float("nan")
    return c, slope


def plot(path: Path, real: dict, synth: dict[str, dict]) -> None:
    """Plot std vs z: the real bins, each profile's plane sweep and scans."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=120)
    for key, label, marker in (
        ("bins_xtion", "real: YCB-Video (Xtion)", "o"),
        ("bins_kinect", "real: LM-O (Kinect v1)", "s"),
    ):
        b = real[key]
        if b:
            ax.plot(
                [x[0] for x in b],
                [1000 * x[2] for x in b],
                marker,
                color="k",
                mfc="none" if marker == "s" else "k",
                label=label,
            )
    colors = {"sensor": "tab:red", "structured_light": "tab:blue"}
    for prof, st in synth.items():
        ax.plot(
            [x[0] for x in st["plane_sweep"]],
            [x[1] for x in st["plane_sweep"]],
            "-",
            color=colors.get(prof),
            label=f"{prof}: plane",
        )
        ax.plot(
            [x[0] for x in st["bins"]],
            [1000 * x[2] for x in st["bins"]],
            "x",
            color=colors.get(prof),
            label=f"{prof}: scans",
        )
    ax.set_xlabel("depth z (m)")
    ax.set_ylabel("local noise std, 7 px patches (mm)")
    ax.set_title("Depth noise vs depth: real frames and synthetic profiles")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Measure, print the tables, optionally plot and write JSON."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--real", type=Path, default=Path(__file__).resolve().parents[1].parent / "shared/data/real")
    ap.add_argument("--rois", type=Path, default=DEFAULT_ROIS)
    ap.add_argument("--n", type=int, default=6, help="synthetic scans per profile")
    ap.add_argument("--seed", type=int, default=9000, help="seed of the synthetic scans (a validation seed)")
    ap.add_argument("--plot", type=Path, default=None, help="PNG of std vs depth")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--fit", action="store_true", help="also run the grid search behind structured_light")
    args = ap.parse_args(argv)
    if not args.real.is_dir():
        print(f"{args.real}: real frames folder not found (give --real)", file=sys.stderr)
        return 2
    cfg = NoiseStatsConfig()
    real = real_stats(args.real, args.rois, cfg)
    z_bins = [b[0] for b in real["bins_xtion"]]
    synth = {p: synth_stats(p, args.n, args.seed, z_bins, cfg) for p in PROFILES}

    print("Local noise std (mm, median over 7 px patches) vs depth")
    head = f"{'z (m)':>6} {'Xtion':>7} {'Kinect':>7}" + "".join(
        f" {p + ' plane':>23} {p + ' scans':>23}" for p in PROFILES
    )
    print(head)
    kin = {round(b[0], 3): b[2] for b in real["bins_kinect"]}
    for b in real["bins_xtion"]:
        z = round(b[0], 3)
        row = f"{z:6.2f} {1000 * b[2]:7.2f} {1000 * kin[z] if z in kin else float('nan'):7.2f}"
        for p in PROFILES:
            sw = dict((round(x[0], 3), x[1]) for x in synth[p]["plane_sweep"])
            sc = {round(x[0], 3): 1000 * x[2] for x in synth[p]["bins"]}
            row += f" {sw.get(z, float('nan')):23.2f} {sc.get(z, float('nan')):23.2f}"
        print(row)
    c_x, slope_x = z2_fit(real["bins_xtion"], 1e-3)
    print(f"\nXtion: std = {c_x:.5f} z^2 (1 mm unit's q^2/12 removed); log-log slope beyond 1 m: {slope_x:.2f}")
    for p in PROFILES:
        c, slope = z2_fit([(z, 0, s / 1000) for z, s in synth[p]["plane_sweep"]], 1e-3 if p != "sensor" else 1e-4)
        print(f"{p} plane: std = {c:.5f} z^2; log-log slope beyond 1 m: {slope:.2f}")

    print(f"\nPatch-size profile at {PROFILE_BAND_M[0]}-{PROFILE_BAND_M[1]} m (median std, mm): spatial correlation")
    print(f"{'patch (px)':>12}" + "".join(f" {s:6d}" for s in PATCH_SIDES))
    print(f"{'Xtion':>12}" + "".join(f" {v:6.2f}" for v in real["patch_profile_xtion"]))
    for p in PROFILES:
        print(f"{p:>12.12}" + "".join(f" {v:6.2f}" for v in synth[p]["patch_profile"]))

    if args.fit:
        print("\nGrid search (best 5): RMS rel. error, length px, white, correlated, profile mm")
        for row in fit_structured_light(real["patch_profile_xtion"], args.seed, cfg)[:5]:
            print(f"  {row[0]:.3f}  {row[1]:.0f}  {row[2]:.4f}  {row[3]:.4f}  {row[4].tolist()}")

    print("\nPer frame / scan: depth step, holes, flying pixels")
    print(f"{'source':<28} {'z (m)':>6} {'step (mm)':>9} {'holes':>7} {'flying':>7}")
    for f in real["frames"]:
        print(
            f"{f['frame']:<28} {f['z_roi_m']:6.3f} {f['quantum_mm']:9.2f} {f['hole_share_roi']:7.3f} "
            f"{f['flying_share']:7.4f}"
        )
    for p in PROFILES:
        for i, r in enumerate(synth[p]["scans"]):
            print(
                f"{p + ' scan ' + str(i):<28} {r['z_part_m']:6.3f} {r['quantum_mm']:9.2f} {r['hole_share_box']:7.3f} "
                f"{r['flying_share']:7.4f}"
            )
    print(
        "holes: real = share inside the ROI, synthetic = inside the part's bounding box; flying: share of the "
        "readings within 2 px of a depth edge lying between two layers (whole image)"
    )
    if args.plot:
        plot(args.plot, real, synth)
        print(f"plot: {args.plot}")
    if args.json:
        args.json.write_text(json.dumps({"real": real, "synthetic": synth}, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
