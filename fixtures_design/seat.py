"""Seating a known part in its fixture: the part pushed home, as a user puts it in, before clearance and contact
are judged (docs/fixtures.md, "Seated: the part pushed home").

A fixture is designed where the reconstruction puts the part; the physical part is then pushed into it. The scan's
depth offset moves the whole reconstruction along the camera rays by about as much as the touch tolerance, so a
fixture judged where it lies in the camera frame says more about that offset than about its shape. `seat_part`
moves the true part rigidly, by a translation in the directions the fixture constrains (`Seating`: a corner along
its faces' normals, a pin anywhere, a cradle across its axis, a nest anywhere), pushed the fixture's way until the
mating faces (and the fixture's stops) hold it, and across the push only as far as those faces make it. A seat
moving the part further than ``bound_clearance_factor`` x the clearance + ``bound_mm`` (+ the design's standoff)
is a failed design: the fixture does not locate the part where it was meant to.

How: points sampled on the mating faces (and stops) each cast a ray along the face's outward normal n to the true
part; the signed distance to its surface along that ray (negative where the point lies inside the part) is the
gap, which a translation t of the part changes by (m . t) / (m . n), m the part's outward normal where the ray
meets it (n . t where the two faces are parallel; a cone's side against a hole's rim or plane is not). The largest
push whose gaps stay >= 0 (a linear program), then the smallest move reaching it (a small quadratic program),
repeated from the moved part until the move changes by less than ``tol_mm``. Output frame, millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from build123d import Face, Shape, Vector

from fixtures_design.model import Fixture, unit


@dataclass(frozen=True)
class SeatConfig:
    """Seating parameters (millimetres)."""

    bound_clearance_factor: float = 3.0  # a seat moving the part more than this x the fixture's clearance ...
    bound_mm: float = 2.0  # ... plus this (mm, plus the design's standoff) fails the design: the lead's rule for
    # issue 18 (a stated bound on how wrong a fixture may place the part, not tuned)
    points: int = 240  # points sampled over the mating faces and stops together (at least 8 per face)
    reach_mm: float = 40.0  # mm: how far each ray looks for the part either way; also the largest move tried
    max_iter: int = 8  # re-linearisations from the moved part
    tol_mm: float = 0.002  # mm: the seat has converged when an iteration moves the part less than this
    graze_cos: float = 0.2  # a ray meeting the part's surface more obliquely than this cosine (78 degrees) changes
    # its gap as if the surface faced the fixture's face (n . t): the exact rate grows without bound there


@dataclass(frozen=True)
class Seat:
    """A seat of the true part in a fixture (output frame, mm).

    move: (3,) the part's translation. move_mm: its length. push_mm: its component along the push. bound_mm: the
    largest move allowed. ok: a seat was found within the bound. reason: why not (empty when ok). min_gap_mm: the
    smallest gap of the sampled points after the move (about 0: touching). contacts: sampled points within 0.05 mm.
    overlap_mm: when no move clears the mating faces (a pocket narrower than the part), the least overlap any move
    leaves (mm); 0 otherwise.
    """

    move: np.ndarray
    move_mm: float
    push_mm: float
    bound_mm: float
    ok: bool
    reason: str
    min_gap_mm: float
    contacts: int
    overlap_mm: float = 0.0


def seat_bound_mm(fixture: Fixture, config: SeatConfig = SeatConfig()) -> float:
    """The largest move (mm) a seat of this fixture may need: factor x clearance + bound_mm + the standoff."""
    standoff = fixture.seating.standoff_mm if fixture.seating is not None else 0.0
    return config.bound_clearance_factor * float(fixture.params.clearance) + config.bound_mm + standoff


def _on_face(face: Face, n: int, grid: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """About ``n`` points ON a face and the face's outward normals there (mm; a face of a solid carries its
    orientation, so the normal points out of the fixture, towards the part). A plane: some of its tessellation's
    vertices (a quarter of ``n``) and seeded area-weighted points in its triangles. A curved face: the vertices of
    a fine tessellation and the points of a ``grid`` x ``grid`` (u, v) sampling that lie on the trimmed face (not
    triangle centroids: on a curved face they lie off the surface by the chord's sag, which would read as a
    gap)."""
    if face.geom_type.name == "PLANE":
        verts, tris = face.tessellate(0.2, 0.2)
        v = np.array([tuple(p) for p in verts])
        tri = v[np.asarray(tris, int).reshape(-1, 3)]
        area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
        rng = np.random.default_rng(0)
        v = v[:: max(1, 4 * len(v) // n)]  # a quarter of the budget on the outline, the rest inside
        k = max(1, n - len(v))
        pick = rng.choice(len(tri), k, p=area / area.sum()) if area.sum() > 0 else np.zeros(0, int)
        a, b = rng.random((2, len(pick), 1))
        flip = a + b > 1
        a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
        t = tri[pick]
        pts = np.concatenate([v, t[:, 0] + a * (t[:, 1] - t[:, 0]) + b * (t[:, 2] - t[:, 0])])
        normal = np.array(tuple(face.normal_at(Vector(*map(float, v[0])))))
        return pts, np.tile(normal, (len(pts), 1))
    verts, _ = face.tessellate(0.01, 0.1)
    v = np.array([tuple(p) for p in verts])
    uv = (np.arange(grid) + 0.5) / grid
    on = [tuple(face.position_at(a, b)) for a in uv for b in uv]
    on = [p for p in on if face.is_inside(Vector(*p), 1e-4)]
    pts = np.concatenate([v, np.array(on).reshape(-1, 3)])
    pts = pts[:: max(1, len(pts) // n)]
    return pts, np.array([tuple(face.normal_at(Vector(*map(float, q)))) for q in pts])


def seat_samples(fixture: Fixture, n_points: int = 240) -> tuple[np.ndarray, np.ndarray]:
    """(points (N, 3), outward unit normals (N, 3)) on the fixture's mating faces (``n_points`` among them, at least
    2 a face) and its stops (half as many again), mm: the normals point from the fixture towards where the part
    is."""
    stops = list(fixture.seating.stops) if fixture.seating is not None else []
    pts, nrm = [], []
    for faces, n in ((list(fixture.mating_faces), n_points), (stops, n_points // 2)):
        for f in faces:
            p, q = _on_face(f, max(2, n // len(faces)))
            pts.append(p)
            nrm.append(q / np.linalg.norm(q, axis=1, keepdims=True))
    return np.concatenate(pts), np.concatenate(nrm)


class _Rays:
    """Signed distances along rays to a solid (mm): positive to where the solid begins in front of a point outside
    it, negative back to where it ends behind a point inside it; NaN where a point inside sees no end within reach,
    +inf where a point outside sees no solid in front."""

    def __init__(self, part: Shape, reach: float, graze_cos: float) -> None:
        from OCP.BRepClass3d import BRepClass3d_SolidClassifier
        from OCP.IntCurvesFace import IntCurvesFace_ShapeIntersector

        self.inter = IntCurvesFace_ShapeIntersector()
        self.inter.Load(part.wrapped, 1e-6)
        self.cls = BRepClass3d_SolidClassifier(part.wrapped)
        self.reach = reach
        self.graze_cos = graze_cos

    def gaps(self, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(gaps (N,), rates (N, 3)): each point's signed distance along its normal to the part, and the vector r
        with which a translation t of the part changes that gap by r . t: for a point outside the part the hit's
        outward normal m over m . n (exact for a plane of the part at any angle), else n itself (inside, on the
        surface, without a hit, or past ``graze_cos``)."""
        from OCP.BRepGProp import BRepGProp_Face
        from OCP.gp import gp_Dir, gp_Lin, gp_Pnt, gp_Vec
        from OCP.TopAbs import TopAbs_IN, TopAbs_ON

        out = np.empty(len(points))
        rate = np.array(normals, float, copy=True)
        for i, (p, n) in enumerate(zip(points, normals)):
            pnt = gp_Pnt(*map(float, p))
            self.cls.Perform(pnt, 1e-6)
            state = self.cls.State()
            if state == TopAbs_ON:
                out[i] = 0.0
                continue
            self.inter.Perform(gp_Lin(pnt, gp_Dir(*map(float, n))), -self.reach, self.reach)
            w = np.array([self.inter.WParameter(j) for j in range(1, self.inter.NbPnt() + 1)])
            pick = np.flatnonzero(w <= 0) if state == TopAbs_IN else np.flatnonzero(w >= 0)
            if not len(pick):
                out[i] = np.nan if state == TopAbs_IN else np.inf
                continue
            if state == TopAbs_IN:
                # Inside: freed along the face's own normal n (at an edge of the part, a hole's rim in a cone, the
                # point is freed either way: no one rate holds).
                out[i] = w[pick].max()
                continue
            j = int(pick[np.argmin(w[pick])])
            out[i] = w[j]
            hit, normal = gp_Pnt(), gp_Vec()
            BRepGProp_Face(self.inter.Face(j + 1)).Normal(
                self.inter.UParameter(j + 1), self.inter.VParameter(j + 1), hit, normal
            )
            if normal.Magnitude() > 0:
                m = np.array([normal.X(), normal.Y(), normal.Z()]) / normal.Magnitude()
                cos = float(m @ n)
                if abs(cos) >= self.graze_cos:
                    rate[i] = m / cos
        return out, rate


