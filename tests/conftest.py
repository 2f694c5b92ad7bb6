"""Shared test fixtures: a tiny hand-made scan folder with exact ground truth, and the shared data folder.

The tiny scan is built with numpy + cv2 only (no generator): a 64 x 48 view of one tilted plane, so every number
in it is known in closed form. ``TINY`` holds those numbers for assertions.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]
#: ../shared/data next to the repository (third-party test material, never copied into the repo). A clone
#: elsewhere can point at it with V2C_SHARED_DATA=/path/to/shared/data.
SHARED_DATA = Path(os.environ.get("V2C_SHARED_DATA") or REPO.parent / "shared" / "data")


class TINY:
    """Closed-form content of the tiny scan (camera frame, metres, pixels)."""

    width, height = 64, 48
    K = np.array([[60.0, 0.0, 31.5], [0.0, 62.0, 23.5], [0.0, 0.0, 1.0]])
    depth_scale = 0.0001  # metres per depth.png unit
    plane_point = np.array([0.0, 0.0, 0.6])  # where the optical axis meets the plane
    plane_normal = np.array([0.1, -0.2, -1.0]) / np.linalg.norm([0.1, -0.2, -1.0])
    face_box = (12, 10, 52, 38)  # x0, y0, x1, y1 of the plane face in gt/faces.png (x1/y1 exclusive)
    hole_box = (0, 0, 4, 3)  # x0, y0, x1, y1 of a patch without depth readings
    part_size_m = 0.05


def tiny_depth_m() -> np.ndarray:
    """(H, W) float64 exact z-depth of the tilted plane along each pixel ray (metres)."""
    h, w = TINY.height, TINY.width
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    K = TINY.K
    rays = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)
    n = TINY.plane_normal
    return (n @ TINY.plane_point) / (rays @ n)


def camera_dict(
    form: str = "v2c",
    *,
    K: np.ndarray | None = None,
    depth_scale: float | None = None,
    size: tuple[int, int] | None = None,
) -> dict:
    """camera.json content in one of the accepted forms: "v2c", "v2c-flat", "open3d", "bop", "bop-file"."""
    K = TINY.K if K is None else np.asarray(K, float)
    ds = TINY.depth_scale if depth_scale is None else depth_scale
    w, h = (TINY.width, TINY.height) if size is None else size
    if form == "v2c":
        return {"width": w, "height": h, "K": K.tolist(), "depth_scale": ds}
    if form == "v2c-flat":
        return {"width": w, "height": h, "K": K.reshape(-1).tolist(), "depth_scale": ds}
    if form == "open3d":  # Open3D PinholeCameraIntrinsic: column-major, no depth scale unless we add it
        return {"width": w, "height": h, "intrinsic_matrix": K.T.reshape(-1).tolist(), "depth_scale": ds}
    if form == "bop":  # BOP scene_camera entry: depth_scale in millimetres per unit
        return {"cam_K": K.reshape(-1).tolist(), "depth_scale": ds * 1000.0}
    if form == "bop-file":  # a whole scene_camera.json keyed by image id: the first entry is used
        entry = {
            "cam_K": K.reshape(-1).tolist(),
            "depth_scale": ds * 1000.0,
            "cam_R_w2c": np.eye(3).reshape(-1).tolist(),
            "cam_t_w2c": [0.0, 0.0, 0.0],
        }
        other = dict(entry, cam_K=(K * 2).reshape(-1).tolist())
        return {"7": other, "3": entry}
    raise ValueError(form)


def write_tiny_scan(
    folder: Path,
    *,
    camera: str = "v2c",
    depth_format: str = "png",
    color_ext: str = "png",
    mask: bool = False,
    gt: bool = False,
) -> Path:
    """Write the tiny scan into ``folder`` (created) and return it."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    h, w = TINY.height, TINY.width
    u, v = np.meshgrid(np.arange(w), np.arange(h))
    rgb = np.stack([(4 * u) % 256, (5 * v) % 256, np.full_like(u, 90)], axis=-1).astype(np.uint8)
    if color_ext == "png":
        cv2.imwrite(str(folder / "color.png"), rgb[..., ::-1])
    else:
        cv2.imwrite(str(folder / f"color.{color_ext}"), rgb[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 95])
    depth = tiny_depth_m()
    x0, y0, x1, y1 = TINY.hole_box
    depth[y0:y1, x0:x1] = 0.0
    if depth_format == "png":
        cv2.imwrite(str(folder / "depth.png"), np.round(depth / TINY.depth_scale).astype(np.uint16))
    else:
        np.save(folder / "depth.npy", depth.astype(np.float32))
    (folder / "camera.json").write_text(json.dumps(camera_dict(camera)))
    if mask:
        m = np.zeros((h, w), np.uint8)
        m[8:40, 16:48] = 255
        cv2.imwrite(str(folder / "mask.png"), m)
    if gt:
        g = folder / "gt"
        g.mkdir(exist_ok=True)
        x0, y0, x1, y1 = TINY.face_box
        faces = np.zeros((h, w), np.uint16)
        faces[y0:y1, x0:x1] = 1
        labels = np.where(faces > 0, 4, 0).astype(np.uint8)  # plane, unaligned
        cv2.imwrite(str(g / "faces.png"), faces)
        cv2.imwrite(str(g / "labels.png"), labels)
        clean = np.where(faces > 0, tiny_depth_m(), 0.0)
        cv2.imwrite(str(g / "depth_clean.png"), np.round(clean / TINY.depth_scale).astype(np.uint16))
        prims = [
            {
                "id": 0,
                "pixel_value": 1,
                "type": "plane",
                "axis_label": "U",
                "params": {"origin": TINY.plane_point.tolist(), "normal": TINY.plane_normal.tolist()},
            },
            {
                "id": 1,
                "pixel_value": 2,
                "type": "cylinder",
                "axis_label": "Z",  # hidden face
                "params": {"origin": [0.0, 0.0, 0.7], "axis": [0.0, 0.0, 1.0], "radius": 0.01},
            },
        ]
        (g / "primitives.json").write_text(json.dumps(prims))
        meta = {
            "generator": "tests/conftest.py",
            "seed": 0,
            "family": "fixture-plane",
            "part_size_m": TINY.part_size_m,
            "axes_cam": np.eye(3).tolist(),
        }
        (g / "meta.json").write_text(json.dumps(meta))
        (g / "part.step").write_text("ISO-10303-21;\nEND-ISO-10303-21;\n")  # a path only; never parsed here
    return folder


