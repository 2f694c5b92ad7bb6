"""Point-to-surface residuals of primitives and their analytic Jacobians, for robust least squares.

A `Term` is one primitive with its points (camera frame, metres); a `Layout` maps one flat parameter vector to
an optional shared rotation frame R and every term's primitive (its local parameters, and a free axis' two
tangent coefficients: the supplement's reparameterisation of unit vectors). `recon_residuals` are the terms'
signed distances in part-size units (E_recon of the paper); `recon_jacobian_blocks` their analytic derivatives,
which `assemble` turns into a sparse matrix. Used by the single-primitive refinement of RANSAC
(`v2c.geometry.ransac.refine_primitive`) and by the joint fits of the geometry stage (`v2c.fit.align`,
`v2c.fit.intersect`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import csr_matrix

from v2c.primitives import Primitive
from v2c.primitives.directions import cross_vec, perturb_direction, rotation_exp, tangent_basis


@dataclass
class Term:
    """One primitive in the joint fit: reference primitive, points (m, 3, metres) and how its axis is set:
    axis_index 0/1/2 = frame row X/Y/Z (times axis_sign), -1 = free axis, -2 = axis fixed at the reference's,
    None = no axis (sphere).
    weight: multiplies the term's residuals (sqrt of the number of inliers each subsampled point stands for, so
    that E_recon is the sum over all inliers as in the paper)."""

    prim: Primitive
    points: np.ndarray
    axis_index: int | None
    axis_sign: float = 1.0
    weight: float = 1.0


@dataclass
class Layout:
    """Maps the flat parameter vector to (R, primitives): [w (3, only if any term is aligned)] then, per term,
    its local parameters and (free axis) two tangent coefficients."""

    terms: Sequence[Term]
    frame0: np.ndarray
    offsets: list[int] = field(default_factory=list)
    size: int = 0
    use_frame: bool = False

    def __post_init__(self) -> None:
        self.use_frame = any(t.axis_index is not None and t.axis_index >= 0 for t in self.terms)
        k = 3 if self.use_frame else 0
        self._bases = []
        for t in self.terms:
            self.offsets.append(k)
            k += t.prim.local_size + (2 if t.axis_index == -1 else 0)
            a = t.prim.axis_vector
            self._bases.append(tangent_basis(a) if a is not None else None)
        self.size = k

    def frame(self, x: np.ndarray) -> np.ndarray:
        """(3, 3) rows X, Y, Z of R in the camera frame for parameters ``x``."""
        if not self.use_frame:
            return self.frame0
        return (rotation_exp(x[:3]) @ self.frame0.T).T

    def primitive(self, x: np.ndarray, i: int, frame: np.ndarray) -> Primitive:
        """Term ``i``'s primitive for parameters ``x`` and frame rows ``frame``."""
        t = self.terms[i]
        o = self.offsets[i]
        nl = t.prim.local_size
        if t.axis_index is None or t.axis_index == -2:
            axis = t.prim.axis_vector
        elif t.axis_index >= 0:
            axis = t.axis_sign * frame[t.axis_index]
        else:
            axis = perturb_direction(t.prim.axis_vector, x[o + nl : o + nl + 2], self._bases[i])
        return t.prim.from_local(x[o : o + nl], axis)

    def columns(self, i: int) -> np.ndarray:
        """Parameter indices term ``i`` depends on."""
        t = self.terms[i]
        o = self.offsets[i]
        own = np.arange(o, o + t.prim.local_size + (2 if t.axis_index == -1 else 0))
        if t.axis_index is not None and t.axis_index >= 0:
            return np.concatenate([np.arange(3), own])
        return own

    def primitives(self, x: np.ndarray) -> tuple[np.ndarray, list[Primitive]]:
        """(frame rows X, Y, Z (3, 3), every term's primitive) for parameters ``x``."""
        f = self.frame(x)
        return f, [self.primitive(x, i, f) for i in range(len(self.terms))]

    def term_jacobian(self, x: np.ndarray, i: int, prim: Primitive, pts: np.ndarray) -> np.ndarray:
        """(m, len(columns(i))) analytic derivatives of term ``i``'s signed distances at ``pts`` (``prim`` = its
        current primitive) with respect to the parameters in ``columns(i)`` (unweighted, metres per unit)."""
        t = self.terms[i]
        nl = t.prim.local_size
        blocks = []
        if t.axis_index is not None and t.axis_index >= 0:  # the frame turns by J_l(w) dw (world frame)
            blocks.append(prim.rotation_gradient(pts) @ left_jacobian(x[:3]))
        blocks.append(prim.local_jacobian(pts, t.prim))
        if t.axis_index == -1:  # a = normalise(a0 + a t1 + b t2): turning by a x da/d(coefficient)
            o = self.offsets[i]
            t1, t2 = self._bases[i]
            u = t.prim.axis_vector + x[o + nl] * t1 + x[o + nl + 1] * t2
            length = float(np.sqrt(u @ u))
            a = u / length
            g = prim.rotation_gradient(pts)
            blocks.append(np.stack([g @ cross_vec(a, (tb - a * (a @ tb)) / length) for tb in (t1, t2)], axis=1))
        return np.concatenate(blocks, axis=1)


