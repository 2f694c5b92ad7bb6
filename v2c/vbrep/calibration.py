"""Calibration of edge confidences: from the raw product of factors (v2c.vbrep.confidence) to the probability that
the edge's type is right.

What "right" means is the bench's matching (`v2c.bench.vbrep.edge_correctness`): at least half of the edge's
projected length lies within ``tol_px`` (3) pixels of ground-truth boundary records of the same type on the true
face(s) its faces cover. For an intersection edge: a true edge of the part, where two true surfaces meet, lies
within 3 px of it (about 1.5 mm at 0.6 m and a 55 degree field of view over 640 px).

The shipped map (``confidence_calibration.json`` beside this module, format 2) is one logistic regression per edge
type over features of the edge (`DEFAULT_FEATURES`, computed by `FEATURE_FUNCTIONS` from the quantities the
extraction records per edge, `v2c.vbrep.assemble`): the raw product's logit, the factors behind it one by one
(image length, agreement, surface angle, depth gap, fit residual and edge-to-depth error over the sensor noise,
depth jump, contour share) and the part's mean segmentation score, which is low on parts unlike the learned
segmenter's training parts. It is fitted (`fit_calibration`: L2-penalised, Newton's method, deterministic) on
learned and oracle reconstructions of training scans only: in-family, training feature-family and corpus-train
scans (scripts/calibrate_confidence.py). Each model's probability then goes through a monotone post-map fitted on
the same edges (`post_isotonic`: an isotonic regression, applied by `post_map`, strictly increasing, so edges keep
their rank). A map of format 1 (one isotonic map of the raw confidence per type,
`isotonic_fit` / `fit_map`, applied by linear interpolation between knots) still loads and applies.

Also here: the expected calibration error (`expected_calibration_error`, equal-width bins) and a reliability
diagram drawn with OpenCV (`reliability_diagram`).
"""

from __future__ import annotations

import contextvars
import itertools
import json
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from v2c.vbrep.model import EdgeType

#: The shipped calibration map (written by scripts/calibrate_confidence.py).
DEFAULT_MAP = Path(__file__).with_name("confidence_calibration.json")
FORMAT = "v2c.confidence_calibration"

#: When set to a list, `record_edges` appends each extraction's per-edge quantities to it (the calibration
#: script's way of reading what the map is fitted on, edge for edge in the VB-Rep's order).
EDGE_RECORD: contextvars.ContextVar[list[list[dict[str, Any]]] | None] = contextvars.ContextVar(
    "v2c_edge_record", default=None
)


def record_edges(quantities: list[dict[str, Any]]) -> None:
    """Hand one extraction's per-edge quantities to the recorder in force (`EDGE_RECORD`); nothing without one."""
    rec = EDGE_RECORD.get()
    if rec is not None:
        rec.append(quantities)


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


def _logit(p: np.ndarray) -> np.ndarray:
    """The log-odds log(p / (1 - p)) of p clipped to [0.005, 0.995] (a raw score of 0 or 1 stays finite)."""
    p = np.clip(np.asarray(p, float), 0.005, 0.995)
    return np.log(p / (1.0 - p))


