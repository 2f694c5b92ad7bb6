"""`v2c bench --real DIR`: the pipeline on the real RGB-D frames of ``DIR`` (../shared/data/real), each with the
region of interest of ``real_rois.json`` around one box or can, measured against what is known of the objects.

Per frame and segmentation method (``learned``, ``geometric``):

- ``faces``: faces of the STEP file as written and read back (`exporters.step.read_typed`), and
  ``faces_per_side``: that count over the object's visible surfaces (``visible_sides`` of real_rois.json, counted
  by eye on color.png: a box shows 3 sides in every frame here, a can its side and top). Faces of other objects
  inside the ROI (the cracker box's ROI holds the mustard bottle and the soup can) count too. The summary's
  ``faces_per_side`` averages it over the box and can frames, ``faces_per_box_side`` over the box frames alone
  (issue 17's figure). ``surfaces``: the VB-Rep faces the file holds (the face ids of the STEP names): a face
  whose bounded region is in pieces is written as one STEP face per piece, which ``faces`` counts each.
- ``box``: ``largest_two_deg``, the angle (degrees) between the normals of the two largest planar faces (VB-Rep
  mesh area) of distinct directions (a plane within 20 degrees of a larger one is a piece of the same side: printed
  art splits sides into parallel pieces, which ``faces_per_side`` counts); ``largest_two_raw_deg`` the same for
  the two largest planes whatever their direction; and `box_angles` (the three largest planes of distinct
  directions, their largest deviation from 90 degrees).
- ``can``: the radius of the largest cylindrical face (`can_radius`) against the published size.
- ``depth_rms_mm``: RMS distance (mm) from the points of the pixels with depth that the segmentation assigned to
  fitted faces to their own face's surface (the unbounded primitive); ``depth_median_mm`` the median of the same
  distances. (Until 2026-11-27 the assigned pixels without depth counted too, as points at the camera centre:
  with a mask, 74-602 mm.)
- ``coverage_3mm``: the share of the object's depth pixels within ``near_mm`` (3 mm) of a face of the STEP file
  as written (camera frame, mm) and read back through OCCT. The object's pixels are *not* the segmentation's: they
  are the ROI's valid depth pixels standing more than `GeometricConfig.min_height_m` above the frame's RANSAC
  ground plane, every object in the ROI (`segment.geometric.part_region` with roi_one_object and roi_ground_margin
  off, as the segmenters took the ROI until 2026-11-29; a depth heuristic: no face assignment involved, so pixels
  the segmentation dropped count as misses). ``coverage_3mm_faces``: the same share over the pixels the
  segmentation assigned to faces. ``coverage_3mm_object``: the same share over the object pixels inside the
  frame's mask polygon (the object alone, neighbours that reach into a ROI left out; the same as
  ``coverage_3mm`` with ``mask``). ``coverage_3mm_object_supported`` (since 2026-12-01): the same share over the
  polygon's pixels whose reading stands above the plane the object rests on, the ground found around the ROI
  (`object_on_support`): the frame's ground above can be a floor far below the table, and then readings of the
  table inside the polygon counted as the object's (the tuna can: 129 of 3,184, a rim the sensor read past, 62 mm
  from the can's axis; 26-125 on the other frames).
  Distances: the read-back shape is tessellated (`synth.occ.tessellate`), each point's nearest mesh vertex
  (KD-tree) decides where it is clearly inside (< near) or clearly outside (> near + the longest triangle edge),
  and the exact point-to-triangle distance (trimesh) decides the rest.
- ``max_tolerance_mm``: the largest tolerance of any vertex or edge of the STEP read back
  (`exporters.readback.largest_tolerance`): the widest gap the file's topology joins.
- ``mask`` (``masks=True``, `v2c bench --real --real-masks`): a frame whose entry in real_rois.json has a ``mask``
  polygon (the object's outline drawn on color.png, occluders left out) is reconstructed with that polygon
  rasterised (`polygon_mask`) as its mask.png, inside its ROI; its object pixels are then the ROI's object pixels
  above (as for the ROI) inside the polygon. ``region`` of each row says which ("roi" or "mask").
- ``seconds``: wall time of load + reconstruction + STEP write (the read-back, figure and metrics are not
  counted), ``cpu_seconds`` the CPU time of this process over the same span (steadier on a shared machine);
  ``process_start_s`` (once per run): a fresh interpreter importing the pipeline and loading the model
  (`v2c.bench.workers.process_start_seconds`), so a frame from the command line costs ``seconds + process_start_s``.
"""

