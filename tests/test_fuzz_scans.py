"""Fuzz suite of bad and odd scan folders (issue 20): every folder goes through the real `v2c` command group
(`v2c info`, and `v2c to-step` for the refused ones) and either fails with exit status 1 and ONE line
``error: <file>: <problem>`` naming the file and the problem, or is a legitimate variant that succeeds. Never a
traceback, and nothing written: not into the scan folder, not into the working folder, not outside the output
folder.

Each case starts from the tiny 64 x 48 scan of conftest (one tilted plane, exact ground truth) and breaks one
thing. The large-image cases write only a header: a 30000 x 30000 PNG must be refused from its first bytes.
"""

from __future__ import annotations

import json
import os
import shutil
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from v2c.cli import main as v2c_main

from conftest import TINY, camera_dict, tiny_depth_m, write_tiny_scan

H, W = TINY.height, TINY.width

#: Expected outcome: OK, or (the file named in the message, words of the problem).
OK = "ok"
Expect = str | tuple[str, str]


# ------------------------------------------------------------------------------------------------ helpers
def _png(path: Path, arr: np.ndarray) -> None:
    assert cv2.imwrite(str(path), arr)


def _png_header_only(path: Path, width: int, height: int, bit_depth: int = 8, color_type: int = 2) -> None:
    """A valid-looking PNG (IHDR, one small IDAT, IEND, correct CRCs) claiming width x height pixels."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)

    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, color_type, 0, 0, 0)
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(b"\0" * 4096)) + chunk(b"IEND", b"")
    )


def _truncate(path: Path, keep: float = 0.6) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])


def _camera(folder: Path, content: dict | str | bytes) -> None:
    p = folder / "camera.json"
    if isinstance(content, bytes):
        p.write_bytes(content)
    else:
        p.write_text(content if isinstance(content, str) else json.dumps(content))


def _K(**changes: float) -> list[list[float]]:
    K = TINY.K.copy()
    idx = {"fx": (0, 0), "skew": (0, 1), "cx": (0, 2), "fy": (1, 1), "cy": (1, 2)}
    for k, v in changes.items():
        K[idx[k]] = v
    return K.tolist()


def _cam_K(folder: Path, **changes: float) -> None:
    _camera(folder, dict(camera_dict(), K=_K(**changes)))


def _npy(folder: Path, arr: np.ndarray) -> None:
    (folder / "depth.png").unlink()
    np.save(folder / "depth.npy", arr, allow_pickle=True)


def _depth_m(folder: Path, depth: np.ndarray) -> None:
    """Replace depth.png by this float depth in metres (as depth.npy)."""
    _npy(folder, depth.astype(np.float32))


def _depth_units(folder: Path, units: np.ndarray) -> None:
    _png(folder / "depth.png", units.astype(np.uint16))


def _tiny_units() -> np.ndarray:
    return np.round(tiny_depth_m() / TINY.depth_scale).astype(np.uint16)


def _one_pixel(folder: Path) -> None:
    d = np.zeros((H, W), np.uint16)
    d[20, 30] = 6000
    _depth_units(folder, d)


def _scattered(folder: Path) -> None:
    d = np.zeros((H, W), np.uint16)
    d[::3, ::3] = _tiny_units()[::3, ::3]  # 352 readings, no two of them neighbours
    _depth_units(folder, d)


def _noise(folder: Path) -> None:
    rng = np.random.default_rng(0)
    _depth_units(folder, rng.uniform(3000, 15000, (H, W)))  # 0.3 .. 1.5 m, uniform: no surface at all


def _outliers(folder: Path) -> None:
    d = _tiny_units()
    d[30, 40] = 100  # one reading of 1 cm (100 x 0.1 mm), nearer than any depth camera: dropped with a note
    _depth_units(folder, d)


def _one_by_one(folder: Path) -> None:
    _png(folder / "color.png", np.full((1, 1, 3), 128, np.uint8))
    _depth_units(folder, np.full((1, 1), 6000))
    _camera(
        folder,
        {"width": 1, "height": 1, "K": [[1.0, 0, 0.0], [0, 1.0, 0.0], [0, 0, 1]], "depth_scale": TINY.depth_scale},
    )


def _faraway(folder: Path) -> None:
    _depth_m(folder, np.full((H, W), 19.0))  # 19 m, inside the depth range, but 20 m wide: not a part


def _nested(depth: int, key: str | None = None) -> str:
    """JSON nested ``depth`` lists deep: the whole document, or the value of ``key`` in a camera.json."""
    inner = "[" * depth + "]" * depth
    return inner if key is None else f'{{"width": {W}, "height": {H}, "depth_scale": 0.0001, "{key}": {inner}}}'


def _symlink_all(folder: Path) -> None:
    """color/depth/camera as symlinks to a copy kept elsewhere."""
    store = folder.parent / (folder.name + "_store")
    store.mkdir()
    for name in ("color.png", "depth.png", "camera.json"):
        (folder / name).rename(store / name)
        (folder / name).symlink_to(store / name)


def _rename(new_name: str) -> Callable[[Path], Path]:
    def f(folder: Path) -> Path:
        return folder.rename(folder.with_name(new_name))

    return f


def _fifo(folder: Path) -> None:
    (folder / "depth.png").unlink()
    os.mkfifo(folder / "depth.png")


def _read_only(folder: Path) -> None:
    for p in folder.rglob("*"):
        p.chmod(0o444 if p.is_file() else 0o555)
    folder.chmod(0o555)


def _jpeg_truncated(folder: Path) -> None:
    (folder / "color.png").unlink()
    rgb = np.random.default_rng(0).integers(0, 255, (H, W, 3), dtype=np.uint8)
    cv2.imwrite(str(folder / "color.jpg"), rgb)
    _truncate(folder / "color.jpg", 0.7)


def _flip_idat(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[data.find(b"IDAT") + 20] ^= 0xFF
    path.write_bytes(bytes(data))


# ------------------------------------------------------------------------------------------------ cases
#: (id, mutate(folder) [-> the folder to use], expected outcome, extra command-line arguments)
CASES: list[tuple[str, Callable[[Path], object] | None, Expect, list[str]]] = [
    # legitimate variants
    ("plain", None, OK, []),
    ("open3d-camera", lambda f: _camera(f, camera_dict("open3d")), OK, []),
    ("bop-camera", lambda f: _camera(f, camera_dict("bop")), OK, []),
    ("bop-file-camera", lambda f: _camera(f, camera_dict("bop-file")), OK, []),
    ("flat-K", lambda f: _camera(f, camera_dict("v2c-flat")), OK, []),
    ("camera-extra-keys", lambda f: _camera(f, dict(camera_dict(), distortion=[0.1, 0, 0, 0], model="x")), OK, []),
    ("camera-utf8-bom", lambda f: _camera(f, b"\xef\xbb\xbf" + json.dumps(camera_dict()).encode()), OK, []),
    ("depth-npy-float64", lambda f: _npy(f, tiny_depth_m()), OK, []),
    ("depth-npy-float16", lambda f: _npy(f, tiny_depth_m().astype(np.float16)), OK, []),
    ("depth-near-outlier", _outliers, OK, []),
    (
        "with-mask",
        lambda f: _png(f / "mask.png", np.pad(np.full((20, 30), 255, np.uint8), ((10, 18), (20, 14)))),
        OK,
        [],
    ),
    ("with-roi", None, OK, ["--roi", "10,5,40,30"]),
    ("non-ascii-folder", _rename("Ünïcødé_部品 scan"), OK, []),
    ("quotes-in-folder-name", _rename('it\'s a "scan"'), OK, []),
    ("symlinked-files", _symlink_all, OK, []),
    ("read-only-folder", _read_only, OK, []),
    ("max-pixels-raised", None, OK, ["--max-pixels", "5000"]),
    # missing, empty, truncated, corrupt
    ("missing-color", lambda f: (f / "color.png").unlink(), ("color.png", "not found"), []),
    ("missing-depth", lambda f: (f / "depth.png").unlink(), ("depth.png", "not found"), []),
    ("missing-camera", lambda f: (f / "camera.json").unlink(), ("camera.json", "not found"), []),
    ("empty-color", lambda f: (f / "color.png").write_bytes(b""), ("color.png", "empty file"), []),
    ("empty-depth", lambda f: (f / "depth.png").write_bytes(b""), ("depth.png", "empty file"), []),
    ("empty-camera", lambda f: _camera(f, ""), ("camera.json", "invalid JSON"), []),
    ("truncated-color", lambda f: _truncate(f / "color.png"), ("color.png", "truncated PNG"), []),
    ("truncated-depth", lambda f: _truncate(f / "depth.png", 0.9), ("depth.png", "truncated PNG"), []),
    (
        "depth-missing-last-byte",
        lambda f: (f / "depth.png").write_bytes((f / "depth.png").read_bytes()[:-1]),
        ("depth.png", "truncated PNG"),
        [],
    ),
    ("corrupt-color-crc", lambda f: _flip_idat(f / "color.png"), ("color.png", "CRC"), []),
    (
        "garbage-color",
        lambda f: (f / "color.png").write_bytes(b"GIF89a not what it says"),
        ("color.png", "not a PNG or JPEG"),
        [],
    ),
    ("truncated-jpeg", _jpeg_truncated, ("color.jpg", "truncated JPEG"), []),
    (
        "truncated-npy",
        lambda f: (_npy(f, tiny_depth_m()), _truncate(f / "depth.npy", 0.5)),
        ("depth.npy", "truncated"),
        [],
    ),
    (
        "garbage-npy",
        lambda f: (_npy(f, tiny_depth_m()), (f / "depth.npy").write_bytes(b"\x93NUMPY garbage")),
        ("depth.npy", "cannot read .npy"),
        [],
    ),
    ("object-npy", lambda f: _npy(f, np.array([[None, 1.0]], dtype=object)), ("depth.npy", "real-number"), []),
    ("both-depth-files", lambda f: np.save(f / "depth.npy", tiny_depth_m()), ("depth.npy", "keep one"), []),
    # sizes
    ("depth-size-mismatch", lambda f: _depth_units(f, np.full((H, W + 2), 6000)), ("depth.png", "differs"), []),
    (
        "mask-size-mismatch",
        lambda f: _png(f / "mask.png", np.full((H - 1, W), 255, np.uint8)),
        ("mask.png", "differs"),
        [],
    ),
    ("camera-size-mismatch", lambda f: _camera(f, camera_dict(size=(640, 480))), ("camera.json", "disagrees"), []),
    (
        "gt-faces-size",
        lambda f: (write_tiny_scan(f, gt=True), _png(f / "gt" / "faces.png", np.ones((H, W - 1), np.uint16))),
        ("faces.png", "differs"),
        [],
    ),
    # depth types and values
    ("depth-8bit", lambda f: _png(f / "depth.png", np.full((H, W), 100, np.uint8)), ("depth.png", "8-bit"), []),
    (
        "depth-3-channel",
        lambda f: _png(f / "depth.png", np.full((H, W, 3), 6000, np.uint16)),
        ("depth.png", "one channel"),
        [],
    ),
    ("color-16bit", lambda f: _png(f / "color.png", np.full((H, W, 3), 300, np.uint16)), ("color.png", "8-bit"), []),
    ("depth-all-zero", lambda f: _depth_units(f, np.zeros((H, W))), ("depth.png", "all depth values are zero"), []),
    ("depth-npy-all-zero", lambda f: _npy(f, np.zeros((H, W), np.float32)), ("depth.npy", "all depth values"), []),
    ("depth-all-65535", lambda f: _depth_units(f, np.full((H, W), 65535)), ("depth.png", "65535"), []),
    (
        "depth-npy-nan",
        lambda f: _npy(f, np.where(tiny_depth_m() > 0.61, np.nan, tiny_depth_m())),
        ("depth.npy", "non-finite"),
        [],
    ),
    ("depth-npy-inf", lambda f: _npy(f, np.full((H, W), np.inf)), ("depth.npy", "non-finite"), []),
    ("depth-npy-negative", lambda f: _npy(f, -tiny_depth_m()), ("depth.npy", "negative"), []),
    ("depth-npy-1e30", lambda f: _npy(f, np.full((H, W), 1e30)), ("depth.npy", "outside"), []),
    ("depth-npy-1e300", lambda f: _npy(f, np.full((H, W), 1e300)), ("depth.npy", "outside"), []),
    (
        "depth-npy-millimetres",
        lambda f: _npy(f, 1000.0 * tiny_depth_m()),
        ("depth.npy", "wrong depth_scale or unit"),
        [],
    ),
    ("depth-npy-int64", lambda f: _npy(f, _tiny_units().astype(np.int64)), ("depth.npy", "int64"), []),
    ("depth-npy-uint16", lambda f: _npy(f, _tiny_units()), ("depth.npy", "uint16"), []),
    ("depth-npy-bool", lambda f: _npy(f, tiny_depth_m() > 0), ("depth.npy", "bool"), []),
    ("depth-npy-3d", lambda f: _npy(f, np.ones((H, W, 2), np.float32)), ("depth.npy", "2-D"), []),
    (
        "depth-scale-micrometres",
        lambda f: _camera(f, dict(camera_dict(), depth_scale=1e-6)),
        ("depth.png", "outside"),
        [],
    ),
    ("one-pixel-depth", _one_pixel, ("depth.png", "one face"), []),
    ("one-by-one-image", _one_by_one, ("depth.png", "one face"), []),
    ("scattered-depth", _scattered, ("depth.png", "scattered"), []),
    ("pure-noise-depth", _noise, ("depth.png", "noise"), []),
    ("landscape-not-part", _faraway, ("depth.npy", "expected a part"), []),
    ("mask-empty", lambda f: _png(f / "mask.png", np.zeros((H, W), np.uint8)), ("mask.png", "marks no pixel"), []),
    (
        "mask-tiny",
        lambda f: _png(f / "mask.png", np.pad(np.full((3, 3), 255, np.uint8), ((20, H - 23), (20, W - 23)))),
        ("depth.png", "one face"),
        [],
    ),
    ("roi-outside", None, ("color.png", "outside the image"), ["--roi", f"10,10,{W + 1},20"]),
    ("roi-tiny", None, ("depth.png", "one face"), ["--roi", "10,10,15,15"]),
    # camera.json
    ("fx-1e-6", lambda f: _cam_K(f, fx=1e-6), ("camera.json", "fx"), []),
    ("fx-1e30", lambda f: _cam_K(f, fx=1e30), ("camera.json", "fx"), []),
    ("fy-1e30", lambda f: _cam_K(f, fy=1e30), ("camera.json", "fy"), []),
    ("fx-zero", lambda f: _cam_K(f, fx=0.0), ("camera.json", "non-positive focal length"), []),
    ("fx-ten-times-fy", lambda f: _cam_K(f, fx=600.0), ("camera.json", "differ by a factor"), []),
    ("skew-1e6", lambda f: _cam_K(f, skew=1e6), ("camera.json", "skew"), []),
    ("cx-1e6", lambda f: _cam_K(f, cx=1e6), ("camera.json", "cx"), []),
    ("cy-minus-1e6", lambda f: _cam_K(f, cy=-1e6), ("camera.json", "cy"), []),
    ("K-nan", lambda f: _cam_K(f, cx=float("nan")), ("camera.json", "non-finite"), []),
    (
        "K-strings",
        lambda f: _camera(f, dict(camera_dict(), K=[[str(x) for x in r] for r in TINY.K])),
        ("camera.json", "3x3 matrix"),
        [],
    ),
    (
        "K-booleans",
        lambda f: _camera(f, dict(camera_dict(), K=[[True, 0, 31.5], [0, True, 23.5], [0, 0, 1]])),
        ("camera.json", "3x3 matrix"),
        [],
    ),
    ("K-2x3", lambda f: _camera(f, dict(camera_dict(), K=TINY.K[:2].tolist())), ("camera.json", "not 3x3"), []),
    ("K-missing", lambda f: _camera(f, {"width": W, "height": H}), ("camera.json", "no intrinsics"), []),
    (
        "depth-scale-true",
        lambda f: _camera(f, dict(camera_dict(), depth_scale=True)),
        ("camera.json", "'depth_scale' = True"),
        [],
    ),
    (
        "depth-scale-string",
        lambda f: _camera(f, dict(camera_dict(), depth_scale="0.0001")),
        ("camera.json", "depth_scale"),
        [],
    ),
    (
        "depth-scale-null",
        lambda f: _camera(f, dict(camera_dict(), depth_scale=None)),
        ("camera.json", "depth_scale"),
        [],
    ),
    (
        "depth-scale-negative",
        lambda f: _camera(f, dict(camera_dict(), depth_scale=-0.001)),
        ("camera.json", "depth_scale"),
        [],
    ),
    (
        "depth-scale-units-per-metre",
        lambda f: _camera(f, dict(camera_dict(), depth_scale=1000)),
        ("camera.json", "units per metre"),
        [],
    ),
    ("width-true", lambda f: _camera(f, dict(camera_dict(), width=True)), ("camera.json", "'width'"), []),
    ("width-fraction", lambda f: _camera(f, dict(camera_dict(), width=64.5)), ("camera.json", "'width'"), []),
    ("camera-nested-100000", lambda f: _camera(f, _nested(100_000)), ("camera.json", "nested too deeply"), []),
    ("camera-K-nested-100000", lambda f: _camera(f, _nested(100_000, "K")), ("camera.json", "nested too deeply"), []),
    ("camera-array", lambda f: _camera(f, "[1, 2, 3]"), ("camera.json", "JSON object"), []),
    ("camera-not-utf8", lambda f: _camera(f, b'{"K": "\xff\xfe"}'), ("camera.json", "UTF-8"), []),
    (
        "camera-invalid-json",
        lambda f: _camera(f, '{"K": [[60, 0, 31.5], [0, 62, 23.5]'),
        ("camera.json", "invalid JSON"),
        [],
    ),
    (
        "gt-meta-nested",
        lambda f: (write_tiny_scan(f, gt=True), (f / "gt" / "meta.json").write_text(_nested(50_000))),
        ("meta.json", "nested too deeply"),
        [],
    ),
    # size limits: headers only, refused before decoding
    (
        "color-30000x30000",
        lambda f: _png_header_only(f / "color.png", 30000, 30000),
        ("color.png", "exceeds the limit"),
        [],
    ),
    (
        "depth-30000x30000",
        lambda f: _png_header_only(f / "depth.png", 30000, 30000, 16, 0),
        ("depth.png", "exceeds the limit"),
        [],
    ),
    (
        "mask-30000x30000",
        lambda f: _png_header_only(f / "mask.png", 30000, 30000, 8, 0),
        ("mask.png", "exceeds the limit"),
        [],
    ),
    (
        "npy-30000x30000-header",
        lambda f: (_npy(f, tiny_depth_m()), _npy_header_only(f / "depth.npy", 30000, 30000)),
        ("depth.npy", "exceeds the limit"),
        [],
    ),
    ("max-pixels-lowered", None, ("color.png", "--max-pixels 3072"), ["--max-pixels", "1000"]),
    # the file system
    (
        "color-is-a-folder",
        lambda f: ((f / "color.png").unlink(), (f / "color.png").mkdir()),
        ("color.png", "found a folder"),
        [],
    ),
    ("depth-is-a-fifo", _fifo, ("depth.png", "not a regular file"), []),
    (
        "camera-links-to-dev-zero",
        lambda f: ((f / "camera.json").unlink(), (f / "camera.json").symlink_to("/dev/zero")),
        ("camera.json", "not a regular file"),
        [],
    ),
    (
        "color-broken-symlink",
        lambda f: ((f / "color.png").unlink(), (f / "color.png").symlink_to(f / "nowhere.png")),
        ("color.png", "broken symlink"),
        [],
    ),
    (
        "depth-symlink-loop",
        lambda f: ((f / "depth.png").unlink(), (f / "depth.png").symlink_to(f / "depth.png")),
        ("depth.png", "cannot read"),
        [],
    ),
    ("scan-is-a-file", lambda f: (shutil.rmtree(f), f.write_text("x")), ("scan", "not a folder"), []),
    ("scan-missing", lambda f: shutil.rmtree(f), ("scan", "not found"), []),
]


def _npy_header_only(path: Path, h: int, w: int) -> None:
    header = {"descr": "<f4", "fortran_order": False, "shape": (h, w)}
    with open(path, "wb") as fp:
        np.lib.format.write_array_header_1_0(fp, header)
        fp.write(b"\0" * 1024)


BAD = [c for c in CASES if c[2] != OK]


def test_enough_cases() -> None:
    assert len(CASES) >= 60 and len(BAD) >= 50, (len(CASES), len(BAD))
    assert len({c[0] for c in CASES}) == len(CASES)


def _make(case: tuple, tmp_path: Path) -> Path:
    _, mutate, _, _ = case
    folder = write_tiny_scan(tmp_path / "scan")
    if mutate is not None:
        new = mutate(folder)
        if isinstance(new, Path):
            folder = new
    return folder


def _invoke(args: list[str], cwd: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.chdir(cwd)
    return CliRunner().invoke(v2c_main, args, catch_exceptions=False)


def _check_refusal(res, expect: tuple[str, str]) -> None:
    fname, problem = expect
    out = res.output
    assert "Traceback" not in out, out
    assert res.exit_code == 1, (res.exit_code, out)
    lines = out.strip().splitlines()
    assert len(lines) == 1, out
    assert lines[0].startswith("error: "), out
    assert fname in lines[0] and problem.lower() in lines[0].lower(), out


def _snapshot(folder: Path) -> dict[str, tuple[int, int, int]]:
    """Recursive {relative path: (mode, size, mtime_ns)} without following symlinks (broken ones included)."""
    out = {}
    for p in sorted(folder.rglob("*")) if folder.exists() else []:
        st = p.lstat()
        out[str(p.relative_to(folder))] = (st.st_mode, st.st_size, st.st_mtime_ns)
    return out


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_info(case, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = _make(case, tmp_path)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    before = _snapshot(tmp_path)
    res = _invoke(["info", str(folder), *case[3]], cwd, monkeypatch)
    assert _snapshot(tmp_path) == before  # nothing written anywhere
    if case[2] == OK:
        assert res.exit_code == 0, res.output
        assert "Traceback" not in res.output and "error" not in res.output.lower(), res.output
        assert f"{W} x {H} px" in res.output
    else:
        _check_refusal(res, case[2])


def test_info_notes_dropped_readings(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A single reading of 1 cm among the 3,072 plane readings at about 0.6 m is dropped as implausible (under
    the 1 % tolerated) and info says so."""
    folder = _make(next(c for c in CASES if c[0] == "depth-near-outlier"), tmp_path)
    res = _invoke(["info", str(folder)], tmp_path, monkeypatch)
    assert res.exit_code == 0, res.output
    assert "note: depth.png: 1 of 3072 readings" in res.output, res.output
    from v2c.scan import load_scan

    scan = load_scan(folder)
    assert scan.depth[30, 40] == 0.0 and float(scan.depth[scan.depth > 0].min()) > 0.5


