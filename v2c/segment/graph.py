"""The 2D edge graph of an instance map: boundaries between instances as simplified polylines.

Boundaries live on the *crack lattice*: the pixel corners, at (u, v) = (j - 0.5, i - 0.5) for corner (i, j),
i in 0..H, j in 0..W, joined by the cracks between 4-neighbouring pixels. The map is padded with 0 (outside counts as
background), so every boundary closes. A crack is active where its two pixels differ. A corner where three or more
active cracks meet (three or more instances, or two in a checkerboard) is a junction: a graph vertex. The active
cracks between junctions form chains; each chain separates one pair of instances and becomes one edge, simplified
with Douglas-Peucker. A closed boundary without a junction (an island) becomes a loop on one vertex (v0 == v1).

Everything is vectorised over cracks: chains are found as connected components of the crack adjacency graph and
ordered by one depth-first traversal (scipy.sparse.csgraph) from a virtual root linked to one end of every chain.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, depth_first_order

from v2c.polyline import rdp_indices


@dataclass
class GraphEdge:
    """One boundary chain. polyline: (K, 2) float pixel coords (u, v), simplified, from vertex v0 to vertex v1.
    instances: the two instances it separates (i < j; 0 = background/outside)."""

    polyline: np.ndarray
    instances: tuple[int, int]
    v0: int
    v1: int


@dataclass
class EdgeGraph:
    """vertices: (M, 2) float pixel coords (u, v) of junctions (and one vertex per island loop).
    vertex_instances: the instances meeting at each vertex (0 = background/outside). edges: boundary chains."""

    vertices: np.ndarray
    vertex_instances: list[frozenset[int]]
    edges: list[GraphEdge] = field(default_factory=list)


def douglas_peucker(points: np.ndarray, tol: float) -> np.ndarray:
    """Douglas-Peucker simplification of an open polyline (K, 2); keeps both ends; ``tol`` in the points' unit.

    A closed polyline (first == last point) is split at the point farthest from its start and each half simplified.
    """
    pts = np.asarray(points, float)
    if len(pts) <= 2:
        return pts.copy()
    if np.allclose(pts[0], pts[-1]):
        k = int(np.argmax(np.linalg.norm(pts - pts[0], axis=1)))
        if k == 0:
            return pts[:1].copy()
        a, b = douglas_peucker(pts[: k + 1], tol), douglas_peucker(pts[k:], tol)
        return np.concatenate([a, b[1:]])
    return pts[rdp_indices(pts, tol)]


def _cracks(lab: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Active cracks of the padded map ``lab`` (H + 2, W + 2): corner ids (a, b) and the labels on each side."""
    h, w = lab.shape[0] - 2, lab.shape[1] - 2
    cid = np.arange((h + 1) * (w + 1)).reshape(h + 1, w + 1)
    # horizontal cracks (i, j)-(i, j+1): pixel above lab[i, j+1], below lab[i+1, j+1]
    up, dn = lab[:-1, 1:-1], lab[1:, 1:-1]
    hm = up != dn
    # vertical cracks (i, j)-(i+1, j): pixel left lab[i+1, j], right lab[i+1, j+1]
    lf, rt = lab[1:-1, :-1], lab[1:-1, 1:]
    vm = lf != rt
    a = np.concatenate([cid[:, :-1][hm], cid[:-1, :][vm]])
    b = np.concatenate([cid[:, 1:][hm], cid[1:, :][vm]])
    la = np.concatenate([up[hm], lf[vm]])
    lb = np.concatenate([dn[hm], rt[vm]])
    return a, b, np.minimum(la, lb), np.maximum(la, lb)


