"""The result figure of a reconstruction (like the paper's result figures), rendered with numpy and OpenCV.

Four panels: the input image, the segmentation, the VB-Rep seen from the camera and from a turned view. Face
meshes are drawn with the painter's algorithm (far triangles first), shaded by their normal; edges are coloured by
type (intersection blue, silhouette red, visibility cyan, occluded green); corners are drawn as white balls,
intersection-visibility vertices as magenta balls.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from v2c.vbrep.model import EdgeType, VBRep, VertexKind

if TYPE_CHECKING:
    from v2c.scan import Scan

#: sRGB edge colours by type (SCAN_FORMAT.md).
EDGE_COLORS: dict[EdgeType, tuple[int, int, int]] = {
    EdgeType.INTERSECTION: (30, 90, 255),
    EdgeType.SILHOUETTE: (235, 30, 30),
    EdgeType.VISIBILITY: (0, 220, 230),
    EdgeType.OCCLUDED: (30, 190, 60),
}
CORNER_COLOR = (250, 250, 250)
INT_VIS_COLOR = (230, 0, 230)
BACKGROUND = (255, 255, 255)


#: Depth (metres, along the viewing axis) under which a point counts as at or behind the viewer in a drawing.
MIN_VIEW_DEPTH_M = 1e-6


def palette(n: int, seed: int = 3) -> np.ndarray:
    """(n, 3) uint8 distinct pastel colours (fixed for a seed)."""
    rng = np.random.default_rng(seed)
    hues = (np.arange(n) * 0.618034 + rng.random()) % 1.0
    hsv = np.stack([hues * 179, np.full(n, 110), np.full(n, 235)], 1).astype(np.uint8)[None]
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)[0]


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    Kx = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * Kx + (1 - np.cos(angle)) * Kx @ Kx


def turned_view(vbrep: VBRep, turn_deg: float = 35.0, tilt_deg: float = 15.0) -> tuple[np.ndarray, np.ndarray]:
    """Rotation and translation (camera frame) of a view turned about the part's up axis (frame Z) through the
    centre of the meshes by ``turn_deg``, then tilted about the camera x axis by ``tilt_deg``: x' = R x + t."""
    V = [f.mesh_vertices for f in vbrep.faces if len(f.mesh_vertices)]
    c = np.concatenate(V).mean(0) if V else np.array([0.0, 0.0, 1.0])
    up = np.asarray(vbrep.frame, float)[2] if np.asarray(vbrep.frame).shape == (3, 3) else np.array([0, -1.0, 0])
    R = _rotation(np.array([1.0, 0, 0]), np.deg2rad(tilt_deg)) @ _rotation(up, np.deg2rad(turn_deg))
    return R, c - R @ c


def _fit_transform(uv: np.ndarray, size: tuple[int, int], margin: float = 0.08) -> tuple[float, np.ndarray]:
    w, h = size
    lo, hi = uv.min(0), uv.max(0)
    s = min((1 - 2 * margin) * w / max(hi[0] - lo[0], 1e-6), (1 - 2 * margin) * h / max(hi[1] - lo[1], 1e-6))
    off = np.array([w, h]) / 2 - s * (lo + hi) / 2
    return s, off


