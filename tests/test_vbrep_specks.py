"""Specks, instances too small for a face, merge into their neighbours (v2c.vbrep.faces.absorb_specks, issue 16)
instead of counting as background, so they leave no junction clutter in the edge graph."""

from __future__ import annotations

import numpy as np

from v2c.segment.graph import build_edge_graph
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.faces import absorb_specks


def test_a_speck_merges_into_its_neighbours():
    # two faces side by side and a 3-pixel speck on their border: without a face it would be background,
    # cutting their shared boundary into runs of a pixel or two
    inst = np.zeros((20, 30), np.int32)
    inst[4:16, 3:15] = 1
    inst[4:16, 15:27] = 2
    inst[9:12, 14] = 3
    graph = build_edge_graph(inst, 1.0)
    assert any(3 in e.instances for e in graph.edges)
    stats: dict = {}
    out, g2 = absorb_specks(inst, graph, {1, 2}, VBRepConfig(), stats)
    assert stats["specks_absorbed"] == [3]
    assert not (out == 3).any() and set(np.unique(out)) == {0, 1, 2}
    assert (out[inst != 3] == inst[inst != 3]).all()
    assert not any(3 in e.instances for e in g2.edges)
    # the two faces now share one edge across the whole height
    shared = [e for e in g2.edges if set(e.instances) == {1, 2}]
    assert len(shared) == 1 and np.ptp(np.asarray(shared[0].polyline)[:, 1]) == 12
    # an instance with a face, or one of fallback_min_px pixels or more, is no speck
    out, g3 = absorb_specks(inst, graph, {1, 2, 3}, VBRepConfig(), stats)
    assert stats["specks_absorbed"] == [] and g3 is graph and (out == inst).all()


def test_a_speck_on_a_box_edge_leaves_the_edge_whole():
    """A 3 x 3 px speck (an instance without a fit) on the intersection edge of two faces of a box: without the
    merge it was background, its outline cut that edge in two; merged, the edge runs whole past it and both faces
    are meshed from their loops."""
    from dataclasses import replace

    from v2c.camera import project
    from v2c.segment.types import Segmentation
    from v2c.vbrep.extract import extract_vbrep
    from v2c.vbrep.model import EdgeType

    from scenes.raycast import box_scene, scene_inputs

    inp = scene_inputs(box_scene(), noise_m=0.0004, seed=1)
    inst = np.asarray(inp.seg.instances).copy()
    # a pixel on the boundary of faces 1 and 2 with both on its row
    vs, us = np.nonzero((inst[:, :-1] == 1) & (inst[:, 1:] == 2))
    v, u = int(vs[len(vs) // 2]), int(us[len(us) // 2])
    speck = int(inst.max()) + 1
    inst[v - 1 : v + 2, u - 1 : u + 2] = speck
    labels = np.concatenate([np.asarray(inp.seg.labels), [0]]).astype(np.uint8)
    seg = Segmentation(inst, labels, np.ones(len(labels), np.float32), "oracle")
    fit = replace(inp.fit, graph=build_edge_graph(inst))
    vb = extract_vbrep(inp.scan, seg, fit)
    assert vb.meta["extract"]["specks_absorbed"] == [speck]
    between = [
        e
        for e in vb.edges
        if EdgeType(e.type) is EdgeType.INTERSECTION and {vb.faces[f].instance for f in e.faces} == {1, 2}
    ]
    assert len(between) == 1
    uv = project(np.asarray(between[0].polyline), vb.K)
    a, b = uv[:-1], uv[1:]
    t = np.clip(np.einsum("ij,ij->i", [u, v] - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
    assert np.min(np.linalg.norm(a + t[:, None] * (b - a) - [u, v], axis=1)) < 3.0  # it runs past the speck
    # both faces are meshed from their loops, which run across the speck (its pixels are covered, as the part's)
    assert {f.id for f in vb.faces if f.instance in (1, 2)} <= set(vb.meta["extract"]["loop_meshes"])


def test_a_stray_island_of_a_face_goes_to_the_face_around_it():
    # face 1 left, face 2 right; four pixels of face 1 stray inside face 2 (a 2 x 2 island), and a 30-pixel
    # piece of face 1 inside face 2 too (a piece as large as island_max_px or more is the face's own)
    from v2c.vbrep.faces import absorb_islands

    inst = np.zeros((30, 40), np.int32)
    inst[2:28, 2:20] = 1
    inst[2:28, 20:38] = 2
    inst[6:8, 28:30] = 1  # the island
    inst[15:20, 25:31] = 1  # a 30 px piece
    stats: dict = {}
    out = absorb_islands(inst, {1, 2}, VBRepConfig(), stats)
    assert stats["islands_absorbed"] == 1
    assert (out[6:8, 28:30] == 2).all()
    assert (out[15:20, 25:31] == 1).all()
    changed = out != inst
    assert changed.sum() == 4
    # a segmentation certain of the instance (the ground truth's score 1) keeps its pieces: a face seen in pieces
    kept = absorb_islands(inst, {1, 2}, VBRepConfig(), stats, np.array([0.0, 1.0, 0.9]))
    assert (kept == inst).all() and stats["islands_absorbed"] == 0
    assert (absorb_islands(inst, {1, 2}, VBRepConfig(), stats, np.array([0.0, 0.97, 0.9])) == out).all()
    # nothing moves with the rule off, or where no other faced instance lies within reach
    off = absorb_islands(inst, {1, 2}, VBRepConfig(island_max_px=0), stats)
    assert (off == inst).all() and stats["islands_absorbed"] == 0
    alone = np.zeros((30, 40), np.int32)
    alone[2:28, 2:20] = 1
    alone[10:12, 30:32] = 1  # an island in the background, 10 px from any face
    alone[2:28, 36:39] = 2
    assert (absorb_islands(alone, {1, 2}, VBRepConfig(), {}) == alone).all()
