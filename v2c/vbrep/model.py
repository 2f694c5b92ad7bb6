"""The view-centric B-rep (VB-Rep) data model and its JSON form.

A VB-Rep is what one RGB-D view shows of a part: bounded analytic faces, typed edges between them or against the
background, and vertices. Everything is in the camera frame (OpenCV: x right, y down, z forward), metres; pixel
coordinates are (u, v) = (column, row).

JSON layout (``FORMAT_VERSION`` 1)::

    {"format": "v2c.vbrep", "format_version": 1,
     "frame": 3x3, "K": 3x3, "image_size": [w, h], "scale": float, "meta": {...},
     "faces": [{"id", "instance", "primitive", "axis_label", "loops", "mesh_vertices", "mesh_triangles",
                "confidence", "sigma_mm"}, ...],
     "edges": [{"id", "type", "confidence", "faces", "polyline", "v0", "v1", "curve", "tangent",
                "confidence_raw", "sigma_mm"}, ...],
     "vertices": [{"id", "kind", "position", "pixel"}, ...]}

Arrays are nested lists; float arrays keep their exact values (JSON floats are written with ``repr`` precision),
so ``VBRep.load(x.save(p)) == x``. Numpy arrays inside ``curve`` dicts and ``meta`` are written as lists and come
back as lists of floats; ``curve`` values are read back as numpy arrays for the keys ``origin``, ``direction``,
``center`` and ``axis``.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

FORMAT_NAME = "v2c.vbrep"
FORMAT_VERSION = 1

#: Keys of an edge's ``curve`` dict that hold vectors (numpy arrays in memory, lists in JSON).
_CURVE_VECTOR_KEYS = ("origin", "direction", "center", "axis")


class EdgeType(str, Enum):  # noqa: UP042 - StrEnum would change str() and format() of members
    """What an edge of the view is: where two surfaces meet, where a curved surface turns away from the camera
    (normal orthogonal to the view ray), the near side of a depth jump, or the far (hidden-behind) side of one."""

    INTERSECTION = "intersection"
    VISIBILITY = "visibility"
    OCCLUDED = "occluded"
    SILHOUETTE = "silhouette"


class VertexKind(str, Enum):  # noqa: UP042 - as EdgeType
    """Corner = three surfaces meet; intersection-visibility = an intersection edge meets a visibility edge;
    occlusion = a vertex on a depth jump (split into an occluded and a silhouette copy); other = anything else."""

    CORNER = "corner"
    INTERSECTION_VISIBILITY = "intersection_visibility"
    OCCLUSION = "occlusion"
    OTHER = "other"


def _arr(x: Any, dtype: Any = np.float64, shape_tail: tuple[int, ...] = ()) -> np.ndarray:
    a = np.asarray(x, dtype=dtype)
    if a.size == 0 and shape_tail:
        a = a.reshape((0, *shape_tail))
    return a


def _eq_arr(a: np.ndarray, b: np.ndarray) -> bool:
    a = np.asarray(a)
    b = np.asarray(b)
    return a.shape == b.shape and bool(np.array_equal(a, b))


def _jsonable(x: Any) -> Any:
    """Recursively turn numpy arrays/scalars and enums into plain JSON values."""
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, Enum):
        return x.value
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    return x


def _deep_eq(a: Any, b: Any) -> bool:
    """Equality for nested dicts/lists that may hold numpy arrays."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return _eq_arr(np.asarray(a), np.asarray(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_deep_eq(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_deep_eq(x, y) for x, y in zip(a, b))
    return bool(a == b)


