"""Cradle for a cylinder: a U or V block under a horizontal cylinder or boss.

Local frame: origin on the cylinder axis at the rim circle, z along the axis into the cylinder's body, y = the
part's up direction made perpendicular to the axis, x = y x z. With R = radius + clearance the block is::

    U: a block from y = -R cos(wrap/2) down to y = -(R + wall), minus the cylinder of radius R: its groove (the
       mating face) wraps ``wrap_deg`` degrees around the underside, ``clearance`` off the cylinder.
    V: a 90-degree V groove whose flanks are tangent to the circle of radius R at 45 degrees either side of the
       bottom: it touches along two lines (the contact points), ``clearance`` off the cylinder.

The block spans ``length`` along the axis, starting ``end_margin`` from the rim circle, clamped to the length of
the cylinder face the view shows.

A cylinder that stands in the body of an up-facing plane (a pillow block's bearing housing on its base plate, a
half-round on a block) has no underside: the block under it would lie inside that body, which neither the scan's
points nor the meshes show inside the block (the plane's top is above it). The plane's own mesh shows it: it
runs beside the cylinder, over the block's footprint, above the block's bottom. Such a cylinder is refused
(`resting_plane`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
from build123d import Plane, Solid

from fixtures_design.frames import FrameMap
from fixtures_design.model import (
    Fixture,
    FixtureKind,
    Seating,
    local_plane,
    place,
    prism,
    sample_face,
    sample_triangles,
    unit,
)
from fixtures_design.references import CircleReference, ReferenceKind

if TYPE_CHECKING:
    from v2c.vbrep.model import VBRep

_S45 = np.sqrt(0.5)


@dataclass(frozen=True)
class CradleParams:
    """Cradle parameters (millimetres, degrees)."""

    style: Literal["U", "V"] = "U"
    clearance: float = 0.2  # mm: gap between the groove and the cylinder
    wall: float = 6.0  # mm: material under the groove and beside it
    length: float = 30.0  # mm: block length along the cylinder axis
    end_margin: float = 2.0  # mm: kept free from the rim circle and from the far end of the seen cylinder
    wrap_deg: float = 120.0  # degrees: U groove's angular span around the underside
    max_tilt_deg: float = 30.0  # degrees: largest angle between the cylinder axis and the horizontal
    rest_plane_tilt_deg: float = 30.0  # degrees: a plane whose outward normal lies within this of up, beside
    # the cylinder under the block, holds the block's place (`resting_plane`)
    rest_samples: int = 2000  # points drawn on each up-facing plane's mesh (area-weighted) for that test
    rest_min_points: int = 5  # of them beside the cylinder, over the block's footprint, refuse the cradle (count)


def u_block_extent(radius: float, p: CradleParams) -> tuple[float, float, float]:
    """(half width, top y, bottom y) of the U block under a cylinder of ``radius`` (mm, the cradle's local x / y;
    the module docstring): it wraps ``wrap_deg`` round the underside with ``wall`` below and beside the groove."""
    half = np.radians(p.wrap_deg) / 2
    return radius * np.sin(half) + p.wall, -radius * np.cos(half), -(radius + p.wall)


def _u_block(radius: float, p: CradleParams, z0: float, z1: float) -> Solid:
    w, y_top, y_bottom = u_block_extent(radius, p)
    block = prism(np.array([(-w, y_top), (w, y_top), (w, y_bottom), (-w, y_bottom)]), z0, z1)
    return block.cut(Solid.make_cylinder(radius, z1 - z0 + 2, Plane.XY.offset(z0 - 1))).clean()


def _v_profile(radius: float, p: CradleParams) -> np.ndarray:
    y_top = -0.3 * radius
    x_top = (radius + y_top * _S45) / _S45  # where a flank tangent at 45 degrees crosses y = y_top
    w = x_top + p.wall
    apex = -radius / _S45
    bottom = apex - p.wall
    return np.array([(-w, bottom), (w, bottom), (w, y_top), (x_top, y_top), (0.0, apex), (-x_top, y_top), (-w, y_top)])


def cradle_axes(axis: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A cradle's axes (module docstring) for a cylinder ``axis`` and the part's ``up`` (one frame): z along the
    axis, y ``up`` made perpendicular to it, x = y x z (unit vectors)."""
    z = unit(axis)
    up = unit(up)
    y = unit(up - (up @ z) * z)
    return np.cross(y, z), y, z


