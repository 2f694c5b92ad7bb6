"""Curves that bound the exported faces (output frame, millimetres): exact intersection curves of two
surfaces, analytic lines/circles, iso-parameter curves, and 2D curves (pcurves) fitted in a surface's (u, v)
space."""

from __future__ import annotations

import warnings

import numpy as np
from OCP.GCE2d import GCE2d_MakeArcOfCircle, GCE2d_MakeSegment
from OCP.Geom import Geom_Circle, Geom_Curve, Geom_Line, Geom_TrimmedCurve
from OCP.Geom2d import Geom2d_BSplineCurve, Geom2d_Curve, Geom2d_Line
from OCP.GeomAdaptor import GeomAdaptor_Curve
from OCP.GeomAPI import GeomAPI_IntSS, GeomAPI_ProjectPointOnCurve
from OCP.gp import gp_Ax1, gp_Ax2, gp_Ax2d, gp_Circ2d, gp_Dir2d, gp_Pnt2d
from OCP.TColgp import TColgp_Array1OfPnt2d
from OCP.TColStd import TColStd_Array1OfInteger, TColStd_Array1OfReal
from scipy.interpolate import splprep

from exporters.frames import FrameMap
from exporters.occ_surfaces import AnalyticSurface, gp_direction, gp_point, perpendicular, unit
from exporters.polygons import densify, dist_to_polyline_2d, simplify_polyline


def intersection_curves(s1: AnalyticSurface, s2: AnalyticSurface, tol: float) -> list[Geom_Curve]:
    """All branches of the exact intersection of two surfaces (GeomAPI_IntSS, tolerance in millimetres)."""
    inter = GeomAPI_IntSS(s1.geom, s2.geom, tol)
    if not inter.IsDone():
        return []
    curves = [inter.Line(i) for i in range(1, inter.NbLines() + 1)]
    # Closed branches come back trimmed to one period: keep the periodic basis so any arc can be cut from it.
    return [c.BasisCurve() if isinstance(c, Geom_TrimmedCurve) and c.BasisCurve().IsPeriodic() else c for c in curves]


def project_on_curve(curve: Geom_Curve, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) mm -> (params (N,), distances (N,)) of the closest points on ``curve`` (inf if none)."""
    params = np.full(len(points), np.nan)
    dists = np.full(len(points), np.inf)
    proj = GeomAPI_ProjectPointOnCurve()
    for i, q in enumerate(points):
        proj.Init(gp_point(q), curve)
        if proj.NbPoints() > 0:
            params[i] = proj.LowerDistanceParameter()
            dists[i] = proj.LowerDistance()
    return params, dists


def curve_points(curve: Geom_Curve, params: np.ndarray) -> np.ndarray:
    """(N,) curve parameters -> (N, 3) millimetres."""
    out = np.empty((len(params), 3))
    for i, t in enumerate(params):
        p = curve.Value(float(t))
        out[i] = p.X(), p.Y(), p.Z()
    return out


def pcurve_points(pcurve: Geom2d_Curve, params: np.ndarray) -> np.ndarray:
    """(N,) parameters of a curve in a surface's (u, v) -> (N, 2) (u, v) values."""
    out = np.empty((len(params), 2))
    for i, t in enumerate(params):
        p = pcurve.Value(float(t))
        out[i] = p.X(), p.Y()
    return out


def nearest_branch(curves: list[Geom_Curve], samples: np.ndarray) -> tuple[Geom_Curve | None, float]:
    """The branch closest to the sample points (N, 3) mm and its largest sample distance (mm)."""
    best, best_d = None, np.inf
    for c in curves:
        _, d = project_on_curve(c, samples)
        if np.max(d) < best_d:
            best, best_d = c, float(np.max(d))
    return best, best_d


#: GeomAbs curve types that are exact analytic curves (no approximation).
ELEMENTARY_CURVES = (
    "GeomAbs_Line",
    "GeomAbs_Circle",
    "GeomAbs_Ellipse",
    "GeomAbs_Hyperbola",
    "GeomAbs_Parabola",
)


def is_elementary(curve: Geom_Curve) -> bool:
    """True for lines, circles and conics (what GeomAPI_IntSS returns when it solves a pair exactly)."""
    return GeomAdaptor_Curve(curve).GetType().name in ELEMENTARY_CURVES


