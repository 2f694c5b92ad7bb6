"""`v2c.camera`: back-projection, pixel rays and projection with the skew term, and bit-identity with the
skew-free formulas they replaced when the skew is 0."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np

from v2c.camera import backproject, pixel_rays, pixel_rays_closed_form, project

K0 = np.array([[525.0, 0.0, 319.5], [0.0, 521.0, 239.5], [0.0, 0.0, 1.0]])
K_SKEW = np.array([[525.0, 12.5, 319.5], [0.0, 521.0, 239.5], [0.0, 0.0, 1.0]])


def _depth(h: int = 48, w: int = 64) -> np.ndarray:
    rng = np.random.default_rng(0)
    d = rng.uniform(0.3, 1.2, (h, w)).astype(np.float32)
    d[rng.random((h, w)) < 0.1] = 0.0
    return d


def test_backproject_without_skew_is_bit_identical_to_the_skew_free_formula() -> None:
    depth = _depth()
    h, w = depth.shape
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    z = depth.astype(float)
    old = np.stack([(u - K0[0, 2]) / K0[0, 0] * z, (v - K0[1, 2]) / K0[1, 1] * z, z], axis=-1)
    assert np.array_equal(backproject(depth, K0), old)


def test_closed_form_rays_without_skew_are_bit_identical_to_the_skew_free_formula() -> None:
    uv = np.random.default_rng(1).uniform(-10, 700, (500, 2))
    old = np.stack([(uv[:, 0] - K0[0, 2]) / K0[0, 0], (uv[:, 1] - K0[1, 2]) / K0[1, 1], np.ones(len(uv))], axis=1)
    assert np.array_equal(pixel_rays_closed_form(uv, K0), old)


def test_skew_round_trip_through_every_map() -> None:
    depth = _depth()
    h, w = depth.shape
    pts = backproject(depth, K_SKEW)
    has = depth > 0
    v, u = np.nonzero(has)
    uv = np.stack([u, v], axis=1).astype(float)
    np.testing.assert_allclose(project(pts[has], K_SKEW), uv, atol=1e-9)
    for rays in (pixel_rays(uv, K_SKEW), pixel_rays_closed_form(uv, K_SKEW)):
        assert np.all(rays[:, 2] == 1.0)
        np.testing.assert_allclose(rays * depth[has].astype(float)[:, None], pts[has], atol=1e-12)
    # the skew moves x by -s * y / fx: ignoring it would be off by up to s * (h / 2) / fy pixels
    assert np.abs(pixel_rays(uv, K_SKEW)[:, 0] - pixel_rays(uv, K0)[:, 0]).max() > 1e-3


def test_camera_imports_nothing_from_v2c() -> None:
    src = Path(__file__).resolve().parents[1] / "v2c" / "camera.py"
    tree = ast.parse(src.read_text())
    mods = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    mods += [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
    assert not [m for m in mods if m and m.split(".")[0] == "v2c"]