from __future__ import annotations

import json
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from v2c.bench.tables import jsonable
from v2c.bench.workers import error_text, precision_of, process_start_seconds

if TYPE_CHECKING:
    from v2c.fit.result import FitResult
    from v2c.pipeline import PipelineConfig
    from v2c.scan import Scan
    from v2c.vbrep.model import VBRep, VFace

#: The frames of the real-data bench with their regions of interest and what is known of their objects.
DEFAULT_ROIS = Path(__file__).with_name("real_rois.json")

#: Distance (mm) within which an object pixel counts as explained by a STEP face.
NEAR_MM = 3.0
#: Linear deflection (mm) of the tessellation of the read-back STEP.
DEFLECTION_MM = 0.2


def load_frames(path: Path = DEFAULT_ROIS) -> dict[str, dict[str, Any]]:
    """Frame folder name -> {"roi": [x0, y0, x1, y1] pixels, "object": "box" | "can", "name", "expected",
    "visible_sides"} of ``path``."""
    return json.loads(Path(path).read_text())["frames"]


def polygon_mask(vertices: list[list[float]], height: int, width: int) -> np.ndarray:
    """(height, width) bool: the pixels inside the polygon ``vertices`` ((x, y) pixels, as real_rois.json's
    ``mask``; pixel centres at integer coordinates), its outline included."""
    import cv2

    out = np.zeros((height, width), np.uint8)
    cv2.fillPoly(out, [np.round(np.asarray(vertices, float)).astype(np.int32).reshape(-1, 1, 2)], 1)
    return out.astype(bool)


def face_area(f: VFace) -> float:
    """Area of a face's mesh (square metres for a camera-frame VB-Rep): the sum of its triangles' areas."""
    V = np.asarray(f.mesh_vertices, float)
    T = np.asarray(f.mesh_triangles, np.int64).reshape(-1, 3)
    if len(T) == 0:
        return 0.0
    return float(0.5 * np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]), axis=1).sum())


def box_angles(vbrep: VBRep, n_planes: int = 3, distinct_deg: float = 20.0) -> dict[str, Any]:
    """Angles (degrees, in [0, 90]) between the normals of the ``n_planes`` largest planar faces (mesh area) of
    distinct directions (a face within ``distinct_deg`` of a larger one kept is a piece of the same box face, or
    parallel to it, and is skipped), and the largest deviation from 90 degrees over the pairs further than 45
    degrees from parallel (faces of one box corner)."""
    planes = sorted((f for f in vbrep.faces if f.primitive.get("type") == "plane"), key=face_area, reverse=True)
    normals = [np.asarray(f.primitive["params"]["normal"], float) for f in planes]
    normals = [n / np.linalg.norm(n) for n in normals]
    kept: list[int] = []
    for i, n in enumerate(normals):  # loop over planes, largest first
        if all(abs(float(n @ normals[k])) < np.cos(np.deg2rad(distinct_deg)) for k in kept):
            kept.append(i)
        if len(kept) == n_planes:
            break
    pairs = []
    for a in range(len(kept)):
        for b in range(a + 1, len(kept)):
            cos = abs(float(normals[kept[a]] @ normals[kept[b]]))
            pairs.append(
                {
                    "faces": [planes[kept[a]].id, planes[kept[b]].id],
                    "angle_deg": float(np.degrees(np.arccos(min(1.0, cos)))),
                }
            )
    corner = [p["angle_deg"] for p in pairs if p["angle_deg"] > 45.0]
    return {
        "plane_faces": len(planes),
        "pairs": pairs,
        "max_error_deg": float(max(abs(90.0 - a) for a in corner)) if corner else float("nan"),
    }


def can_radius(vbrep: VBRep) -> dict[str, Any]:
    """Radius (mm) of the largest cylindrical face (mesh area) and the number of cylindrical faces."""
    cyl = sorted((f for f in vbrep.faces if f.primitive.get("type") == "cylinder"), key=face_area, reverse=True)
    if not cyl:
        return {"cylinder_faces": 0, "radius_mm": float("nan")}
    return {
        "cylinder_faces": len(cyl),
        "radius_mm": 1000.0 * float(cyl[0].primitive["params"]["radius"]),
        "face": cyl[0].id,
    }