def _log_clip(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """The log of x clipped to [lo, hi] (NaN stays NaN)."""
    return np.log(np.clip(np.asarray(x, float), lo, hi))


#: The features a logistic calibration may use: name -> function of the edge quantities (arrays; what
#: `v2c.vbrep.assemble` records for each edge, see `EDGE_RECORD`). NaN where a quantity does not apply to the
#: edge's type: the model fills it with its training median.
FEATURE_FUNCTIONS: dict[str, Callable[[dict[str, np.ndarray]], np.ndarray]] = {
    # the product of today's factors, on the logit scale
    "logit_raw": lambda q: _logit(q["raw"]),
    # its factors, each on its own: length of the edge in the image (pixels) and the share of samples agreeing
    "log_length_px": lambda q: _log_clip(q["length_px"], 1.0, 1e4),
    "agreement": lambda q: np.asarray(q["agreement"], float),
    # intersection: the surfaces' angle (degrees, up to 90) and their depth gap over the intersection threshold
    "angle_deg": lambda q: np.minimum(np.asarray(q["angle_deg"], float), 90.0),
    "gap_rel": lambda q: np.clip(np.asarray(q["gap_rel"], float), 0.0, 2.0),
    # the faces' fit residual and the edge-to-depth error over the sensor's depth noise there (log)
    "log_residual_noise": lambda q: _log_clip(q["residual_noise"], 0.01, 1e3),
    "log_depth_err_noise": lambda q: _log_clip(q["depth_err_noise"], 0.01, 1e3),
    # what reveals an unfamiliar reconstruction: the segmenter's score of the edge's less sure face, the
    # smaller face's size (pixels, log), the part's pixel-weighted mean score and its number of faces (log)
    "seg_score_min": lambda q: np.asarray(q["seg_score_min"], float),
    "log_face_px_min": lambda q: _log_clip(q["face_px_min"], 1.0, 1e7),
    "part_score_mean": lambda q: np.asarray(q["part_score_mean"], float),
    "log_n_faces": lambda q: _log_clip(q["n_faces"], 1.0, 1e4),
    # the edge's 1-sigma position error (mm, log)
    "log_sigma_mm": lambda q: _log_clip(q["sigma_mm"], 1e-3, 1e2),
    # outlines: the depth jump over the intersection threshold (log; the background's infinite jump clipped) and a
    # visibility edge's share of samples with a contour point
    "log_jump_rel": lambda q: _log_clip(q["jump_rel"], 0.01, 1e3),
    "vis_share": lambda q: np.asarray(q["vis_share"], float),
}


#: The features of the shipped map (chosen on the validation scans, scripts/calibrate_confidence.py): today's
#: factors one by one, and the part's mean segmentation score, which is low where the learned segmenter meets a part
#: unlike its training parts (measured per candidate set in docs/vbrep.md, "Calibration").
DEFAULT_FEATURES: tuple[str, ...] = (
    "logit_raw",
    "log_length_px",
    "agreement",
    "angle_deg",
    "gap_rel",
    "log_residual_noise",
    "log_depth_err_noise",
    "log_jump_rel",
    "vis_share",
    "part_score_mean",
)


#: The weight of training edges (source-weighted: mean weight 1, so about that many edges) that each knot of the
#: isotonic post-map of a fitted logistic model rests on at least (`post_isotonic`). Chosen on the validation scans
#: (docs/vbrep.md, "An isotonic post-map on the logistic model"): 20, 50, 100, 200 and 400 gave summed
#: intersection ECEs over the four validation columns of 0.157, 0.157, 0.157, 0.152 and 0.157 (0.185 without it).
POST_MIN_BLOCK = 200.0


def _sigmoid(z: np.ndarray) -> np.ndarray:
    """1 / (1 + exp(-z)), z clipped to [-30, 30] (no overflow; probabilities within 1e-13 of 0 and 1)."""
    return 1.0 / (1.0 + np.exp(-np.clip(z, -30.0, 30.0)))


def post_isotonic(
    p: np.ndarray, y: np.ndarray, w: np.ndarray | None = None, min_block: float = POST_MIN_BLOCK
) -> tuple[np.ndarray, np.ndarray]:
    """Knots (x, y) of a monotone recalibration of a model's probabilities ``p`` against the outcomes ``y`` (1
    right, 0 wrong; weights ``w``): the weighted isotonic fit (`isotonic_fit`), each knot resting on at least
    ``min_block`` of weight, its value kept within [1 / (2 w), 1 - 1 / (2 w)] of its weight w; x and y
    strictly increasing, y within (0, 1). A logistic model is monotone in its score but not
    calibrated in every range of it (its one slope serves all of them); the post-map, applied by `post_map`,
    corrects that on the training edges."""
    xk, yk, wk = isotonic_fit(np.asarray(p, float), np.asarray(y, float), w, min_block=min_block)
    # a block of all right (or all wrong) edges says at most 1 - 1/(2 n) (at least 1/(2 n)), not certainty: a
    # knot at 1 would tie every edge beyond it, and the map must keep their order
    yk = np.clip(yk, 0.5 / wk, 1.0 - 0.5 / wk)
    keep = [0]
    for i in range(1, len(xk)):  # the clipped ends may meet a neighbour: keep y strictly increasing
        if yk[i] > yk[keep[-1]]:
            keep.append(i)
    return xk[keep], yk[keep]


def post_map(p: np.ndarray, xk: np.ndarray, yk: np.ndarray) -> np.ndarray:
    """``p`` mapped through the knots (`post_isotonic`): linear between them; beyond the first, the larger of p
    shifted by the first knot's offset (y0 - x0) and the line from (0, 0) to it; beyond the last, the smaller of
    p shifted by its offset and the line from it to (1, 1). Strictly increasing everywhere (the knots are), so
    every edge keeps its rank (references chosen best first are tried in the same order), and within [0, 1]."""
    p = np.asarray(p, float)
    out = np.interp(p, xk, yk)
    x0, y0, x1, y1 = xk[0], yk[0], xk[-1], yk[-1]
    lo, hi = p < x0, p > x1
    if lo.any():
        out[lo] = np.maximum(p[lo] + (y0 - x0), y0 * p[lo] / x0)
    if hi.any():
        out[hi] = np.minimum(p[hi] + (y1 - x1), y1 + (p[hi] - x1) * (1.0 - y1) / (1.0 - x1))
    return np.clip(out, 0.0, 1.0)


def feature_matrix(quantities: dict[str, Any] | list[dict[str, Any]], names: tuple[str, ...]) -> np.ndarray:
    """(n, len(names)) features of n edges from their quantities (one edge's dict or a list of them); NaN where a
    quantity does not apply."""
    rows = [quantities] if isinstance(quantities, dict) else list(quantities)
    keys = [k for k, v in rows[0].items() if not isinstance(v, str)] if rows else []
    q = {k: np.array([r.get(k, np.nan) for r in rows], float) for k in keys}
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.stack([FEATURE_FUNCTIONS[n](q) for n in names], axis=1) if rows else np.zeros((0, len(names)))


@dataclass(frozen=True)
class LogisticModel:
    """p = 1 / (1 + exp(-(b + sum_i w_i (x_i - mean_i) / std_i))) over the named features (`FEATURE_FUNCTIONS`),
    a NaN feature replaced by ``fill`` (its training median); then, when ``post_x`` / ``post_y`` are given, p
    mapped through them (`post_map`: a monotone recalibration of p fitted by `post_isotonic`, strictly
    increasing, so the edges keep their order)."""

    features: tuple[str, ...]
    fill: np.ndarray
    mean: np.ndarray
    std: np.ndarray
    coef: np.ndarray
    intercept: float
    post_x: np.ndarray | None = None
    post_y: np.ndarray | None = None

    def probability(self, quantities: dict[str, Any] | list[dict[str, Any]]) -> np.ndarray:
        """The probability right of each edge whose quantities are given (one dict or a list)."""
        X = feature_matrix(quantities, self.features)
        X = np.where(np.isfinite(X), X, self.fill)
        p = _sigmoid(self.intercept + ((X - self.mean) / self.std) @ self.coef)
        return p if self.post_x is None else post_map(p, self.post_x, self.post_y)

    def to_dict(self) -> dict[str, Any]:
        """JSON form (numbers rounded to 6 significant digits)."""

        def r(a: np.ndarray) -> list[float]:
            return [float(f"{v:.6g}") for v in np.asarray(a, float)]

        out: dict[str, Any] = {
            "features": list(self.features),
            "fill": r(self.fill),
            "mean": r(self.mean),
            "std": r(self.std),
            "coef": r(self.coef),
            "intercept": float(f"{self.intercept:.6g}"),
        }
        if self.post_x is not None:
            out["post"] = {k: [round(float(v), 6) for v in a] for k, a in (("x", self.post_x), ("y", self.post_y))}
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str, etype: str) -> LogisticModel:
        """Inverse of `to_dict`; ValueError (naming ``source``) for an unknown feature or arrays of other lengths."""
        names = tuple(d["features"])
        bad = [n for n in names if n not in FEATURE_FUNCTIONS]
        if bad:
            raise ValueError(
                f"{source}: unknown feature(s) {bad} of {etype!r}, expected some of {list(FEATURE_FUNCTIONS)}"
            )
        arrs = [np.asarray(d[k], float) for k in ("fill", "mean", "std", "coef")]
        if any(len(a) != len(names) for a in arrs) or np.any(arrs[2] <= 0):
            raise ValueError(f"{source}: {etype!r} needs fill, mean, std (> 0) and coef of {len(names)} values each")
        post = d.get("post")
        px = py = None
        if post is not None:
            px, py = np.asarray(post["x"], float), np.asarray(post["y"], float)
            ok = len(px) == len(py) >= 2 and np.all(np.diff(px) > 0) and np.all(np.diff(py) > 0)
            if not ok or px[0] < 0 or px[-1] > 1 or py[0] < 0 or py[-1] > 1:
                raise ValueError(
                    f"{source}: the post-map of {etype!r} needs at least two knots in [0, 1], strictly increasing "
                    "in x and in y"
                )
        return cls(names, *arrs, float(d["intercept"]), px, py)