def curve_from_dict(curve: dict | None, fmap: FrameMap) -> Geom_Curve | None:
    """The analytic line or circle of a VB-Rep edge's ``curve`` dict (camera metres) in the output frame, or
    None (no dict, kind "intersection", degenerate values)."""
    if not curve:
        return None
    try:
        if curve.get("kind") == "line":
            o = fmap.points(np.asarray(curve["origin"], float))
            return Geom_Line(gp_Ax1(gp_point(o), gp_direction(unit(fmap.vectors(curve["direction"])))))
        if curve.get("kind") == "circle":
            c = fmap.points(np.asarray(curve["center"], float))
            n = unit(fmap.vectors(curve["axis"]))
            r = fmap.length(curve["radius"])
            if not r > 0:
                return None
            return Geom_Circle(gp_Ax2(gp_point(c), gp_direction(n), gp_direction(perpendicular(n))), r)
    except (KeyError, ValueError, TypeError):
        return None
    return None


def iso_curve(
    s: AnalyticSurface, uv0: np.ndarray, uv1: np.ndarray, tol: float
) -> tuple[Geom_Curve, Geom2d_Curve, float, float] | None:
    """When the (u, v) segment uv0 -> uv1 runs along an iso-parameter line of ``s`` (the other parameter
    constant within ``tol``): (exact 3D iso curve, matching 2D line, parameter at uv0, parameter at uv1), both
    curves sharing one parametrisation (a circle or line for every analytic surface). Else None."""
    du, dv = np.abs(np.asarray(uv1, float) - np.asarray(uv0, float))
    if dv <= tol < du:  # v constant: the curve runs in u
        v = 0.5 * (uv0[1] + uv1[1])
        return (
            s.geom.VIso(float(v)),
            Geom2d_Line(gp_Pnt2d(0.0, float(v)), gp_Dir2d(1.0, 0.0)),
            float(uv0[0]),
            float(uv1[0]),
        )
    if du <= tol < dv:  # u constant: the curve runs in v
        u = 0.5 * (uv0[0] + uv1[0])
        return (
            s.geom.UIso(float(u)),
            Geom2d_Line(gp_Pnt2d(float(u), 0.0), gp_Dir2d(0.0, 1.0)),
            float(uv0[1]),
            float(uv1[1]),
        )
    return None


def _circle_arc(uv: np.ndarray, tol: float) -> Geom2d_Curve | None:
    """A circular arc through open (N >= 3, 2) points when they and the polyline between them fit one within
    ``tol`` (algebraic fit), from the first to the last point in their direction of travel; else None."""
    if len(uv) < 3 or np.linalg.norm(uv[-1] - uv[0]) <= tol:
        return None
    A = np.column_stack([2 * uv, np.ones(len(uv))])
    (a, b, c), *_ = np.linalg.lstsq(A, (uv**2).sum(1), rcond=None)
    r2 = c + a * a + b * b
    if not r2 > 0:
        return None
    r = float(np.sqrt(r2))
    # the whole polyline must lie on the circle, not only its points: three points always fit one, and a
    # corner's few points would become an arc bulging off the polyline between them
    dense = densify(uv, 60)
    if np.abs(np.linalg.norm(dense - (a, b), axis=1) - r).max() > tol or r > 1e4 * np.ptp(uv, axis=0).max():
        return None
    ang = np.unwrap(np.arctan2(uv[:, 1] - b, uv[:, 0] - a))
    ccw = ang[-1] > ang[0]
    circ = gp_Circ2d(gp_Ax2d(gp_Pnt2d(float(a), float(b)), gp_Dir2d(1.0, 0.0)), r)
    arc = GCE2d_MakeArcOfCircle(circ, gp_Pnt2d(*uv[0]), gp_Pnt2d(*uv[-1]), bool(ccw))
    if not arc.IsDone():
        return None
    curve = arc.Value()
    start = curve.Value(curve.FirstParameter())
    span = curve.LastParameter() - curve.FirstParameter()
    # the arc must start at the first point and sweep the points' angle (GCE2d's sense convention, checked)
    if np.hypot(start.X() - uv[0, 0], start.Y() - uv[0, 1]) > tol or abs(span - abs(ang[-1] - ang[0])) > 1e-3:
        return None
    return curve


