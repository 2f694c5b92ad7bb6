"""Calibration of edge confidences: from the raw product of factors (v2c.vbrep.confidence) to the probability that
the edge's type is right.

What "right" means is the bench's matching (`v2c.bench.vbrep.edge_correctness`): at least half of the edge's
projected length lies within ``tol_px`` (3) pixels of ground-truth boundary records of the same type on the true
face(s) its faces cover. For an intersection edge: a true edge of the part, where two true surfaces meet, lies
within 3 px of it (about 1.5 mm at 0.6 m and a 55 degree field of view over 640 px).

The map is one isotonic (monotone non-decreasing) regression of right/wrong on the raw confidence per edge type,
fitted by pool-adjacent-violators (`isotonic_fit`) on training and validation scans only
(scripts/calibrate_confidence.py), stored as knots in ``confidence_calibration.json`` beside this module and
applied by linear interpolation between the knots (`CalibrationMap.apply`), clipped to [0, 1].

Also here: the expected calibration error (`expected_calibration_error`, equal-width bins) and a reliability
diagram drawn with OpenCV (`reliability_diagram`).
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from v2c.vbrep.model import EdgeType

#: The shipped calibration map (written by scripts/calibrate_confidence.py).
DEFAULT_MAP = Path(__file__).with_name("confidence_calibration.json")
FORMAT = "v2c.confidence_calibration"


def isotonic_fit(
    x: np.ndarray, y: np.ndarray, w: np.ndarray | None = None, min_block: float = 1.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted isotonic (non-decreasing) least-squares regression of ``y`` on ``x`` by pool-adjacent-violators.

    Returns knots (xk, yk, wk): each pooled block's weighted mean x, its value and its weight; xk strictly
    increasing, yk non-decreasing. Ties in x are pooled first (a function of x cannot give two values at one x),
    and so are neighbouring blocks of equal value. ``min_block``: a block lighter than this is pooled with the neighbour
    whose value is closer (pooling neighbours of a non-decreasing sequence keeps it non-decreasing), so that no
    knot rests on a handful of edges."""
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    w = np.ones_like(x) if w is None else np.asarray(w, float)
    if len(x) == 0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    order = np.lexsort((y, x))  # deterministic for ties
    x, y, w = x[order], y[order], w[order]
    ux, inv = np.unique(x, return_inverse=True)
    ws = np.bincount(inv, w)
    ys = np.bincount(inv, w * y) / ws
    xs = ux
    # blocks as stacks of (weighted sum of y, weight, weighted sum of x)
    sy, sw, sx = [], [], []
    for yi, wi, xi in zip(ys, ws, xs):
        sy.append(yi * wi)
        sw.append(wi)
        sx.append(xi * wi)
        while len(sy) > 1 and sy[-2] / sw[-2] >= sy[-1] / sw[-1]:
            b_y, b_w, b_x = sy.pop(), sw.pop(), sx.pop()
            sy[-1] += b_y
            sw[-1] += b_w
            sx[-1] += b_x
    while len(sw) > 1 and min(sw) < min_block:
        i = int(np.argmin(sw))
        if i == 0:
            j = 1
        elif i == len(sw) - 1:
            j = i - 1
        else:
            v = sy[i] / sw[i]
            j = i - 1 if abs(sy[i - 1] / sw[i - 1] - v) <= abs(sy[i + 1] / sw[i + 1] - v) else i + 1
        lo, hi = min(i, j), max(i, j)
        sy[lo] += sy.pop(hi)
        sw[lo] += sw.pop(hi)
        sx[lo] += sx.pop(hi)
    sw_a = np.asarray(sw)
    return np.asarray(sx) / sw_a, np.asarray(sy) / sw_a, sw_a