@dataclass
class CalibrationMap:
    """Per edge type, the map from an edge to the probability that its type is right: a logistic model over
    features of the edge (``models``; needs the edge's quantities), else knots (x: raw confidence, y: probability
    right) of a monotone map; a type with neither keeps its raw value. ``meta``: how it was fitted (scans, counts,
    tolerance)."""

    knots: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    models: dict[str, LogisticModel] = field(default_factory=dict)

    def apply(
        self,
        etype: EdgeType | str,
        raw: float | np.ndarray,
        quantities: dict[str, Any] | list[dict[str, Any]] | None = None,
    ) -> float | np.ndarray:
        """Calibrated probability in [0, 1] of edge(s) of one type: by its logistic model from ``quantities`` (one
        edge's dict or a list; ValueError without them), else by its knots from ``raw`` (constant beyond the end
        knots), else ``raw``."""
        t = EdgeType(etype).value
        model = self.models.get(t)
        if model is not None:
            if quantities is None:
                raise ValueError(f"the calibration of {t!r} edges needs their quantities, not only the raw score")
            out = model.probability(quantities)
            return float(out[0]) if isinstance(quantities, dict) else out
        k = self.knots.get(t)
        r = np.asarray(raw, float)
        out = r if k is None or len(k[0]) == 0 else np.interp(r, k[0], k[1])
        out = np.clip(out, 0.0, 1.0)
        return float(out) if np.ndim(out) == 0 else out

    def to_dict(self) -> dict[str, Any]:
        """The JSON form of ``confidence_calibration.json`` (knots rounded to 6 decimals)."""
        types: dict[str, Any] = {
            t: {"x": [round(float(v), 6) for v in xk], "y": [round(float(v), 6) for v in yk]}
            for t, (xk, yk) in self.knots.items()
        }
        types.update({t: m.to_dict() for t, m in self.models.items()})
        return {"format": FORMAT, "format_version": 2, "meta": self.meta, "types": dict(sorted(types.items()))}

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = "calibration") -> CalibrationMap:
        """Inverse of `to_dict` (format versions 1: knots only, and 2); ValueError (naming ``source``) for another
        format, an unknown edge type or feature, or knots that are not monotone."""
        if d.get("format") != FORMAT:
            raise ValueError(f"{source}: format {d.get('format')!r}, expected {FORMAT!r}")
        knots, models = {}, {}
        for t, k in d.get("types", {}).items():
            EdgeType(t)  # ValueError naming the bad type
            if "features" in k:
                models[t] = LogisticModel.from_dict(k, source, t)
                continue
            xk, yk = np.asarray(k["x"], float), np.asarray(k["y"], float)
            if len(xk) != len(yk) or np.any(np.diff(xk) <= 0) or np.any(np.diff(yk) < 0):
                raise ValueError(f"{source}: knots of {t!r} are not increasing in x and non-decreasing in y")
            knots[t] = (xk, yk)
        return cls(knots, dict(d.get("meta", {})), models)

    def save(self, path: str | Path) -> Path:
        """Write the `to_dict` form as JSON to ``path`` (atomically, `v2c.io_safe`); returns it."""
        from v2c.io_safe import write_text_atomic

        return write_text_atomic(path, json.dumps(self.to_dict(), indent=1) + "\n")


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