def build_edge_graph(instances: np.ndarray, simplify_px: float = 1.0) -> EdgeGraph:
    """Edge graph of an (H, W) integer instance map (0 = background); polylines simplified to ``simplify_px``
    pixels (Douglas-Peucker tolerance). Vertex and polyline coordinates are pixel (u, v), pixel centres at
    integers, so boundaries run along half-integer coordinates."""
    inst = np.asarray(instances)
    h, w = inst.shape
    lab = np.zeros((h + 2, w + 2), np.int64)
    lab[1:-1, 1:-1] = inst
    a, b, l0, l1 = _cracks(lab)
    n = len(a)
    if n == 0:
        return EdgeGraph(np.zeros((0, 2)), [], [])
    ncorner = (h + 1) * (w + 1)
    deg = np.bincount(np.concatenate([a, b]), minlength=ncorner)

    # crack adjacency through degree-2 corners: each such corner pairs exactly two cracks
    end_crack = np.concatenate([np.arange(n), np.arange(n)])
    end_corner = np.concatenate([a, b])
    sel = deg[end_corner] == 2
    ec, cc = end_crack[sel], end_corner[sel]
    o = np.argsort(cc, kind="stable")
    p0, p1 = ec[o][0::2], ec[o][1::2]
    ncomp, comp = connected_components(coo_matrix((np.ones(len(p0)), (p0, p1)), shape=(n, n)), directed=False)
    cdeg = np.bincount(np.concatenate([p0, p1]), minlength=n)

    # one start crack per chain: an end (crack degree <= 1) of a path, the smallest crack of a cycle
    big = n + 1
    end_key = np.where(cdeg <= 1, np.arange(n), big)
    start = np.full(ncomp, big)
    np.minimum.at(start, comp, end_key)
    cyclic = start == big
    first_any = np.full(ncomp, big)
    np.minimum.at(first_any, comp, np.arange(n))
    start = np.where(cyclic, first_any, start)
    # break each cycle next to its start crack: drop the first adjacency pair that touches it
    is_cyc_start = np.zeros(n, bool)
    is_cyc_start[start[cyclic]] = True
    touch = is_cyc_start[p0] | is_cyc_start[p1]
    touch_idx = np.flatnonzero(touch)
    owner = np.where(is_cyc_start[p0[touch_idx]], p0[touch_idx], p1[touch_idx])
    _, first = np.unique(owner, return_index=True)
    keep = np.ones(len(p0), bool)
    keep[touch_idx[first]] = False
    q0, q1 = p0[keep], p1[keep]

    # one DFS from a virtual root linked to every start orders every chain contiguously, end to end
    root = n
    rows = np.concatenate([q0, np.full(ncomp, root)])
    cols = np.concatenate([q1, start])
    g = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n + 1, n + 1)).tocsr()
    order = depth_first_order(g, root, directed=False, return_predecessors=False)[1:]
    oc = comp[order]
    oa, ob = a[order], b[order]
    same_next = np.zeros(len(order), bool)
    same_next[:-1] = oc[:-1] == oc[1:]
    na, nb = np.roll(oa, -1), np.roll(ob, -1)
    shared = np.where((oa == na) | (oa == nb), oa, ob)  # corner shared with the next crack (if same chain)
    bounds = np.flatnonzero(np.diff(np.concatenate([[-1], oc, [-2]])) != 0)

    # vertices: junction corners, then one corner per cycle
    junction = np.flatnonzero(deg >= 3)
    cyc_corner = []
    chains = []
    for s, e in pairwise(bounds):  # loop over chains (edges), not over points
        k = e - s
        if k == 1:
            seq = np.array([oa[s], ob[s]])
        else:
            mid = shared[s : e - 1]
            c_first = ob[s] if oa[s] == mid[0] else oa[s]
            c_last = ob[e - 1] if oa[e - 1] == mid[-1] else oa[e - 1]
            seq = np.concatenate([[c_first], mid, [c_last]])
        if cyclic[oc[s]]:
            cyc_corner.append(seq[0])
        chains.append((seq, (int(l0[order[s]]), int(l1[order[s]]))))
    vcorner = np.concatenate([junction, np.asarray(cyc_corner, np.int64)])
    vid = {int(c): i for i, c in enumerate(vcorner)}
    vi, vj = np.divmod(vcorner, w + 1)
    vertices = np.stack([vj - 0.5, vi - 0.5], axis=1).astype(float)
    quad = np.stack([lab[vi, vj], lab[vi, vj + 1], lab[vi + 1, vj], lab[vi + 1, vj + 1]], axis=1)
    vinst = [frozenset(int(x) for x in row) for row in quad]

    edges = []
    for seq, pair in chains:
        ci, cj = np.divmod(seq, w + 1)
        poly = douglas_peucker(np.stack([cj - 0.5, ci - 0.5], axis=1).astype(float), simplify_px)
        edges.append(GraphEdge(polyline=poly, instances=pair, v0=vid[int(seq[0])], v1=vid[int(seq[-1])]))
    return EdgeGraph(vertices=vertices, vertex_instances=vinst, edges=edges)


__all__ = ["EdgeGraph", "GraphEdge", "build_edge_graph", "douglas_peucker"]