@dataclass
class CalibrationMap:
    """Per edge type, knots (x: raw confidence, y: probability right) of a monotone map; a type without knots
    keeps its raw value. ``meta``: how it was fitted (scans, counts, tolerance)."""

    knots: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    def apply(self, etype: EdgeType | str, raw: float | np.ndarray) -> float | np.ndarray:
        """Calibrated probability in [0, 1] for raw confidence(s) of an edge type; constant beyond the end knots."""
        k = self.knots.get(EdgeType(etype).value)
        r = np.asarray(raw, float)
        out = r if k is None or len(k[0]) == 0 else np.interp(r, k[0], k[1])
        out = np.clip(out, 0.0, 1.0)
        return float(out) if np.ndim(out) == 0 else out

    def to_dict(self) -> dict[str, Any]:
        """The JSON form of ``confidence_calibration.json`` (knots rounded to 6 decimals)."""
        return {
            "format": FORMAT,
            "format_version": 1,
            "meta": self.meta,
            "types": {
                t: {"x": [round(float(v), 6) for v in xk], "y": [round(float(v), 6) for v in yk]}
                for t, (xk, yk) in sorted(self.knots.items())
            },
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "calibration") -> CalibrationMap:
        """Inverse of `to_dict`; ValueError (naming ``source``) for another format, an unknown edge type or knots
        that are not monotone."""
        if d.get("format") != FORMAT:
            raise ValueError(f"{source}: format {d.get('format')!r}, expected {FORMAT!r}")
        knots = {}
        for t, k in d.get("types", {}).items():
            EdgeType(t)  # ValueError naming the bad type
            xk, yk = np.asarray(k["x"], float), np.asarray(k["y"], float)
            if len(xk) != len(yk) or np.any(np.diff(xk) <= 0) or np.any(np.diff(yk) < 0):
                raise ValueError(f"{source}: knots of {t!r} are not increasing in x and non-decreasing in y")
            knots[t] = (xk, yk)
        return cls(knots, dict(d.get("meta", {})))

    def save(self, path: str | Path) -> Path:
        """Write the `to_dict` form as JSON to ``path``; returns it."""
        path = Path(path)
        path.write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        return path


@lru_cache(maxsize=4)
def load_map(path: str | None = None) -> CalibrationMap | None:
    """The calibration map at ``path`` (None: the shipped one); None when the shipped file is absent."""
    p = Path(path) if path else DEFAULT_MAP
    if not p.is_file():
        if path:
            raise ValueError(f"{p}: calibration map not found")
        return None
    return CalibrationMap.from_dict(json.loads(p.read_text()), str(p))


def fit_map(
    types: np.ndarray,
    raw: np.ndarray,
    ok: np.ndarray,
    min_edges: int = 20,
    min_block: int = 20,
    meta: dict[str, Any] | None = None,
) -> CalibrationMap:
    """Isotonic map per edge type from labelled edges (types: EdgeType values, raw: raw confidences, ok: 0/1);
    a type with fewer than ``min_edges`` edges gets no knots (keeps its raw value). Each knot rests on at least
    ``min_block`` edges, and its value is the block's share right with one right and one wrong pseudo-edge added
    ((k + 1) / (n + 2), Laplace): a block where every edge was right says 0.99 on 100 edges, not 1 (a running
    maximum keeps the values non-decreasing after that shrink)."""
    types, raw, ok = np.asarray(types), np.asarray(raw, float), np.asarray(ok, float)
    knots = {}
    for t in EdgeType:
        s = types == t.value
        if s.sum() >= min_edges:
            xk, yk, n = isotonic_fit(raw[s], ok[s], min_block=min_block)
            yk = np.maximum.accumulate((yk * n + 1.0) / (n + 2.0))
            knots[t.value] = (xk, yk)
    return CalibrationMap(knots, dict(meta or {}))


