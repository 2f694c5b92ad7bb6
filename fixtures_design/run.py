"""Scan (or VB-Rep JSON) -> fixture files: what `v2c fixture` does, as one function.

    >>> from fixtures_design.run import fixture_for_scan
    >>> res = fixture_for_scan("samples/bracket", "corner")       # writes samples/bracket/fixtures/...
    >>> res.files.step, res.fixture.reference

The VB-Rep comes from `v2c.pipeline.reconstruct` (or a saved VB-Rep JSON). The ground the part stands on is taken
from the scan's depth around the part when the scan has a mask (the nest plate's floor), else from the lowest point
of the VB-Rep. The assembly holds the reconstructed part, the true part (a synthetic scan's gt/part.step) or
nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np

from fixtures_design.assembly import FixtureFiles, reconstructed_part, true_part, write_fixture
from fixtures_design.design import Params, design_fixture
from fixtures_design.frames import Frame
from fixtures_design.model import Fixture, FixtureKind
from v2c.vbrep.model import VBRep

if TYPE_CHECKING:
    from v2c.scan import Scan

PartChoice = Literal["reconstructed", "true", "none"]


@dataclass
class FixtureRun:
    """What `fixture_for_scan` made: the VB-Rep, the fixture and the files written."""

    vbrep: VBRep
    fixture: Fixture
    files: FixtureFiles


def ground_height(scan: Scan, vbrep: VBRep, ring_px: int = 25) -> float | None:
    """Height (metres, along the VB-Rep frame's Z, camera origin) of the ground around the part, or None.

    The median height of the valid depth pixels in a ``ring_px`` wide ring around the scan's part mask.
    """
    import cv2

    from exporters import proper_rotation

    mask = getattr(scan, "mask", None)
    if mask is None:
        return None
    kernel = np.ones((2 * ring_px + 1, 2 * ring_px + 1), np.uint8)
    ring = (cv2.dilate(mask.astype(np.uint8), kernel) > 0) & ~mask & (scan.depth > 0)
    if ring.sum() < 50:
        return None
    up = proper_rotation(vbrep.frame)[2]
    return float(np.median(scan.points()[ring] @ up))


STEP_SUFFIXES = (".step", ".stp")


def load_vbrep(
    source: str | Path, segmentation: str = "learned", roi: tuple[int, int, int, int] | None = None
) -> tuple[VBRep, object | None]:
    """A VB-Rep from a scan folder (reconstructed, within ``roi`` pixels x0, y0, x1, y1 when given), a VB-Rep JSON
    file or a ``v2c to-step`` STEP file (`fixtures_design.step_input`); the loaded scan (or None)."""
    path = Path(source)
    if path.is_file() and path.suffix == ".json":
        return VBRep.load(path), None
    if path.is_file() and path.suffix.lower() in STEP_SUFFIXES:
        from fixtures_design.step_input import vbrep_from_step

        return vbrep_from_step(path), None
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan

    scan = load_scan(path, roi=roi)
    return reconstruct(scan, segmentation=segmentation), scan


def fixture_for_scan(
    source: str | Path,
    kind: FixtureKind | str,
    out_dir: str | Path | None = None,
    frame: Frame | str = Frame.PART,
    min_confidence: float = 0.5,
    segmentation: str = "learned",
    part: PartChoice = "reconstructed",
    params: Params | None = None,
    roi: tuple[int, int, int, int] | None = None,
    force: bool = True,
) -> FixtureRun:
    """Design a fixture of ``kind`` for a scan folder or VB-Rep JSON and write its files into ``out_dir``.

    out_dir: default ``<scan>/fixtures`` (or ``<file stem>_fixtures`` next to a JSON or STEP). part: which part goes
    into the assembly ("true" needs a synthetic scan's gt/part.step). Millimetres, ``frame`` as in `v2c to-step`;
    a STEP input keeps the STEP's own frame (``frame`` is ignored) and its faces are the reconstructed part.
    Raises `NoReferenceError` when no intersection edge qualifies; nothing is written then. force: False refuses
    (`v2c.errors.OutputError`, before any work) to replace an existing output file that v2c did not write
    (`v2c.io_safe.check_replaceable`; `v2c fixture` without ``--force``).
    """
    from v2c.io_safe import check_replaceable

    source = Path(source)
    if out_dir is None:
        out_dir = source / "fixtures" if source.is_dir() else source.with_name(source.stem + "_fixtures")
    stem = f"fixture_{FixtureKind(kind).value}"  # the names `write_fixture` gives the set
    for name in (f"{stem}.step", f"{stem}.stl", f"{stem}_assembly.step"):
        check_replaceable(Path(out_dir) / name, force)
    vbrep, scan = load_vbrep(source, segmentation, roi)
    from_step = source.suffix.lower() in STEP_SUFFIXES
    if from_step:
        frame = Frame.CAMERA  # the VB-Rep is in the file's frame already
    ground = ground_height(scan, vbrep) if scan is not None else None
    points = scan.points()[scan.valid] if scan is not None else None  # what the depth shows of the part
    fixture = design_fixture(
        vbrep, kind, params, frame=frame, min_confidence=min_confidence, ground_height=ground, points=points
    )
    if part == "true":
        gt = source / "gt" / "part.step"
        if not gt.exists():
            raise FileNotFoundError(f"{gt}: no true part (only synthetic scans have gt/part.step)")
        shape = true_part(gt, fixture.fmap)
    elif part == "reconstructed" and from_step:
        from fixtures_design.step_input import step_shape

        shape = step_shape(source)
    elif part == "reconstructed":
        shape = reconstructed_part(vbrep, fixture.fmap)
    else:
        shape = None
    files = write_fixture(fixture, out_dir, part=shape, part_label=f"{part}_part")
    return FixtureRun(vbrep, fixture, files)
