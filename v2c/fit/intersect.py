"""Iterative intersection refinement (the paper's E_int): boundaries of the 2D edge graph are lifted along their
camera rays and pulled onto every neighbouring surface they are close to, while the surfaces are pulled to them.

Lifted points are the graph's vertices plus samples every edge_sample_px along the edges between two part
instances. Point i sits at s_i * ray_i (s_i = z-depth, metres; ray_i has z = 1). Its candidate surfaces are the
fitted instances that meet there in the image; I_i keeps those within d_int * scale of the point, except that of
two near-parallel planes (normals within parallel_deg) only the nearer stays (supplement's parallel-plane
rejection: a step between parallel faces is an occlusion, not an intersection), and likewise of two coaxial
cylinders. Then

    E = E_int + w_r E_recon,   E_int = sum_i sum_{j in I_i} rho(d(s_i ray_i, P_j)^2 / scale^2)

(E_recon as in `align`, rho the soft-l1 loss) is minimised over all s_i, the primitives and R with the same Layout,
solver and analytic Jacobian as `align` (the depth column of an E_int row is n_j . ray_i), and the whole is repeated
with I_i recomputed at d_int * d_int_second_factor (paper: d_int / 5). See docs/geometry.md for w_r.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix

from v2c.camera import pixel_rays_closed_form
from v2c.fit.config import FitConfig
from v2c.geometry.residuals import Layout, Term, assemble, recon_jacobian_blocks, recon_residuals, sparsity
from v2c.primitives import Primitive
from v2c.segment.graph import EdgeGraph


@dataclass
class Lifted:
    """Boundary points to lift: pixel coords uv (L, 2), rays (L, 3, z = 1), candidate term indices per point,
    graph vertex index per point (-1 for edge samples), z-depths s (L,) metres."""

    uv: np.ndarray
    rays: np.ndarray
    candidates: list[tuple[int, ...]]
    vertex: np.ndarray
    s: np.ndarray


def boundary_points(graph: EdgeGraph, term_of: dict[int, int], K: np.ndarray, spacing_px: float) -> Lifted:
    """The graph's vertices and samples along its part-part edges, with candidate terms (fitted instances)."""
    uv = [graph.vertices.reshape(-1, 2)]
    cands: list[tuple[int, ...]] = [
        tuple(sorted(term_of[i] for i in vi if i in term_of)) for vi in graph.vertex_instances
    ]
    vert = [np.arange(len(graph.vertices))]
    for e in graph.edges:
        if 0 in e.instances or not all(i in term_of for i in e.instances):
            continue
        seg = np.diff(e.polyline, axis=0)
        cum = np.concatenate([[0.0], np.cumsum(np.linalg.norm(seg, axis=1))])
        if cum[-1] < 2 * spacing_px:
            continue
        t = np.arange(spacing_px, cum[-1] - 0.5 * spacing_px, spacing_px)
        pts = np.stack([np.interp(t, cum, e.polyline[:, 0]), np.interp(t, cum, e.polyline[:, 1])], axis=1)
        uv.append(pts)
        cands += [tuple(sorted(term_of[i] for i in e.instances))] * len(pts)
        vert.append(np.full(len(pts), -1))
    u = np.concatenate(uv)
    return Lifted(u, pixel_rays_closed_form(u, K), cands, np.concatenate(vert), np.zeros(len(u)))


def _pairs(cands: Sequence[tuple[int, ...]]) -> tuple[np.ndarray, np.ndarray]:
    """Flatten candidate lists into (point index, term index) arrays."""
    pi = np.fromiter((i for i, c in enumerate(cands) for _ in c), int)
    tj = np.fromiter((j for c in cands for j in c), int)
    return pi, tj


def _distances(prims: Sequence[Primitive], pts: np.ndarray, pi: np.ndarray, tj: np.ndarray) -> np.ndarray:
    """|d| of pts[pi[k]] (or pts[pi[k], :, :] for a depth grid) to prims[tj[k]], looping over primitives."""
    out = np.zeros((len(pi),) + pts.shape[1:-1])
    for j in np.unique(tj):
        k = np.flatnonzero(tj == j)
        p = pts[pi[k]]
        out[k] = np.abs(prims[j].signed_distance(p.reshape(-1, 3))).reshape(p.shape[:-1])
    return out


