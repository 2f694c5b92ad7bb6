"""Instances too small for RANSAC (FitConfig.small_instance_px to min_instance_px pixels) are fitted with their
label's type on the shared frame's axis (issue 16: on corpus parts every type error of the oracle path was such a
face, left to the VB-Rep's free-plane fallback)."""

from __future__ import annotations

import numpy as np
from test_fit_helpers import Box, make_scan, render_boxes, turned_frame

from v2c.fit import fit_scan
from v2c.fit.config import FitConfig
from v2c.fit.stage import _Fits, _small_instances
from v2c.geometry.points import InstancePoints
from v2c.labels import label_of
from v2c.primitives import Cylinder, Plane
from v2c.segment.types import Segmentation


def test_small_box_faces_are_fitted_on_the_frame() -> None:
    """A 5 x 4 x 3 mm box beside a 10 x 8 x 6 cm one (same turn): its three visible faces cover 18-24 pixels,
    under min_instance_px. They come back as planes whose normals are the ground truth's within 0.1 degrees (the
    frame's axes) and pass within 0.2 mm of the true face centres."""
    r = turned_frame((115.0, 20.0, 35.0))
    big = Box(np.array([0.0, 0.0, 0.45]), r, np.array([0.05, 0.04, 0.03]))
    small = Box(np.array([0.07, 0.05, 0.40]), r, np.array([0.0025, 0.002, 0.0016]))
    depth, inst, labels, planes = render_boxes([big, small], r, 0.0005, 0)
    cfg = FitConfig()
    counts = np.bincount(inst.ravel(), minlength=13)
    tiny = [i for i in range(7, 13) if counts[i] > 0]
    assert len(tiny) == 3
    assert all(cfg.small_instance_px <= counts[i] < cfg.min_instance_px for i in tiny)
    fit = fit_scan(*make_scan(depth, inst, labels), cfg)
    for i in tiny:
        p = fit.primitives[i]
        assert isinstance(p, Plane)
        assert abs(p.axis_vector @ planes[i][1]) > np.cos(np.deg2rad(0.1))
        assert abs(float(p.signed_distance(planes[i][0][None])[0])) < 2e-4
        assert fit.axis_labels[i] in ("X", "Y", "Z")
    # the no-axis ablation has no frame to lend: the small faces stay unfitted there
    free = fit_scan(*make_scan(depth, inst, labels), cfg, ablation="no-axis")
    assert not any(i in free.primitives for i in tiny)


def _cylinder_patch(radius: float, n: int, noise: float, seed: int) -> InstancePoints:
    """``n`` points on a 90-degree arc (2 mm long) of a cylinder along the camera's y axis, 0.4 m away, facing
    the camera; exact normals; ``noise`` metres of Gaussian noise along them."""
    rng = np.random.default_rng(seed)
    ang = rng.uniform(-np.pi / 4, np.pi / 4, n)
    y = rng.uniform(-0.001, 0.001, n)
    nrm = np.stack([np.sin(ang), np.zeros(n), -np.cos(ang)], axis=1)
    centre = np.array([0.0, 0.0, 0.4])
    x = centre + radius * nrm + y[:, None] * np.array([0.0, 1.0, 0.0])
    x = x + rng.normal(0.0, noise, n)[:, None] * nrm
    return InstancePoints(pixels=np.arange(n), points=x, normals=nrm)


def test_small_cylinder_takes_the_labelled_axis_and_its_radius() -> None:
    """A 20-point arc of a 3 mm cylinder labelled cylinder-Y, the frame's Y being its axis: a cylinder on that
    axis, radius within 10 %; labelled with the unaligned class U it is left out (no axis to lend)."""
    frame = np.eye(3)
    ip = _cylinder_patch(0.003, 20, 5e-5, 1)
    for lab, fitted in ((label_of("cylinder", "Y"), True), (label_of("cylinder", "U"), False)):
        seg = Segmentation(
            instances=np.zeros((2, 2), np.int32),
            labels=np.array([0, lab], np.uint8),
            scores=np.ones(2, np.float32),
            method="oracle",
        )
        fits, axis_idx = _Fits(), {}
        _small_instances(fits, {1: ip}, seg, axis_idx, frame, 0.05, FitConfig())
        assert (1 in fits.prims) == fitted
        if fitted:
            p = fits.prims[1]
            assert isinstance(p, Cylinder)
            assert abs(p.axis_vector @ frame[1]) > 1 - 1e-9
            assert abs(p.radius - 0.003) < 0.0003
            assert axis_idx[1] == 1
