"""One entry point: a fixture of a given kind for a VB-Rep, in the part or camera frame (millimetres).

``design_fixture(vbrep, "corner")`` selects the best qualifying reference (highest confidence, then longest edge
or largest radius) among the VB-Rep's intersection edges and builds the fixture on it; pass ``reference`` to choose
another one from `fixtures_design.references.select_references`. Raises `NoReferenceError` when no intersection
edge qualifies for the kind (the nest needs no edge, only face meshes).
"""

from __future__ import annotations

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
from v2c.vbrep.model import VBRep

Params = CornerParams | PinParams | CradleParams | NestParams

#: Which reference each kind of fixture seats on.
REFERENCE_OF: dict[FixtureKind, ReferenceKind] = {
    FixtureKind.CORNER: ReferenceKind.DIHEDRAL,
    FixtureKind.PIN: ReferenceKind.HOLE,
    FixtureKind.CRADLE: ReferenceKind.BOSS,
}

DEFAULT_PARAMS: dict[FixtureKind, Params] = {
    FixtureKind.CORNER: CornerParams(),
    FixtureKind.PIN: PinParams(),
    FixtureKind.CRADLE: CradleParams(),
    FixtureKind.NEST: NestParams(),
}


def design_fixture(
    vbrep: VBRep,
    kind: FixtureKind | str,
    params: Params | None = None,
    frame: Frame | str = Frame.PART,
    min_confidence: float = 0.5,
    reference: Reference | None = None,
    selection: SelectionConfig | None = None,
    ground_height: float | None = None,
) -> Fixture:
    """A fixture of ``kind`` for ``vbrep`` (camera frame, metres), built in ``frame`` (millimetres).

    min_confidence: intersection edges under it (in [0, 1]) are never references. The candidates are tried best
    first until the generator accepts one (long enough for a corner, a hole's rim for a pin, horizontal for a
    cradle); `NoReferenceError` lists why each was refused. ground_height: for a nest, the ground's height (metres
    along the VB-Rep frame's Z from the camera centre, see `fixtures_design.run.ground_height`); default: the
    lowest point of the face meshes.
    """
    kind = FixtureKind(kind)
    params = DEFAULT_PARAMS[kind] if params is None else params
    fmap = output_frame(vbrep, frame)
    if kind is FixtureKind.NEST:
        return design_nest(vbrep, fmap, params, ground_height)
    refs = [reference] if reference is not None else select_references(
        vbrep, [REFERENCE_OF[kind]], min_confidence, selection or SelectionConfig())
    errors = []
    for ref in refs:  # best first; the geometry checks of the generator may still refuse one
        try:
            if kind is FixtureKind.CORNER:
                return design_corner(ref, fmap, params)
            if kind is FixtureKind.PIN:
                return design_pin(ref, fmap, params)
            return design_cradle(ref, fmap, up_vector(vbrep, fmap), params)
        except ValueError as exc:
            if reference is not None:
                raise
            errors.append(str(exc))
    raise NoReferenceError(f"no {REFERENCE_OF[kind].value} qualifies for a {kind.value}: " + "; ".join(errors))