def init_depths(
    lifted: Lifted, prims: Sequence[Primitive], depth: np.ndarray, valid: np.ndarray, scale: float, config: FitConfig
) -> np.ndarray:
    """z-depths (L,) metres: the median valid depth within depth_window_px of each point, then a 1D search within
    +-depth_search * scale for the depth closest to all candidate surfaces (truncated at d_int)."""
    if len(lifted.uv) == 0:
        return np.zeros(0)
    h, w = depth.shape
    r = config.depth_window_px
    ui = np.clip(np.rint(lifted.uv[:, 0]).astype(int), 0, w - 1)
    vi = np.clip(np.rint(lifted.uv[:, 1]).astype(int), 0, h - 1)
    off = np.arange(-r, r + 1)
    vv = np.clip(vi[:, None, None] + off[None, :, None], 0, h - 1)
    uu = np.clip(ui[:, None, None] + off[None, None, :], 0, w - 1)
    dwin = np.where(valid[vv, uu], depth[vv, uu], np.nan).reshape(len(ui), -1)
    med = np.nanmedian(np.where(np.isnan(dwin).all(axis=1, keepdims=True), 1.0, dwin), axis=1)
    allnan = np.isnan(dwin).all(axis=1)
    if (~allnan).any():
        med[allnan] = np.median(med[~allnan])
    grid = np.linspace(-1.0, 1.0, 41) * config.depth_search * scale
    s_grid = med[:, None] + grid[None, :]  # (L, S)
    pi, tj = _pairs(lifted.candidates)
    if len(pi) == 0:
        return med
    pts = s_grid[:, :, None] * lifted.rays[:, None, :]
    d = np.minimum(_distances(prims, pts, pi, tj) / scale, config.d_int)
    cost = np.zeros_like(s_grid)
    np.add.at(cost, pi, d**2)
    return s_grid[np.arange(len(med)), np.argmin(cost, axis=1)]


def never_meeting(prims: Sequence[Primitive], parallel_deg: float, coaxial_tol: float) -> np.ndarray:
    """(N, N) bool: pairs of surfaces that must never be forced to intersect. The supplement's parallel planes
    (normals within parallel_deg), and by the same argument coaxial cylinders (axes within parallel_deg, axis lines
    closer than coaxial_tol metres): the boundary between them in the image is a step seen edge-on or an occlusion,
    never a crease."""
    n = len(prims)
    out = np.zeros((n, n), bool)
    cos_par = np.cos(np.deg2rad(parallel_deg))
    for kind in ("plane", "cylinder"):
        idx = np.flatnonzero([p.type == kind for p in prims])
        if len(idx) < 2:
            continue
        ax = np.array([prims[j].axis_vector for j in idx])
        par = np.abs(ax @ ax.T) > cos_par
        if kind == "cylinder":  # also coaxial: distance between the (parallel) axis lines
            o = np.array([prims[j].origin for j in idx])
            dv = o[:, None, :] - o[None, :, :]
            along = np.einsum("ijk,ik->ij", dv, ax)
            perp = np.linalg.norm(dv - along[..., None] * ax[:, None, :], axis=2)
            par &= perp < coaxial_tol
        np.fill_diagonal(par, False)
        out[np.ix_(idx, idx)] = par
    return out


