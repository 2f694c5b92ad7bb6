"""Parts for the generator: procedural families built with build123d, and real STEP parts.

Every part comes back in its rest pose: millimetres, Z up, the part resting on the plane z = 0 and centred on the
Z axis (bounding-box centre at x = y = 0). The rest frame's X, Y, Z are the part's model axes (SCAN_FORMAT.md axis
classes). Dimensions are random, drawn from the generator passed in; the scene later scales the part uniformly to
its physical size, so absolute millimetres here only set proportions.

Families and the surfaces they give:
  block    box with holes, countersinks (cones), boss (fillet: torus), slot, pocket, dimple (sphere), fillets
  shaft    stepped shaft lying on its side: cylinders, chamfers (cones), shoulder fillets (tori), keyway, cross hole
  flange   disc with hub, bore and bolt circle: hub fillet (torus), chamfers (cones)
  knob     base, tapered neck (cone), domed cap (sphere), rounded rim (torus), radial holes (unaligned cylinders)
  turned   base plate with a feature block turned about Z by a non-multiple of 90 degrees (unaligned planes/holes)
  bracket  L bracket with bend fillet and holes in both legs
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
from build123d import (
    Align,
    Axis,
    Box,
    Cone,
    Cylinder,
    Edge,
    GeomType,
    Part,
    Pos,
    Rot,
    Sphere,
    chamfer,
    fillet,
)
from OCP.TopoDS import TopoDS_Shape
from scipy.spatial.transform import Rotation

from v2c.synth import occ

_MIN = (Align.CENTER, Align.CENTER, Align.MIN)


@dataclass
class RestPart:
    """A part in its rest pose (millimetres, Z up, resting on z = 0, bbox centred on the Z axis)."""

    shape: TopoDS_Shape
    family: str
    bbox: tuple[np.ndarray, np.ndarray]  # (lo, hi) tight bounding box, mm: lo = (-x, -y, 0), hi = (x, y, z)
    info: dict = field(default_factory=dict)  # family parameters, source file for CAD parts


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _turn_angle_deg(rng: np.random.Generator, margin_deg: float = 10.0) -> float:
    """A turn about Z well away from multiples of 90 degrees (so the turned features are unaligned)."""
    return float(rng.uniform(margin_deg, 90.0 - margin_deg) + 90.0 * rng.integers(0, 4))


def _circle_edges_at(part: Part, z: float, radius: float, tol: float = 1e-6) -> list[Edge]:
    """Circular edges of `part` lying in the plane z with the given radius (mm)."""
    out = []
    for e in part.edges().filter_by(GeomType.CIRCLE):
        if abs(e.center().Z - z) < tol and abs(e.radius - radius) < tol:
            out.append(e)
    return out


def build_block(rng: np.random.Generator) -> tuple[Part, dict]:
    """Box with corner holes (plain or countersunk), optional vertical fillets and one centre feature."""
    L = _u(rng, 60, 120)
    W = _u(rng, 40, L)
    H = _u(rng, 12, 40)
    part = Box(L, W, H, align=_MIN)
    info: dict = {"L": L, "W": W, "H": H}
    corner_r = 0.0
    if rng.random() < 0.6:
        corner_r = _u(rng, 0.05, 0.15) * W
        part = fillet(part.edges().filter_by(Axis.Z), corner_r)
    info["corner_fillet"] = corner_r
    inset = max(corner_r, 0.1 * W) + 0.06 * W
    hole_r = _u(rng, 0.025, 0.05) * W
    countersink = bool(rng.random() < 0.5)
    info.update(hole_radius=hole_r, countersink=countersink)
    for sx in (-1, 1):
        for sy in (-1, 1):
            x, y = sx * (L / 2 - inset - hole_r), sy * (W / 2 - inset - hole_r)
            part -= Pos(x, y, -1) * Cylinder(hole_r, H + 2, align=_MIN)
            if countersink:
                depth = min(hole_r, 0.3 * H)
                part -= Pos(x, y, H - depth) * Cone(hole_r, hole_r + depth * 1.2, depth + 0.5, align=_MIN)
    feature = str(rng.choice(["boss", "pocket", "slot", "dimple", "none"]))
    info["feature"] = feature
    span = min(L - 4 * (inset + 2 * hole_r), W) * 0.8
    if feature == "boss" and span > 8:
        br = _u(rng, 0.2, 0.45) * span
        bh = _u(rng, 0.3, 1.0) * H
        part += Pos(0, 0, H) * Cylinder(br, bh, align=_MIN)
        if rng.random() < 0.7:
            part = fillet(_circle_edges_at(part, H + bh, br), _u(rng, 0.1, 0.3) * min(br, bh))
        if rng.random() < 0.5:
            part -= Pos(0, 0, H + bh - 0.5 * bh) * Cylinder(0.4 * br, bh, align=_MIN)
    elif feature == "pocket" and span > 8:
        pl, pw = _u(rng, 0.4, 0.9) * span, _u(rng, 0.3, 0.8) * span
        pd = _u(rng, 0.2, 0.6) * H
        pocket = Box(pl, pw, pd + 1, align=_MIN)
        pocket = fillet(pocket.edges().filter_by(Axis.Z), _u(rng, 0.05, 0.2) * min(pl, pw))
        part -= Pos(0, 0, H - pd) * pocket
    elif feature == "slot" and span > 8:
        sw = _u(rng, 0.15, 0.3) * span
        sl = _u(rng, 0.5, 0.9) * span
        sd = _u(rng, 0.3, 0.7) * H
        slot = Box(sl - sw, sw, sd + 1, align=_MIN)
        slot += Pos(-(sl - sw) / 2, 0, 0) * Cylinder(sw / 2, sd + 1, align=_MIN)
        slot += Pos((sl - sw) / 2, 0, 0) * Cylinder(sw / 2, sd + 1, align=_MIN)
        part -= Pos(0, 0, H - sd) * Rot(0, 0, 90 * int(rng.integers(0, 2))) * slot
    elif feature == "dimple" and span > 8:
        depth = _u(rng, 0.2, 0.6) * H
        rad = _u(rng, 0.2, 0.45) * span
        sr = (rad**2 + depth**2) / (2 * depth)
        part -= Pos(0, 0, H + sr - depth) * Sphere(sr)
    return part, info


def build_shaft(rng: np.random.Generator) -> tuple[Part, dict]:
    """Stepped shaft with end chamfers, shoulder fillets, optional keyway and cross hole; lies on its side."""
    n = int(rng.integers(2, 5))
    radii = np.sort(rng.uniform(6, 20, n))[::-1]
    lengths = rng.uniform(15, 45, n)
    order = rng.permutation(n) if rng.random() < 0.3 else np.arange(n)
    radii = radii[order]
    part = None
    z = 0.0
    for r, length in zip(radii, lengths, strict=True):
        seg = Pos(0, 0, z) * Cylinder(float(r), float(length), align=_MIN)
        part = seg if part is None else part + seg
        z += float(length)
    total = z
    info: dict = {"radii": radii.tolist(), "lengths": lengths.tolist()}
    for zc, r in ((0.0, radii[0]), (total, radii[-1])):
        if rng.random() < 0.8:
            part = chamfer(_circle_edges_at(part, zc, float(r)), _u(rng, 0.08, 0.25) * float(r))
    z = 0.0
    for k in range(n - 1):
        z += float(lengths[k])
        small = float(min(radii[k], radii[k + 1]))
        if abs(radii[k] - radii[k + 1]) > 2 and rng.random() < 0.6:
            part = fillet(_circle_edges_at(part, z, small), _u(rng, 0.1, 0.4) * abs(radii[k] - radii[k + 1]))
    if rng.random() < 0.5:
        k = int(np.argmax(lengths))
        z0 = float(np.sum(lengths[:k]))
        r = float(radii[k])
        kl, kw = 0.6 * float(lengths[k]), 0.4 * r
        part -= Pos(0, r - 0.25 * r, z0 + 0.2 * float(lengths[k])) * Box(
            kw, r, kl, align=(Align.CENTER, Align.MIN, Align.MIN)
        )
    if rng.random() < 0.5:
        k = int(rng.integers(0, n))
        zc = float(np.sum(lengths[:k]) + 0.5 * lengths[k])
        part -= Pos(0, 0, zc) * Rot(0, 90, 0) * Cylinder(0.25 * float(radii[k]), 3 * float(radii.max()))
    # Lie it on its side: the shaft axis becomes the model X axis.
    part = Rot(0, 90, 0) * part
    return part, info


def build_flange(rng: np.random.Generator) -> tuple[Part, dict]:
    """Disc with a raised hub, central bore and bolt-circle holes; hub fillet and chamfers."""
    R = _u(rng, 35, 70)
    t = _u(rng, 0.12, 0.3) * R
    hr = _u(rng, 0.35, 0.55) * R
    hh = _u(rng, 0.3, 1.2) * R
    bore = _u(rng, 0.35, 0.7) * hr
    part = Cylinder(R, t, align=_MIN) + Pos(0, 0, t) * Cylinder(hr, hh, align=_MIN)
    if rng.random() < 0.7:
        part = fillet(_circle_edges_at(part, t, hr), _u(rng, 0.1, 0.3) * min(R - hr, hh))
    if rng.random() < 0.7:
        part = chamfer(_circle_edges_at(part, t + hh, hr), _u(rng, 0.05, 0.15) * hr)
    part -= Pos(0, 0, -1) * Cylinder(bore, t + hh + 2, align=_MIN)
    if rng.random() < 0.7:
        part = chamfer(_circle_edges_at(part, t + hh, bore), _u(rng, 0.1, 0.3) * (hr - bore))
    nb = int(rng.integers(3, 9))
    br = _u(rng, 0.04, 0.08) * R
    pitch = 0.5 * (R + hr)
    phase = _u(rng, 0, 360)
    for k in range(nb):
        a = np.deg2rad(phase + 360.0 * k / nb)
        part -= Pos(pitch * np.cos(a), pitch * np.sin(a), -1) * Cylinder(br, t + 2, align=_MIN)
    return part, {"R": R, "t": t, "hub_radius": hr, "hub_height": hh, "bore": bore, "bolts": nb}


def build_knob(rng: np.random.Generator) -> tuple[Part, dict]:
    """Knob: cylindrical base with rounded rim (torus), conical neck, spherical cap; optional radial holes."""
    R1 = _u(rng, 20, 40)
    h1 = _u(rng, 0.3, 0.8) * R1
    R2 = _u(rng, 0.45, 0.8) * R1
    R3 = _u(rng, 0.5, 0.9) * R2
    h2 = _u(rng, 0.4, 1.2) * R1
    part = Cylinder(R1, h1, align=_MIN)
    part += Pos(0, 0, h1) * Cone(R2, R3, h2, align=_MIN)
    top = h1 + h2
    rs = R3 / np.sin(np.deg2rad(_u(rng, 35, 75)))
    zc = top - np.sqrt(rs**2 - R3**2)
    cap = Pos(0, 0, zc) * Sphere(float(rs)) & Pos(0, 0, top) * Cylinder(R3 * 1.01, rs * 2, align=_MIN)
    part += cap
    rim = _u(rng, 0.2, 0.6) * min(R1 - R2, h1)
    part = fillet(_circle_edges_at(part, h1, R1), rim)
    if rng.random() < 0.5:
        part = chamfer(_circle_edges_at(part, 0.0, R1), _u(rng, 0.03, 0.08) * R1)
    n_holes = int(rng.integers(0, 4))
    turn = _turn_angle_deg(rng)
    for k in range(n_holes):
        a = turn + 360.0 * k / max(n_holes, 1)
        part -= (
            Pos(0, 0, 0.5 * h1) * Rot(0, 0, a) * Rot(0, 90, 0) * Cylinder(_u(rng, 0.08, 0.15) * h1, 3 * R1, align=_MIN)
        )
    return part, {
        "R1": R1,
        "h1": h1,
        "R2": R2,
        "R3": R3,
        "h2": h2,
        "cap_radius": float(rs),
        "holes": n_holes,
        "hole_turn_deg": turn,
    }


def build_turned(rng: np.random.Generator) -> tuple[Part, dict]:
    """Base plate carrying a block turned about Z by a non-multiple of 90 degrees, with holes through it."""
    L = _u(rng, 70, 130)
    W = _u(rng, 50, L)
    H = _u(rng, 8, 20)
    part = Box(L, W, H, align=_MIN)
    if rng.random() < 0.5:
        part = fillet(part.edges().filter_by(Axis.Z), _u(rng, 0.04, 0.12) * W)
    turn = _turn_angle_deg(rng)
    bl = _u(rng, 0.35, 0.55) * W
    bw = _u(rng, 0.25, 0.45) * W
    bh = _u(rng, 0.5, 1.5) * bw
    block = Box(bl, bw, bh, align=_MIN)
    if rng.random() < 0.5:
        block = fillet(block.edges().filter_by(Axis.Z), _u(rng, 0.05, 0.2) * bw)
    block -= Pos(0, 0, 0.55 * bh) * Rot(0, 90, 0) * Cylinder(_u(rng, 0.15, 0.3) * min(bw, bh), 2 * bl)
    if rng.random() < 0.5:
        block = chamfer(block.edges().filter_by(Axis.Y).group_by(Axis.Z)[-1], _u(rng, 0.1, 0.25) * bw)
    part += Pos(0, 0, H) * Rot(0, 0, turn) * block
    hole_r = _u(rng, 0.03, 0.06) * W
    for sx in (-1, 1):
        for sy in (-1, 1):
            part -= Pos(sx * (L / 2 - 3 * hole_r), sy * (W / 2 - 3 * hole_r), -1) * Cylinder(hole_r, H + 2, align=_MIN)
    return part, {"L": L, "W": W, "H": H, "turn_deg": turn, "block": [bl, bw, bh]}


def build_bracket(rng: np.random.Generator) -> tuple[Part, dict]:
    """L bracket: horizontal and vertical legs with a filleted bend and holes in both legs."""
    L = _u(rng, 50, 100)
    W = _u(rng, 30, 70)
    T = _u(rng, 5, 12)
    Hv = _u(rng, 35, 90)
    part = Box(L, W, T, align=_MIN) + Pos(-L / 2 + T / 2, 0, 0) * Box(T, W, Hv, align=_MIN)
    inner = [
        e
        for e in part.edges().filter_by(Axis.Y)
        if abs(e.center().X - (-L / 2 + T)) < 1e-6 and abs(e.center().Z - T) < 1e-6
    ]
    bend = _u(rng, 0.5, 2.0) * T
    part = fillet(inner, bend)
    hole_r = _u(rng, 0.06, 0.12) * W
    nh = int(rng.integers(1, 3))
    for k in range(nh):
        y = (k - (nh - 1) / 2) * W / nh
        part -= Pos(_u(rng, 0.15, 0.3) * L + T / 2 + bend / 2, y, -1) * Cylinder(hole_r, T + 2, align=_MIN)
        part -= (
            Pos(-L / 2 - 1, y, T + bend + _u(rng, 0.3, 0.6) * (Hv - T - bend))
            * Rot(0, 90, 0)
            * Cylinder(hole_r, T + 2, align=_MIN)
        )
    if rng.random() < 0.6:
        part = fillet(part.edges().filter_by(Axis.X).group_by(Axis.Z)[-1], _u(rng, 0.1, 0.4) * T)
    return part, {"L": L, "W": W, "T": T, "Hv": Hv, "bend": bend}


FAMILIES: dict[str, Callable[[np.random.Generator], tuple[Part, dict]]] = {
    "block": build_block,
    "shaft": build_shaft,
    "flange": build_flange,
    "knob": build_knob,
    "turned": build_turned,
    "bracket": build_bracket,
}


def rest_on_ground(shape: TopoDS_Shape) -> tuple[TopoDS_Shape, tuple[np.ndarray, np.ndarray]]:
    """Translate `shape` so its bounding box sits on z = 0 centred on the Z axis; returns it and its new box."""
    lo, hi = occ.bounding_box(shape)
    shift = -np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]])
    moved = occ.transform_shape(shape, np.hstack([np.eye(3), shift[:, None]]))
    return moved, (lo + shift, hi + shift)


def make_procedural(family: str, rng: np.random.Generator, max_tries: int = 5) -> RestPart:
    """Build a random part of `family` in its rest pose (a failed boolean or invalid solid is re-drawn)."""
    builder = FAMILIES[family]
    last: Exception | None = None
    for _ in range(max_tries):
        try:
            part, info = builder(rng)
        except Exception as exc:  # noqa: BLE001 - an OCCT boolean/fillet failure: draw other dimensions
            last = exc
            continue
        if part.is_valid and len(part.solids()) == 1:
            shape, box = rest_on_ground(part.wrapped)
            return RestPart(shape, family, box, info)
    raise RuntimeError(f"could not build a valid {family} part in {max_tries} tries: {last}")


# ---- real STEP parts -------------------------------------------------------------------------------------------

#: A convex-hull facet normal to a model axis is preferred as the resting face if its area is at least this share
#: of the largest facet's.
ALIGNED_FACET_MIN_SHARE = 0.3


def _hull_rest_rotation(shape: TopoDS_Shape) -> np.ndarray:
    """Rotation (3, 3) putting the largest facet of the convex hull down (outward normal to -Z).

    When that facet's normal is a model axis the rotation is a signed permutation, so the file's axes stay the
    part's axes; otherwise the turn about Z is chosen to put the largest horizontal plane normal on X.
    """
    import trimesh

    lo, hi = occ.bounding_box(shape)
    size = float(np.max(hi - lo))
    faces = occ.faces_of(shape)
    mesh = occ.tessellate(shape, faces, 0.01 * size, 0.5)
    hull = trimesh.Trimesh(mesh.vertices, mesh.triangles, process=True).convex_hull
    # Group hull triangles into planar facets by (rounded) normal and offset.
    normals = hull.face_normals
    offsets = np.einsum("ij,ij->i", normals, hull.triangles_center)
    key = np.round(np.hstack([normals * 1e4, offsets[:, None] / size * 1e4])).astype(np.int64)
    _, inverse = np.unique(key, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    area = np.bincount(inverse, weights=hull.area_faces)
    facet_n = np.zeros((len(area), 3))
    np.add.at(facet_n, inverse, normals)
    facet_n /= np.linalg.norm(facet_n, axis=1, keepdims=True)
    # Prefer a facet whose normal is a model axis, so the file's axes stay the part's axes (a designer's
    # features are aligned with them), unless it is much smaller than the largest facet.
    aligned = np.abs(facet_n).max(axis=1) > 1 - 1e-9
    best = int(np.argmax(area))
    if aligned.any() and area[aligned].max() >= ALIGNED_FACET_MIN_SHARE * area[best]:
        best = int(np.flatnonzero(aligned)[np.argmax(area[aligned])])
    n = facet_n[best]
    k = int(np.argmax(np.abs(n)))
    if aligned[best]:
        # Signed permutation: the facet's axis becomes -Z.
        z = np.zeros(3)
        z[k] = -np.sign(n[k])
        x = np.zeros(3)
        x[(k + 1) % 3] = 1.0
        y = np.cross(z, x)
        return np.stack([x, y, z])
    # the smallest rotation taking n to -Z (n is no model axis here, so never antiparallel to it)
    rot = Rotation.align_vectors([[0.0, 0.0, -1.0]], [n])[0].as_matrix()
    best_dir, best_area = None, 0.0
    for face in faces:
        prim = occ.face_primitive(face, 1.0)
        if prim["type"] != "plane":
            continue
        d = rot @ np.asarray(prim["params"]["normal"])
        if abs(d[2]) < 1e-6:
            from OCP.BRepGProp import BRepGProp
            from OCP.GProp import GProp_GProps

            props = GProp_GProps()
            BRepGProp.SurfaceProperties_s(face, props)
            if props.Mass() > best_area:
                best_dir, best_area = d, props.Mass()
    if best_dir is not None:
        a = np.arctan2(best_dir[1], best_dir[0])
        rot = Rotation.from_rotvec([0.0, 0.0, -a]).as_matrix() @ rot
    return rot


@lru_cache(maxsize=32)
def _load_cad_rest(path_str: str) -> tuple[TopoDS_Shape, tuple[np.ndarray, np.ndarray]]:
    shape = occ.read_step(Path(path_str))
    rot = _hull_rest_rotation(shape)
    posed = occ.transform_shape(shape, np.hstack([rot, np.zeros((3, 1))]))
    return rest_on_ground(posed)


def load_cad(path: Path) -> RestPart:
    """A real STEP part in its rest pose (largest convex-hull facet down). Cached per process: the scene scales and
    turns it at random for every scan, so caching the file read is legitimate."""
    shape, box = _load_cad_rest(str(Path(path).resolve()))
    return RestPart(shape, "cad", box, {"file": Path(path).name})


def list_cad_files(directory: Path) -> list[Path]:
    """STEP files (*.step, *.stp, any case) in `directory`, sorted by name for reproducibility."""
    files = [p for p in Path(directory).iterdir() if p.suffix.lower() in (".step", ".stp") and p.is_file()]
    return sorted(files, key=lambda p: p.name)
