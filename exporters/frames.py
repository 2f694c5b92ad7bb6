"""Output frames of the STEP export: the camera frame, or the recovered part frame with a findable origin.

Both map camera-frame metres (the VB-Rep's units) to millimetres. Pure numpy: no OCCT here.

Part frame (``Frame.PART``): the VB-Rep's recovered axis frame (``VBRep.frame`` rows X, Y, Z, camera frame)
becomes the output X, Y, Z axes. The origin is the *footprint origin*: the centre of the X/Y bounding box of
the visible geometry, at its lowest Z. For a part standing on the ground (Z up) this is the centre of the
bottom of the visible part's axis-aligned bounding box. `frame_map` places it from the VB-Rep's points (face
meshes, edge polylines, vertices); `exporters.step.build` then moves it onto the exported faces and edges
exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from v2c.vbrep.model import VBRep

#: Metres -> millimetres.
MM_PER_M = 1000.0


class Frame(str, Enum):  # noqa: UP042 - StrEnum would change str() and format() of the members
    """Which frame the STEP geometry is written in (millimetres either way)."""

    PART = "part"
    CAMERA = "camera"


@dataclass(frozen=True)
class FrameMap:
    """Rigid map camera metres -> output millimetres: ``p_out = scale * rotation @ (p_cam - origin)``.

    rotation: (3, 3) rows = the output X, Y, Z axes in the camera frame (a proper rotation, det = +1).
    origin: (3,) camera-frame metres of the output origin. scale: output units per metre (1000: millimetres).
    """

    rotation: np.ndarray
    origin: np.ndarray
    scale: float = MM_PER_M

    def points(self, p: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame metres -> (..., 3) output millimetres."""
        return self.scale * (np.asarray(p, float) - self.origin) @ self.rotation.T

    def vectors(self, d: np.ndarray) -> np.ndarray:
        """(..., 3) camera-frame directions -> (..., 3) output directions (unit length kept)."""
        return np.asarray(d, float) @ self.rotation.T

    def length(self, x: float) -> float:
        """A length in metres -> output millimetres."""
        return float(x) * self.scale

    def shifted(self, shift: np.ndarray) -> FrameMap:
        """The map whose output is this one's plus ``shift`` (3,) output millimetres."""
        return FrameMap(
            self.rotation, self.origin - self.rotation.T @ np.asarray(shift, float) / self.scale, self.scale
        )

    @property
    def camera_center(self) -> np.ndarray:
        """(3,) the camera centre in output millimetres (faces seen by the camera face towards it)."""
        return self.points(np.zeros(3))


def proper_rotation(frame: np.ndarray) -> np.ndarray:
    """Nearest proper rotation (rows orthonormal, det +1) to a (3, 3) row frame.

    A left-handed frame would mirror the part; its Y row is flipped (Y = Z x X, as SCAN_FORMAT.md defines it).
    """
    u, _, vt = np.linalg.svd(np.asarray(frame, float))
    r = u @ vt
    if np.linalg.det(r) < 0:
        r[1] = np.cross(r[2], r[0])
    return r


def vbrep_points(vbrep: VBRep) -> np.ndarray:
    """(N, 3) camera-frame metres: every face mesh vertex, edge polyline point and vertex of the VB-Rep."""
    chunks = [np.asarray(f.mesh_vertices, float).reshape(-1, 3) for f in vbrep.faces]
    chunks += [np.asarray(e.polyline, float).reshape(-1, 3) for e in vbrep.edges]
    chunks += [np.asarray(v.position, float).reshape(1, 3) for v in vbrep.vertices]
    chunks = [c for c in chunks if len(c)]
    return np.concatenate(chunks) if chunks else np.zeros((0, 3))


def part_origin(vbrep: VBRep, rotation: np.ndarray) -> np.ndarray:
    """(3,) camera-frame metres of the footprint origin (module docstring) for a part frame ``rotation``."""
    pts = vbrep_points(vbrep)
    if len(pts) == 0:
        return np.zeros(3)
    q = pts @ rotation.T  # part-frame coordinates (metres), origin at the camera
    lo, hi = q.min(0), q.max(0)
    o_part = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    return rotation.T @ o_part


def frame_map(vbrep: VBRep, frame: Frame | str = Frame.PART) -> FrameMap:
    """The camera -> output map of ``frame`` for this VB-Rep (see module docstring)."""
    frame = Frame(frame)
    if frame is Frame.CAMERA:
        return FrameMap(np.eye(3), np.zeros(3))
    rot = proper_rotation(vbrep.frame)
    return FrameMap(rot, part_origin(vbrep, rot))