@dataclass(eq=False)
class VFace:
    """A bounded analytic face.

    primitive: ``{"type": "plane"|..., "params": {...}}`` (v2c.primitives to_dict form, camera frame, metres).
    loops: boundary loops as (edge id, reversed) pairs; the outer loop first.
    mesh_vertices: (n, 3) float camera-frame metres; mesh_triangles: (m, 3) int indices into mesh_vertices.
    confidence: [0, 1].
    sigma_mm: 1-sigma position error (millimetres) of the fitted surface along its normal at the face's observed
      points' centroid, from the fit's covariance and the depth noise (v2c.vbrep.uncertainty); None when unknown
      (a VB-Rep written before it existed).
    """

    id: int
    instance: int
    primitive: dict
    axis_label: str | None
    loops: list[list[tuple[int, bool]]] = field(default_factory=list)
    mesh_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    mesh_triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    confidence: float = 1.0
    sigma_mm: float | None = None

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, VFace):
            return NotImplemented
        return (
            self.id == other.id
            and self.instance == other.instance
            and _deep_eq(self.primitive, other.primitive)
            and self.axis_label == other.axis_label
            and [[(int(e), bool(r)) for e, r in lp] for lp in self.loops]
            == [[(int(e), bool(r)) for e, r in lp] for lp in other.loops]
            and _eq_arr(self.mesh_vertices, other.mesh_vertices)
            and _eq_arr(self.mesh_triangles, other.mesh_triangles)
            and self.confidence == other.confidence
            and self.sigma_mm == other.sigma_mm
        )

    def to_dict(self) -> dict:
        """JSON-ready form (arrays as lists, enums as their values)."""
        return {
            "id": int(self.id),
            "instance": int(self.instance),
            "primitive": _jsonable(self.primitive),
            "axis_label": self.axis_label,
            "loops": [[[int(e), bool(r)] for e, r in lp] for lp in self.loops],
            "mesh_vertices": np.asarray(self.mesh_vertices, np.float64).tolist(),
            "mesh_triangles": np.asarray(self.mesh_triangles, np.int64).tolist(),
            "confidence": float(self.confidence),
            "sigma_mm": None if self.sigma_mm is None else float(self.sigma_mm),
        }

    @classmethod
    def from_dict(cls, d: dict) -> VFace:
        """Inverse of `to_dict`."""
        return cls(
            id=int(d["id"]),
            instance=int(d["instance"]),
            primitive=d["primitive"],
            axis_label=d.get("axis_label"),
            loops=[[(int(e), bool(r)) for e, r in lp] for lp in d.get("loops", [])],
            mesh_vertices=_arr(d.get("mesh_vertices", []), np.float64, (3,)),
            mesh_triangles=_arr(d.get("mesh_triangles", []), np.int64, (3,)),
            confidence=float(d.get("confidence", 1.0)),
            sigma_mm=None if d.get("sigma_mm") is None else float(d["sigma_mm"]),
        )


