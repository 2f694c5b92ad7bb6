"""Ray-cast test scenes with exact ground truth for the geometry tests (boxes and cylinders, camera frame).

Also tested here: the scenes themselves (depth of a fronto-parallel face equals its analytic distance).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from v2c.labels import label_of
from v2c.primitives.directions import rotation_exp, unit
from v2c.segment.types import Segmentation

K_TEST = np.array([[615.0, 0.0, 160.0], [0.0, 615.0, 120.0], [0.0, 0.0, 1.0]])
SIZE = (320, 240)


@dataclass
class Box:
    """Box centre (3,) metres, rotation (3, 3) columns = box axes in the camera frame, half extents (3,) metres."""

    centre: np.ndarray
    rot: np.ndarray
    half: np.ndarray


@dataclass
class FakeScan:
    """The part of `v2c.scan.Scan` that `fit_scan` reads."""

    depth: np.ndarray
    K: np.ndarray
    valid: np.ndarray
    path: Path = Path("<test scene>")
    gt: object = None
    mask: np.ndarray | None = None
    extra: dict = field(default_factory=dict)


def turned_frame(angles_deg: tuple[float, float, float]) -> np.ndarray:
    """Rotation (3, 3) whose columns are the part axes X, Y, Z in the camera frame, from Euler-like angles."""
    a = np.deg2rad(angles_deg)
    return (
        rotation_exp(np.array([a[0], 0, 0]))
        @ rotation_exp(np.array([0, a[1], 0]))
        @ rotation_exp(np.array([0, 0, a[2]]))
    )


def rays(K: np.ndarray = K_TEST, size: tuple[int, int] = SIZE) -> np.ndarray:
    w, h = size
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    return np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones_like(u)], axis=-1)


def render_boxes(
    boxes: list[Box],
    frame_cols: np.ndarray,
    noise_m: float = 0.0,
    seed: int = 0,
    K: np.ndarray = K_TEST,
    size: tuple[int, int] = SIZE,
):
    """Depth (H, W) metres, instances (H, W) (box b face f -> 6 b + f + 1), labels per instance (18-class against
    the part frame ``frame_cols`` columns X, Y, Z) and gt planes {instance: (point, normal)}."""
    d = rays(K, size)
    h, w = d.shape[:2]
    depth = np.full((h, w), np.inf)
    inst = np.zeros((h, w), np.int32)
    planes = {}
    nlab = 6 * len(boxes) + 1
    labels = np.zeros(nlab, np.uint8)
    for b, box in enumerate(boxes):
        dl = d @ box.rot  # ray directions in box coordinates
        ol = -box.centre @ box.rot
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (-box.half - ol) / dl
            t2 = (box.half - ol) / dl
        tmin, tmax = np.minimum(t1, t2), np.maximum(t1, t2)
        tn = np.nanmax(tmin, axis=-1)
        tf = np.nanmin(tmax, axis=-1)
        ax = np.nanargmax(tmin, axis=-1)
        hit = (tn <= tf) & (tn > 0) & (tn < depth)
        side = np.where(np.take_along_axis(dl, ax[..., None], -1)[..., 0] > 0, 0, 1)  # 1 = + face
        face = 2 * ax + side
        depth[hit] = tn[hit]
        inst[hit] = 6 * b + face[hit] + 1
        for f in range(6):
            n = box.rot[:, f // 2] * (1 if f % 2 else -1)
            planes[6 * b + f + 1] = (box.centre + n * box.half[f // 2], n)
            k = int(np.argmax(np.abs(frame_cols.T @ n)))
            cos = abs(frame_cols[:, k] @ n)
            labels[6 * b + f + 1] = label_of("plane", "XYZ"[k] if cos > np.cos(np.deg2rad(1.5)) else "U")
    depth[~np.isfinite(depth)] = 0.0
    if noise_m > 0:
        rng = np.random.default_rng(seed)
        depth = np.where(depth > 0, depth + rng.normal(0, noise_m, depth.shape), 0.0)
    return depth, inst, labels, planes


def make_scan(depth: np.ndarray, inst: np.ndarray, labels: np.ndarray, K: np.ndarray = K_TEST):
    seg = Segmentation(
        instances=inst.astype(np.int32), labels=labels, scores=np.ones(len(labels), np.float32), method="oracle"
    )
    return FakeScan(depth=depth.astype(np.float32), K=K, valid=depth > 0), seg


def turned_box_scene(noise_m: float = 0.0005, seed: int = 0):
    """A 10 x 8 x 6 cm box turned by ~(110, 20, 35) degrees, 0.45 m in front of the camera."""
    r = turned_frame((115.0, 20.0, 35.0))
    box = Box(np.array([0.0, 0.0, 0.45]), r, np.array([0.05, 0.04, 0.03]))
    depth, inst, labels, planes = render_boxes([box], r, noise_m, seed)
    return depth, inst, labels, planes, r


def test_scene_depth_is_exact() -> None:
    r = np.eye(3)
    box = Box(np.array([0.0, 0.0, 0.5]), r, np.array([0.05, 0.05, 0.05]))
    depth, inst, _, planes = render_boxes([box], r)
    assert abs(depth[120, 160] - 0.45) < 1e-12
    assert inst[120, 160] == 5  # the -z face (box 0, axis 2, side 0) faces the camera
    p, n = planes[5]
    assert np.allclose(n, [0, 0, -1]) and np.allclose(p, [0, 0, 0.45])
    assert unit(np.array([1.0, 0, 0]))[0] == 1.0
