"""The VB-Rep as a build123d `Compound` or a cadquery `Shape`, for scripting on top of a reconstruction.

Same geometry as the STEP export (`exporters.step.build`): one open shell per group of connected analytic
faces, then the free edges, in millimetres, in the part frame by default (``frame="camera"`` for the camera
frame). The VB-Rep names (``"<type>:<axis>:f<id>"``, ``"<type>:<confidence>:e<id>"``) are in the STEP file
only; use `exporters.step.build` for the face/edge id -> OCCT shape maps.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from exporters.brep_config import BrepConfig
from exporters.frames import Frame
from exporters.step import build

if TYPE_CHECKING:
    import build123d
    import cadquery

    from v2c.vbrep.model import VBRep


def to_build123d(vbrep: VBRep, frame: Frame | str = Frame.PART, config: BrepConfig | None = None) -> build123d.Compound:
    """A build123d Compound of the VB-Rep (millimetres), labelled "v2c"."""
    import build123d as bd

    comp = bd.Compound(build(vbrep, frame, config).shape)
    comp.label = "v2c"
    return comp


def to_cadquery(vbrep: VBRep, frame: Frame | str = Frame.PART, config: BrepConfig | None = None) -> cadquery.Shape:
    """A cadquery Shape (a `cadquery.Compound`) of the VB-Rep (millimetres)."""
    import cadquery as cq

    return cq.Shape.cast(build(vbrep, frame, config).shape)