@dataclass(eq=False)
class VEdge:
    """A typed edge.

    faces: the ids of the 1 or 2 faces it bounds (intersection edges: 2; others: 1).
    polyline: (K, 3) camera-frame metres, from vertex v0 to vertex v1 (v0 == v1 for a closed loop).
    curve: intersection edges' analytic curve, camera frame, metres:
      ``{"kind": "line", "origin": (3,), "direction": (3,)}`` |
      ``{"kind": "circle", "center": (3,), "axis": (3,), "radius": float}`` |
      ``{"kind": "intersection"}`` (general intersection of the two faces' surfaces; the polyline samples it);
      None for other edge types.
    tangent: an intersection edge where its two faces meet tangentially (G1: a fillet, a blend, a dome on a
      cylinder); its polyline runs along their line of contact.
    confidence: [0, 1], the calibrated probability that the edge's type is right (docs/vbrep.md, "Confidence").
    confidence_raw: the uncalibrated product of factors it was mapped from (v2c.vbrep.confidence); None in a
      VB-Rep written before calibration existed.
    sigma_mm: 1-sigma position error (millimetres) of the edge across its run, RMS over its samples, propagated
      from its faces' fit covariances and the depth noise (v2c.vbrep.uncertainty); None when unknown.
    """

    id: int
    type: EdgeType
    confidence: float
    faces: tuple[int, ...]
    polyline: np.ndarray
    v0: int
    v1: int
    curve: dict | None = None
    tangent: bool = False
    confidence_raw: float | None = None
    sigma_mm: float | None = None

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, VEdge):
            return NotImplemented
        return (
            self.id == other.id
            and EdgeType(self.type) == EdgeType(other.type)
            and self.confidence == other.confidence
            and tuple(int(f) for f in self.faces) == tuple(int(f) for f in other.faces)
            and _eq_arr(self.polyline, other.polyline)
            and self.v0 == other.v0
            and self.v1 == other.v1
            and _deep_eq(self.curve, other.curve)
            and bool(self.tangent) == bool(other.tangent)
            and self.confidence_raw == other.confidence_raw
            and self.sigma_mm == other.sigma_mm
        )

    def to_dict(self) -> dict:
        """JSON-ready form (arrays as lists, enums as their values)."""
        return {
            "id": int(self.id),
            "type": EdgeType(self.type).value,
            "confidence": float(self.confidence),
            "faces": [int(f) for f in self.faces],
            "polyline": np.asarray(self.polyline, np.float64).tolist(),
            "v0": int(self.v0),
            "v1": int(self.v1),
            "curve": _jsonable(self.curve),
            "tangent": bool(self.tangent),
            "confidence_raw": None if self.confidence_raw is None else float(self.confidence_raw),
            "sigma_mm": None if self.sigma_mm is None else float(self.sigma_mm),
        }

    @classmethod
    def from_dict(cls, d: dict) -> VEdge:
        """Inverse of `to_dict` (curve vectors back to arrays)."""
        curve = d.get("curve")
        if curve is not None:
            curve = {k: (np.asarray(v, np.float64) if k in _CURVE_VECTOR_KEYS else v) for k, v in curve.items()}
        return cls(
            id=int(d["id"]),
            type=EdgeType(d["type"]),
            confidence=float(d["confidence"]),
            faces=tuple(int(f) for f in d["faces"]),
            polyline=_arr(d["polyline"], np.float64, (3,)),
            v0=int(d["v0"]),
            v1=int(d["v1"]),
            curve=curve,
            tangent=bool(d.get("tangent", False)),
            confidence_raw=None if d.get("confidence_raw") is None else float(d["confidence_raw"]),
            sigma_mm=None if d.get("sigma_mm") is None else float(d["sigma_mm"]),
        )


