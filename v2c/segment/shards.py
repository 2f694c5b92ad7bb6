"""Compact training shards: generated scans packed small enough to travel to an accelerator machine.

A generated scan folder holds about 0.9 MB (noisy depth and colour as PNG barely compress). A shard keeps, per
scan, what the noise is drawn *from* and what the targets are: the colour image as lossy WebP (``color_quality``),
the clean depth (`gt/depth_clean.png`, 0.1 mm units), the face-id and label maps and the intrinsics, about 45 kB.
``realise`` turns a packed scan back into a training sample on the machine that trains: it draws the depth noise
anew with the generator's own noise model (`v2c.synth.noise.apply_depth_noise`, any profile, any seed: every
realisation is a fresh draw), adds the colour read noise that the lossy colour smoothed away, computes the
network inputs exactly as inference does (`v2c.segment.data.compute_features`) and the boundary target.

Clutter beside the part is ignored in the labels (`v2c.segment.data.ignore_clutter`). The one approximation:
the generator's grazing-angle dropout uses the renderer's exact ``cos_incidence``; here it comes from the clean
depth's own normals (central differences inside continuous surfaces, one-sided at a depth step).

Frames: camera (OpenCV), metres. Only numpy, OpenCV and the noise model are imported (no scan loader, no OCCT), so
a bare machine with numpy and OpenCV can unpack.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from v2c.camera import backproject
from v2c.segment.data import FeatureConfig, boundary_map, compute_features, ignore_clutter, quantise

#: Depth unit of gt/depth_clean.png (metres per unit), as the generator writes it (`v2c.synth.dataset.DEPTH_SCALE`).
CLEAN_DEPTH_UNIT_M = 1e-4
SHARD_FORMAT = 1


@dataclass(frozen=True)
class ShardConfig:
    """Packing of scans into shards (units in the comments)."""

    color_quality: int = 90  # WebP quality of the colour image (lossy; 90 keeps printed-art edges, ~20 kB at 640x480)
    max_shard_mb: float = 48.0  # largest shard (MiB); one shard travels in one call of the device tool (64 MiB)
    color_read_noise: float = 2.0  # 8-bit levels of Gaussian read noise added back on unpacking (synth ColorNoise)
    continuity_rel: float = 0.02  # depth step (relative to depth) beyond which two pixels are not one surface


@dataclass
class PackedScan:
    """One scan as stored in a shard: encoded images and the intrinsics."""

    name: str  # the scan folder's path relative to the packed root
    color: bytes  # WebP, BGR
    depth_clean: bytes  # 16-bit PNG, CLEAN_DEPTH_UNIT_M per unit, 0 = nothing
    faces: bytes  # 16-bit PNG face ids (0 = not the part)
    labels: bytes  # 8-bit PNG labels (255 = ignored)
    K: np.ndarray  # (3, 3) pixels
    family: str
    profile: str  # the noise profile the scan was generated with (the packed data holds no noise)


def _encode_png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise ValueError("PNG encoding failed")
    return buf.tobytes()


def pack_scan(folder: str | Path, root: str | Path, cfg: ShardConfig = ShardConfig()) -> PackedScan:
    """Read one generated scan folder (color.png, camera.json, gt/) and encode it for a shard."""
    folder = Path(folder)
    color = cv2.imread(str(folder / "color.png"), cv2.IMREAD_COLOR)
    dclean = cv2.imread(str(folder / "gt" / "depth_clean.png"), cv2.IMREAD_UNCHANGED)
    faces = cv2.imread(str(folder / "gt" / "faces.png"), cv2.IMREAD_UNCHANGED)
    labels = cv2.imread(str(folder / "gt" / "labels.png"), cv2.IMREAD_UNCHANGED)
    for what, img in (("color.png", color), ("gt/depth_clean.png", dclean), ("gt/faces.png", faces)):
        if img is None:
            raise ValueError(f"{folder / what}: missing or unreadable")
    if labels is None:
        raise ValueError(f"{folder / 'gt/labels.png'}: missing or unreadable")
    cam = json.loads((folder / "camera.json").read_text())
    meta = json.loads((folder / "gt" / "meta.json").read_text())
    ok, webp = cv2.imencode(".webp", color, [cv2.IMWRITE_WEBP_QUALITY, cfg.color_quality])
    if not ok:
        raise ValueError(f"{folder / 'color.png'}: WebP encoding failed")
    return PackedScan(
        name=str(folder.relative_to(root)),
        color=webp.tobytes(),
        depth_clean=_encode_png(dclean.astype(np.uint16)),
        faces=_encode_png(faces.astype(np.uint16)),
        labels=_encode_png(labels.astype(np.uint8)),
        K=np.asarray(cam["K"], np.float64).reshape(3, 3),
        family=str(meta.get("family", "")),
        profile=str(meta.get("noise", {}).get("profile", "sensor")),
    )


def _packed_size(p: PackedScan) -> int:
    return len(p.color) + len(p.depth_clean) + len(p.faces) + len(p.labels) + 200


def write_shards(
    scans: list[Path], root: str | Path, out_dir: str | Path, cfg: ShardConfig = ShardConfig()
) -> list[Path]:
    """Pack ``scans`` (folders under ``root``) into ``out_dir``/shard_XXX.npz, each at most ``cfg.max_shard_mb``.

    Scans are taken in the given order, so a caller that interleaves its groups gets every shard balanced.
    Returns the shard paths; ``out_dir``/shards.json lists each shard's scans.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    limit = int(cfg.max_shard_mb * 2**20)
    shards: list[Path] = []
    index: dict[str, list[str]] = {}
    group: list[PackedScan] = []
    size = 0

    def flush() -> None:
        nonlocal group, size
        if not group:
            return
        path = out / f"shard_{len(shards):03d}.npz"
        _save(group, path)
        shards.append(path)
        index[path.name] = [p.name for p in group]
        group, size = [], 0

    for folder in scans:
        p = pack_scan(folder, root, cfg)
        if group and size + _packed_size(p) > limit:
            flush()
        group.append(p)
        size += _packed_size(p)
    flush()
    (out / "shards.json").write_text(json.dumps({"format": SHARD_FORMAT, "shards": index}, indent=1))
    return shards