@pytest.mark.parametrize("case", BAD, ids=[c[0] for c in BAD])
def test_to_step_refuses_and_writes_nothing(case, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    folder = _make(case, tmp_path)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    before = _snapshot(tmp_path)
    out = tmp_path / "out"
    res = _invoke(
        ["to-step", str(folder), "-o", str(out / "part.step"), "--segmentation", "oracle", *case[3]], cwd, monkeypatch
    )
    _check_refusal(res, case[2])
    assert not out.exists()
    assert _snapshot(tmp_path) == before


def _run_measured(args: list[str], cwd: Path, timeout: float = 300.0) -> tuple[int, str, float, float]:
    """Run ``python -m v2c ARGS`` in a child; (exit status, stdout+stderr, wall seconds, peak RSS in GB)."""
    import subprocess
    import sys

    probe = (
        "import resource, subprocess, sys, time; t = time.perf_counter(); "
        "r = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
        "dt = time.perf_counter() - t; "
        "print(r.stdout + r.stderr, end=''); "
        "print(f'@@ {r.returncode} {dt:.3f} {resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss}')"
    )
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    res = subprocess.run(
        [sys.executable, "-c", probe, sys.executable, "-m", "v2c", *args],
        check=True,
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    out, _, tail = res.stdout.rpartition("@@ ")
    rc, secs, kb = tail.split()
    return int(rc), out, float(secs), int(kb) / 2**20


@pytest.mark.parametrize("command", ["info", "to-step"])
def test_4000x3000_scan_is_refused_fast_and_small(command: str, tmp_path: Path) -> None:
    """A 4000 x 3000 scan (12 megapixels; it ran 25 min and wrote a 90 MB STEP before) is refused by its PNG
    header: exit 1, one line naming color.png, the size and --max-pixels, well under 60 s and 3 GB."""
    scan = tmp_path / "big"
    scan.mkdir()
    h, w = 3000, 4000
    u, v = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    _png(scan / "color.png", np.stack([u % 256, v % 256, (u + v) % 256], -1).astype(np.uint8))
    _png(scan / "depth.png", (600 + 0.01 * u + 0.02 * v).astype(np.uint16))
    (scan / "camera.json").write_text(
        json.dumps(
            {"width": w, "height": h, "depth_scale": 0.001, "K": [[3000.0, 0, 2000.0], [0, 3000.0, 1500.0], [0, 0, 1]]}
        )
    )
    before = _snapshot(tmp_path)
    args = [command, str(scan)] + (["-o", str(tmp_path / "out") + "/"] if command == "to-step" else [])
    rc, out, secs, gb = _run_measured(args, tmp_path)
    assert rc == 1, out
    lines = out.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in out, out
    assert lines[0].startswith("error: ") and "color.png" in lines[0] and "4000x3000" in lines[0], out
    assert "--max-pixels 12000000" in lines[0], out
    assert secs < 60.0 and gb < 3.0, (secs, gb)
    assert _snapshot(tmp_path) == before


#: Legitimate variants that also run the whole pipeline (`to-step`, oracle segmentation on the tiny scan with gt/).
TO_STEP_OK = ["plain", "open3d-camera", "depth-npy-float64", "non-ascii-folder", "symlinked-files", "read-only-folder"]


@pytest.mark.parametrize("name", TO_STEP_OK)
def test_to_step_on_legitimate_variants_writes_only_the_output_set(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    case = next(c for c in CASES if c[0] == name)
    folder = write_tiny_scan(tmp_path / "scan", gt=True)
    if case[1] is not None:
        new = case[1](folder)
        folder = new if isinstance(new, Path) else folder
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    out = tmp_path / "out"
    before = _snapshot(tmp_path)
    res = _invoke(["to-step", str(folder), "-o", f"{out}/", "--segmentation", "oracle"], cwd, monkeypatch)
    assert res.exit_code == 0 and "Traceback" not in res.output, res.output
    stem = folder.name
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{stem}{s}" for s in (".png", ".step", ".vbrep.json"))
    after = {k: v for k, v in _snapshot(tmp_path).items() if not k.startswith("out")}
    assert after == before  # the scan, its symlink targets and the working folder are untouched


#: `v2c fixture` also takes a VB-Rep JSON or a STEP: (file name, content, words of the problem).
FIXTURE_INPUTS = [
    ("deep.vbrep.json", "[" * 100_000 + "]" * 100_000, "nested too deeply"),
    ("other.json", '{"a": 1}', "format version"),
    ("broken.json", '{"format": "v2c.vbrep", ', "not a valid VB-Rep JSON"),
    ("garbage.step", "ISO-10303-21;\nHEADER;\nnonsense", "not a readable STEP file"),
    ("empty.step", "", "not a readable STEP file"),
]


@pytest.mark.parametrize("name,content,problem", FIXTURE_INPUTS, ids=[c[0] for c in FIXTURE_INPUTS])
def test_fixture_refuses_bad_inputs(
    name: str, content: str, problem: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    src = tmp_path / name
    src.write_text(content)
    before = _snapshot(tmp_path)
    res = _invoke(["fixture", str(src), "--kind", "corner"], tmp_path, monkeypatch)
    lines = [ln for ln in res.output.strip().splitlines() if "StepFile" not in ln]  # OCCT's own parser line
    assert res.exit_code == 1 and "Traceback" not in res.output, res.output
    assert len(lines) == 1 and lines[0].startswith(f"error: {src}") and problem in lines[0], res.output
    assert _snapshot(tmp_path) == before


@pytest.mark.parametrize("name", ["camera-nested-100000", "pure-noise-depth", "fx-1e30"])
def test_fixture_and_reconstruct_refuse_bad_scans(name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    case = next(c for c in CASES if c[0] == name)
    folder = _make(case, tmp_path)
    before = _snapshot(tmp_path)
    for args in (["fixture", str(folder), "--kind", "corner"], ["reconstruct", str(folder)], ["fit", str(folder)]):
        _check_refusal(_invoke(args, tmp_path, monkeypatch), case[2])
    assert _snapshot(tmp_path) == before