def step_mesh(step_path: Path, deflection_mm: float = DEFLECTION_MM) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) mm, triangles (m, 3)) of every face of the STEP at ``step_path`` read back through OCCT
    (`exporters.step.read_typed`), in the file's frame."""
    from exporters import read_typed
    from v2c.synth.occ import faces_of, tessellate

    shape = read_typed(step_path).shape
    fm = tessellate(shape, faces_of(shape), deflection_mm, 0.2)
    return fm.vertices, fm.triangles


def distances_to_mesh(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray, near: float) -> np.ndarray:
    """(N,) distances from ``points`` to the mesh (units of the inputs), each one exact or an upper bound, such
    that ``distance < near`` is exactly the true test: the nearest vertex (of the mesh subdivided to edges of at
    most near / 2) bounds the distance from above, and from below by its value minus the longest edge; points
    whose bounds straddle ``near`` go through trimesh's exact closest point."""
    import trimesh
    from scipy.spatial import cKDTree

    pts = np.asarray(points, float)
    if len(pts) == 0 or len(triangles) == 0:
        return np.full(len(pts), np.inf)
    # densify long triangles so that the vertex bound is tight (thin faces have long edges)
    v, t = trimesh.remesh.subdivide_to_size(vertices, triangles, max_edge=max(near / 2, 1e-9), max_iter=12)
    d_vert, _ = cKDTree(v).query(pts)
    edge = float(np.max(np.linalg.norm(v[t] - v[np.roll(t, 1, axis=1)], axis=2)))
    out = d_vert.copy()
    unsure = (d_vert >= near) & (d_vert - edge < near)
    if unsure.any():
        mesh = trimesh.Trimesh(v, t, process=False)
        _, d, _ = trimesh.proximity.closest_point(mesh, pts[unsure])
        out[unsure] = d
    return out


def _surface_distances(points: np.ndarray, inst: np.ndarray, fit: FitResult, valid: np.ndarray) -> np.ndarray:
    """Distances (m) of the face pixels' points to their own fitted primitive (camera frame); pixels without a
    depth reading (``valid`` False) have no point and are left out (an instance may hold such pixels: with a mask
    they join the nearest instance)."""
    out = []
    for i, prim in fit.primitives.items():
        m = (inst == i) & valid
        if m.any():
            out.append(np.abs(prim.signed_distance(points[m])))
    return np.concatenate(out) if out else np.zeros(0)