def left_jacobian(w: np.ndarray) -> np.ndarray:
    """Left Jacobian of SO(3) at the rotation vector ``w``: exp(w + dw) = exp(J_l(w) dw) exp(w) to first order."""
    th = float(np.linalg.norm(w))
    k = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if th < 1e-8:
        return np.eye(3) + 0.5 * k
    return np.eye(3) + (1 - np.cos(th)) / th**2 * k + (th - np.sin(th)) / th**3 * (k @ k)


def assemble(
    blocks: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
    shape: tuple[int, int],
    extra: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> csr_matrix:
    """Sparse matrix from dense blocks (row indices (m,), column indices (c,), values (m, c)) plus optional
    single entries ``extra`` = (rows (k,), cols (k,), values (k,))."""
    rows = [np.repeat(r, len(c)) for r, c, _ in blocks]
    cols = [np.tile(c, len(r)) for r, c, _ in blocks]
    vals = [v.reshape(-1) for _, _, v in blocks]
    if extra is not None:
        rows.append(extra[0])
        cols.append(extra[1])
        vals.append(extra[2])
    if not rows:
        return csr_matrix(shape)
    return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=shape)


def recon_jacobian_blocks(
    layout: Layout, x: np.ndarray, prims: Sequence[Primitive], scale: float, row0: int = 0, factor: float = 1.0
) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Jacobian blocks of `recon_residuals` (times ``factor``), rows starting at ``row0``."""
    out = []
    r = row0
    for i, (p, t) in enumerate(zip(prims, layout.terms, strict=True)):
        m = len(t.points)
        vals = layout.term_jacobian(x, i, p, t.points) * (factor * t.weight / scale)
        out.append((np.arange(r, r + m), layout.columns(i), vals))
        r += m
    return out


def sparsity(blocks: Sequence[tuple[int, np.ndarray]], ncols: int) -> csr_matrix:
    """Jacobian sparsity from consecutive row blocks: (number of rows, parameter columns they depend on)."""
    rows, cols = [], []
    r = 0
    for c, cs in blocks:
        rr = np.arange(r, r + c)
        rows.append(np.repeat(rr, len(cs)))
        cols.append(np.tile(np.asarray(cs, int), c))
        r += c
    if not rows:
        return csr_matrix((0, ncols), dtype=np.int8)
    return csr_matrix(
        (np.ones(sum(len(x) for x in rows), np.int8), (np.concatenate(rows), np.concatenate(cols))), shape=(r, ncols)
    )


def recon_residuals(prims: Sequence[Primitive], terms: Sequence[Term], scale: float) -> np.ndarray:
    """Point-to-surface distances of every term's points, in part-size units (concatenated)."""
    if not terms:
        return np.zeros(0)
    return np.concatenate([t.weight * p.signed_distance(t.points) for p, t in zip(prims, terms, strict=True)]) / scale