def render_vbrep(
    vbrep: VBRep,
    size: tuple[int, int] = (480, 480),
    R: np.ndarray | None = None,
    t: np.ndarray | None = None,
    crop: tuple[float, np.ndarray] | None = None,
    supersample: int = 2,
) -> np.ndarray:
    """(h, w, 3) uint8 RGB drawing of the VB-Rep seen by the scan's camera moved to x' = R x + t (camera frame,
    metres). crop: (scale, offset) mapping camera pixels to panel pixels; fitted to the geometry when None."""
    R = np.eye(3) if R is None else np.asarray(R, float)
    t = np.zeros(3) if t is None else np.asarray(t, float)
    K = np.asarray(vbrep.K, float)
    ss = supersample
    w, h = size[0] * ss, size[1] * ss

    def proj(x: np.ndarray) -> np.ndarray:
        y = np.asarray(x, float).reshape(-1, 3) @ R.T + t
        p = y @ K.T
        z = p[:, 2:3]
        # Points at or behind the viewer's plane have no image position: nan, left out of fitting and drawing.
        return np.where(z > MIN_VIEW_DEPTH_M, p[:, :2] / np.where(z > MIN_VIEW_DEPTH_M, z, 1.0), np.nan)

    all_pts = [f.mesh_vertices for f in vbrep.faces if len(f.mesh_vertices)]
    all_pts += [e.polyline for e in vbrep.edges]
    img = np.full((h, w, 3), BACKGROUND, np.uint8)
    if not all_pts:
        return cv2.resize(img, size, interpolation=cv2.INTER_AREA)
    if crop is None:
        px = proj(np.concatenate(all_pts))
        s, off = _fit_transform(px[np.isfinite(px).all(axis=1)], (w, h))
    else:
        s, off = crop[0] * ss, crop[1] * ss

    def to_px(x: np.ndarray) -> np.ndarray:
        return proj(x) * s + off

    cols = palette(max(1, len(vbrep.faces)))
    tri_pts, tri_col, tri_z = [], [], []
    for f in vbrep.faces:
        if len(f.mesh_triangles) == 0:
            continue
        V = np.asarray(f.mesh_vertices, float)
        T = np.asarray(f.mesh_triangles, np.int64)
        Vc = V @ R.T + t
        n = np.cross(Vc[T[:, 1]] - Vc[T[:, 0]], Vc[T[:, 2]] - Vc[T[:, 0]])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-15)
        centre = Vc[T].mean(1)
        view = -centre / np.linalg.norm(centre, axis=1, keepdims=True)
        shade = 0.35 + 0.65 * np.abs(np.einsum("ij,ij->i", n, view))
        tri_pts.append(to_px(V)[T])
        tri_col.append(shade[:, None] * cols[f.id % len(cols)][None].astype(float))
        tri_z.append(centre[:, 2])
    if tri_pts:
        P = np.concatenate(tri_pts)
        C = np.concatenate(tri_col).clip(0, 255).astype(np.uint8)
        # A point at or behind the viewer's plane projects to inf/nan: such triangles are not drawn.
        ok = np.isfinite(P).all(axis=(1, 2))
        order = [k for k in np.argsort(-np.concatenate(tri_z)) if ok[k]]
        Pi = np.rint(np.where(np.isfinite(P), P, 0.0) * 4).astype(np.int32)  # 2 fractional bits
        for k in order:
            cv2.fillConvexPoly(img, Pi[k], C[k].tolist(), lineType=cv2.LINE_8, shift=2)
    thick = max(1, 2 * ss)
    for etype in (EdgeType.OCCLUDED, EdgeType.SILHOUETTE, EdgeType.VISIBILITY, EdgeType.INTERSECTION):
        for e in vbrep.edges:
            if EdgeType(e.type) is etype and len(e.polyline) >= 2:
                q = to_px(e.polyline)
                q = np.rint(q[np.isfinite(q).all(axis=1)] * 4).astype(np.int32)
                if len(q) < 2:
                    continue
                cv2.polylines(img, [q], False, EDGE_COLORS[etype], thick, cv2.LINE_AA, shift=2)
    r = 4 * ss
    for v in vbrep.vertices:
        kind = VertexKind(v.kind)
        if kind not in (VertexKind.CORNER, VertexKind.INTERSECTION_VISIBILITY):
            continue
        c = to_px(v.position[None])[0]
        if not np.isfinite(c).all():
            continue
        c = tuple(int(x) for x in np.rint(c))
        col = CORNER_COLOR if kind is VertexKind.CORNER else INT_VIS_COLOR
        cv2.circle(img, c, r, (40, 40, 40), -1, cv2.LINE_AA)
        cv2.circle(img, c, r - ss, col, -1, cv2.LINE_AA)
        cv2.circle(img, (c[0] - r // 3, c[1] - r // 3), max(1, r // 3), (255, 255, 255), -1, cv2.LINE_AA)
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


def _crop_box(mask: np.ndarray, margin: int = 20) -> tuple[int, int, int, int]:
    vs, us = np.nonzero(mask)
    if len(us) == 0:
        return 0, 0, mask.shape[1], mask.shape[0]
    _h, _w = mask.shape
    side = max(us.max() - us.min(), vs.max() - vs.min()) + 2 * margin
    cu, cv_ = (us.min() + us.max()) / 2, (vs.min() + vs.max()) / 2
    x0, y0 = round(cu - side / 2), round(cv_ - side / 2)
    return x0, y0, x0 + int(side), y0 + int(side)


def _crop(img: np.ndarray, box: tuple[int, int, int, int], size: tuple[int, int]) -> np.ndarray:
    x0, y0, x1, y1 = box
    h, w = img.shape[:2]
    pad = max(0, -x0, -y0, x1 - w, y1 - h)
    if pad:
        img = cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=BACKGROUND)
    sub = img[y0 + pad : y1 + pad, x0 + pad : x1 + pad]
    return cv2.resize(sub, size, interpolation=cv2.INTER_AREA)


def segmentation_image(color: np.ndarray, instances: np.ndarray) -> np.ndarray:
    """Instances coloured over a dimmed image (RGB uint8)."""
    out = (0.35 * color.astype(float) + 0.65 * 255).astype(np.uint8)
    ids = np.unique(instances[instances > 0])
    cols = palette(int(instances.max()) + 1 if len(ids) else 1)
    m = instances > 0
    out[m] = cols[instances[m] % len(cols)]
    edges = cv2.morphologyEx(instances.astype(np.float32), cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    out[edges & m] = (60, 60, 60)
    return out


def _title(panel: np.ndarray, text: str) -> np.ndarray:
    bar = np.full((34, panel.shape[1], 3), 255, np.uint8)
    cv2.putText(bar, text, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.65, (20, 20, 20), 1, cv2.LINE_AA)
    return np.concatenate([bar, panel])


def _legend(width: int) -> np.ndarray:
    """Edge colours and vertex balls, wrapped onto as many rows as the width needs."""
    items = [(t.value, EDGE_COLORS[t], "line") for t in EdgeType] + [
        ("corner", CORNER_COLOR, "ball"),
        ("intersection-visibility vertex", INT_VIS_COLOR, "ball"),
    ]
    font, scale = cv2.FONT_HERSHEY_SIMPLEX, 0.5
    rows: list[list[tuple[str, tuple, str, int]]] = [[]]
    x = 12
    for name, col, kind in items:
        w = 34 + cv2.getTextSize(name, font, scale, 1)[0][0] + 18
        if x + w > width and rows[-1]:
            rows.append([])
            x = 12
        rows[-1].append((name, col, kind, x))
        x += w
    bar = np.full((30 * len(rows) + 6, width, 3), 255, np.uint8)
    for r, row in enumerate(rows):
        y = 18 + 30 * r
        for name, col, kind, x in row:
            if kind == "line":
                cv2.line(bar, (x, y), (x + 26, y), col, 4, cv2.LINE_AA)
            else:
                cv2.circle(bar, (x + 13, y), 7, (40, 40, 40), -1, cv2.LINE_AA)
                cv2.circle(bar, (x + 13, y), 6, col, -1, cv2.LINE_AA)
            cv2.putText(bar, name, (x + 34, y + 5), font, scale, (20, 20, 20), 1, cv2.LINE_AA)
    return bar


def result_figure(
    scan: Scan,
    instances: np.ndarray,
    vbrep: VBRep,
    path: str | Path | None = None,
    panel: int = 420,
    source: str = "VB-Rep",
) -> np.ndarray:
    """The 2 x 2 result figure (RGB uint8): input image, segmentation, VB-Rep from the camera and from a turned
    view, with a legend. scan: the scan (its ``color``, (H, W, 3) RGB, is drawn); instances: (H, W) int instance map.
    source: what the lower panels show, in their titles ("VB-Rep", or "STEP" when ``vbrep`` is the written file
    read back, `exporters.readback`).
    Written as PNG to ``path`` when given."""
    color = np.asarray(scan.color)
    mask = np.asarray(instances) > 0
    box = _crop_box(mask)
    size = (panel, panel)
    side = box[2] - box[0]
    s = panel / max(side, 1)
    crop = (s, np.array([-box[0] * s, -box[1] * s]))
    p1 = _crop(color, box, size)
    p2 = _crop(segmentation_image(color, np.asarray(instances)), box, size)
    p3 = render_vbrep(vbrep, size, crop=crop)
    R, t = turned_view(vbrep)
    p4 = render_vbrep(vbrep, size, R, t)
    top = np.concatenate([_title(p1, "input"), _title(p2, "segmentation")], 1)
    bottom = np.concatenate([_title(p3, f"{source} (camera view)"), _title(p4, f"{source} (turned view)")], 1)
    fig = np.concatenate([top, bottom, _legend(top.shape[1])], 0)
    if path is not None:
        import io

        from PIL import Image, PngImagePlugin

        from v2c.io_safe import v2c_origin, write_bytes_atomic

        info = PngImagePlugin.PngInfo()
        info.add_text("Software", v2c_origin())  # the mark by which v2c knows the file as its own
        buf = io.BytesIO()
        Image.fromarray(fig).save(buf, "PNG", pnginfo=info, compress_level=6)
        write_bytes_atomic(Path(path), buf.getvalue())  # exclusive temporary in the folder, renamed into place
    return fig
