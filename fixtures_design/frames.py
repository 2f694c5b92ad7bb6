"""Output frames of the fixture designer, shared with ``v2c to-step`` (``exporters.frames``).

- ``"camera"``: the camera frame (OpenCV: x right, y down, z forward), millimetres.
- ``"part"``: the VB-Rep's recovered axis frame (``VBRep.frame`` rows X, Y, Z) on X / Y / Z, millimetres, origin at
  the footprint origin of ``v2c to-step``: the centre of the X/Y bounding box of the B-rep that
  `exporters.build` makes of the VB-Rep, at its lowest Z (`exporters.frame_map`'s estimate from the
  VB-Rep's points when that build fails).

Fixtures, the reconstructed part and the true part are all placed in the same output frame, so a fixture's STEP
lines up with the ``to-step`` STEP of the same scan and frame.
"""

from __future__ import annotations

import numpy as np

from exporters import Frame, FrameMap, frame_map, proper_rotation
from v2c.vbrep.model import VBRep

__all__ = ["Frame", "FrameMap", "camera_mm_matrix", "output_frame", "up_vector"]


def output_frame(vbrep: VBRep, frame: Frame | str = Frame.PART) -> FrameMap:
    """The camera-metres -> output-millimetres map of ``frame`` ("part" or "camera") for this VB-Rep, the very map
    ``v2c to-step`` writes its STEP in."""
    if Frame(frame) is Frame.CAMERA:
        return frame_map(vbrep, frame)
    fmap = None
    try:
        from exporters import build, quiet_occt

        with quiet_occt():
            fmap = build(vbrep, frame).fmap
    except Exception:  # noqa: BLE001 - the exporter's build failing leaves the points-based estimate
        fmap = None
    return fmap if fmap is not None else frame_map(vbrep, frame)


def up_vector(vbrep: VBRep, fmap: FrameMap) -> np.ndarray:
    """(3,) unit vector: the part's up axis (the VB-Rep frame's Z row) in the output frame."""
    return fmap.vectors(proper_rotation(vbrep.frame)[2])


def camera_mm_matrix(fmap: FrameMap) -> np.ndarray:
    """(4, 4) homogeneous matrix taking camera-frame MILLIMETRES (e.g. gt/part.step) to output millimetres."""
    m = np.eye(4)
    m[:3, :3] = fmap.rotation
    m[:3, 3] = -fmap.scale * fmap.rotation @ fmap.origin
    return m