def _solve_move(
    dirs: np.ndarray, push: np.ndarray, rates: np.ndarray, gaps: np.ndarray, cap: float, tol: float
) -> np.ndarray | None:
    """The increment u (coordinates in ``dirs``) with gaps + (rates . dirs^T) u >= 0 that pushes furthest along
    ``push``, and of those the shortest; None when no u within +-cap keeps every gap >= 0."""
    from scipy.optimize import linprog, minimize

    keep = np.isfinite(gaps)
    a = -(rates[keep] @ dirs.T)  # a u <= gaps
    b = gaps[keep]
    k = len(dirs)
    pk = dirs @ push
    res = linprog(-pk, A_ub=a, b_ub=b, bounds=[(-cap, cap)] * k, method="highs")
    if res.status != 0:
        return None
    best = -float(res.fun)
    cons = [{"type": "ineq", "fun": lambda u: b - a @ u, "jac": lambda u: -a}]
    cons.append({"type": "ineq", "fun": lambda u: pk @ u - (best - tol), "jac": lambda u: pk})
    qp = minimize(
        lambda u: 0.5 * u @ u, res.x, jac=lambda u: u, constraints=cons, method="SLSQP", options={"ftol": 1e-12}
    )
    u = qp.x if qp.success and np.all(b - a @ qp.x >= -tol) else res.x
    return np.asarray(u, float)