def _save(group: list[PackedScan], path: Path) -> None:
    arrays: dict[str, np.ndarray] = {}
    meta = []
    for i, p in enumerate(group):
        for key in ("color", "depth_clean", "faces", "labels"):
            arrays[f"{i}_{key}"] = np.frombuffer(getattr(p, key), np.uint8)
        meta.append({"name": p.name, "K": p.K.tolist(), "family": p.family, "profile": p.profile})
    arrays["meta"] = np.frombuffer(json.dumps({"format": SHARD_FORMAT, "scans": meta}).encode(), np.uint8)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **arrays)  # already-compressed images: no zip compression
    tmp.replace(path)


def read_shard(path: str | Path) -> list[PackedScan]:
    """The packed scans of one shard file."""
    with np.load(Path(path)) as z:
        meta = json.loads(bytes(z["meta"]).decode())
        if meta.get("format") != SHARD_FORMAT:
            raise ValueError(f"{path}: shard format {meta.get('format')!r}, expected {SHARD_FORMAT}")
        return [
            PackedScan(
                name=m["name"],
                color=bytes(z[f"{i}_color"]),
                depth_clean=bytes(z[f"{i}_depth_clean"]),
                faces=bytes(z[f"{i}_faces"]),
                labels=bytes(z[f"{i}_labels"]),
                K=np.asarray(m["K"], np.float64),
                family=m["family"],
                profile=m["profile"],
            )
            for i, m in enumerate(meta["scans"])
        ]


def _decode(buf: bytes, flags: int) -> np.ndarray:
    img = cv2.imdecode(np.frombuffer(buf, np.uint8), flags)
    if img is None:
        raise ValueError("an image in the shard does not decode")
    return img