def memberships(
    lifted: Lifted,
    prims: Sequence[Primitive],
    scale: float,
    d_thresh: float,
    parallel_deg: float,
    coaxial_tol: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """(point, term) pairs of I_i: candidates within d_thresh * scale of the lifted point, with parallel-plane
    rejection (of two surfaces in I_i that `never_meeting` flags, the farther is dropped). Only points with at
    least two members are kept (one surface alone gives no intersection). coaxial_tol: metres."""
    pi, tj = _pairs(lifted.candidates)
    if len(pi) == 0:
        return pi, tj
    x = lifted.s[:, None] * lifted.rays
    d = _distances(prims, x, pi, tj)
    keep = d < d_thresh * scale
    never = never_meeting(prims, parallel_deg, coaxial_tol)
    if never.any():
        # compare every two memberships of the same point: pi is sorted, so they are at most maxc - 1 apart
        maxc = int(np.bincount(pi).max())
        drop = np.zeros(len(pi), bool)
        for o in range(1, maxc):  # loop over the (few) offsets, vectorised over all points
            k1 = np.arange(len(pi) - o)
            k2 = k1 + o
            same = (pi[k1] == pi[k2]) & keep[k1] & keep[k2] & never[tj[k1], tj[k2]]
            drop[k1[same & (d[k1] > d[k2])]] = True
            drop[k2[same & (d[k2] >= d[k1])]] = True
        keep &= ~drop
    pi, tj = pi[keep], tj[keep]
    n_per = np.bincount(pi, minlength=len(lifted.s))
    ok = n_per[pi] >= 2
    return pi[ok], tj[ok]


def refine_intersections(
    terms: Sequence[Term],
    frame0: np.ndarray,
    lifted: Lifted,
    scale: float,
    config: FitConfig,
    d_thresh: float,
    member_prims: Sequence[Primitive] | None = None,
) -> tuple[np.ndarray, list[Primitive], np.ndarray, int]:
    """One round: I_i at d_thresh (part-size units), then minimise E_int + w_r E_recon over s, the primitives and R.

    member_prims: the surfaces I_i is measured against (default: the terms' own, i.e. the current ones).
    Returns (frame, primitives, s, number of (point, surface) intersection residuals)."""
    layout = Layout(terms, frame0)
    _, prims0 = layout.primitives(np.zeros(layout.size))
    pi, tj = memberships(
        lifted,
        prims0 if member_prims is None else member_prims,
        scale,
        d_thresh,
        config.parallel_deg,
        config.coaxial_tol * scale,
    )
    if len(pi) == 0:
        return frame0, prims0, lifted.s.copy(), 0
    pts_used = np.unique(pi)
    s_index = np.full(len(lifted.s), -1)
    s_index[pts_used] = np.arange(len(pts_used))
    ns = len(pts_used)
    n0 = layout.size
    rays = lifted.rays
    counts = [len(t.points) for t in terms]
    wr = np.sqrt(config.w_r)
    order = np.argsort(tj, kind="stable")
    pi, tj = pi[order], tj[order]
    groups = [(j, np.flatnonzero(tj == j)) for j in np.unique(tj)]

    def fun(x: np.ndarray) -> np.ndarray:
        _, prims = layout.primitives(x[:n0])
        s = x[n0:][s_index[pi]]
        p = s[:, None] * rays[pi]
        r_int = np.empty(len(pi))
        for j, k in groups:
            r_int[k] = prims[j].signed_distance(p[k])
        return np.concatenate([r_int / scale, wr * recon_residuals(prims, terms, scale)])

    shape = (len(pi) + int(sum(counts)), n0 + ns)

    def jac(x: np.ndarray) -> csr_matrix:
        _, prims = layout.primitives(x[:n0])
        s = x[n0:][s_index[pi]]
        ray = rays[pi]
        p = s[:, None] * ray
        blocks = []
        for j, k in groups:  # E_int rows: the surface's parameters, and the point's depth along its ray
            blocks.append((k, layout.columns(j), layout.term_jacobian(x[:n0], j, prims[j], p[k]) / scale))
        ds = np.empty(len(pi))
        for j, k in groups:
            ds[k] = np.sum(prims[j].normal(p[k]) * ray[k], axis=1) / scale
        blocks += recon_jacobian_blocks(layout, x[:n0], prims, scale, row0=len(pi), factor=wr)
        return assemble(blocks, shape, extra=(np.arange(len(pi)), n0 + s_index[pi], ds))

    x0 = np.concatenate([np.zeros(n0), lifted.s[pts_used]])
    if config.jacobian == "fd":
        blocks = [(1, np.concatenate([layout.columns(j), [n0 + s_index[i]]])) for i, j in zip(pi, tj, strict=True)]
        blocks += [(c, layout.columns(i)) for i, c in enumerate(counts)]
        jac_kw: dict = {"jac_sparsity": sparsity(blocks, n0 + ns)}
    else:
        jac_kw = {"jac": jac, "tr_solver": "lsmr", "tr_options": {"atol": config.lsmr_tol, "btol": config.lsmr_tol}}
    res = least_squares(
        fun,
        x0,
        method="trf",
        loss=config.loss,
        f_scale=config.loss_scale,
        x_scale="jac",
        max_nfev=config.max_nfev,
        ftol=config.ftol,
        xtol=config.ftol,
        **jac_kw,
    )
    frame, prims = layout.primitives(res.x[:n0])
    s = lifted.s.copy()
    s[pts_used] = res.x[n0:]
    return frame, prims, s, len(pi)