def _least_overlap(dirs: np.ndarray, rates: np.ndarray, gaps: np.ndarray, cap: float) -> float:
    """The smallest s (mm) such that some move u within +-cap keeps every gap >= -s: how much too tight the
    fixture's faces are for the part (a linear program; ``cap`` when even that fails)."""
    from scipy.optimize import linprog

    keep = np.isfinite(gaps)
    a = -(rates[keep] @ dirs.T)
    k = len(dirs)
    cost = np.zeros(k + 1)
    cost[-1] = 1.0
    res = linprog(
        cost,
        A_ub=np.hstack([a, -np.ones((len(a), 1))]),
        b_ub=gaps[keep],
        bounds=[(-cap, cap)] * k + [(0, None)],
        method="highs",
    )
    return float(res.x[-1]) if res.status == 0 else cap


def seat_part(fixture: Fixture, part: Shape, config: SeatConfig = SeatConfig()) -> Seat:
    """Seat ``part`` (a solid in the fixture's output frame, mm, e.g. `fixtures_design.assembly.true_part`) in
    ``fixture``: the translation that pushes it home (module docstring). A fixture without ``seating`` raises
    ValueError."""
    if fixture.seating is None:
        raise ValueError(f"the {fixture.kind.value} fixture does not state how a part is seated in it")
    dirs = np.atleast_2d(np.asarray(fixture.seating.directions, float))
    push = unit(fixture.seating.push)
    bound = seat_bound_mm(fixture, config)
    pts, nrm = seat_samples(fixture, config.points)
    rays = _Rays(part, config.reach_mm, config.graze_cos)
    move = np.zeros(3)
    reason = ""
    overlap = 0.0
    for _ in range(config.max_iter):
        g, rate = rays.gaps(pts - move, nrm)
        # A point deeper in the part than the bound is not held by its face (a pin's tip in a hole's floor, a block
        # inside a boss's base): moving along that face cannot clear it, so it does not steer the seat; the cut
        # measured after seating counts it.
        g = np.where(np.isnan(g) | (g < -bound), np.inf, g)
        if not np.isfinite(g).any():
            reason = "no mating face has the part in front of it, or less than the bound inside it"
            break
        u = _solve_move(dirs, push, rate, g, config.reach_mm, 1e-3 * config.tol_mm)
        if u is None:
            overlap = _least_overlap(dirs, rate, g, config.reach_mm)
            reason = (
                f"no move keeps the part clear of the mating faces: wherever it goes, it overlaps them by at least "
                f"{overlap:.2f} mm (the fixture is too tight for it)"
            )
            break
        step = u @ dirs
        move = move + step
        if np.linalg.norm(move) > config.reach_mm:
            reason = f"nothing stops the push within {config.reach_mm:g} mm"
            break
        if np.linalg.norm(step) < config.tol_mm:
            break
    g, _ = rays.gaps(pts - move, nrm)
    fin = g[np.isfinite(g)]
    size = float(np.linalg.norm(move))
    if not reason and size > bound:
        reason = f"the seat moves the part {size:.2f} mm, more than the bound {bound:.2f} mm"
    return Seat(
        move=move,
        move_mm=size,
        push_mm=float(move @ push),
        bound_mm=bound,
        ok=not reason,
        reason=reason,
        min_gap_mm=float(fin.min()) if len(fin) else float("inf"),
        contacts=int((np.abs(fin) <= 0.05).sum()),
        overlap_mm=overlap,
    )
