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
