"""Extent framing keeps the camera above the ground (v2c.synth.appearance.frame_scene).

Regression: placing the part high in the image moved the camera down along the image's vertical, for low camera
elevations down to about a centimetre above the ground plane; the ground then covered most of the image at depths
of 2-5 cm (about 0.5 % of the training recipe's random-appearance scans, e.g. seed 131 scans 40 and 179 of its
"train" row). The renderer's depth was right for that camera: the camera was wrong.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from v2c.synth import occ
from v2c.synth.appearance import FRAMING_STREAM, FramingConfig, frame_scene, project
from v2c.synth.dataset import SynthConfig, generate_scan
from v2c.synth.families import FAMILY_GROUPS
from v2c.synth.scene import SceneConfig, sample_scene

NEAR_FRACTION = 0.2  # no depth reading nearer than this x the camera's distance to the part (scene: >= 0.24 x)
PLANE_TOL_REL = 1e-5  # the clean ground depth is a ray/plane intersection: off the plane by at most this x the
# depth (the renderer's ground rays are float32)
GROUND_SHARE = 0.5  # with clutter: at least this share of the background readings is ground
REST_TOL_M = 1e-3  # the part's lowest mesh vertex lies on the ground within this (0.5 mm chords)


def test_extent_framing_keeps_the_camera_above_the_part() -> None:
    """Low cameras (elevation 15-17 deg) and random placements: the camera's height above the part's centre stays
    at least sin(min_sight_elevation_deg) x the centre's depth, and the whole part stays in the image."""
    lo, hi = np.array([-40.0, -25.0, 0.0]), np.array([40.0, 25.0, 30.0])  # rest-pose box, mm
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    cfg = FramingConfig()
    sin_min = np.sin(np.deg2rad(cfg.min_sight_elevation_deg))
    scene_cfg = SceneConfig(elevation_deg=(15.0, 17.0))
    clamped = 0
    for i in range(40):
        scene = sample_scene(np.random.default_rng([7, i]), lo, hi, 160, 120, scene_cfg)
        framed, info = frame_scene(scene, corners, np.random.default_rng([7, i, FRAMING_STREAM]), cfg)
        rot, trans = framed.world_to_cam[:, :3], framed.world_to_cam[:, 3]
        eye = -rot.T @ trans
        pts = corners @ scene.rest_to_world[:, :3].T + scene.rest_to_world[:, 3]
        centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
        zc = (centre - eye) @ rot[2]
        assert eye[2] - centre[2] >= sin_min * zc - 1e-9, (i, eye, centre, zc)
        clamped += bool(eye[2] - centre[2] < sin_min * zc + 1e-6)
        uv, z = project(framed.K, framed.world_to_cam, pts)
        assert (z > 0).all() and (uv >= 0).all() and (uv[:, 0] < 160).all() and (uv[:, 1] < 120).all(), (i, uv)
    assert clamped >= 5  # the limit was met on a good share of these placements (the part drawn high in the image)


def test_random_look_scan_ground_depth(tmp_path: Path) -> None:
    """Scans 40 and 179 of the training recipe's random-appearance "train" row (seed 131) at 160x120: the ground
    is one plane, the part stands on it, and no reading is nearer than NEAR_FRACTION x the camera distance (before
    the fix 7 % and 16 % of the clean depth was, at 3-5 cm)."""
    occ.silence_occt()
    cfg = SynthConfig(
        width=160,
        height=120,
        noise="sensor",
        scene=SceneConfig(print_share=0.0),
        families=FAMILY_GROUPS["train"],
        appearance="random",
        framing="extent",
    )
    for index in (40, 179):
        folder = generate_scan(tmp_path, 131, index, cfg)
        meta = json.loads((folder / "gt" / "meta.json").read_text())
        dist = meta["framing"]["distance_m"]
        clean = np.load(folder / "gt" / "depth_clean.npy").astype(np.float64)
        noisy = cv2.imread(str(folder / "depth.png"), cv2.IMREAD_UNCHANGED) * meta["depth_scale"]
        for depth in (clean, noisy):
            valid = depth[depth > 0]
            assert valid.min() >= NEAR_FRACTION * dist, (index, valid.min(), dist)

        # The ground's clean depth: back-projected, one plane (fitted), on which the part (part.step) stands.
        K = np.array(json.loads((folder / "camera.json").read_text())["K"])
        faces = cv2.imread(str(folder / "gt" / "faces.png"), cv2.IMREAD_UNCHANGED)
        v, u = np.nonzero((faces == 0) & (clean > 0))
        z = clean[v, u]
        pts = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
        on = _plane_inliers(pts)  # clutter objects stand on the ground: the ground is the dominant plane
        assert on.mean() >= (GROUND_SHARE if meta["appearance"]["clutter"] else 1.0), (index, on.mean())
        pts = pts[on]
        mean = pts.mean(axis=0)
        normal = np.linalg.svd(pts - mean)[2][2]
        if normal @ mean > 0:
            normal = -normal  # towards the camera
        assert (np.abs((pts - mean) @ normal) <= PLANE_TOL_REL * pts[:, 2]).all(), index
        shape = occ.read_step(folder / "gt" / "part.step")
        mesh = occ.tessellate(shape, occ.faces_of(shape), 0.5, 0.5)
        heights = (mesh.vertices * 1e-3 - mean) @ normal
        assert abs(heights.min()) < REST_TOL_M, (index, heights.min())
        camera_height = -(mean @ normal)
        assert camera_height > heights.max(), (index, camera_height, heights.max())  # these parts: below the camera


def _plane_inliers(pts: np.ndarray) -> np.ndarray:
    """Bool mask of the points on the plane through the most points among planes of deterministic point triples."""
    rng = np.random.default_rng(0)
    best = np.zeros(len(pts), bool)
    for _ in range(200):
        a, b, c = pts[rng.choice(len(pts), 3, replace=False)]
        n = np.cross(b - a, c - a)
        if np.linalg.norm(n) < 1e-12:
            continue
        on = np.abs((pts - a) @ (n / np.linalg.norm(n))) <= PLANE_TOL_REL * pts[:, 2]
        if on.sum() > best.sum():
            best = on
    return best


def test_suite_cache_of_random_looks_follows_the_framing_version(tmp_path: Path, monkeypatch) -> None:
    """A new framing version re-renders the cached random-appearance bench suites, never the plain ones."""
    from v2c.bench import suite as S
    from v2c.bench.run import BenchConfig
    from v2c.synth import appearance

    bench = BenchConfig(cache_dir=tmp_path)
    plain = S.suite_cache_dir(S.SuiteConfig(bench=bench))
    rand = S.suite_cache_dir(S.SuiteConfig(bench=bench, appearance="random"))
    monkeypatch.setattr(appearance, "FRAMING_VERSION", appearance.FRAMING_VERSION + 1)
    assert S.suite_cache_dir(S.SuiteConfig(bench=bench)) == plain
    assert S.suite_cache_dir(S.SuiteConfig(bench=bench, appearance="random")) != rand