def fit_logistic(
    X: np.ndarray, y: np.ndarray, w: np.ndarray | None = None, l2: float = 1.0
) -> tuple[float, np.ndarray]:
    """Weighted logistic regression of y (0/1) on the columns of X (no NaN): (intercept, coefficients) minimising
    the weighted log loss plus ``l2`` / 2 * |coefficients|^2 (intercept not penalised), by Newton's method from 0.
    Weights are scaled to mean 1, so ``l2`` reads against the number of examples. Deterministic."""
    X, y = np.asarray(X, float), np.asarray(y, float)
    w = np.ones(len(y)) if w is None else np.asarray(w, float)
    w = w * (len(w) / w.sum())
    A = np.c_[np.ones(len(y)), X]
    pen = np.full(A.shape[1], float(l2))
    pen[0] = 0.0
    beta = np.zeros(A.shape[1])
    for _ in range(100):
        p = _sigmoid(A @ beta)
        grad = A.T @ (w * (p - y)) + pen * beta
        H = (A * (w * p * (1.0 - p))[:, None]).T @ A + np.diag(pen + 1e-9)
        step = np.linalg.solve(H, grad)
        beta -= step
        if np.max(np.abs(step)) < 1e-10:
            break
    return float(beta[0]), beta[1:]


def source_weights(sources: np.ndarray) -> np.ndarray:
    """Per example the weight that gives every source the same total weight (mean weight 1)."""
    sources = np.asarray(sources)
    names, inv, counts = np.unique(sources, return_inverse=True, return_counts=True)
    return len(sources) / (len(names) * counts[inv])