def cos_incidence_from_depth(depth: np.ndarray, K: np.ndarray, continuity_rel: float) -> np.ndarray:
    """(H, W) |cos| of the angle between each pixel's viewing ray and the surface normal of the clean depth.

    Per image direction, the central difference where both neighbours lie on the pixel's continuous surface (depth
    steps under ``continuity_rel`` x depth), else the one-sided difference to the neighbour that does (a pixel on
    a silhouette keeps its own surface's slope); 1 where neither does (isolated pixels, image border, no depth).
    """
    z = depth.astype(np.float32)
    pts = backproject(depth, K).astype(np.float32)
    h, w = z.shape
    tol = np.float32(continuity_rel) * z

    def slope(axis: int) -> tuple[np.ndarray, np.ndarray]:
        prev_p, next_p = np.roll(pts, 1, axis), np.roll(pts, -1, axis)
        prev_z, next_z = np.roll(z, 1, axis), np.roll(z, -1, axis)
        ok_prev = (prev_z > 0) & (np.abs(prev_z - z) < tol)
        ok_next = (next_z > 0) & (np.abs(next_z - z) < tol)
        edge = np.zeros((h, w), bool)
        if axis == 0:
            edge[0], edge[-1] = True, True
        else:
            edge[:, 0], edge[:, -1] = True, True
        ok_prev &= ~edge
        ok_next &= ~edge
        d = np.where(
            (ok_prev & ok_next)[..., None],
            0.5 * (next_p - prev_p),
            np.where(ok_next[..., None], next_p - pts, pts - prev_p),
        )
        return d, (ok_prev | ok_next) & (z > 0)

    dv, okv = slope(0)
    du, oku = slope(1)
    nx = du[..., 1] * dv[..., 2] - du[..., 2] * dv[..., 1]
    ny = du[..., 2] * dv[..., 0] - du[..., 0] * dv[..., 2]
    nz = du[..., 0] * dv[..., 1] - du[..., 1] * dv[..., 0]
    dot = np.abs(nx * pts[..., 0] + ny * pts[..., 1] + nz * pts[..., 2])
    denom = np.sqrt((nx * nx + ny * ny + nz * nz) * np.sum(pts * pts, axis=2))
    good = okv & oku & (denom > 0)
    return np.where(good, dot / np.where(good, denom, 1.0), np.float32(1.0)).astype(np.float32)


def realise(
    p: PackedScan,
    profile: str,
    seed: int | tuple[int, ...],
    cfg: ShardConfig = ShardConfig(),
    features: FeatureConfig | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One training sample of a packed scan with fresh noise of ``profile`` drawn from ``seed``.

    Returns (quantised features (9, H, W) uint8, labels (H, W) uint8, boundary (H, W) uint8, noisy depth (H, W)
    float32 metres), the first three as `v2c.segment.data.build_cache` stores them.
    """
    from v2c.synth.noise import apply_depth_noise

    rng = np.random.default_rng(seed)
    color = cv2.cvtColor(_decode(p.color, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    clean = _decode(p.depth_clean, cv2.IMREAD_UNCHANGED).astype(np.float64) * CLEAN_DEPTH_UNIT_M
    faces = _decode(p.faces, cv2.IMREAD_UNCHANGED)
    labels = ignore_clutter(_decode(p.labels, cv2.IMREAD_UNCHANGED).astype(np.uint8), faces, clean, p.K)
    cos = cos_incidence_from_depth(clean, p.K, cfg.continuity_rel)
    depth = apply_depth_noise(profile, clean, cos, rng)
    depth = (np.round(depth / CLEAN_DEPTH_UNIT_M) * CLEAN_DEPTH_UNIT_M).astype(np.float32)  # as depth.png stores it
    if cfg.color_read_noise > 0:
        noisy = color.astype(np.float32) + cfg.color_read_noise * rng.standard_normal(color.shape, dtype=np.float32)
        color = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
    x = quantise(compute_features(color, depth, p.K, faces > 0, features or FeatureConfig()))
    return x, labels, boundary_map(faces).astype(np.uint8), depth


def interleaved_scans(root: str | Path) -> list[Path]:
    """Generated scans under ``root`` (folders with gt/meta.json), taken round-robin over their parent folders (the
    recipe's rows), so that every shard of `write_shards` holds each row in proportion."""
    groups: dict[Path, list[Path]] = {}
    for meta in sorted(Path(root).glob("*/scan_*/gt/meta.json")):
        groups.setdefault(meta.parent.parent.parent, []).append(meta.parent.parent)
    rows = [groups[k] for k in sorted(groups)]
    total = sum(len(r) for r in rows)
    # each row's scans spread evenly over the whole order (position (j + 0.5) / len(row))
    keyed = [((j + 0.5) / len(r), k, s) for k, r in enumerate(rows) for j, s in enumerate(r)]
    out = [s for _, _, s in sorted(keyed)]
    assert len(out) == total
    return out