@pytest.fixture(scope="session")
def tiny_scan_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A valid tiny scan with mask-free depth.png, v2c camera.json and gt/. Read-only: copy before changing."""
    return write_tiny_scan(tmp_path_factory.mktemp("tiny") / "scan", gt=True)


@pytest.fixture
def scan_copy(tiny_scan_dir: Path, tmp_path: Path) -> Path:
    """A private copy of the tiny scan that a test may break."""
    return Path(shutil.copytree(tiny_scan_dir, tmp_path / "scan"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """../shared/data (real frames, CAD parts); skipped with a reason when the folder is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(
            f"shared test data not found at {SHARED_DATA} (expected next to the repository; "
            "set V2C_SHARED_DATA to use another place)"
        )
    return SHARED_DATA


@pytest.fixture(scope="session")
def shared_cad(shared_data: Path) -> Path:
    """../shared/data/cad: real STEP parts (mm and inch units), see ../shared/data/README.md."""
    cad = shared_data / "cad"
    if not cad.is_dir():
        pytest.skip(f"shared CAD parts not found at {cad}")
    return cad


def real_scan_dirs() -> list[Path]:
    """The real RGB-D frames of ../shared/data/real (empty when the folder is absent)."""
    real = SHARED_DATA / "real"
    return sorted(p for p in real.iterdir() if p.is_dir()) if real.is_dir() else []


def listing(folder: Path) -> dict[str, tuple[int, int]]:
    """Recursive {relative path: (size, mtime_ns)} of a folder, to prove a command wrote nothing."""
    folder = Path(folder)
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(folder.rglob("*"))}
