"""One entry point: a fixture of a given kind for a VB-Rep, in the part or camera frame (millimetres).

``design_fixture(vbrep, "corner")`` selects the best qualifying reference (highest confidence, then longest edge
or largest radius) among the VB-Rep's intersection edges and builds the fixture on it; pass ``reference`` to choose
another one from `fixtures_design.references.select_references`. Raises `NoReferenceError` when no intersection
edge qualifies for the kind (the nest needs no edge, only face meshes).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fixtures_design.corner import CornerParams, design_corner
from fixtures_design.cradle import CradleParams, design_cradle
from fixtures_design.frames import Frame, output_frame, up_vector
from fixtures_design.model import Fixture, FixtureKind
from fixtures_design.nest import NestParams, design_nest
from fixtures_design.pin import PinParams, design_pin
from fixtures_design.references import (
    NoReferenceError,
    Reference,
    ReferenceKind,
    SelectionConfig,
    select_references,
)
from fixtures_design.verify import (
    EvidenceConfig,
    hole_opening,
    observed_inside,
    part_inside_share,
    wall_inside,
    wall_narrowing,
)
from v2c.vbrep.model import VBRep

Params = CornerParams | PinParams | CradleParams | NestParams

#: Which reference each kind of fixture seats on.
REFERENCE_OF: dict[FixtureKind, ReferenceKind] = {
    FixtureKind.CORNER: ReferenceKind.DIHEDRAL,
    FixtureKind.PIN: ReferenceKind.HOLE,
    FixtureKind.CRADLE: ReferenceKind.BOSS,
}

#: Default clearance = max(the kind's own clearance, CLEARANCE_K x hypot(the largest 1-sigma position error (mm) of
#: the VB-Rep faces the fixture mates with, `VFace.sigma_mm`, and `DEPTH_BIAS_MM`); for a nest the median sigma over
#: all faces. Chosen on training families with `v2c bench --stage fixtures` (docs/fixtures.md, "What the scan vouches
#: for"): on 24 scans of seed 7100, corner / pin / cradle cut 25 / 11 / 7 % at k = 0.5 / 1 / 1.5 and touch (median
#: within 1 mm) 61 / 25 / 7 %: no k meets both (cut <= 2 %, touch >= 90 %); 1 halves the cuts of 0.5, and what still
#: cuts at 1 is two holes fitted wrong and a block over an unseen feature, not the clearance. Seated (the true part
#: pushed home, `fixtures_design.seat`; docs/fixtures.md "Seated: the part pushed home"), on the same 24 scans after
#: the hole land fix: k = 0.5 / 1 with DEPTH_BIAS_MM cut 7.4 / 3.7 % and touch 88.9 / 81.5 %, without it (k = 0.5 / 1)
#: 7.4 / 7.4 % and 92.6 / 85.2 %: only pins differ, and the smaller clearances let a second wrong hole cut, so 1 stays.
#: Pins have their own rule since (`pin_clearance`, PIN_CLEARANCE_K): CLEARANCE_K is the corners', cradles' and nests'.
CLEARANCE_K = 1.0

#: References whose mating faces' 1-sigma position error exceeds this (mm) are refused by `design_fixture`. None
#: (no limit) by default: on the training scans the designs that cut had sigma 0.49-0.86 mm, no larger than those
#: that did not, so no limit removed cuts without removing as many good designs (docs/fixtures.md).
MAX_SIGMA_MM: float | None = None

#: A design whose solid holds more than this share of points sampled on the VB-Rep's own face meshes
#: (`fixtures_design.verify.part_inside_share`) would cut into the reconstructed part: with a share given, its
#: reference is refused and the next one tried. None (off) by default: on the training scans (seed 7100, 12 scans)
#: it refused nothing, so they cannot choose it; see docs/fixtures.md for what it did on the leave-out families.
MAX_PART_INSIDE_SHARE: float | None = None


def mating_sigma_mm(vbrep: VBRep, ref: Reference) -> float | None:
    """Largest `VFace.sigma_mm` (mm) of the faces a reference mates with (a dihedral edge's two planes; a circle's
    cylinder and plane); None when none of them has one (a VB-Rep written before sigma existed)."""
    ids = ref.faces if hasattr(ref, "faces") else (ref.cylinder_face, ref.plane_face)
    sig = [f.sigma_mm for f in vbrep.faces if f.id in ids and f.sigma_mm is not None]
    return max(sig) if sig else None


def outline_sigma_mm(vbrep: VBRep) -> float | None:
    """Median `VFace.sigma_mm` (mm) over the VB-Rep's faces (what a nest's pocket follows); None without any."""
    sig = [f.sigma_mm for f in vbrep.faces if f.sigma_mm is not None]
    return float(np.median(sig)) if sig else None


#: 1-sigma (mm) of the depth offset a scan's low-frequency depth error leaves on the whole part: the sensor
#: profile's fBm warp (+-2 mm over the image, `v2c.synth.noise.SensorNoise.warp_amplitude_m`) moves every face of
#: one part by about the same amount along the camera rays, which no fit of that part can see (the faces' sigma
#: does not hold it). Measured on the training scans of `v2c bench --stage fixtures` (seed 7100, 24 scans): the
#: median of depth - clean depth over each part's pixels ranged -1.2..+1.4 mm, RMS 0.74 mm.
DEPTH_BIAS_MM = 0.74


#: A pin's radial clearance (`pin_clearance`) comes from the error of the hole's *radius*, not from its faces'
#: positional sigma: seated, the part sits on the pin, so the hole's place (and the scan's depth offset, which moves
#: the whole part) sets where the part goes, not whether the pin fits. On the training holes of `v2c bench --stage
#: fixtures --families train --seed 7100 --n 48` (26 pins whose hole matched a true one; 640x480 `sensor` noise,
#: learned segmentation) the fitted radius was off by -0.65..+0.53 mm, RMS 0.22 mm: HOLE_RADIUS_SIGMA_MM. It
#: tracked neither the fit's covariance (errors of 0.04-2.6 times its radius sigma: the far, small holes with the
#: largest covariance sigma were among the best fitted), nor the depth noise at the hole (the largest errors were on
#: near holes), nor the rim's pixel footprint (RMS 0.23 px, but the far holes again fitted best): a constant in mm
#: was the best model (docs/fixtures.md, "Pins: the hole's radius"). PIN_CLEARANCE_K = 3 (three sigma, 0.66 mm)
#: clears every training hole's radius error (the largest, +0.53 mm, needs k >= 2.4) while the loosest pin's play
#: (clearance - error) stays at 1.0 mm. Before, k x hypot(faces' sigma, DEPTH_BIAS_MM) gave the training pins
#: clearances of 0.77-1.54 mm and 5 of 26 sat loose (seated mating median over 1 mm).
HOLE_RADIUS_SIGMA_MM = 0.22
PIN_CLEARANCE_K = 3.0


def pin_clearance(params: Params, k: float = PIN_CLEARANCE_K) -> Params:
    """``params`` with clearance max(params.clearance, k * HOLE_RADIUS_SIGMA_MM) (mm): the pin's radial play
    against the hole's radius error; unchanged when k is not positive."""
    if not k > 0:
        return params
    return replace(params, clearance=max(params.clearance, k * HOLE_RADIUS_SIGMA_MM))


