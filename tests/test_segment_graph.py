"""The 2D edge graph of an instance map: exact vertices and edge instance pairs on known maps."""

from __future__ import annotations

import numpy as np

from v2c.segment.graph import build_edge_graph, douglas_peucker


def _edge_map(g) -> dict[tuple[int, int], tuple[tuple[float, float], tuple[float, float]]]:
    out = {}
    for e in g.edges:
        a, b = tuple(g.vertices[e.v0]), tuple(g.vertices[e.v1])
        assert np.allclose(e.polyline[0], a) and np.allclose(e.polyline[-1], b)
        out[e.instances] = tuple(sorted([a, b]))
    return out


def test_t_junction_vertices_and_edges() -> None:
    m = np.zeros((20, 30), np.int32)
    m[:10] = 1
    m[10:, :15] = 2
    m[10:, 15:] = 3
    g = build_edge_graph(m)
    verts = {tuple(v): s for v, s in zip(g.vertices.tolist(), g.vertex_instances, strict=True)}
    assert verts == {
        (14.5, 9.5): frozenset({1, 2, 3}),  # the T junction
        (-0.5, 9.5): frozenset({0, 1, 2}),  # boundaries meeting the image border (outside = 0)
        (29.5, 9.5): frozenset({0, 1, 3}),
        (14.5, 19.5): frozenset({0, 2, 3}),
    }
    edges = _edge_map(g)
    assert set(edges) == {(1, 2), (1, 3), (2, 3), (0, 1), (0, 2), (0, 3)}
    assert edges[(1, 2)] == ((-0.5, 9.5), (14.5, 9.5))
    assert edges[(1, 3)] == ((14.5, 9.5), (29.5, 9.5))
    assert edges[(2, 3)] == ((14.5, 9.5), (14.5, 19.5))
    # straight boundaries simplify to their two ends; the outer boundary of 1 keeps the image corners
    e12 = next(e for e in g.edges if e.instances == (1, 2))
    assert len(e12.polyline) == 2
    e01 = next(e for e in g.edges if e.instances == (0, 1))
    assert {tuple(p) for p in e01.polyline.tolist()} == {(-0.5, 9.5), (-0.5, -0.5), (29.5, -0.5), (29.5, 9.5)}


def test_island_is_a_loop_on_one_vertex() -> None:
    m = np.ones((10, 12), np.int32)
    m[3:6, 4:8] = 2
    g = build_edge_graph(m)
    loop = next(e for e in g.edges if e.instances == (1, 2))
    assert loop.v0 == loop.v1
    assert g.vertex_instances[loop.v0] == frozenset({1, 2})
    assert {tuple(p) for p in loop.polyline.tolist()} == {(3.5, 2.5), (7.5, 2.5), (7.5, 5.5), (3.5, 5.5)}
    assert len(g.edges) == 2  # the island and the outer border of instance 1


def test_diagonal_boundary_is_simplified_within_tolerance() -> None:
    v, u = np.mgrid[0:40, 0:40]
    m = np.where(u > v, 1, 2).astype(np.int32)
    g = build_edge_graph(m, simplify_px=1.0)
    e = next(e for e in g.edges if e.instances == (1, 2))
    assert len(e.polyline) <= 3  # a staircase within 1 px of a straight line
    # where u = v + 1 meets the border
    assert np.allclose(sorted(map(tuple, g.vertices[[e.v0, e.v1]].tolist())), [(0.5, -0.5), (39.5, 38.5)])


def test_douglas_peucker_keeps_corner() -> None:
    pts = np.array([[0, 0], [1, 0.1], [2, 0], [3, 2], [4, 4]], float)
    out = douglas_peucker(pts, 0.5)
    assert out.tolist() == [[0, 0], [2, 0], [4, 4]]