def reliability_bins(conf: np.ndarray, ok: np.ndarray, n_bins: int = 10) -> dict[str, np.ndarray]:
    """Equal-width bins of [0, 1] (the last closed): per bin the count, mean confidence and share right (NaN for
    an empty bin)."""
    conf, ok = np.asarray(conf, float), np.asarray(ok, float)
    b = np.clip((conf * n_bins).astype(int), 0, n_bins - 1)
    count = np.bincount(b, minlength=n_bins).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_conf = np.bincount(b, conf, n_bins) / count
        acc = np.bincount(b, ok, n_bins) / count
    return {"count": count, "confidence": mean_conf, "accuracy": acc}


def expected_calibration_error(conf: np.ndarray, ok: np.ndarray, n_bins: int = 10) -> float:
    """ECE: sum over equal-width bins of (share of edges in the bin) * |share right - mean confidence|; NaN for
    no edges."""
    if len(conf) == 0:
        return float("nan")
    r = reliability_bins(conf, ok, n_bins)
    s = r["count"] > 0
    return float(np.sum(r["count"][s] * np.abs(r["accuracy"][s] - r["confidence"][s])) / r["count"].sum())


def reliability_diagram(
    curves: dict[str, tuple[np.ndarray, np.ndarray]],
    path: str | Path,
    title: str = "",
    n_bins: int = 10,
    size: int = 420,
) -> Path:
    """PNG reliability diagram (OpenCV): per curve (label -> (confidence, right)) the share right against the mean
    confidence of each non-empty bin, dot area by count, the diagonal for reference; ECE in the legend."""
    import cv2

    colors = [(200, 90, 30), (40, 40, 220), (40, 160, 40), (160, 40, 160)]  # BGR
    m, W, H = 50, size + 70, size + 80 + 22 * len(curves)
    img = np.full((H, W, 3), 255, np.uint8)

    def px(c: float, a: float) -> tuple[int, int]:
        return int(m + c * size), int(m + (1 - a) * size)

    cv2.rectangle(img, px(0, 0), px(1, 1), (0, 0, 0), 1)
    for t in np.linspace(0, 1, 6):
        cv2.line(img, px(t, 0), (px(t, 0)[0], px(t, 0)[1] + 4), (0, 0, 0), 1)
        cv2.putText(
            img,
            f"{t:.1f}",
            (px(t, 0)[0] - 10, px(t, 0)[1] + 16),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.35,
            (0, 0, 0),
            1,
            cv2.LINE_AA,
        )
        cv2.putText(
            img, f"{t:.1f}", (m - 30, px(0, t)[1] + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 0, 0), 1, cv2.LINE_AA
        )
    cv2.line(img, px(0, 0), px(1, 1), (150, 150, 150), 1, cv2.LINE_AA)
    cv2.putText(
        img, "confidence", (m + size // 2 - 35, m + size + 32), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA
    )
    cv2.putText(img, "share right", (4, m - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    if title:
        cv2.putText(img, title, (m, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    for i, (label, (conf, ok)) in enumerate(curves.items()):
        col = colors[i % len(colors)]
        r = reliability_bins(conf, ok, n_bins)
        s = r["count"] > 0
        pts = [px(c, a) for c, a in zip(r["confidence"][s], r["accuracy"][s])]
        for p0, p1 in itertools.pairwise(pts):
            cv2.line(img, p0, p1, col, 2, cv2.LINE_AA)
        tot = max(r["count"].sum(), 1.0)
        for p, n in zip(pts, r["count"][s]):
            cv2.circle(img, p, int(3 + 12 * np.sqrt(n / tot)), col, -1, cv2.LINE_AA)
        ece = expected_calibration_error(conf, ok, n_bins)
        y = m + size + 50 + 22 * i
        cv2.line(img, (m, y - 4), (m + 20, y - 4), col, 3)
        cv2.putText(
            img,
            f"{label}: ECE {ece:.3f} ({len(conf)} edges)",
            (m + 28, y),
            cv2.FONT_HERSHEY_SIMPLEX,
            0.42,
            (0, 0, 0),
            1,
            cv2.LINE_AA,
        )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img, [cv2.IMWRITE_PNG_COMPRESSION, 9])
    return path
