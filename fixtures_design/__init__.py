"""Fixtures that mate with a reconstructed part's high-confidence intersection edges (docs/fixtures.md).

    >>> from fixtures_design import design_fixture, write_fixture, reconstructed_part
    >>> fx = design_fixture(vbrep, "corner", frame="part", min_confidence=0.6)
    >>> write_fixture(fx, "out/", part=reconstructed_part(vbrep, fx.fmap))

References (`select_references`) come only from intersection edges; generators (`design_corner`, `design_pin`,
`design_cradle`, `design_nest`) build build123d solids in millimetres in the part or camera frame.
`fixture_for_scan` does the whole of ``v2c fixture``: scan folder (or VB-Rep JSON, or ``v2c to-step`` STEP) ->
fixture files. Example scripts: `fixtures_design.examples` (on the bundled sample scans).
"""

from fixtures_design.assembly import FixtureFiles, assembly, reconstructed_part, true_part, write_fixture
from fixtures_design.corner import CornerParams, design_corner
from fixtures_design.cradle import CradleParams, design_cradle
from fixtures_design.design import design_fixture
from fixtures_design.model import Fixture, FixtureKind
from fixtures_design.nest import NestParams, design_nest, footprint
from fixtures_design.pin import PinParams, design_pin
from fixtures_design.references import (
    CircleReference,
    DihedralReference,
    NoReferenceError,
    ReferenceKind,
    SelectionConfig,
    explain_edges,
    select_references,
)
from fixtures_design.run import FixtureRun, fixture_for_scan, ground_height
from fixtures_design.seat import Seat, SeatConfig, seat_part
from fixtures_design.verify import check_mating, interference

__all__ = [
    "CircleReference",
    "CornerParams",
    "CradleParams",
    "DihedralReference",
    "Fixture",
    "FixtureFiles",
    "FixtureKind",
    "FixtureRun",
    "NestParams",
    "NoReferenceError",
    "PinParams",
    "ReferenceKind",
    "Seat",
    "SeatConfig",
    "SelectionConfig",
    "assembly",
    "check_mating",
    "design_corner",
    "design_cradle",
    "design_fixture",
    "design_nest",
    "design_pin",
    "explain_edges",
    "fixture_for_scan",
    "footprint",
    "ground_height",
    "interference",
    "reconstructed_part",
    "seat_part",
    "select_references",
    "true_part",
    "write_fixture",
]
