"""Ground-truth VB-Reps for the tests: a true part's B-rep as the reconstruction would see it.

`vbrep_from_shape` turns a solid posed in the camera frame (millimetres, as gt/part.step) into a VB-Rep (metres):
the faces the camera sees (the given face indices, e.g. those of gt/faces.png, or else the faces with a triangle
facing the camera) with their analytic primitive, outward normal and mesh; every B-rep edge between two seen faces
as an ``intersection`` edge with its analytic curve (line or circle); every other edge of a seen face as a
``silhouette`` edge. Hidden-surface occlusion is not modelled beyond the face set.

`posed_part` places a part modelled in its own frame (millimetres, Z up, resting on Z = 0) in front of a camera.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np
from build123d import Shape, import_step
from OCP.BRep import BRep_Tool
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape, TopTools_IndexedMapOfShape

from fixtures_design.model import transformed
from fixtures_design.occ import M_PER_MM, edge_curve, face_mesh, face_primitive, faces_the_camera, occt_faces
from v2c.labels import axis_class
from v2c.vbrep.model import EdgeType, VBRep, VEdge, VertexKind, VFace, VVertex

from scenes.vbrep import K_DEFAULT, look_at, project


def vbrep_from_shape(
    shape: Shape,
    axes_cam: np.ndarray,
    visible: Iterable[int] | None = None,
    confidence: float = 0.95,
    part_size_m: float | None = None,
    deflection_mm: float = 0.2,
    curved: bool = False,
) -> VBRep:
    """A ground-truth VB-Rep of ``shape`` (camera frame, millimetres) seen from the camera at the origin.

    axes_cam: (3, 3) rows = the part's X, Y, Z axes in the camera frame (the VB-Rep's ``frame``).
    visible: 0-based ``TopExp_Explorer`` indices of the faces seen (gt/faces.png - 1); default: every planar or
    cylindrical face with a triangle facing the camera (with ``curved``, torus and cone faces too). Faces of other
    surface types are left out.
    confidence: given to every face and intersection edge. Returns a VB-Rep in metres.
    """
    BRepMesh_IncrementalMesh(shape.wrapped, deflection_mm, False, 0.3, True)
    occ = occt_faces(shape)
    seen = None if visible is None else {int(i) for i in visible}
    faces: list[VFace] = []
    face_of: dict[int, int] = {}  # OCCT face index -> VFace id
    fmap = TopTools_IndexedMapOfShape()
    for i, f in enumerate(occ):
        fmap.Add(f)
        v, t = face_mesh(f)
        prim = face_primitive(f, curved)
        if prim is None or (seen is not None and i not in seen) or (seen is None and not faces_the_camera(v, t)):
            continue
        d = np.asarray(prim["params"].get("normal", prim["params"].get("axis")), float)
        face_of[i] = len(faces)
        faces.append(VFace(len(faces), i + 1, prim, axis_class(d, axes_cam).value, [], v * M_PER_MM, t, confidence))
    emap = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape.wrapped, TopAbs_EDGE, TopAbs_FACE, emap)
    edges: list[VEdge] = []
    vertices: list[VVertex] = []
    for k in range(1, emap.Extent() + 1):
        edge = TopoDS.Edge_s(emap.FindKey(k))
        if BRep_Tool.Degenerated_s(edge):
            continue
        owners = sorted({fmap.FindIndex(f) - 1 for f in emap.FindFromIndex(k)})
        ids = tuple(face_of[o] for o in owners if o in face_of)
        if not ids:
            continue
        poly_mm, curve = edge_curve(edge)
        poly = poly_mm * M_PER_MM
        if len(ids) == 2:
            etype, conf = EdgeType.INTERSECTION, confidence
        else:
            etype, conf, curve = EdgeType.SILHOUETTE, 0.9, None
        v0 = len(vertices)
        closed = np.linalg.norm(poly[0] - poly[-1]) < 1e-9
        for p in poly[:1] if closed else (poly[0], poly[-1]):
            p = np.asarray(p).reshape(3)
            vertices.append(VVertex(len(vertices), VertexKind.OTHER, p, project(p)[0]))
        edges.append(VEdge(len(edges), etype, conf, ids, poly, v0, v0 if closed else v0 + 1, curve))
    pts = np.concatenate([f.mesh_vertices for f in faces]) if faces else np.zeros((1, 3))
    size = part_size_m if part_size_m is not None else float(np.ptp(pts @ np.asarray(axes_cam).T, axis=0).max())
    return VBRep(
        faces,
        edges,
        vertices,
        frame=np.asarray(axes_cam, float),
        K=K_DEFAULT.copy(),
        image_size=(640, 480),
        scale=size,
        meta={"source": "ground truth"},
    )


def posed_part(
    part: Shape, elevation_deg: float = 40.0, azimuth_deg: float = 30.0, distance_mm: float = 400.0
) -> tuple[Shape, np.ndarray]:
    """Place ``part`` (its own frame, mm, Z up) in the camera frame (mm) of a camera looking at its centre.

    The camera sits at ``distance_mm`` from the part's bounding-box centre, ``elevation_deg`` above the horizon,
    ``azimuth_deg`` around Z from +X. Returns (posed shape, axes_cam: rows = part X, Y, Z in the camera frame).
    """
    bb = part.bounding_box()
    target = np.array([bb.center().X, bb.center().Y, bb.center().Z])
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    eye = target + distance_mm * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    r = look_at(eye, target)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = -r @ eye
    return transformed(part, m), r.T.copy()


def load_step(path: str | Path) -> Shape:
    """A STEP file as one build123d shape (gt/part.step: camera frame, millimetres)."""
    return import_step(str(path))


def visible_faces_of_scan(faces_png: np.ndarray) -> Sequence[int]:
    """0-based face indices seen in a gt/faces.png array (uint16, 1 + face index, 0 = background)."""
    vals = np.unique(faces_png)
    return [int(v) - 1 for v in vals if v > 0]


def holed_block(size_mm: tuple[float, float, float] = (60.0, 40.0, 20.0), hole_d_mm: float = 10.0) -> Shape:
    """A block (its own frame, mm, resting on Z = 0, centred in X/Y) with a vertical through hole at X = -L/4."""
    from build123d import Box, Cylinder, Pos

    lx, ly, lz = size_mm
    block = Pos(0, 0, lz / 2) * Box(lx, ly, lz)
    return block - Pos(-lx / 4, 0, lz / 2) * Cylinder(hole_d_mm / 2, lz + 2)


def lying_rod(length_mm: float = 60.0, diameter_mm: float = 20.0) -> Shape:
    """A round rod (its own frame, mm) lying on Z = 0 with its axis along X, centred in X."""
    from build123d import Cylinder, Pos, Rot

    return Pos(0, 0, diameter_mm / 2) * Rot(0, 90, 0) * Cylinder(diameter_mm / 2, length_mm)


def vbrep_from_scan(scan_dir: str | Path, confidence: float = 0.95) -> tuple[VBRep, Shape]:
    """Ground-truth VB-Rep of a synthetic scan folder, and its true part (camera frame, mm).

    Reads gt/part.step (camera frame, millimetres), gt/faces.png (the faces seen) and gt/meta.json (``axes_cam``,
    ``part_size_m``).
    """
    import json

    import cv2

    gt = Path(scan_dir) / "gt"
    shape = load_step(gt / "part.step")
    faces_png = cv2.imread(str(gt / "faces.png"), cv2.IMREAD_UNCHANGED)
    if faces_png is None:
        raise FileNotFoundError(f"{gt / 'faces.png'}: missing or unreadable")
    meta = json.loads((gt / "meta.json").read_text())
    vb = vbrep_from_shape(
        shape,
        np.asarray(meta["axes_cam"], float),
        visible_faces_of_scan(faces_png),
        confidence,
        float(meta["part_size_m"]),
    )
    vb.meta["scan"] = str(scan_dir)
    return vb, shape


def synthetic_scan(out_dir: str | Path, family: str, seed: int, width: int = 320, height: int = 240) -> Path:
    """A small generated scan (`v2c.synth`) of one part family into ``out_dir/<family>_<seed>`` (reused if there)."""
    from v2c.synth.dataset import SynthConfig, generate_scan, scan_name

    folder = Path(out_dir) / f"{family}_{seed}"
    if (folder / scan_name(0) / "gt" / "meta.json").exists():
        return folder / scan_name(0)
    return generate_scan(folder, seed, 0, SynthConfig(width=width, height=height, families=(family,)))


def true_faces(vbrep: VBRep, truth_cam: Shape, m: np.ndarray) -> dict[int, Shape]:
    """VB-Rep face id -> the true part's face it is (ground-truth VB-Reps: instance = face index + 1), moved by
    the (4, 4) camera-mm -> output-mm transform ``m``."""
    from build123d import Face

    occ = occt_faces(truth_cam)
    return {f.id: transformed(Face(occ[f.instance - 1]), m) for f in vbrep.faces}
