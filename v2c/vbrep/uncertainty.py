"""Positional uncertainty (1 sigma, millimetres) of faces and edges from the fit's covariance and the depth noise.

Face: the primitive's parameters are perturbed by its local parameters (`Primitive.local_jacobian`: offset,
radius, axis position) and a small rotation (`Primitive.rotation_gradient`); J (N, p) holds the derivatives of the
signed distance of the face's N observed points. With s the residual standard deviation, the parameter covariance
is ``C = s^2 (J^T J)^+`` (pseudo-inverse: directions that do not move the surface, such as a turn of a cylinder
about its own axis, get none), and the 1-sigma offset of the surface along its normal at a point x is
``sqrt(g(x) C g(x)^T)`` with g(x) the row of J at x. A face's sigma is that at the closest surface point to its
observed points' centroid: for a plane fitted to N points with i.i.d. noise s, ``s / sqrt(N)``.

``s = max(RMS fit residual, sigma_z(z))``: the sensor's depth noise at the face's median depth
(``UncertaintyConfig.depth_sigma_coeff_per_m * z^2``, the `sensor` profile's law) is a floor, since a trimmed fit's
residual can undercount it.

The covariance takes point errors as independent, but a depth sensor's error is partly common to a whole face (a
low-frequency warp, a bias): that part is not shrunk by N. It is added in quadrature as ``depth_correlated *
sigma_z(z)`` (``depth_correlated`` = 1: the whole per-pixel depth sigma). Checked on the tuning scans (bench seed
9600, scans 0-9, learned, 82 faces matched to a true face; the error is the median signed distance of the true
face's clean-depth points to the fitted surface): with the covariance alone the median |error| / sigma is 14 (4 %
within 1 sigma); with the correlated term 0.80, and 56 / 94 / 98 % within 1 / 2 / 3 sigma (a normal law: 68 / 95 /
99.7).

Edge, at each sample x: an intersection edge moves where both surfaces move: the displacement d in the plane of
the two normals n_a, n_b solving ``n_a . d = e_a, n_b . d = e_b`` with independent e_a ~ sigma_a(x), e_b ~
sigma_b(x): ``var = (sigma_a^2 + sigma_b^2) / sin^2(angle)`` (angle clipped below at ``min_angle_deg``: nearly
tangent surfaces meet in a poorly defined curve). A one-face edge (visibility, silhouette, occluded) lies on its
face's surface where the image puts the outline: ``var = sigma_face(x)^2 + (half_pixel * z / f)^2``. The edge's
sigma is the RMS over its samples.

"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from v2c.primitives.base import Primitive


@dataclass(frozen=True)
class UncertaintyConfig:
    """Noise model of the positional uncertainty (module docstring). The extraction builds it from the sigma_*
    fields of `VBRepConfig` (`v2c.vbrep.assemble.uncertainty_config`); the defaults serve direct callers."""

    depth_sigma_coeff_per_m: float = 0.0015  # 1/m: depth noise sigma = coeff * z^2 (z metres), the sensor law
    depth_correlated: float = 1.0  # fraction of that sigma common to a whole face (not averaged out over its points)
    min_angle_deg: float = 5.0  # degrees: intersection angle floor (sigma / sin(angle) stays finite)
    half_pixel: float = 0.5  # pixels: an outline's position in the image is known to about half a pixel
    max_points: int = 20000  # points per face used for J (a seeded subsample beyond; the sigma scales back)
    seed: int = 0


def _jacobian(prim: Primitive, X: np.ndarray) -> np.ndarray:
    """(N, p) derivatives of the signed distance at X with respect to the local parameters and a rotation."""
    try:
        jl = np.asarray(prim.local_jacobian(X, prim), float).reshape(len(X), -1)
    except NotImplementedError:
        jl = np.zeros((len(X), 0))
    return np.hstack([jl, np.asarray(prim.rotation_gradient(X), float)])


@dataclass
class FaceCovariance:
    """A fitted primitive's parameter covariance (C = s^2 (J^T J)^+ in the layout of `_jacobian`)."""

    prim: Primitive
    cov: np.ndarray
    s: float  # metres: residual standard deviation used
    n: int  # points
    floor_m: float = 0.0  # metres: the face-wide (correlated) depth error, added in quadrature

    def fit_sigma_at(self, x: np.ndarray) -> np.ndarray:
        """The covariance's part alone (metres): ``sqrt(g C g^T)`` at the closest surface points to x (N, 3)."""
        x = np.asarray(x, float).reshape(-1, 3)
        if len(x) == 0:
            return np.zeros(0)
        g = _jacobian(self.prim, self.prim.closest_point(x))
        return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", g, self.cov, g), 0.0))

    def sigma_at(self, x: np.ndarray) -> np.ndarray:
        """1-sigma offset (metres) of the surface along its normal at the closest surface points to x (N, 3):
        the fit's covariance and the face-wide depth error in quadrature."""
        return np.sqrt(self.fit_sigma_at(x) ** 2 + self.floor_m**2)