def sigma_clearance(
    params: Params, sigma_mm: float | None, k: float = CLEARANCE_K, bias_mm: float = DEPTH_BIAS_MM
) -> Params:
    """``params`` with clearance max(params.clearance, k * hypot(sigma_mm, bias_mm)) (mm): the faces' own 1-sigma
    and the scan's depth offset (`DEPTH_BIAS_MM`) together; unchanged when sigma_mm is None."""
    if sigma_mm is None or not k > 0:
        return params
    return replace(params, clearance=max(params.clearance, k * float(np.hypot(sigma_mm, bias_mm))))


DEFAULT_PARAMS: dict[FixtureKind, Params] = {
    FixtureKind.CORNER: CornerParams(),
    FixtureKind.PIN: PinParams(),
    FixtureKind.CRADLE: CradleParams(),
    FixtureKind.NEST: NestParams(),
}


def evidence_refusal(fx: Fixture, points: np.ndarray, evidence: EvidenceConfig) -> str | None:
    """Why the scan's observed points of the part (camera frame, metres, (N, 3)) refuse the design ``fx``, or None.

    Any kind: more than ``evidence.max_points`` of them lie inside it beyond the depth noise (`observed_inside`).
    A pin besides: it is wider than the opening its hole's plane shows by more than ``opening_tol_mm`` +
    ``opening_tol_rel`` x the hole's radius (`hole_opening`), or more than ``max_wall_share`` (and at least
    ``min_wall_points``) of the hole's wall points lie inside it beyond their radial noise (`wall_inside`): the hole
    is fitted too wide, or narrower somewhere than its fit (a counterbore's step); or its wall points come nearer
    the axis going down it faster than ``wall_max_narrowing`` at ``wall_narrowing_z`` standard errors
    (`wall_narrowing`): a chamfer or countersink was fitted as the hole.
    """
    ref, fmap = fx.reference, fx.fmap
    n_in, deepest = observed_inside(fx, points, evidence)
    if n_in > evidence.max_points:
        return (
            f"{ref.label}: the {fx.kind.value} would hold {n_in} of the scan's points of the part, up to "
            f"{deepest:.1f} mm deep (more than {evidence.max_points} beyond {evidence.n_sigma:g} sigma of "
            "depth noise): the reconstruction there is not what the depth shows"
        )
    if fx.kind is not FixtureKind.PIN:
        return None
    pin_r = fx.notes["pin_radius_mm"]
    opening = hole_opening(ref.center, ref.axis, ref.radius, points, evidence)
    tol = evidence.opening_tol_mm + evidence.opening_tol_rel * fmap.length(ref.radius)
    if opening is not None and pin_r > fmap.length(opening) + tol:
        return (
            f"{ref.label}: the pin (radius {pin_r:.2f} mm) is wider than the opening the hole's plane shows "
            f"(radius {fmap.length(opening):.2f} mm) by more than {tol:.2f} mm: the hole is fitted too wide"
        )
    depth = (fx.notes["depth_mm"] + fx.params.clearance) / fmap.scale
    n_in, n_wall = wall_inside(ref.center, ref.axis, ref.radius, pin_r / fmap.scale, depth, points, evidence)
    if n_in >= evidence.min_wall_points and n_in > evidence.max_wall_share * n_wall:
        return (
            f"{ref.label}: {n_in} of the hole's {n_wall} wall points lie inside the pin (radius {pin_r:.2f} mm) "
            f"beyond {evidence.n_sigma:g} sigma of their noise (more than {100 * evidence.max_wall_share:g} %): the "
            "hole is narrower than its fit somewhere"
        )
    slope, se, n_wall = wall_narrowing(ref.center, ref.axis, ref.radius, depth, points, evidence)
    narrows = slope - evidence.wall_narrowing_z * se > evidence.wall_max_narrowing
    if n_wall >= evidence.wall_narrowing_min_points and narrows:
        return (
            f"{ref.label}: the hole's {n_wall} wall points come {slope:.2f} +- {se:.2f} mm nearer its axis per mm "
            f"of depth (more than {evidence.wall_max_narrowing:g} at {evidence.wall_narrowing_z:g} standard "
            "errors): a chamfer or countersink was fitted as the hole, which is narrower below"
        )
    return None


