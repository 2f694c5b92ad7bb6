"""The feature-based part generator (v2c/synth/features.py): every feature kind, stocks, labels, determinism, yield.

Each feature kind is applied to a known stock (a box, or a turned part for the kinds that need a cylinder) and the
faces it adds are read back from OCCT with the scan generator's own `occ.face_primitive`: a hole adds a cylinder of
the drawn radius, a fillet a cylinder or torus of the drawn radius, and volumes change by the exact amount the drawn
dimensions give. Rendered scans of feature parts carry the labels their faces' types and axes say.
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
import pytest
from build123d import Align, Box, Cylinder, Pos
from click.testing import CliRunner

from v2c.labels import axis_class, label_of
from v2c.synth import features as F
from v2c.synth import occ
from v2c.synth.families import (
    FAMILY_GROUPS,
    FEATURE_FAMILIES,
    LEAVE_OUT_FAMILIES,
    PROCEDURAL_FAMILIES,
    TRAIN_FAMILIES,
)

_BASE = (Align.CENTER, Align.CENTER, Align.MIN)
BOX = (80.0, 60.0, 30.0)  # mm
TOL = 1e-6  # mm: radii are stored exactly as drawn
#: Seeds tried per kind until the feature applies (some draws find no room and are skipped, as in a real part).
SEEDS = 40


def box_work() -> F.Work:
    return F.Work(F._as_solid(Box(*BOX, align=_BASE)), "test", 60.0)


def turned_work() -> F.Work:
    """A shaft with a shoulder: cylinders r 20 (z 0-30) and r 12 (z 30-60), a full top disc."""
    solid = Cylinder(20, 30, align=_BASE) + Pos(0, 0, 30) * Cylinder(12, 30, align=_BASE)
    return F.Work(F._as_solid(solid), "test", 40.0)


def surfaces(shape) -> list[dict]:
    """(type, params in mm) of every face, read with the scan generator's face_primitive."""
    return [occ.face_primitive(f, 1.0) for f in occ.faces_of(shape)]


def _key(s: dict) -> tuple:
    p = s["params"]
    if s["type"] == "torus":
        return ("torus", round(p["radius"], 6), round(p["minor_radius"], 6))
    if s["type"] in ("cylinder", "sphere"):
        return (s["type"], round(p["radius"], 6))
    if s["type"] == "cone":
        return ("cone", round(math.degrees(p["half_angle"]), 6))
    return (s["type"],)


def added(before: F.Work, after_shape) -> Counter:
    """Faces the feature added, by (type, radius...) key: after minus before (positive counts only)."""
    diff = Counter(_key(s) for s in surfaces(after_shape))
    diff.subtract(Counter(_key(s) for s in surfaces(before.shape)))
    return Counter({k: v for k, v in diff.items() if v > 0})


def has(new: Counter, kind: str, radius: float | None = None, count: int = 1, minor: float | None = None) -> bool:
    """`new` holds at least `count` faces of `kind` with the radius (and torus minor radius) within TOL."""
    n = 0
    for key, c in new.items():
        if key[0] != kind:
            continue
        if radius is not None and abs(key[1] - radius) > TOL:
            continue
        if minor is not None and abs(key[2] - minor) > TOL:
            continue
        n += c
    return n >= count


def apply_first(kind: str, stock) -> tuple[F.Work, F.Work, dict]:
    """(stock before, stock after, params) for the first seed on which `kind` applies."""
    for seed in range(SEEDS):
        before, after = stock(), stock()
        rec = F.apply_feature(after, kind, np.random.default_rng(seed))
        if rec is not None:
            assert F.shape_problem(after.shape) is None
            assert after.features == [kind] and after.params == [rec]
            return before, after, rec
    raise AssertionError(f"{kind} never applied in {SEEDS} seeds: {after.skipped}")


def test_at_least_ten_feature_kinds():
    assert len(F.FEATURE_KINDS) >= 10
    assert set(F.FEATURES) == set(F.FEATURE_KINDS)