def polyline_curve(uv: np.ndarray) -> Geom2d_Curve:
    """The polyline itself as a degree-1 B-spline (parameter = chord length); repeated points are dropped."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(uv, axis=0), axis=1) > 1e-12])
    uv = uv[keep]
    if len(uv) < 2:
        raise ValueError("degenerate polyline")
    knots_v = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(uv, axis=0), axis=1))])
    poles = TColgp_Array1OfPnt2d(1, len(uv))
    for i, (u, v) in enumerate(uv):
        poles.SetValue(i + 1, gp_Pnt2d(float(u), float(v)))
    knots = TColStd_Array1OfReal(1, len(uv))
    mults = TColStd_Array1OfInteger(1, len(uv))
    for i, k in enumerate(knots_v):
        knots.SetValue(i + 1, float(k))
        mults.SetValue(i + 1, 2 if i in (0, len(uv) - 1) else 1)
    return Geom2d_BSplineCurve(poles, knots, mults, 1)


def fit_pcurve(uv: np.ndarray, tol: float, circles: bool = False) -> Geom2d_Curve:
    """A 2D curve through (N, 2) parameter-space points (a simplified polyline, possibly only a few corners):

    a segment when they are collinear within ``tol`` (parameter units); a circular arc when ``circles`` and
    they fit one within ``tol``; else a C2 B-spline (degree 3 to 8) approximating the densified polyline
    within ``tol`` and keeping its end points, unless it strays more than 3 ``tol`` from the polyline (sharp
    corners), in which case the polyline itself (degree 1)."""
    uv = np.asarray(uv, float)
    a, b = uv[0], uv[-1]
    chord = b - a
    n = np.linalg.norm(chord)
    if n > 1e-12:
        off = np.abs((uv[:, 0] - a[0]) * chord[1] - (uv[:, 1] - a[1]) * chord[0]) / n
        if len(uv) == 2 or off.max() <= tol:
            return GCE2d_MakeSegment(gp_Pnt2d(*a), gp_Pnt2d(*b)).Value()
    if circles:
        arc = _circle_arc(uv, tol)
        if arc is not None:
            return arc
    uv = simplify_polyline(uv, 0.5 * tol)  # long pixel-step polylines: keep only what shapes them
    c = _smoothing_bspline(uv, tol)
    if c is not None:
        ts = np.linspace(c.FirstParameter(), c.LastParameter(), 200)
        q = np.array([[c.Value(t).X(), c.Value(t).Y()] for t in ts])
        if dist_to_polyline_2d(q, uv).max() <= 3 * tol:
            return c
    return polyline_curve(uv)


def _smoothing_bspline(uv: np.ndarray, tol: float) -> Geom2d_Curve | None:
    """A cubic smoothing spline (FITPACK, chord-length parameter) of the densified polyline whose residual is
    about ``tol``, clamped to the polyline's exact end points; None when FITPACK fails."""
    dense = densify(uv, 60)
    step = np.linalg.norm(np.diff(dense, axis=0), axis=1)
    keep = np.concatenate([[True], step > 1e-12])
    dense, step = dense[keep], step[step > 1e-12]
    if len(dense) < 4:
        return None
    par = np.concatenate([[0.0], np.cumsum(step)])
    try:
        with warnings.catch_warnings():  # FITPACK's "s too small" note: the result is checked by the caller
            warnings.simplefilter("ignore", RuntimeWarning)
            (t, c, k), _ = splprep(dense.T, u=par / par[-1], k=3, s=len(dense) * (0.5 * tol) ** 2, quiet=2)
    except (ValueError, TypeError):
        return None
    n = len(t) - k - 1
    poles_np = np.stack([np.asarray(c[0])[:n], np.asarray(c[1])[:n]], 1)
    poles_np[0], poles_np[-1] = uv[0], uv[-1]  # clamped spline: its ends are its end poles
    knots_v, mults_v = np.unique(np.round(t, 12), return_counts=True)
    poles = TColgp_Array1OfPnt2d(1, n)
    for i, (u, v) in enumerate(poles_np):
        poles.SetValue(i + 1, gp_Pnt2d(float(u), float(v)))
    knots = TColStd_Array1OfReal(1, len(knots_v))
    mults = TColStd_Array1OfInteger(1, len(knots_v))
    for i, (kv, m) in enumerate(zip(knots_v, mults_v)):
        knots.SetValue(i + 1, float(kv))
        mults.SetValue(i + 1, int(m))
    try:
        return Geom2d_BSplineCurve(poles, knots, mults, k)
    except Exception:  # noqa: BLE001 - OCCT rejects inconsistent knots: let the caller fall back
        return None
