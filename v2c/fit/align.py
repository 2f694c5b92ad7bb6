"""Global aligned fit: all primitives at once, every axis-labelled one (X, Y, Z) taking its axis from one shared
rotation frame R (3 dof, axis-angle around a robust initial frame), unaligned ones keeping free axes (2 dof each,
a tangent-plane update of their RANSAC axis: the supplement's reparameterisation of unit vectors).

E_recon = sum over primitives and their (subsampled) points of rho(d(x, P)^2 / scale^2), solved with scipy
``least_squares(method="trf", loss="soft_l1")``: 'trf' because it is the method that takes both a robust loss and
a sparse Jacobian (a primitive's residuals depend only on its own parameters and R), soft-l1 because its quadratic
core keeps the least-squares accuracy on inliers while boundary points and flying pixels count only linearly.
The Jacobian is analytic (`v2c.geometry.residuals.Layout.term_jacobian`: each primitive's `local_jacobian` and
`rotation_gradient`, chained through the axis parameterisation and SO(3)'s left Jacobian), dense with the exact
trust-region solver for small problems and sparse with lsmr for large ones; ``jacobian="fd"`` falls back to
scipy's grouped sparse finite differences (``jac_sparsity``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.sparse import csr_matrix

from v2c.geometry.residuals import Layout, Term, assemble, recon_jacobian_blocks, recon_residuals, sparsity
from v2c.primitives import Primitive
from v2c.primitives.directions import nearest_rotation, tangent_basis, unit

AXIS_NAMES = ("X", "Y", "Z")


def init_frame(
    axes: Sequence[np.ndarray],
    labels: Sequence[int],
    weights: Sequence[float],
    view_dir: np.ndarray,
    outlier_deg: float,
) -> np.ndarray:
    """Robust initial frame R (rows X, Y, Z, camera frame) from RANSAC axes with class labels 0/1/2.

    Per class: the axis agreeing (within ``outlier_deg``, sign ignored) with the largest total weight is the seed;
    the principal direction of the weighted scatter of the agreeing axes is the class direction. The three are
    made orthonormal by Wahba's problem (SVD) weighted by class support, so a missing class is filled in by the two
    others and a single wrong label cannot tilt the frame. Signs follow SCAN_FORMAT.md: Z towards the camera (up,
    the camera looks down), X away from it along ``view_dir`` (camera -> part), Y = Z x X.
    """
    axes = np.asarray([unit(a) for a in axes]).reshape(-1, 3)
    labels = np.asarray(labels, int)
    weights = np.asarray(weights, float)
    cos_tol = np.cos(np.deg2rad(outlier_deg))
    dirs, support = np.zeros((3, 3)), np.zeros(3)
    for k in range(3):
        sel = labels == k
        if not sel.any():
            continue
        a, w = axes[sel], weights[sel]
        agree = np.abs(a @ a.T) > cos_tol
        seed = int(np.argmax(agree @ w))
        m = agree[seed]
        s = np.sign(a[m] @ a[seed])
        am = a[m] * s[:, None]
        _, evecs = np.linalg.eigh((am * w[m][:, None]).T @ am)
        e = evecs[:, -1]
        e = e if e @ a[seed] >= 0 else -e
        dirs[k], support[k] = e, np.sum(w[m])
    if np.all(support > 0) and np.linalg.det(dirs) < 0:  # axes are undirected: make the triple right-handed
        dirs[int(np.argmin(support))] *= -1
    b = support[:, None] * dirs  # Wahba: maximise sum_k support_k dirs_k . R_k
    if not b.any():
        return np.eye(3)
    if np.linalg.matrix_rank(b, tol=1e-9 * np.abs(b).max()) == 1:  # one class: complete it arbitrarily
        k = int(np.argmax(np.abs(b).sum(axis=1)))
        e = unit(b[k])
        t1, t2 = tangent_basis(e)
        rows = [None, None, None]
        rows[k], rows[(k + 1) % 3], rows[(k + 2) % 3] = e, t1, t2
        r = np.array(rows)
    else:
        r = nearest_rotation(b)  # rows = frame axes in the camera frame
    return orient_frame(r, view_dir)


def frame_from_axes(
    axes: Sequence[np.ndarray], weights: Sequence[float], view_dir: np.ndarray, tol_deg: float
) -> np.ndarray | None:
    """A frame from unlabelled axes (weak labels: the geometric segmenter): the weighted-consensus direction, then
    the consensus direction among the axes orthogonal to it (within ``tol_deg``), completed by their cross product.
    Naming follows SCAN_FORMAT.md's conventions as far as a camera can tell: Z is the direction closest to the
    image's up (-y), X the remaining one closer to the viewing direction. None without axes."""
    a = np.asarray([unit(x) for x in axes]).reshape(-1, 3)
    w = np.asarray(weights, float)
    if len(a) == 0:
        return None
    cos_tol = np.cos(np.deg2rad(tol_deg))

    def consensus(sel: np.ndarray) -> np.ndarray:
        agree = (np.abs(a @ a.T) > cos_tol) & sel[None, :]
        seed = int(np.argmax(np.where(sel, agree @ w, -1.0)))
        m = agree[seed]
        am = a[m] * np.sign(a[m] @ a[seed])[:, None]
        e = np.linalg.eigh((am * w[m][:, None]).T @ am)[1][:, -1]
        return e if e @ a[seed] >= 0 else -e

    e1 = consensus(np.ones(len(a), bool))
    ortho = np.abs(a @ e1) < np.sin(np.deg2rad(tol_deg))
    e2 = consensus(ortho) if ortho.any() else tangent_basis(e1)[0]
    e2 = unit(e2 - (e2 @ e1) * e1)
    dirs = [e1, e2, np.cross(e1, e2)]
    kz = int(np.argmax([abs(d[1]) for d in dirs]))
    rest = [d for k, d in enumerate(dirs) if k != kz]
    kx = int(np.argmax([abs(d @ view_dir) for d in rest]))
    z, x = dirs[kz], rest[kx]
    return orient_frame(np.array([x, np.cross(z, x), z]), view_dir)