def measure_frame(
    folder: Path,
    spec: dict[str, Any],
    segmentation: str,
    out_dir: Path,
    near_mm: float = NEAR_MM,
    use_mask: bool = False,
    weights: Path | None = None,
    config: PipelineConfig | None = None,
) -> dict[str, Any]:
    """Reconstruct one frame with its ROI (and, with ``use_mask``, the ``mask`` polygon of ``spec`` as its
    mask.png), write its STEP (camera frame) and figure into ``out_dir``, read the STEP back and measure it (module
    docstring). ``weights``: the learned segmenter's weights file (None: the shipped one); ``config``: the pipeline's
    settings (`PipelineConfig`; None: the shipped ones). Raises whatever the pipeline raises."""
    from dataclasses import replace

    from exporters import result_figure, write
    from v2c import pipeline
    from v2c.bench.workers import segment_scan
    from v2c.scan import backproject, load_scan
    from v2c.segment.geometric import GeometricConfig, part_region

    use_mask = use_mask and bool(spec.get("mask"))
    stem = f"{folder.name}_{segmentation}" + ("_mask" if use_mask else "")
    out_dir.mkdir(parents=True, exist_ok=True)
    t0, c0 = time.perf_counter(), time.process_time()
    scan = load_scan(folder, roi=tuple(spec["roi"]))
    roi_scan = scan
    if use_mask:
        scan = replace(scan, mask=polygon_mask(spec["mask"], scan.height, scan.width))
    seg_in: Any = segment_scan(scan, segmentation, weights) if weights is not None else segmentation
    vbrep, seg, fit = pipeline.reconstruct(scan, segmentation=seg_in, config=config, return_stages=True)
    step_path = out_dir / f"{stem}.step"
    report = write(vbrep, step_path, frame="camera", product=stem)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    entry: dict[str, Any] = {
        "ok": True,
        "error": None,
        "region": "mask" if use_mask else "roi",
        "seconds": seconds,
        "cpu_seconds": cpu,
        "step": str(step_path),
        "stage_seconds": vbrep.meta.get("timings", {}),
        "warnings": list(report.warnings),
    }
    try:
        figure = out_dir / f"{stem}.png"
        result_figure(scan, seg.instances, vbrep, figure)
        entry["figure"] = str(figure)
    except Exception as exc:  # noqa: BLE001 - a figure is a convenience: the measurement stands without it
        entry["warnings"].append(f"figure not written ({error_text(exc)})")

    from exporters import read_typed
    from exporters.readback import largest_tolerance

    typed = read_typed(step_path)
    entry["max_tolerance_mm"] = largest_tolerance(typed.shape)  # the widest gap the file's topology joins
    n_sides = spec.get("visible_sides")
    entry["faces"] = len(typed.faces)
    entry["faces_per_side"] = len(typed.faces) / n_sides if n_sides else None
    # the VB-Rep faces the file holds (a face whose bounded region is in pieces is written as several faces)
    named = {f.id for f in typed.faces if f.id is not None}
    entry["surfaces"] = len(named) + sum(f.id is None for f in typed.faces)
    entry["face_types"] = {
        t_: sum(f.primitive.get("type") == t_ for f in vbrep.faces)
        for t_ in ("plane", "cylinder", "cone", "sphere", "torus")
    }
    if spec["object"] == "box":
        planes = sorted((f for f in vbrep.faces if f.primitive.get("type") == "plane"), key=face_area, reverse=True)
        box = box_angles(vbrep)
        # the two largest planes of distinct directions (box_angles' first pair): printed art splits a box side
        # into parallel pieces, counted by faces_per_side; the raw two largest planes are kept too
        box["largest_two_deg"] = box["pairs"][0]["angle_deg"] if box["pairs"] else float("nan")
        if len(planes) >= 2:
            n0, n1 = (np.asarray(f.primitive["params"]["normal"], float) for f in planes[:2])
            cos = abs(float(n0 @ n1) / (np.linalg.norm(n0) * np.linalg.norm(n1)))
            box["largest_two_raw_deg"] = float(np.degrees(np.arccos(min(1.0, cos))))
        else:
            box["largest_two_raw_deg"] = float("nan")
        entry["box"] = box
    else:
        can = can_radius(vbrep)
        exp = spec.get("expected", {}).get("radius_mm")
        if exp:
            can["error_pct"] = 100.0 * (can["radius_mm"] - float(exp)) / float(exp)
        entry["can"] = can

    pts = backproject(scan.depth, scan.K)
    inst = np.asarray(seg.instances)
    d_fit = _surface_distances(pts, inst, fit, scan.valid)
    entry["depth_rms_mm"] = float(1000 * np.sqrt(np.mean(d_fit**2))) if len(d_fit) else float("nan")
    entry["depth_median_mm"] = float(1000 * np.median(d_fit)) if len(d_fit) else float("nan")

    # the depth heuristic of the ROI alone (ground plane estimated without the mask), then inside the mask
    # (the ruler as it was before the ROI path picked one object: every pixel above the frame's ground in the ROI)
    obj = part_region(roi_scan, GeometricConfig(roi_one_object=False, roi_ground_margin=0.0))[0]
    in_polygon = None  # the frame's mask polygon, rasterised (already the scan's mask with use_mask)
    if use_mask:
        in_polygon = scan.mask
        obj &= scan.mask
    elif spec.get("mask"):
        in_polygon = polygon_mask(spec["mask"], scan.height, scan.width)
    supported = object_on_support(roi_scan, in_polygon) if in_polygon is not None else None
    faces_px = (inst > 0) & scan.valid & np.isin(inst, list(fit.primitives))
    verts, tris = step_mesh(step_path)
    sel = obj | faces_px | (supported if supported is not None else False)
    d = distances_to_mesh(1000.0 * pts[sel], verts, tris, near_mm)
    dmap = np.full(inst.shape, np.inf)
    dmap[sel] = d
    entry["object_px"] = int(obj.sum())
    entry["coverage_3mm"] = float(np.mean(dmap[obj] < near_mm)) if obj.any() else float("nan")
    entry["coverage_3mm_faces"] = float(np.mean(dmap[faces_px] < near_mm)) if faces_px.any() else float("nan")
    on_object = obj & in_polygon if in_polygon is not None else None
    entry["coverage_3mm_object"] = (
        float(np.mean(dmap[on_object] < near_mm)) if on_object is not None and on_object.any() else float("nan")
    )
    entry["coverage_3mm_object_supported"] = (
        float(np.mean(dmap[supported] < near_mm)) if supported is not None and supported.any() else float("nan")
    )
    return entry