@pytest.mark.parametrize("kind", [k for k in F.FEATURE_KINDS if k not in ("groove", "dome", "ball_end")])
def test_feature_on_box(kind: str):
    before, after, p = apply_first(kind, box_work)
    new = added(before, after.shape)
    dv = F.volume(after.shape) - F.volume(before.shape)
    L, W, _ = BOX
    if kind == "through_hole":
        assert has(new, "cylinder", p["radius"])
        # Through the whole box along a face normal: the removed volume is pi r^2 times a box side.
        t = -dv / (math.pi * p["radius"] ** 2)
        assert min(abs(t - s) for s in BOX) < 1e-6 * t
    elif kind == "blind_hole":
        r, d = p["radius"], p["depth"]
        assert has(new, "cylinder", r)
        tip = r / math.tan(math.radians(59.0)) if p["drill_point"] else 0.0
        if p["drill_point"]:
            assert has(new, "cone") and any(abs(k[1] - 59.0) < 1e-6 for k in new if k[0] == "cone")
        else:
            assert has(new, "plane")  # the hole's floor
        assert -dv == pytest.approx(math.pi * r * r * (d + tip / 3.0), rel=1e-6)
    elif kind == "counterbore":
        assert has(new, "cylinder", p["radius"]) and has(new, "cylinder", p["counterbore_radius"])
        assert has(new, "plane")  # the counterbore's annular floor
    elif kind == "countersink":
        assert has(new, "cylinder", p["radius"])
        assert any(k[0] == "cone" and abs(k[1] - 45.0) < 1e-6 for k in new)
    elif kind == "boss":
        assert has(new, "cylinder", p["radius"])
        assert dv == pytest.approx(math.pi * p["radius"] ** 2 * p["height"], rel=1e-6)
    elif kind == "pocket":
        a, b, rc, d = p["length"], p["width"], p["corner_radius"], p["depth"]
        assert has(new, "cylinder", rc, count=4)
        assert -dv == pytest.approx((a * b - (4 - math.pi) * rc * rc) * d, rel=1e-6)
    elif kind == "slot":
        w = p["width"]
        assert has(new, "cylinder", 0.5 * w, count=2)
        if not p["through"]:
            assert -dv == pytest.approx(((p["length"] - w) * w + math.pi * w * w / 4) * p["depth"], rel=1e-6)
    elif kind == "rib":
        assert dv == pytest.approx(p["length"] * p["thickness"] * p["height"], rel=1e-6)
        assert sum(c for k, c in new.items() if k[0] == "plane") >= 3
    elif kind == "step":
        other = W if p["axis"] == "X" else L
        assert -dv == pytest.approx(p["width"] * p["depth"] * other, rel=1e-6)
        assert len(occ.faces_of(after.shape)) == 8  # a box with one step: two faces more
    elif kind == "fillet":
        assert p["edge"] == "line"  # a box has only line edges: the blend is a cylinder of the drawn radius
        assert has(new, "cylinder", p["radius"])
    elif kind == "chamfer":
        assert p["edge"] == "line"
        assert len(occ.faces_of(after.shape)) == len(occ.faces_of(before.shape)) + 1
        assert dv < 0
    elif kind in ("linear_pattern", "circular_pattern"):
        per = 2 if p["of"] == "slot" else 1
        assert has(new, "cylinder", p["member_radius"], count=per * p["count"])
        assert (dv > 0) == (p["of"] == "boss")
    elif kind == "union":
        if p["primitive"] == "box":
            assert dv == pytest.approx(float(np.prod(p["size"])), rel=1e-6)
        else:
            assert has(new, "cylinder", p["radius"]) and dv > 0
    elif kind == "cut":
        assert dv < 0
        if p["primitive"] == "sphere":
            assert has(new, "sphere", p["radius"])
        elif p["primitive"] == "cylinder":
            assert has(new, "cylinder", p["radius"])
        else:
            assert has(new, "plane")
    else:
        raise AssertionError(f"no check for {kind}")


@pytest.mark.parametrize(
    "kind", ["groove", "dome", "ball_end", "fillet", "chamfer", "through_hole", "circular_pattern"]
)
def test_feature_on_turned_stock(kind: str):
    before, after, p = apply_first(kind, turned_work)
    new = added(before, after.shape)
    if kind == "groove":
        if p["shape"] == "round":
            assert has(new, "torus", p["radius"], minor=p["tube_radius"])
        else:
            assert has(new, "cylinder", p["radius"] - p["depth"])
    elif kind == "dome":
        assert p["sphere_radius"] > p["disc_radius"] and has(new, "sphere", p["sphere_radius"])
    elif kind == "ball_end":
        assert p["sphere_radius"] == p["disc_radius"] and has(new, "sphere", p["disc_radius"])
        assert not has(new, "plane")  # tangent: the disc is gone, no new flat
    elif kind == "fillet":
        if p["edge"] == "circle":
            assert has(new, "torus", minor=p["radius"])
        else:
            assert has(new, "cylinder", p["radius"])
    elif kind == "chamfer":
        assert has(new, "cone" if p["edge"] == "circle" else "plane")
    elif kind == "through_hole":
        assert has(new, "cylinder", p["radius"])
    elif kind == "circular_pattern":
        per = 2 if p["of"] == "slot" else 1
        assert has(new, "cylinder", p["member_radius"], count=per * p["count"])