def orient_frame(r: np.ndarray, view_dir: np.ndarray) -> np.ndarray:
    """Flip pairs of rows (keeping det = +1) so that Z . view_dir < 0 and then X . view_dir >= 0."""
    r = np.array(r, float)
    if r[2] @ view_dir > 0:
        r[[1, 2]] *= -1
    if r[0] @ view_dir < 0:
        r[[0, 1]] *= -1
    return r


def align_fit(
    terms: Sequence[Term],
    frame0: np.ndarray,
    scale: float,
    loss: str,
    loss_scale: float,
    max_nfev: int,
    ftol: float = 1e-8,
    jacobian: str = "analytic",
    lsmr_tol: float = 1e-5,
) -> tuple[np.ndarray, list[Primitive]]:
    """Minimise E_recon over R and every primitive jointly (see module docstring). Returns (frame, primitives).

    jacobian: "analytic" (each primitive's `local_jacobian` and `rotation_gradient`, chained through the axis
    parameterisation) or "fd" (sparse finite differences, for checking)."""
    from scipy.optimize import least_squares

    layout = Layout(terms, frame0)
    counts = [len(t.points) for t in terms]
    if layout.size == 0 or sum(counts) <= layout.size:
        return frame0, [t.prim for t in terms]
    # small problems: the exact trust-region solver on a dense Jacobian is fastest; large ones: lsmr, sparse
    dense = layout.size * int(sum(counts)) <= 500_000

    def fun(x: np.ndarray) -> np.ndarray:
        _, prims = layout.primitives(x)
        return recon_residuals(prims, terms, scale)

    nrows = int(sum(counts))

    def jac(x: np.ndarray) -> csr_matrix | np.ndarray:
        _, prims = layout.primitives(x)
        j = assemble(recon_jacobian_blocks(layout, x, prims, scale), (nrows, layout.size))
        return j.toarray() if dense else j

    if jacobian == "fd":
        jac_kw: dict = {"jac_sparsity": sparsity([(c, layout.columns(i)) for i, c in enumerate(counts)], layout.size)}
    else:
        jac_kw = (
            {"jac": jac, "tr_solver": "exact"}
            if dense
            else {"jac": jac, "tr_solver": "lsmr", "tr_options": {"atol": lsmr_tol, "btol": lsmr_tol}}
        )
    res = least_squares(
        fun,
        np.zeros(layout.size),
        method="trf",
        loss=loss,
        f_scale=loss_scale,
        x_scale="jac",
        max_nfev=max_nfev,
        ftol=ftol,
        xtol=ftol,
        **jac_kw,
    )
    return layout.primitives(res.x)
