"""`v2c fixture SCAN --kind corner|pin|cradle|nest`: a fixture on the scan's sure edges (docs/fixtures.md)."""

from __future__ import annotations

from pathlib import Path

import click

from v2c.cli_support import max_pixels_option, roi_option, verbosity_options
from v2c.commands import frame_index_option, pick_options, segmentation_option


@click.command("fixture")
@max_pixels_option
@click.argument("scan", type=click.Path(path_type=Path))
@click.option(
    "--kind",
    type=click.Choice(["corner", "pin", "cradle", "nest"]),
    required=True,
    help="corner: L block on a convex edge; pin: tapered locating pin in a hole; cradle: U block under a "
    "horizontal cylinder; nest: plate with a pocket following the visible footprint.",
)
@click.option(
    "-o",
    "--output",
    "out",
    type=click.Path(path_type=Path),
    default=None,
    help="Output folder. Default: SCAN/fixtures (or <stem>_fixtures next to a VB-Rep JSON or STEP).",
)
@click.option(
    "--frame",
    type=click.Choice(["part", "camera"]),
    default="part",
    show_default=True,
    help="part: recovered axes on X/Y/Z, origin at the bottom centre of the visible part (as to-step); "
    "camera: the camera frame. Millimetres either way.",
)
@click.option(
    "--min-confidence",
    type=click.FloatRange(0.0, 1.0),
    default=0.5,
    show_default=True,
    help="Intersection edges under this confidence are never used as references.",
)
@segmentation_option()
@click.option(
    "--clearance",
    type=click.FloatRange(min=0.0),
    default=None,
    metavar="MM",
    help="Gap between fixture and part in millimetres (default: the fixture kind's, 0.1-0.2 mm). "
    "Raise it to absorb reconstruction error.",
)
@click.option(
    "--part",
    "part",
    type=click.Choice(["reconstructed", "true", "none"]),
    default="reconstructed",
    show_default=True,
    help="Part placed in the assembly STEP (true: a synthetic scan's gt/part.step).",
)
@click.option("--force", is_flag=True, help="Replace existing files that v2c did not write.")
@roi_option
@pick_options
@frame_index_option
@verbosity_options
def command(
    scan: Path,
    kind: str,
    out: Path | None,
    frame: str,
    min_confidence: float,
    segmentation: str,
    clearance: float | None,
    part: str,
    force: bool,
    roi: tuple[int, int, int, int] | None,
) -> None:
    """Design a fixture for SCAN (a scan folder, a VB-Rep JSON, or a STEP written by `v2c to-step`) and write
    <kind> STEP, STL and assembly STEP. A STEP input keeps its own frame.

    Only intersection edges at or above --min-confidence are used as references (a cradle may also rest on a
    convex cylinder face at or above it, after every edge); when none qualifies the command says what was
    needed and lists the edges (and cylinder faces), and writes nothing.
    """
    import dataclasses

    from fixtures_design.design import DEFAULT_PARAMS
    from fixtures_design.model import FixtureKind
    from fixtures_design.references import NoReferenceError
    from fixtures_design.run import fixture_for_scan
    from v2c.scan import ScanError

    # without --clearance: None, the kind's defaults (design_fixture may raise them by its clearance_k)
    params = None
    if clearance is not None:
        params = dataclasses.replace(DEFAULT_PARAMS[FixtureKind(kind)], clearance=clearance)
    try:
        res = fixture_for_scan(
            scan,
            kind,
            out,
            frame=frame,
            min_confidence=min_confidence,
            segmentation=segmentation,
            part=part,
            params=params,
            roi=roi,
            force=force,
        )
    except (ScanError, NoReferenceError, FileNotFoundError) as exc:
        raise click.ClickException(str(exc)) from None
    except ValueError as exc:
        raise click.ClickException(str(exc) if str(scan) in str(exc) else f"{scan}: {exc}") from None
    fx = res.fixture
    ref = fx.reference
    if getattr(ref, "edge_id", 0) < 0:  # a cradle on a cylinder face alone (no edge)
        sig = next((f.sigma_mm for f in res.vbrep.faces if f.id == ref.cylinder_face), None)
        extra = "" if sig is None else f", position 1-sigma {sig:.2f} mm"
        what = f"cylinder face f{ref.cylinder_face} (boss, face confidence {ref.confidence:.2f}{extra})"
    elif hasattr(ref, "edge_id"):
        # the chosen edge's figures: calibrated probability that it is a true edge, raw score, 1-sigma position
        e = next((e for e in res.vbrep.edges if e.id == ref.edge_id), None)
        extra = ""
        if e is not None and e.confidence_raw is not None:
            extra += f", raw score {e.confidence_raw:.2f}"
        if e is not None and e.sigma_mm is not None:
            extra += f", position 1-sigma {e.sigma_mm:.2f} mm"
        what = f"edge e{ref.edge_id} ({ref.kind.value}, confidence {ref.confidence:.2f} = probability right{extra})"
    else:
        what = f"footprint ({len(ref.outlines)} outline(s))"
    why = ""
    if kind == "pin" and clearance is None:  # a pin's default play: the hole radius's error, not the faces' sigma
        from fixtures_design.design import HOLE_RADIUS_SIGMA_MM, PIN_CLEARANCE_K

        why = f" ({PIN_CLEARANCE_K:g} x the hole radius's 1-sigma {HOLE_RADIUS_SIGMA_MM:g} mm)"
    if kind == "pin":
        n = fx.notes
        why += f"; pin radius {n['pin_radius_mm']:.2f} mm at the flange"
        if n["shank_radius_mm"] < n["pin_radius_mm"]:
            why += f", narrowing along a {fx.params.taper_deg:g}-degree cone to {n['shank_radius_mm']:.2f} mm"
    click.echo(
        f"{kind} fixture on {what}: {fx.volume_mm3:.0f} mm^3, {len(fx.mating_faces)} mating faces, "
        f"clearance {fx.params.clearance:.2f} mm{why}"
    )
    for p in (res.files.step, res.files.stl, res.files.assembly):
        click.echo(f"  {p}")