def test_fillet_of_a_circle_edge_is_a_torus_of_the_drawn_radius():
    # Among the turned stock's edges, force a circle edge: the blend must be a torus with that minor radius.
    for seed in range(SEEDS):
        w = turned_work()
        rec = F.apply_feature(w, "fillet", np.random.default_rng(seed))
        if rec is not None and rec["edge"] == "circle":
            new = added(turned_work(), w.shape)
            assert has(new, "torus", minor=rec["radius"])
            return
    raise AssertionError("no circle-edge fillet in the seeds tried")


def test_hex_stock_has_six_side_planes_at_sixty_degrees():
    solid, _ = F.stock_polygon(np.random.default_rng(0), 6, 40.0, 50.0)
    assert F.shape_problem(solid.wrapped) is None
    faces = surfaces(solid.wrapped)
    assert len(faces) == 8 and all(s["type"] == "plane" for s in faces)
    sides = [np.asarray(s["params"]["normal"]) for s in faces if abs(s["params"]["normal"][2]) < 1e-9]
    assert len(sides) == 6
    angles = sorted(math.degrees(math.atan2(n[1], n[0])) % 360 for n in sides)
    steps = np.diff(angles + [angles[0] + 360])
    assert np.allclose(steps, 60.0, atol=1e-9)
    assert any(np.allclose(n, [0, -1, 0], atol=1e-12) for n in sides)  # one flat faces -Y (it rests on it lying)
    for s in faces:  # each side 20 mm (half the across-flats) from the axis, normals pointing out
        n, o = np.asarray(s["params"]["normal"]), np.asarray(s["params"]["origin"])
        if abs(n[2]) < 1e-9:
            assert float(n @ o) == pytest.approx(20.0, abs=1e-9)


def test_extruded_sketch_and_turned_stocks_are_valid_analytic_solids():
    for seed in range(8):
        rng = np.random.default_rng(seed)
        solid, info = F.stock_extrude(rng, 90.0, 50.0, 20.0)
        assert F.shape_problem(solid.wrapped) is None, info
        solid, info = F.stock_turned(rng, 3, (8, 30), (8, 30))
        assert F.shape_problem(solid.wrapped) is None, info
        assert {"plane", "cylinder"} <= set(F.face_types(solid.wrapped))


def test_deterministic_given_a_seed_in_rest_pose_with_records():
    for family in FEATURE_FAMILIES:
        a = F.make_feature_part(family, np.random.default_rng([3, 1]))
        b = F.make_feature_part(family, np.random.default_rng([3, 1]))
        assert a.info == b.info and a.family == b.family == family
        assert [_key(s) for s in surfaces(a.shape)] == [_key(s) for s in surfaces(b.shape)]
        assert np.array_equal(a.bbox[0], b.bbox[0]) and np.array_equal(a.bbox[1], b.bbox[1])
        # Rest pose of parts.py: on z = 0, bounding box centred on the Z axis; a valid solid of analytic faces.
        lo, hi = a.bbox
        assert abs(lo[2]) < 1e-9 and np.allclose(lo[:2], -hi[:2], atol=1e-9)
        assert F.shape_problem(a.shape) is None
        # The record: the kinds applied, in order, each with its drawn parameters.
        assert a.info["features"] == [p["kind"] for p in a.info["feature_params"]]
        assert set(a.info["features"]) <= set(F.FEATURE_KINDS)
    other = F.make_feature_part("feat_prismatic", np.random.default_rng([3, 2]))
    assert other.info != F.make_feature_part("feat_prismatic", np.random.default_rng([3, 1])).info


def test_valid_share_and_feature_records():
    report = F.measure(60, 11)
    assert report["valid_share"] >= 0.95, report
    # Parts hold several features each, of many kinds.
    assert report["mean_features"] >= 2.5
    assert len(report["kinds"]) >= 12


def test_family_lists():
    assert len(LEAVE_OUT_FAMILIES) == 3 and set(LEAVE_OUT_FAMILIES) <= set(FEATURE_FAMILIES)
    assert not set(TRAIN_FAMILIES) & set(LEAVE_OUT_FAMILIES)
    assert set(TRAIN_FAMILIES) | set(LEAVE_OUT_FAMILIES) == set(PROCEDURAL_FAMILIES) | set(FEATURE_FAMILIES)
    assert not set(FAMILY_GROUPS["features"]) & set(LEAVE_OUT_FAMILIES)
    # Today's default mix is unchanged: the six procedural families, in their order.
    from v2c.commands.synth import PROCEDURAL
    from v2c.synth.dataset import SynthConfig
    from v2c.synth.parts import FAMILIES

    assert SynthConfig().families == PROCEDURAL == PROCEDURAL_FAMILIES == tuple(FAMILIES)