def fit_calibration(
    rows: list[dict[str, Any]],
    features: tuple[str, ...] = tuple(FEATURE_FUNCTIONS),
    source_key: str | None = None,
    l2: float = 1.0,
    min_edges: int = 20,
    meta: dict[str, Any] | None = None,
    non_negative: tuple[str, ...] = ("logit_raw",),
    post_min_block: float | None = None,
) -> CalibrationMap:
    """Logistic model per edge type from labelled edges (rows: the recorded quantities of each edge with its
    ``type`` and ``ok`` (1: right, 0: wrong)). Per type, the features that apply to it (not NaN on every edge and
    not constant) are standardised (training mean and standard deviation; NaN filled with the training median).
    ``source_key``: a row field naming where the edge came from; every source then weighs the same in the fit
    (`source_weights`). A type with fewer than ``min_edges`` edges gets no model (keeps its raw value).
    ``non_negative``: features whose weight may not be negative (an edge's probability never falls as its raw
    score rises, the rest fixed): one the fit gives a negative weight is fixed at 0 and the rest refitted (an
    active set; the raw score and its own factors are correlated, and a refit on other edges can tip its weight
    below 0). ``post_min_block``: when given, each model gets a monotone post-map of its probability fitted on the
    same edges and weights (`post_isotonic` with that min_block; None: none)."""
    models = {}
    for t in EdgeType:
        r = [x for x in rows if x["type"] == t.value]
        if len(r) < min_edges:
            continue
        X = feature_matrix(r, features)
        finite = np.isfinite(X)
        with np.errstate(invalid="ignore"):
            fill = np.array(
                [np.median(X[finite[:, j], j]) if finite[:, j].any() else np.nan for j in range(X.shape[1])]
            )
        X = np.where(finite, X, fill)
        std = X.std(0) if len(X) else np.zeros(X.shape[1])
        keep = np.isfinite(fill) & (std > 1e-9)
        X, fill, std = X[:, keep], fill[keep], std[keep]
        mean = X.mean(0)
        y = np.array([x["ok"] for x in r], float)
        w = source_weights(np.array([x[source_key] for x in r])) if source_key else None
        names = tuple(n for n, k in zip(features, keep) if k)
        Z = (X - mean) / std
        free = np.ones(len(names), bool)
        while True:
            b, sub = fit_logistic(Z[:, free], y, w, l2)
            coef = np.zeros(len(names))
            coef[free] = sub
            neg = [j for j, n in enumerate(names) if n in non_negative and free[j] and coef[j] < 0]
            if not neg:
                break
            free[neg] = False
        model = LogisticModel(names, fill, mean, std, coef, b)
        if post_min_block is not None:
            px, py = post_isotonic(_sigmoid(b + Z @ coef), y, w, post_min_block)
            if len(px) >= 2:  # one block: the logistic model is calibrated as a whole already
                model = replace(model, post_x=px, post_y=py)
        models[t.value] = model
    return CalibrationMap({}, dict(meta or {}), models)


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