def object_on_support(roi_scan: Scan, polygon: np.ndarray) -> np.ndarray:
    """(H, W) bool: the pixels of ``polygon`` (the object's outline) whose reading stands more than
    `GeometricConfig.min_height_m` above the plane the object rests on, the ground found around the ROI
    (`segment.geometric.part_region` with its ROI band, every object of the ROI): the object's own readings. The
    frame's ground of ``coverage_3mm_object`` can be a floor far below the table, and then a reading of the table
    inside the polygon (a rim pixel that the sensor read past, 20 mm outside the tuna can) counts as the object's.
    ``roi_scan``: the scan with its ROI and without a mask."""
    from v2c.segment.geometric import GeometricConfig, part_region

    return part_region(roi_scan, GeometricConfig(roi_one_object=False))[0] & polygon


def real_bench(
    data_dir: Path,
    rois_path: Path = DEFAULT_ROIS,
    segmentations: tuple[str, ...] = ("learned",),
    out_dir: Path | None = None,
    progress: bool = True,
    start: bool = True,
    masks: bool = False,
    weights: Path | None = None,
    config: PipelineConfig | None = None,
) -> dict[str, Any]:
    """Every frame of ``rois_path`` found in ``data_dir``, with every segmentation method: `measure_frame`, a
    frame that fails reported with its error. ``start``: also measure the process start once; ``masks``: frames
    with a ``mask`` polygon are reconstructed and measured with it (module docstring); ``weights``: the learned
    segmenter's weights file (None: the shipped one); ``config``: the pipeline's settings (`PipelineConfig`, None:
    the shipped ones; its ``refine`` reaches the learned segmenter's checks only without ``weights``)."""
    from tqdm import tqdm

    frames_spec = load_frames(rois_path)
    out_dir = Path(out_dir) if out_dir else Path(tempfile.mkdtemp(prefix="v2c-real-"))
    out_dir.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    jobs = [(name, spec, m) for m in segmentations for name, spec in frames_spec.items()]
    for name, spec, method in tqdm(jobs, desc="real", unit="frame", disable=not progress):
        folder = Path(data_dir) / name
        row: dict[str, Any] = {
            "frame": name,
            "segmentation": method,
            "object": spec["object"],
            "name": spec.get("name"),
            "roi": spec["roi"],
            "expected": spec.get("expected", {}),
            "visible_sides": spec.get("visible_sides"),
        }
        rows.append(row)
        if not folder.is_dir():
            row.update(ok=False, error=f"{folder}: not found")
            continue
        t = time.perf_counter()
        try:
            row.update(measure_frame(folder, spec, method, out_dir, use_mask=masks, weights=weights, config=config))
        except Exception as exc:  # noqa: BLE001 - the report says which frame failed and why
            row.update(ok=False, error=error_text(exc), seconds=time.perf_counter() - t)
    summary = {m: _summary([r for r in rows if r["segmentation"] == m]) for m in segmentations}
    start_s = process_start_seconds(list(segmentations)) if start else float("nan")
    return jsonable(
        {
            "data_dir": str(data_dir),
            "segmentations": list(segmentations),
            "masks": masks,
            "weights": None if weights is None else str(weights),
            "network_precision": precision_of(segmentations),
            "out_dir": str(out_dir),
            "near_mm": NEAR_MM,
            "process_start_s": start_s,
            "frames": rows,
            "summary": summary,
        }
    )