def _cradle_axes(ref: CircleReference, fmap: FrameMap, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The cradle's axes in the output frame (`cradle_axes` of the reference's axis)."""
    return cradle_axes(fmap.vectors(ref.axis), up)


def resting_plane(
    vbrep: VBRep, ref: CircleReference, fmap: FrameMap, up: np.ndarray, params: CradleParams = CradleParams()
) -> int | None:
    """The id of an up-facing plane face (outward normal within ``rest_plane_tilt_deg`` of ``up``, output frame)
    with at least ``rest_min_points`` of ``rest_samples`` points drawn on its mesh beside the cylinder of ``ref``
    under the cradle's block (along the seen cylinder, between its radius and its radius plus the wall from its
    axis, sideways) and above the block's bottom: that plane's body fills the block's place, so nothing is under
    the cylinder for a cradle. None when there is none. A free lying cylinder has no such plane beside it (the
    ground is not a face); a flat on its top lies within its radius; a block a boss stands out of lies behind the
    boss, not along it."""
    x, y, z = _cradle_axes(ref, fmap, up)
    up = unit(up)
    origin = fmap.points(ref.center)
    radius = fmap.length(ref.radius)
    seen = fmap.length(ref.extent)
    cos_tilt = np.cos(np.radians(params.rest_plane_tilt_deg))
    for f in vbrep.faces:  # loop over up-facing plane faces
        if f.primitive.get("type") != "plane":
            continue
        normal = unit(fmap.vectors(np.asarray(f.primitive["params"]["normal"], float)))
        if normal @ up < cos_tilt:
            continue
        v = fmap.points(np.asarray(f.mesh_vertices, float).reshape(-1, 3))
        t = np.asarray(f.mesh_triangles, int).reshape(-1, 3)
        if not len(v) or not len(t):
            continue
        q = sample_triangles(v[t], params.rest_samples, seed=int(f.id)) - origin
        along, side, height = q @ z, np.abs(q @ x), q @ y
        beside = (along >= 0) & (along <= seen) & (side > radius) & (side <= radius + params.wall)
        if int(np.count_nonzero(beside & (height > -(radius + params.wall)))) >= params.rest_min_points:
            return int(f.id)
    return None


def design_cradle(
    ref: CircleReference,
    fmap: FrameMap,
    up: np.ndarray,
    params: CradleParams = CradleParams(),
    vbrep: VBRep | None = None,
) -> Fixture:
    """A cradle under the boss/cylinder of ``ref`` (camera frame, metres), output frame of ``fmap`` (mm).

    up: (3,) the part's up direction in the output frame (`fixtures_design.frames.up_vector`). vbrep: the
    reconstruction ``ref`` comes from; when given, a cylinder standing in an up-facing plane's body is refused
    (`resting_plane`). Mating faces: the U groove (or the two V flanks); contact points on the groove (or the V's
    contact lines).
    """
    if ref.kind is not ReferenceKind.BOSS:
        raise ValueError(f"{ref.label} is the rim of a {ref.kind.value}: a cradle needs a boss/cylinder")
    up = unit(up)
    tilt = float(np.degrees(np.arcsin(min(1.0, abs(unit(fmap.vectors(ref.axis)) @ up)))))
    if tilt > params.max_tilt_deg:  # (before the axes: a vertical cylinder has no sideways direction)
        raise ValueError(
            f"cylinder of {ref.label} is {tilt:.0f} deg off the horizontal (cradles take up to "
            f"{params.max_tilt_deg:.0f} deg)"
        )
    x, y, z = _cradle_axes(ref, fmap, up)
    if vbrep is not None:
        rest = resting_plane(vbrep, ref, fmap, up, params)
        if rest is not None:
            raise ValueError(
                f"the cylinder of {ref.label} stands in the body of face {rest} (an up-facing plane beside it "
                "over the cradle's footprint, above the cradle's bottom): nothing under it for a cradle"
            )
    seen = fmap.length(ref.extent)
    length = min(params.length, seen - 2 * params.end_margin)
    if length <= 0:
        raise ValueError(f"the view shows only {seen:.1f} mm of the cylinder of {ref.label}")
    radius = fmap.length(ref.radius) + params.clearance
    z0, z1 = params.end_margin, params.end_margin + length
    plane = local_plane(fmap.points(ref.center), x, z)
    if params.style == "U":
        local = _u_block(radius, params, z0, z1)
        groove = [f for f in local.faces() if f.geom_type.name == "CYLINDER"]
        pts_local = np.concatenate([sample_face(f) for f in groove])
    elif params.style == "V":
        local = prism(_v_profile(radius, params), z0, z1)
        groove = [
            f
            for f in local.faces()
            if f.geom_type.name == "PLANE" and abs(abs(np.array(tuple(f.normal_at(f.center())))[0]) - _S45) < 1e-6
        ]
        zs = np.linspace(z0, z1, 25)
        pts_local = np.concatenate(
            [np.stack([np.full_like(zs, s * radius * _S45), np.full_like(zs, -radius * _S45), zs], 1) for s in (-1, 1)]
        )
    else:
        raise ValueError(f"unknown cradle style {params.style!r}: expected 'U' or 'V'")
    m = np.stack([np.array(tuple(plane.x_dir)), np.array(tuple(plane.y_dir)), np.array(tuple(plane.z_dir))])
    pts = pts_local @ m + np.array(tuple(plane.origin))
    return Fixture(
        FixtureKind.CRADLE,
        place(local, plane),
        [place(f, plane) for f in groove],
        pts,
        ref,
        fmap,
        params,
        [ref.cylinder_face] * len(groove),
        {"length_mm": length, "groove_radius_mm": radius, "tilt_deg": tilt},
        Seating(np.stack([x, y]), -y),  # seated: the cylinder let down into the groove (free along its axis)
    )