def test_training_recipe_refuses_leave_out_families(tmp_path):
    from v2c.segment.train import generate_training_data

    with pytest.raises(ValueError, match="leave-out"):
        generate_training_data(tmp_path, recipe=((64, 48, "none", 1, 0, 0.0, ("feat_prismatic", "feat_hex")),))
    assert not any(tmp_path.iterdir())


# ---- through the scan generator ----------------------------------------------------------------------------------


def _synth(args: list[str]):
    from v2c.commands.synth import command

    return CliRunner().invoke(command, args, catch_exceptions=False)


def test_cli_families_groups_and_errors(tmp_path):
    from v2c.commands.synth import _parse_families

    assert _parse_families(None, None, None) is None  # default: today's mix, decided in the command
    assert _parse_families(None, None, "features") == FAMILY_GROUPS["features"]
    assert _parse_families(None, None, "leave-out,block") == (*LEAVE_OUT_FAMILIES, "block")
    result = _synth([str(tmp_path / "x"), "--families", "feat_nope", "--quiet"])
    assert result.exit_code == 2 and "unknown family feat_nope" in result.output
    assert not (tmp_path / "x").exists()


@pytest.fixture(scope="module")
def feature_scans(tmp_path_factory) -> list[Path]:
    out = tmp_path_factory.mktemp("feat")
    families = "feat_knob,feat_turned,feat_block,feat_hex"
    result = _synth(
        [
            str(out),
            "--n",
            "4",
            "--seed",
            "21",
            "--size",
            "160x120",
            "--noise",
            "none",
            "--families",
            families,
            "--quiet",
        ]
    )
    assert result.exit_code == 0, result.output
    return sorted(out.glob("scan_*"))


def test_scans_of_feature_parts_carry_exact_labels(feature_scans):
    seen_types: set[str] = set()
    for folder in feature_scans:
        meta = json.loads((folder / "gt" / "meta.json").read_text())
        prims = json.loads((folder / "gt" / "primitives.json").read_text())
        assert meta["family"] in FEATURE_FAMILIES
        assert meta["part"]["features"] == [p["kind"] for p in meta["part"]["feature_params"]]
        # The part rebuilt from the same draws: the scan's faces are its faces, type for type.
        rng = np.random.default_rng([21, meta["index"]])
        rng.integers(4)  # the scan's family draw
        part = F.make_feature_part(meta["family"], rng)
        assert part.info == meta["part"]
        assert sorted(F.face_types(part.shape)) == sorted(p["type"] for p in prims)
        scale_m = meta["part_size_m"] / float(np.max(part.bbox[1] - part.bbox[0]))  # metres per rest-pose mm
        # Every drawn sphere / torus / cylinder radius of a feature appears among the scan's primitives.
        radii = {p["type"]: [] for p in prims}
        for p in prims:
            radii[p["type"]].append(p["params"].get("minor_radius", p["params"].get("radius")))
        for rec in part.info["feature_params"]:
            if rec["kind"] in ("dome", "ball_end"):
                assert min(abs(r - rec["sphere_radius"] * scale_m) for r in radii["sphere"]) < 1e-9
            if rec["kind"] == "fillet":
                cands = radii.get("torus" if rec["edge"] == "circle" else "cylinder", [])
                assert min(abs(r - rec["radius"] * scale_m) for r in cands) < 1e-9
            if rec["kind"] in ("through_hole", "blind_hole", "counterbore", "countersink"):
                assert min(abs(r - rec["radius"] * scale_m) for r in radii["cylinder"]) < 1e-9
        # Labels: every face pixel carries its face's type and axis class against axes_cam.
        faces = cv2.imread(str(folder / "gt" / "faces.png"), cv2.IMREAD_UNCHANGED)
        labels = cv2.imread(str(folder / "gt" / "labels.png"), cv2.IMREAD_UNCHANGED)
        axes = np.asarray(meta["axes_cam"])
        for p in prims:
            pix = faces == p["pixel_value"]
            if not pix.any():
                continue
            seen_types.add(p["type"])
            if p["type"] == "sphere":
                want = label_of("sphere", None)
            else:
                direction = p["params"]["normal"] if p["type"] == "plane" else p["params"]["axis"]
                want = label_of(p["type"], axis_class(np.asarray(direction), axes))
            assert p["label"] == want
            assert (labels[pix] == want).all()
    assert {"plane", "cylinder"} <= seen_types and seen_types & {"sphere", "torus", "cone"}