def _summary(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in rows if r.get("ok")]
    boxes = [r for r in ok if r["object"] == "box"]
    cans = [r for r in ok if r["object"] == "can" and r["expected"].get("radius_mm")]

    def mean(v: list[float]) -> float:
        v = [x for x in v if x is not None and np.isfinite(x)]
        return float(np.mean(v)) if v else float("nan")

    return {
        "frames": len(rows),
        "failed": len(rows) - len(ok),
        "faces_per_side": mean([r["faces_per_side"] for r in ok if r.get("faces_per_side")]),
        # issue 17's figure: over the box frames alone
        "faces_per_box_side": mean([r["faces_per_side"] for r in boxes if r.get("faces_per_side")]),
        "box_angle_error_deg": mean([abs(90.0 - r["box"]["largest_two_deg"]) for r in boxes]),
        # over the cans that have a cylindrical face; `cans_without_cylinder` says how many have none (a mean over
        # the others alone would hide them)
        "can_radius_error_pct": mean([abs(r["can"].get("error_pct", float("nan"))) for r in cans]),
        "cans": len(cans),
        "cans_without_cylinder": sum(1 for r in cans if not r["can"].get("cylinder_faces")),
        "coverage_3mm": mean([r["coverage_3mm"] for r in ok]),
        "coverage_3mm_object": mean([r.get("coverage_3mm_object") for r in ok]),
        "coverage_3mm_object_supported": mean([r.get("coverage_3mm_object_supported") for r in ok]),
        "depth_rms_mm": mean([r["depth_rms_mm"] for r in ok]),
        "seconds_median": float(np.median([r["seconds"] for r in ok])) if ok else float("nan"),
        "cpu_seconds_median": float(np.median([r["cpu_seconds"] for r in ok])) if ok else float("nan"),
    }


def _f(v: Any, fmt: str = ".1f") -> str:
    return "" if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, fmt)


def format_table(report: dict[str, Any]) -> str:
    """Markdown table of `real_bench`, one row per frame and method, then a summary line per method."""
    lines = [
        (
            "| frame | object | seg. | faces | faces/side | measured | expected | depth RMS mm | "
            "within 3 mm (object / faces) | largest tolerance mm | s (CPU s) |"
        ),
        "| --- | --- | --- | ---: | ---: | --- | --- | ---: | ---: | ---: | ---: |",
    ]
    for r in report["frames"]:
        if not r.get("ok"):
            meas, exp = f"error: {r.get('error')}", ""
        elif r["object"] == "box":
            b = r["box"]
            meas = (
                f"two largest planes {_f(b['largest_two_deg'])} deg (3 planes: max error "
                f"{_f(b['max_error_deg'])}; any direction {_f(b.get('largest_two_raw_deg'))})"
            )
            exp = "90 deg"
        else:
            c = r["can"]
            rad = r["expected"].get("radius_mm")
            if not c.get("cylinder_faces"):
                meas = "no cylindrical face"
            else:
                meas = f"radius {_f(c['radius_mm'])} mm" + (f" ({_f(c.get('error_pct'), '+.1f')} %)" if rad else "")
            exp = f"{rad:.1f} mm" if rad else ""
        cov = f"{_f(100 * r['coverage_3mm'])} / {_f(100 * r['coverage_3mm_faces'])} %" if r.get("ok") else ""
        lines.append(
            f"| {r['frame']} | {r['object']} | {r['segmentation']} | {r.get('faces', '')} | "
            f"{_f(r.get('faces_per_side'))} | {meas} | {exp} | {_f(r.get('depth_rms_mm'), '.2f')} | "
            f"{cov} | {_f(r.get('max_tolerance_mm'), '.3g')} | {_f(r.get('seconds'))} ({_f(r.get('cpu_seconds'))}) |"
        )
    for m, s in report["summary"].items():
        lines.append("")
        where = " (mask polygons)" if report.get("masks") else ""
        lines.append(
            f"{m}{where}: {s['frames'] - s['failed']} of {s['frames']} frames ok; faces per visible side "
            f"{_f(s['faces_per_side'], '.2f')} (boxes {_f(s.get('faces_per_box_side'), '.2f')}); box angle error "
            f"{_f(s['box_angle_error_deg'])} deg; can "
            f"radius error {_f(s['can_radius_error_pct'])} % ({s['cans'] - s['cans_without_cylinder']} of {s['cans']} "
            f"cans with a cylindrical face); within {report['near_mm']:g} mm "
            f"{_f(100 * s['coverage_3mm'])} % (the object alone {_f(100 * s.get('coverage_3mm_object', float('nan')))} "
            f"%, its readings above its support "
            f"{_f(100 * s.get('coverage_3mm_object_supported', float('nan')))} %); "
            f"depth RMS {_f(s['depth_rms_mm'], '.2f')} mm; median "
            f"{_f(s['seconds_median'])} s ({_f(s['cpu_seconds_median'])} CPU s) per frame + "
            f"{_f(report['process_start_s'])} s process start"
        )
    return "\n".join(lines)