def face_covariance(prim: Primitive, X: np.ndarray, residual_m: float, cfg: UncertaintyConfig) -> FaceCovariance | None:
    """Covariance of ``prim`` fitted to points X (N, 3, camera frame, metres) with RMS residual ``residual_m``;
    None for fewer points than parameters."""
    X = np.asarray(X, float).reshape(-1, 3)
    X = X[np.isfinite(X).all(1)]
    n = len(X)
    if n == 0:
        return None
    z = float(np.median(X[:, 2]))
    s = max(float(residual_m) if np.isfinite(residual_m) else 0.0, cfg.depth_sigma_coeff_per_m * z * z)
    w = 1.0
    if n > cfg.max_points:  # J^T J grows with N: a subsample's, scaled by N / m, estimates it
        X = X[np.random.default_rng(cfg.seed).choice(n, cfg.max_points, replace=False)]
        w = n / cfg.max_points
    J = _jacobian(prim, X)
    if len(X) < J.shape[1]:
        return None
    cov = s * s * np.linalg.pinv(w * (J.T @ J), rcond=1e-10, hermitian=True)
    return FaceCovariance(prim, cov, s, n, cfg.depth_correlated * cfg.depth_sigma_coeff_per_m * z * z)


def face_sigma_m(fc: FaceCovariance, X: np.ndarray) -> float:
    """A face's 1-sigma (metres): at the closest surface point to its points' centroid."""
    c = np.nanmean(np.asarray(X, float).reshape(-1, 3), axis=0)
    return float(fc.sigma_at(c[None])[0])


def intersection_sigma_m(fa: FaceCovariance, fb: FaceCovariance, x: np.ndarray, cfg: UncertaintyConfig) -> float:
    """RMS over the samples x (K, 3) of an intersection edge's 1-sigma position error (metres)."""
    x = np.asarray(x, float).reshape(-1, 3)
    if len(x) == 0:
        return float("nan")
    na, nb = fa.prim.normal(x), fb.prim.normal(x)
    sin = np.linalg.norm(np.cross(na, nb), axis=1)
    sin = np.maximum(sin, np.sin(np.deg2rad(cfg.min_angle_deg)))
    var = (fa.sigma_at(x) ** 2 + fb.sigma_at(x) ** 2) / sin**2
    return float(np.sqrt(np.mean(var)))


def outline_sigma_m(f: FaceCovariance, x: np.ndarray, focal_px: float, cfg: UncertaintyConfig) -> float:
    """RMS over the samples x (K, 3) of a one-face edge's 1-sigma position error (metres)."""
    x = np.asarray(x, float).reshape(-1, 3)
    if len(x) == 0:
        return float("nan")
    var = f.sigma_at(x) ** 2 + (cfg.half_pixel * x[:, 2] / focal_px) ** 2
    return float(np.sqrt(np.mean(var)))
