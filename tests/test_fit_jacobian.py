"""Analytic Jacobians of the joint fits against finite differences (all types; aligned and free axes)."""

from __future__ import annotations

import numpy as np
from scipy.optimize._numdiff import approx_derivative

from v2c.geometry.residuals import Layout, Term, assemble, recon_jacobian_blocks, recon_residuals
from v2c.primitives import Cone, Cylinder, Plane, Sphere, Torus
from v2c.primitives.directions import rotation_exp, unit


def test_recon_jacobian_matches_finite_differences() -> None:
    rng = np.random.default_rng(0)
    frame = rotation_exp(np.array([0.3, -0.4, 0.2])).T
    prims = [
        (Plane([0.0, 0.0, 0.5], -frame[2]), 2, -1.0),
        (Cylinder([0.01, 0.0, 0.5], frame[0], 0.03), 0, 1.0),
        (Cone([0.0, 0.02, 0.45], unit(np.array([0.2, -0.3, 0.9])), 0.5), -1, 1.0),
        (Torus([0.0, 0.0, 0.52], frame[1], 0.04, 0.01), 1, 1.0),
        (Sphere([0.02, 0.0, 0.5], 0.03), None, 1.0),
        (Plane([0.0, 0.01, 0.5], unit(np.array([0.1, 0.2, -1.0]))), -1, 1.0),
    ]
    terms = []
    for p, k, sign in prims:
        centre = p.origin + (0.05 * p.axis_vector if p.type == "cone" else 0.0)  # away from the apex singularity
        x = p.closest_point(centre + rng.normal(0, 0.03, (50, 3))) + rng.normal(0, 0.002, (50, 3))
        terms.append(Term(p, x, k, sign, weight=1.5))
    layout = Layout(terms, frame)
    x0 = rng.normal(0, 1e-3, layout.size)  # away from the reference, where the chain rule matters

    def fun(x: np.ndarray) -> np.ndarray:
        return recon_residuals(layout.primitives(x)[1], terms, 0.1)

    _, cur = layout.primitives(x0)
    ana = assemble(
        recon_jacobian_blocks(layout, x0, cur, 0.1), (sum(len(t.points) for t in terms), layout.size)
    ).toarray()
    num = approx_derivative(fun, x0, method="3-point")
    assert np.abs(ana - num).max() < 1e-5 * np.abs(num).max()
