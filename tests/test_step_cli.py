"""`v2c to-step`: the whole pipeline on tiny scans (one tilted plane with exact ground truth, oracle
segmentation), a batch with a broken scan, output options, and bad input writing nothing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from OCP.Bnd import Bnd_Box
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepBndLib import BRepBndLib
from OCP.TopAbs import TopAbs_FACE
from OCP.TopExp import TopExp_Explorer
from OCP.TopoDS import TopoDS

from exporters.step import EDGE_COLORS, read_typed
from v2c.commands.to_step import command as to_step
from v2c.vbrep.model import VBRep

from conftest import TINY, listing, write_tiny_scan


def _run(args: list[str]):
    return CliRunner().invoke(to_step, args, catch_exceptions=False)


def _plane_of(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(point, unit normal) of the only face of a STEP file (millimetres, the file's frame)."""
    exp = TopExp_Explorer(read_typed(path).shape, TopAbs_FACE)
    pln = BRepAdaptor_Surface(TopoDS.Face_s(exp.Current())).Plane()
    loc, n = pln.Location(), pln.Axis().Direction()
    return np.array([loc.X(), loc.Y(), loc.Z()]), np.array([n.X(), n.Y(), n.Z()])


@pytest.fixture
def batch(tmp_path: Path) -> Path:
    """A folder of three scans: two good ones (a, b) and one without depth (c)."""
    root = tmp_path / "scans"
    write_tiny_scan(root / "a", gt=True)
    write_tiny_scan(root / "b", gt=True, mask=True)
    write_tiny_scan(root / "c", gt=True)
    (root / "c" / "depth.png").unlink()
    return root


def test_batch_with_a_broken_scan(batch: Path) -> None:
    res = _run([str(batch), "--segmentation", "oracle", "--frame", "camera"])
    assert res.exit_code != 0
    assert "2 of 3 scans written, 1 failed" in res.output
    assert f"{batch / 'c' / 'depth.png'}: file not found" in res.output
    assert not (batch / "c" / "reconstruction.step").exists()
    assert [p.name for p in batch.rglob("*tmp*")] == []  # atomic writes: nothing half-written left over
    for name in ("a", "b"):
        step_path = batch / name / "reconstruction.step"
        back = read_typed(step_path)
        assert [f.surface for f in back.faces] == ["plane"]
        assert back.edges and all(e.type is not None for e in back.edges)
        for e in back.edges:
            assert e.type is e.layer_type is e.color_type
            assert e.color == pytest.approx(EDGE_COLORS[e.type], abs=1e-3)
        # camera frame, millimetres: the plane of the scan's ground truth (noise-free depth)
        point, normal = _plane_of(step_path)
        assert abs(abs(normal @ TINY.plane_normal) - 1.0) < 1 - np.cos(np.deg2rad(1.0))
        assert abs((point - TINY.plane_point * 1000.0) @ TINY.plane_normal) < 1.0
        # extras next to the STEP
        vb = VBRep.load(batch / name / "reconstruction.vbrep.json")
        assert len(vb.faces) == 1 and vb.faces[0].primitive["type"] == "plane"
        assert (batch / name / "reconstruction.png").stat().st_size > 0


def test_single_bad_scan_fails_with_the_loader_message_and_writes_nothing(batch: Path) -> None:
    before = listing(batch)
    res = _run([str(batch / "c"), "--segmentation", "oracle"])
    assert res.exit_code == 1
    assert f"{batch / 'c' / 'depth.png'}: file not found" in res.output
    assert listing(batch) == before


def test_output_file_and_no_extras(tmp_path: Path) -> None:
    """-o names the STEP of one scan; --no-extras writes nothing else. Part frame (default): the origin is the
    footprint origin, so the geometry's bounding box is centred in X and Y and starts at Z = 0."""
    scan = write_tiny_scan(tmp_path / "scan", gt=True)
    before = listing(scan)
    out = tmp_path / "out" / "plane.step"
    res = _run([str(scan), "--segmentation", "oracle", "-o", str(out), "--no-extras"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in out.parent.iterdir()) == ["plane.step"]
    assert listing(scan) == before
    back = read_typed(out)
    assert back.products == ["scan"] and [f.surface for f in back.faces] == ["plane"]
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(back.shape, box, False, False)
    lo, hi = np.array(box.CornerMin().Coord()), np.array(box.CornerMax().Coord())
    np.testing.assert_allclose(lo[:2], -hi[:2], atol=1e-3)
    assert lo[2] == pytest.approx(0.0, abs=1e-3) and hi[2] > 1.0


def test_batch_into_an_output_folder(tmp_path: Path) -> None:
    root = tmp_path / "scans"
    write_tiny_scan(root / "a", gt=True)
    write_tiny_scan(root / "b", gt=True)
    out = tmp_path / "steps"
    res = _run([str(root / "a"), str(root / "b"), "--segmentation", "oracle", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "2 of 2 scans written." in res.output
    assert sorted(p.name for p in out.iterdir()) == [
        "a.png",
        "a.step",
        "a.vbrep.json",
        "b.png",
        "b.step",
        "b.vbrep.json",
    ]
