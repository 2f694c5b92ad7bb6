"""VB-Rep extraction: the view-centric B-rep data model (`model`) and its extraction from fitted primitives."""

from v2c.vbrep.model import EdgeType, VBRep, VEdge, VertexKind, VFace, VVertex

__all__ = ["EdgeType", "VBRep", "VEdge", "VFace", "VVertex", "VertexKind"]