def design_fixture(
    vbrep: VBRep,
    kind: FixtureKind | str,
    params: Params | None = None,
    frame: Frame | str = Frame.PART,
    min_confidence: float = 0.5,
    reference: Reference | None = None,
    selection: SelectionConfig | None = None,
    ground_height: float | None = None,
    clearance_k: float = CLEARANCE_K,
    max_sigma_mm: float | None = MAX_SIGMA_MM,
    max_part_inside_share: float | None = MAX_PART_INSIDE_SHARE,
    points: np.ndarray | None = None,
    evidence: EvidenceConfig | None = None,
    bias_mm: float = DEPTH_BIAS_MM,
    pin_k: float | None = None,
) -> Fixture:
    """A fixture of ``kind`` for ``vbrep`` (camera frame, metres), built in ``frame`` (millimetres).

    params: None = the kind's defaults, with the clearance raised to ``clearance_k`` times the mating faces'
    1-sigma position error when clearance_k > 0 (`sigma_clearance`, per reference tried); given params are used
    as they are.
    min_confidence: intersection edges under it (in [0, 1]) are never references. The candidates are tried best
    first until the generator accepts one (long enough for a corner, a hole's rim for a pin, horizontal for a
    cradle); `NoReferenceError` lists why each was refused. ground_height: for a nest, the ground's height (metres
    along the VB-Rep frame's Z from the camera centre, see `fixtures_design.run.ground_height`); default: the
    lowest point of the face meshes. max_sigma_mm: references whose mating faces' 1-sigma (`mating_sigma_mm`)
    is larger are refused when the references are chosen here (None: none refused; a given ``reference`` is
    always tried). max_part_inside_share: a design built on a reference chosen here whose solid holds more than
    this share of points sampled on the VB-Rep's face meshes is refused (None: no check).
    points: the scan's observed points of the part (camera frame, metres, (N, 3); e.g. the valid pixels of its
    mask): a corner, pin or cradle holding more than ``evidence.max_points`` of them deeper than the depth noise
    (`fixtures_design.verify.observed_inside`), or a pin its hole's plane or wall points say is too wide
    (`evidence_refusal`), is refused with the reason, and the next reference tried (a given ``reference`` raises
    ValueError). None: no check (a VB-Rep or STEP without its scan). bias_mm: the scan's depth-offset 1-sigma in
    the default clearance (`sigma_clearance`). A pin's default clearance is instead ``pin_k`` (None:
    PIN_CLEARANCE_K) times the hole radius's 1-sigma (`pin_clearance`, HOLE_RADIUS_SIGMA_MM; ``clearance_k`` and
    ``bias_mm`` do not apply to it).
    """
    kind = FixtureKind(kind)
    evidence = evidence or EvidenceConfig()
    auto = params is None  # default params: the clearance follows each reference's positional uncertainty
    params = DEFAULT_PARAMS[kind] if params is None else params
    fmap = output_frame(vbrep, frame)
    if kind is FixtureKind.NEST:  # the pocket follows every face's outline: their median sigma
        p = sigma_clearance(params, outline_sigma_mm(vbrep), clearance_k, bias_mm) if auto else params
        return design_nest(vbrep, fmap, p, ground_height, points)
    refs = (
        [reference]
        if reference is not None
        else select_references(vbrep, [REFERENCE_OF[kind]], min_confidence, selection or SelectionConfig())
    )
    errors = []
    for ref in refs:  # best first; the geometry checks of the generator may still refuse one
        sigma = mating_sigma_mm(vbrep, ref)
        if reference is None and max_sigma_mm is not None and sigma is not None and sigma > max_sigma_mm:
            errors.append(f"{ref.label}: its faces' 1-sigma {sigma:.2f} mm is over max_sigma_mm {max_sigma_mm:g}")
            continue
        if not auto:
            p = params
        elif kind is FixtureKind.PIN:  # the hole's radius error, not its place (HOLE_RADIUS_SIGMA_MM)
            p = pin_clearance(params, PIN_CLEARANCE_K if pin_k is None else pin_k)
        else:
            p = sigma_clearance(params, sigma, clearance_k, bias_mm)
        try:
            if kind is FixtureKind.CORNER:
                fx = design_corner(ref, fmap, p)
            elif kind is FixtureKind.PIN:
                fx = design_pin(ref, fmap, p)
            else:
                fx = design_cradle(ref, fmap, up_vector(vbrep, fmap), p, vbrep=vbrep)
        except ValueError as exc:
            if reference is not None:
                raise
            errors.append(str(exc))
            continue
        if points is not None:
            msg = evidence_refusal(fx, points, evidence)
            if msg is not None:
                if reference is not None:
                    raise ValueError(msg)
                errors.append(msg)
                continue
        if reference is None and max_part_inside_share is not None:
            inside = part_inside_share(fx, vbrep)
            if inside > max_part_inside_share:
                errors.append(
                    f"{ref.label}: the {kind.value} would hold {100 * inside:.1f} % of the reconstructed part's "
                    f"surface (max_part_inside_share {max_part_inside_share:g})"
                )
                continue
        return fx
    raise NoReferenceError(f"no {REFERENCE_OF[kind].value} qualifies for a {kind.value}: " + "; ".join(errors))
