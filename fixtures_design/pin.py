"""Locating pin for a cylindrical hole: a pin on a flange, inserted along the hole's axis.

Local frame: origin at the hole's rim centre (on the plane the hole pierces), z along the hole axis into the
material. The pin (radius = hole radius - clearance at the flange) runs from the flange down to ``depth`` into the
hole (clamped to ``depth_radii`` hole radii and to the hole depth the view shows, less the clearance); the flange
(radius = pin radius + ``flange``, thickness ``wall``) sits ``clearance`` above the plane, no wider than the plane
face around the hole (``land``). Below the flange the pin narrows along a cone (``taper`` mm in radius at
``taper_deg``, a locating pin's lead) to its shank: a hole the reconstruction fitted up to ``taper`` too wide still
takes the pin, its rim resting on the cone a little above the flange instead of on the pin's end (docs/fixtures.md,
"A tapered pin").
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from build123d import Face, Plane, Solid

from fixtures_design.frames import FrameMap
from fixtures_design.model import Fixture, FixtureKind, Seating, faces_facing, local_plane, place, sample_face, unit
from fixtures_design.references import CircleReference, ReferenceKind


@dataclass(frozen=True)
class PinParams:
    """Locating pin parameters (millimetres)."""

    clearance: float = 0.1  # mm: radial gap pin-hole, and the gap between flange and the hole's plane
    depth: float = 10.0  # mm: insertion depth of the pin below the hole's rim
    depth_radii: float = 1.0  # ... and at most this many of the hole's radii (ratio): a counterbore's step lies
    # below its rim by about a radius, and a pin past it runs into the narrower hole (on the training holes of
    # `v2c bench --stage fixtures`, 2 of 26 pins; docs/fixtures.md, "Pins: the hole's radius")
    wall: float = 5.0  # mm: flange thickness
    flange: float = 2.0  # mm: flange radius beyond the pin radius (clamped to the plane's land around the hole); a
    # narrow flange stays clear of a counterbore's wall when the part moves across to clear the pin (4 mm before:
    # 1 of 26 training pins pushed its flange into the counterbore's wall)
    taper: float = 2.0  # mm: how much narrower (in radius) the pin's shank is than its top at the flange, reached
    # along a cone from the flange down; 0 = a plain cylinder. Pins seated on their learned reconstructions
    # (docs/fixtures.md, "A tapered pin"), cut / touch: corpus training split (tuning, 63 pins) plain 11.3 / 85.5 %,
    # 1 mm 6.3 / 90.5 %, 2 mm 4.8 / 79.4 %; validation (training families seed 7200, 21 pins, and the corpus
    # validation split, 5): plain 0 / 100 % and 20 / 80 %, 1 mm 4.8 / 95.2 % and 20 / 80 % (two pins that fit came
    # to rest on the cone, cutting 0.2-0.3 %), 2 mm 0 / 100 % and 0 / 80 %
    taper_deg: float = 45.0  # degrees: the cone's half-angle (a 90-degree countersink's); a rim resting on it stands
    # (top radius - hole radius) / tan(taper_deg) above the flange
    shank_share: float = 0.5  # the shank keeps at least this share of the top radius (fraction: a small hole's pin
    # is not whittled to a needle)


def design_pin(ref: CircleReference, fmap: FrameMap, params: PinParams = PinParams()) -> Fixture:
    """A locating pin for the hole ``ref`` (camera frame, metres), in the output frame of ``fmap`` (mm).

    Mating faces: the pin's side below the flange (against the hole wall: its cone, or its cylinder when
    ``params.taper`` is 0) and the flange's underside (against the hole's plane), each ``params.clearance`` off at
    the flange.
    """
    if ref.kind is not ReferenceKind.HOLE:
        raise ValueError(f"edge e{ref.edge_id} is the rim of a {ref.kind.value}: a locating pin needs a hole")
    if ref.site != "rim":
        raise ValueError(f"edge e{ref.edge_id} is a hole's {ref.site}, not its opening rim")
    c = params.clearance
    r = fmap.length(ref.radius) - c
    if r <= 0:
        raise ValueError(
            f"hole e{ref.edge_id} radius {fmap.length(ref.radius):.2f} mm is not above the clearance {c} mm"
        )
    depth = min(params.depth, params.depth_radii * fmap.length(ref.radius), fmap.length(ref.extent) - c)
    if depth <= 0:
        raise ValueError(f"hole e{ref.edge_id} shows only {fmap.length(ref.extent):.2f} mm of depth")
    flange_r = min(r + params.flange, max(r + c, fmap.length(ref.land) - c))
    z = unit(fmap.vectors(ref.axis))
    x = np.cross(z, [1.0, 0.0, 0.0])
    if np.linalg.norm(x) < 0.1:
        x = np.cross(z, [0.0, 1.0, 0.0])
    plane = local_plane(fmap.points(ref.center), x, z)
    # Flange from z = -(c + wall) to -c; pin from -c to depth (local z points into the hole).
    flange = Solid.make_cylinder(flange_r, params.wall, Plane.XY.offset(-(c + params.wall)))
    slope = np.tan(np.radians(params.taper_deg))  # the cone's loss of radius per mm of depth
    shank_r = max(r - max(params.taper, 0.0), params.shank_share * r)
    cone_h = min((r - shank_r) / slope, depth + c) if shank_r < r else 0.0
    end_r = r - cone_h * slope  # the shank's radius (r without a cone; less deep than the cone, the cone's end)
    if cone_h > 0:  # the lead: a cone from r at the flange down to the shank, then the shank to the pin's end
        pin = Solid.make_cone(r, end_r, cone_h, Plane.XY.offset(-c))
        if depth + c - cone_h > 1e-6:
            pin = pin.fuse(Solid.make_cylinder(end_r, depth + c - cone_h, Plane.XY.offset(cone_h - c)))
        side_type, side_r = "CONE", None
    else:
        pin = Solid.make_cylinder(r, depth + c, Plane.XY.offset(-c))
        side_type, side_r = "CYLINDER", r
    local = flange.fuse(pin).clean()
    side = [
        f for f in local.faces() if f.geom_type.name == side_type and (side_r is None or abs(f.radius - side_r) < 1e-6)
    ]
    under = faces_facing(local, [0, 0, 1], np.array([0, 0, -c]))
    mating: list[Face] = [place(f, plane) for f in side + under]
    pts = np.concatenate([sample_face(f) for f in mating])
    refs = [ref.cylinder_face] * len(side) + [ref.plane_face] * len(under)
    return Fixture(
        FixtureKind.PIN,
        place(local, plane),
        mating,
        pts,
        ref,
        fmap,
        params,
        refs,
        {"pin_radius_mm": r, "depth_mm": depth, "flange_radius_mm": flange_r, "shank_radius_mm": end_r},
        Seating(np.eye(3), -z),  # seated: the part lowered onto the flange, moved across the axis only to clear the pin
    )
