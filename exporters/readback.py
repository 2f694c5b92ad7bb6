"""What the user got: a written STEP read back through OCCT and compared with the reconstruction it came from.

`check_written` reads the file (`exporters.xcaf.read_xcaf_step`), measures every face's area per VB-Rep face id
(all pieces of an outline-bounded face together), counts the edges without a type, and compares the file's
bounding box with the reconstruction's (the VB-Rep meshes in the file's frame). It also returns the file as a
drawable VB-Rep (`drawn`): its faces tessellated and its edges sampled, mapped back into the camera frame, so the
result figure shows what was written, not the VB-Rep it came from.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from OCP.BRepAdaptor import BRepAdaptor_Curve
from OCP.ShapeAnalysis import ShapeAnalysis_ShapeTolerance
from OCP.TopAbs import TopAbs_SHAPE
from OCP.TopoDS import TopoDS, TopoDS_Shape

from exporters.brep import bounding_box, drawn_area, face_area, face_triangulation
from exporters.brep_config import BrepConfig
from exporters.brep_outline import reconstructed_area
from exporters.frames import FrameMap
from exporters.occ_surfaces import make_surface
from exporters.step import faces_by_id, parse_edge_name, quiet_occt
from exporters.xcaf import read_xcaf_step
from v2c.vbrep.model import VBRep, VEdge, VFace


@dataclass(frozen=True)
class ReadbackConfig:
    """area_tol_rel: a face counts as written whole when its area in the file is within this fraction of its
    VB-Rep mesh area; box_tol_rel: the file's bounding box counts as the reconstruction's when each extent is
    within this fraction of the reconstruction's largest extent; deflection_rel, angle_rad: tessellation
    deflection of the drawn faces, as a fraction of the part size, and angle (radians): the STEP writer's round
    trip's (`BrepConfig.roundtrip_mesh_*`), so a face it let through is drawn whole here; edge_samples: points
    per drawn edge; max_stretch: mesh triangles this much larger on the surface than flat span two sheets of it
    and are no part of the reconstructed area (the writer's `BrepConfig.outline_max_stretch`)."""

    area_tol_rel: float = 0.02
    box_tol_rel: float = 0.10
    deflection_rel: float = BrepConfig.roundtrip_mesh_deflection_rel
    angle_rad: float = BrepConfig.roundtrip_mesh_angle_rad
    edge_samples: int = 24
    max_stretch: float = BrepConfig.outline_max_stretch


@dataclass(frozen=True)
class FaceArea:
    """One VB-Rep face: its reconstructed area (its mesh's region on its surface, `brep_outline.reconstructed_area`),
    the area of the faces named after it in the file, and the area of their triangulation by OCCT's mesher (what
    FreeCAD and any other viewer draw; mm²). None: not meshed."""

    id: int
    reconstructed: float
    written: float
    meshed: float | None = None

    @property
    def ratio(self) -> float:
        """Written / reconstructed area (1.0 for an empty mesh written empty, infinite for one written non-empty)."""
        if self.reconstructed > 0:
            return self.written / self.reconstructed
        return 1.0 if self.written == 0 else float("inf")


@dataclass
class Readback:
    """The comparison. faces: per VB-Rep face; n_edges / untyped_edges: edges of the file and those whose name
    carries no edge type; box_written / box_reconstructed: (lo, hi) mm in the file's frame; max_tolerance: the
    largest tolerance of any vertex or edge of the file (mm; OCCT's precision, 1e-7 mm, where every edge meets its
    faces and vertices exactly), a gap the file's topology bridges: two faces' edges meeting at a vertex this far
    apart; part_size: the reconstruction's size in the file (mm); drawn: the file as a VB-Rep
    in the camera frame (metres) for figures."""

    path: Path
    faces: list[FaceArea] = field(default_factory=list)
    n_edges: int = 0
    untyped_edges: int = 0
    box_written: tuple[np.ndarray, np.ndarray] | None = None
    box_reconstructed: tuple[np.ndarray, np.ndarray] | None = None
    max_tolerance: float = 0.0
    part_size: float = float("nan")
    drawn: VBRep | None = None
    config: ReadbackConfig = field(default_factory=ReadbackConfig)

    @property
    def max_tolerance_rel(self) -> float:
        """``max_tolerance`` in part sizes (NaN without a part size)."""
        return self.max_tolerance / self.part_size if self.part_size > 0 else float("nan")

    def off_faces(self) -> list[FaceArea]:
        """Faces whose written area is off their reconstructed area by more than ``area_tol_rel``, or that the
        mesher draws short of that (`unmeshed_faces`)."""
        tol = self.config.area_tol_rel
        return [f for f in self.faces if abs(f.written - f.reconstructed) > tol * f.reconstructed or self._short(f)]

    def unmeshed_faces(self) -> list[FaceArea]:
        """Faces in the file whose triangulation covers less than 1 - ``area_tol_rel`` of their area: a boundary
        wire OCCT's mesher refuses leaves the face without triangles, a hole in every viewer."""
        return [f for f in self.faces if self._short(f)]

    def _short(self, f: FaceArea) -> bool:
        """Whether OCCT's mesher draws face ``f`` short of 1 - ``area_tol_rel`` of its written area."""
        return f.meshed is not None and f.meshed < (1 - self.config.area_tol_rel) * f.written

    @property
    def area_share(self) -> float:
        """Written / reconstructed area over all faces."""
        total = sum(f.reconstructed for f in self.faces)
        return sum(min(f.written, f.reconstructed) for f in self.faces) / total if total > 0 else 1.0

    @property
    def box_ok(self) -> bool:
        """Whether the file's bounding box matches the reconstruction's within ``box_tol_rel``."""
        if self.box_written is None or self.box_reconstructed is None:
            return self.box_written is None and self.box_reconstructed is None
        ext_w = self.box_written[1] - self.box_written[0]
        ext_r = self.box_reconstructed[1] - self.box_reconstructed[0]
        return bool(np.all(np.abs(ext_w - ext_r) <= self.config.box_tol_rel * ext_r.max()))

    def box_inside(self, margin_rel: float = 0.05) -> bool:
        """Whether the file's bounding box lies inside the reconstruction's, padded by ``margin_rel`` of its
        largest extent on every side: nothing was written far from the part."""
        if self.box_written is None or self.box_reconstructed is None:
            return self.box_written is None
        lo, hi = self.box_reconstructed
        pad = margin_rel * float((hi - lo).max())
        return bool(np.all(self.box_written[0] >= lo - pad) and np.all(self.box_written[1] <= hi + pad))

    def summary(self) -> str:
        """One line: faces written whole, area share, untyped edges, bounding box."""
        off = self.off_faces()
        n_short = sum(self._short(f) for f in off)
        tol = 100 * self.config.area_tol_rel
        worst = sorted(off, key=lambda f: -abs(f.written - f.reconstructed))[:3]
        detail = ", ".join(f"f{f.id} {f.written:.0f} of {f.reconstructed:.0f} mm²" for f in worst)
        return (
            f"read back: {len(self.faces) - len(off)} of {len(self.faces)} faces within {tol:.0f} % of their "
            f"reconstructed area ({100 * self.area_share:.1f} % of the area written)"
            + (f", off: {detail}" if off else "")
            + (f", {n_short} not meshed by OCCT" if n_short else "")
            + f"; {self.untyped_edges} of {self.n_edges} edges untyped; bounding box "
            + ("matches" if self.box_ok else "differs from")
            + " the reconstruction's"
            + f"; largest tolerance {self.max_tolerance:.3g} mm ({100 * self.max_tolerance_rel:.2g} % of the part)"
        )


def largest_tolerance(shape: TopoDS_Shape) -> float:
    """The largest tolerance of any vertex, edge or face of ``shape`` (its units): how far apart the geometry its
    topology joins may lie (an edge's curve end off its vertex, an edge off a face's surface)."""
    if shape is None or shape.IsNull():
        return 0.0
    return float(ShapeAnalysis_ShapeTolerance().Tolerance(shape, 1, TopAbs_SHAPE))


def _inverse_points(fmap: FrameMap, p: np.ndarray) -> np.ndarray:
    """(N, 3) output millimetres -> camera-frame metres (the inverse of ``fmap.points``)."""
    return np.asarray(p, float) @ fmap.rotation / fmap.scale + fmap.origin


def _edge_points(edge: TopoDS.Edge, n: int) -> np.ndarray:
    c = BRepAdaptor_Curve(edge)
    ts = np.linspace(c.FirstParameter(), c.LastParameter(), n)
    return np.array([c.Value(float(t)).Coord() for t in ts])


def check_written(
    vbrep: VBRep,
    path: str | Path,
    fmap: FrameMap,
    config: ReadbackConfig | None = None,
) -> Readback:
    """Read the STEP at ``path`` (written from ``vbrep`` with the frame map ``fmap``) and compare; see the
    module doc."""
    cfg = config or ReadbackConfig()
    path = Path(path)
    with quiet_occt():
        rs = read_xcaf_step(path)
    out = Readback(path=path, config=cfg)
    size = max(fmap.length(vbrep.scale), 1.0)
    out.part_size = size
    out.max_tolerance = largest_tolerance(rs.shape)
    by_id = faces_by_id(rs.faces)
    written = {fid: sum(face_area(f) for f in fs) for fid, fs in by_id.items()}
    deflection = cfg.deflection_rel * size
    meshes = {fid: [face_triangulation(f, deflection, cfg.angle_rad) for f in fs] for fid, fs in by_id.items()}
    recon_pts = []
    for f in vbrep.faces:
        pts = fmap.points(np.asarray(f.mesh_vertices, float).reshape(-1, 3))
        if len(pts):
            recon_pts.append(pts)
        drawn = [drawn_area(g, deflection, cfg.angle_rad) for g in by_id.get(f.id, [])]
        try:
            surf = make_surface(f.primitive, fmap, f.mesh_vertices) if len(pts) else None
        except (KeyError, ValueError, TypeError):
            surf = None  # a face the writer could not give a surface either: its flat mesh area
        out.faces.append(
            FaceArea(
                f.id,
                reconstructed_area(surf, pts, f.mesh_triangles, cfg.max_stretch),
                written.get(f.id, 0.0),
                sum(drawn) if drawn else None,
            )
        )
    if recon_pts:
        allp = np.concatenate(recon_pts)
        out.box_reconstructed = (allp.min(0), allp.max(0))
    if rs.faces or rs.edges:
        out.box_written = bounding_box(rs.shape)
    out.n_edges = len(rs.edges)
    edges = []
    for e in rs.edges:
        _, etype, conf, sig, _ = parse_edge_name(e.name)
        if etype is None:
            out.untyped_edges += 1
            continue
        poly = _inverse_points(fmap, _edge_points(TopoDS.Edge_s(e.shape), cfg.edge_samples))
        edges.append(
            VEdge(
                id=len(edges),
                type=etype,
                confidence=conf,
                faces=(),
                polyline=poly,
                v0=-1,
                v1=-1,
                sigma_mm=sig,
            )
        )
    faces = []
    for f in vbrep.faces:
        parts = meshes.get(f.id, [])
        verts, tris, base = [], [], 0
        for p, t in parts:
            verts.append(_inverse_points(fmap, p))
            tris.append(t + base)
            base += len(p)
        faces.append(
            VFace(
                id=f.id,
                instance=f.instance,
                primitive=f.primitive,
                axis_label=f.axis_label,
                confidence=f.confidence,
                loops=[],
                mesh_vertices=np.concatenate(verts) if verts else np.zeros((0, 3)),
                mesh_triangles=np.concatenate(tris) if tris else np.zeros((0, 3), int),
            )
        )
    out.drawn = VBRep(
        faces=faces,
        edges=edges,
        vertices=list(vbrep.vertices),
        frame=vbrep.frame,
        K=vbrep.K,
        image_size=vbrep.image_size,
        scale=vbrep.scale,
        meta=dict(vbrep.meta),
    )
    return out
