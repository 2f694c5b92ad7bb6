"""Corner locator: an L block that seats on a convex dihedral edge of the part.

Cross-section, in the edge's local frame (x = outward normal of face A, y = outward normal of face B, z along the
edge; the part fills the quadrant x < 0, y < 0)::

          y
          |  +---------------+          inner faces: x = c (against face A) and y = c (against face B),
          |  |   wall t      |          c = clearance; each leg reaches ``leg`` along its face (clamped to
      ----+--+---+           |          ``leg_fraction`` of how far the face reaches from the edge)
     part    | c |  wall t   |
     (x<0,   |   |           |
      y<0)   +---+-----------+---- x

The block spans ``length`` along the edge, centred on it and kept ``end_margin`` from its ends.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fixtures_design.frames import FrameMap
from fixtures_design.model import (
    Fixture,
    FixtureKind,
    Seating,
    faces_facing,
    local_plane,
    place,
    prism,
    sample_face,
)
from fixtures_design.references import DihedralReference


@dataclass(frozen=True)
class CornerParams:
    """Corner locator parameters (millimetres)."""

    clearance: float = 0.2  # mm: gap between each inner face and the part face it locates
    wall: float = 6.0  # mm: wall thickness of each leg
    leg: float = 15.0  # mm: how far each inner face reaches from the edge along its part face
    length: float = 40.0  # mm: block length along the edge
    end_margin: float = 2.0  # mm: kept free at each end of the edge
    leg_fraction: float = 0.8  # of the face's reach from the edge: the most a leg covers
    leg_end_margin: float = 3.0  # mm: a leg ends at least this far short of where its face ends, along the block's
    # whole length (the face's narrowest reach there, `DihedralReference.reach`): a wall rising where a ledge ends
    # stays clear of the leg after the part is pushed home
    min_leg: float = 2.0  # mm: a shorter leg does not locate; the edge is refused


def corner_profile(leg_a: float, leg_b: float, p: CornerParams) -> np.ndarray:
    """(6, 2) L profile in the edge's local (x, y), mm (see the module docstring)."""
    c, t = p.clearance, p.wall
    return np.array([(c, -leg_a), (c + t, -leg_a), (c + t, c + t), (-leg_b, c + t), (-leg_b, c), (c, c)])


def _narrowest_reach(ref: DihedralReference, i: int, lo_mm: float, hi_mm: float, fmap: FrameMap) -> float:
    """The least reach (metres) of face ``i`` from the edge over the bins of ``ref.reach`` that meet [lo_mm, hi_mm]
    (output millimetres from the edge's start); ``ref.depths[i]`` where no bin there holds its mesh (a reference
    made without bins)."""
    at, reach = np.asarray(ref.reach_at, float), np.asarray(ref.reach[i], float)
    if not len(at):
        return float(ref.depths[i])
    half = 0.5 * (at[1] - at[0]) if len(at) > 1 else float(ref.length)
    lo, hi = lo_mm / fmap.scale, hi_mm / fmap.scale
    sel = (at + half >= lo) & (at - half <= hi) & np.isfinite(reach)
    return float(reach[sel].min()) if sel.any() else float(ref.depths[i])


def design_corner(ref: DihedralReference, fmap: FrameMap, params: CornerParams = CornerParams()) -> Fixture:
    """An L block seated on ``ref`` (camera frame, metres), built in the output frame of ``fmap`` (mm).

    Mating faces: the two inner faces, ``params.clearance`` off the two planes of the edge.
    """
    a = fmap.vectors(ref.normals[0])
    b = fmap.vectors(ref.normals[1])
    b = b - (b @ a) * a  # square the frame (the planes are perpendicular within the selection tolerance)
    b /= np.linalg.norm(b)
    z = np.cross(a, b)
    p0, p1 = fmap.points(ref.start), fmap.points(ref.end)
    edge_len = float(np.linalg.norm(p1 - p0))
    length = min(params.length, edge_len - 2 * params.end_margin)
    if length <= 0:
        raise ValueError(
            f"edge e{ref.edge_id} is {edge_len:.1f} mm long: too short for end margins of {params.end_margin} mm"
        )
    # depths[0] is how far face A reaches from the edge (along -y), depths[1] face B (along -x); over the block's
    # span (centred on the edge) the narrowest reach of each face bounds its leg.
    legs = []
    for i, name in enumerate("AB"):
        reach = fmap.length(_narrowest_reach(ref, i, edge_len / 2 - length / 2, edge_len / 2 + length / 2, fmap))
        leg = min(params.leg, params.leg_fraction * reach, reach - params.leg_end_margin)
        if leg < params.min_leg:
            raise ValueError(
                f"edge e{ref.edge_id}: face {name} (f{ref.faces[i]}) reaches only {reach:.1f} mm from the edge over "
                f"the block's span: a leg ending {params.leg_end_margin:g} mm short of it is under "
                f"{params.min_leg:g} mm"
            )
        legs.append(leg)
    leg_a, leg_b = legs
    plane = local_plane(0.5 * (p0 + p1), a, z)
    local = prism(corner_profile(leg_a, leg_b, params), -length / 2, length / 2)
    solid = place(local, plane)
    c = params.clearance
    against_a = faces_facing(local, [-1, 0, 0], np.array([c, 0, 0]))
    against_b = faces_facing(local, [0, -1, 0], np.array([0, c, 0]))
    mating = [place(f, plane) for f in against_a + against_b]
    refs = [ref.faces[0]] * len(against_a) + [ref.faces[1]] * len(against_b)
    pts = np.concatenate([sample_face(f) for f in mating])
    # Seated: the part pushed into the corner, along both faces' outward normals (free along the edge).
    seating = Seating(np.stack([a, b]), (a + b) / np.sqrt(2.0))
    notes = {"leg_mm": (leg_a, leg_b), "length_mm": length}
    return Fixture(FixtureKind.CORNER, solid, mating, pts, ref, fmap, params, refs, notes, seating)