@dataclass(eq=False)
class VVertex:
    """A vertex: position (3,) camera-frame metres; pixel (2,) its (u, v) image position."""

    id: int
    kind: VertexKind
    position: np.ndarray
    pixel: np.ndarray

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, VVertex):
            return NotImplemented
        return (
            self.id == other.id
            and VertexKind(self.kind) == VertexKind(other.kind)
            and _eq_arr(self.position, other.position)
            and _eq_arr(self.pixel, other.pixel)
        )

    def to_dict(self) -> dict:
        """JSON-ready form (arrays as lists, enums as their values)."""
        return {
            "id": int(self.id),
            "kind": VertexKind(self.kind).value,
            "position": np.asarray(self.position, np.float64).tolist(),
            "pixel": np.asarray(self.pixel, np.float64).tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> VVertex:
        """Inverse of `to_dict`."""
        return cls(
            id=int(d["id"]),
            kind=VertexKind(d["kind"]),
            position=np.asarray(d["position"], np.float64),
            pixel=np.asarray(d["pixel"], np.float64),
        )


@dataclass(eq=False)
class VBRep:
    """A view-centric B-rep.

    frame: (3, 3) rows = the recovered axis frame's X, Y, Z unit vectors in the camera frame.
    K: (3, 3) camera intrinsics (pixels). image_size: (w, h) pixels. scale: part size estimate (metres).
    meta: free-form JSON-able dict (e.g. ``meta["timings"]``: seconds per pipeline stage).
    Face/edge/vertex ids equal their index in the lists.
    """

    FORMAT_VERSION = FORMAT_VERSION

    faces: list[VFace] = field(default_factory=list)
    edges: list[VEdge] = field(default_factory=list)
    vertices: list[VVertex] = field(default_factory=list)
    frame: np.ndarray = field(default_factory=lambda: np.eye(3))
    K: np.ndarray = field(default_factory=lambda: np.eye(3))
    image_size: tuple[int, int] = (0, 0)
    scale: float = 1.0
    meta: dict = field(default_factory=dict)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, VBRep):
            return NotImplemented
        return (
            self.faces == other.faces
            and self.edges == other.edges
            and self.vertices == other.vertices
            and _eq_arr(self.frame, other.frame)
            and _eq_arr(self.K, other.K)
            and tuple(self.image_size) == tuple(other.image_size)
            and self.scale == other.scale
            and _deep_eq(self.meta, other.meta)
        )

    # ----------------------------------------------------------------- queries
    def edges_of_type(self, t: EdgeType | str) -> list[VEdge]:
        """The edges of type ``t``, in id order."""
        t = EdgeType(t)
        return [e for e in self.edges if EdgeType(e.type) is t]

    def vertices_of_kind(self, k: VertexKind | str) -> list[VVertex]:
        """The vertices of kind ``k``, in id order."""
        k = VertexKind(k)
        return [v for v in self.vertices if VertexKind(v.kind) is k]

    # -------------------------------------------------------------------- JSON
    def to_dict(self) -> dict:
        """JSON-ready form (arrays as lists, enums as their values)."""
        return {
            "format": FORMAT_NAME,
            "format_version": FORMAT_VERSION,
            "frame": np.asarray(self.frame, np.float64).tolist(),
            "K": np.asarray(self.K, np.float64).tolist(),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "scale": float(self.scale),
            "meta": _jsonable(self.meta),
            "faces": [f.to_dict() for f in self.faces],
            "edges": [e.to_dict() for e in self.edges],
            "vertices": [v.to_dict() for v in self.vertices],
        }

    @classmethod
    def from_dict(cls, d: dict) -> VBRep:
        """Inverse of `to_dict`; raises ValueError for another format."""
        if d.get("format", FORMAT_NAME) != FORMAT_NAME:
            raise ValueError(f"not a VB-Rep document (format {d.get('format')!r})")
        version = int(d.get("format_version", -1))
        if version != FORMAT_VERSION:
            raise ValueError(f"VB-Rep format version {version} is not supported (expected {FORMAT_VERSION})")
        w, h = d["image_size"]
        return cls(
            faces=[VFace.from_dict(f) for f in d["faces"]],
            edges=[VEdge.from_dict(e) for e in d["edges"]],
            vertices=[VVertex.from_dict(v) for v in d["vertices"]],
            frame=np.asarray(d["frame"], np.float64),
            K=np.asarray(d["K"], np.float64),
            image_size=(int(w), int(h)),
            scale=float(d["scale"]),
            meta=d.get("meta", {}),
        )

    def to_json(self, indent: int | None = None) -> str:
        """The `to_dict` form as JSON text."""
        return json.dumps(self.to_dict(), indent=indent)

    @classmethod
    def from_json(cls, text: str) -> VBRep:
        """Inverse of `to_json`."""
        return cls.from_dict(json.loads(text))

    def save(self, path: str | Path) -> Path:
        """Write the JSON (UTF-8) to ``path`` atomically (`v2c.io_safe`: an exclusive temporary in the same folder,
        renamed into place). Returns the path."""
        from v2c.io_safe import write_text_atomic

        return write_text_atomic(Path(path), self.to_json())

    @classmethod
    def load(cls, path: str | Path) -> VBRep:
        """Read a VB-Rep JSON file written by `save`."""
        path = Path(path)
        try:
            return cls.from_json(path.read_text(encoding="utf-8"))
        except RecursionError:
            raise ValueError(f"{path}: not a valid VB-Rep JSON (nested too deeply)") from None
        except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a valid VB-Rep JSON ({exc})") from exc
