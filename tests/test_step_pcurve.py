"""Edges fitted in a face's (u, v) follow their polyline (exporters.occ_curves.fit_pcurve, issue 16): the VB-Rep
meshes a face from its loops' polylines, so a written edge that bulges off its polyline moves the STEP face off
its mesh."""

from __future__ import annotations

import numpy as np

from exporters.brep_config import BrepConfig
from exporters.occ_curves import fit_pcurve
from exporters.polygons import densify, dist_to_polyline_2d


def _samples(curve, n: int = 400) -> np.ndarray:  # noqa: ANN001 - an OCCT Geom2d_Curve
    ts = np.linspace(curve.FirstParameter(), curve.LastParameter(), n)
    return np.array([[curve.Value(t).X(), curve.Value(t).Y()] for t in ts])


def test_a_corner_of_three_points_is_not_written_as_an_arc():
    # a silhouette that runs 10 mm along one side and 30 mm up the other (a plane's corner, thinned to its three
    # points): any three points lie on a circle, whose arc bulged up to 7 mm off the polyline before
    tol = 0.2
    uv = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 30.0]])
    c = fit_pcurve(uv, tol, circles=True)
    assert dist_to_polyline_2d(_samples(c), uv).max() <= 3 * tol
    # and a polyline that does run along a circle stays an exact arc through its ends
    a = np.linspace(0.0, 2.0, 9)
    arc = np.stack([20 * np.cos(a), 20 * np.sin(a)], 1)
    c = fit_pcurve(arc, tol, circles=True)
    q = _samples(c)
    assert np.abs(np.linalg.norm(q, axis=1) - 20).max() < 1e-9
    assert np.allclose(q[0], arc[0]) and np.allclose(q[-1], arc[-1])
    assert dist_to_polyline_2d(densify(arc, 200), q).max() <= tol


def test_pcurve_tolerance_is_tighter_than_the_fit_tolerance():
    cfg = BrepConfig()
    assert cfg.pcurve_tol_abs < cfg.fit_tol_abs and cfg.pcurve_tol_rel < cfg.fit_tol_rel
