"""Adaptive epsilon placement: points where the front bends and where Eq. 11 chooses (issue 31 point 5).

A uniform epsilon grid samples an L-shaped front badly: on Case 1 nine of
eleven points sat on the flat arm and none in the knee, where the Eq. 11
choice lies. ``[pareto] placement = "adaptive"`` places the points instead:

1. **Anchors and a seed.** A and B, then one seed point in the middle of the
   epsilon range (``[pareto] spacing``).
2. **Normalised arc length.** Each objective is scaled by utopia U and nadir N,
   ``z_i = (f_i - U_i) / (N_i - U_i)`` (paper Eq. 11), and the front is
   interpolated linearly between the solved points. Its *edges* join points
   that are neighbours in the constrained objectives (the epsilon coordinates
   ``z_2 .. z_N``: sorted for two objectives, a Delaunay triangulation for
   more). The next epsilon is the midpoint of the longest edge in normalised
   objective space, so the points go where the front is long, not where the
   epsilon range is. This phase takes half of ``max_solves``.
3. **Refinement around the Eq. 11 choice.** The converged point C closest to U
   and its neighbours on the front bracket the minimum of the distance (a
   distance unimodal along the front). While a neighbour differs from C by more
   than one of C's standard errors in some parameter, a probe is placed on that
   edge: on the side where a parabola of the distance over the arc length
   through C and its neighbours has its minimum, at that minimum; on the other
   side at the fraction ``0.9 / r`` of the edge to a neighbour ``r`` standard
   errors away, so that it lands about 0.9 standard errors from C if the
   parameters are linear along the edge. A probe closer to U becomes C. Refinement stops
   when both neighbours lie within one standard error of C in every parameter:
   no further point can move the choice by more than its own standard error
   (the *bracket* criterion). It also stops at ``max_solves`` (reported as not
   converged) or when an edge cannot be split any more.

Three or more objectives: :mod:`.placement_nd` (anchors and a coarse grid, then the same refinement
in the plane of epsilon coordinates, with the same settings).

The functions below are pure functions of normalised objective points
(arrays ``(points, objectives)``); :class:`AdaptiveFront` is the driver that
solves the points through the narrow interface of a front solver:
``anchors()``, ``solve_point(key, solve)`` (the run folder's store: a resumed
run loads finished points and places the next ones exactly as the first run
did), ``solve_epsilon(epsilon, index, start, leaving)`` and
``anchor_a_start()``. Standard errors come from a callable (the Cramer-Rao
machinery of :mod:`pyomo_heli.uncertainty`, passed in by the workflow).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..log import get_logger
from .snapshot import Snapshot

#: epsilon coordinates (normalised) closer than this to a solved or tried point are not placed again
MIN_STEP = 1e-6
#: a parameter without a standard error (at a bound) counts as unmoved within this relative change
NO_SE_RTOL = 1e-9


# ----------------------------------------------------------------------------- pure functions
def normalise(F, utopia, nadir) -> np.ndarray:
    """``(F - U) / (N - U)`` per objective (Eq. 11's scaling); F is ``(points, objectives)``."""
    F = np.atleast_2d(np.asarray(F, float))
    U, N = np.asarray(utopia, float), np.asarray(nadir, float)
    span = N - U
    if np.any(~np.isfinite(span)) or np.any(span <= 0):
        raise ValueError(f"degenerate front: nadir - utopia = {span.tolist()} (the anchors coincide in an objective)")
    return (F - U) / span


def denormalise(z, utopia, nadir, columns) -> np.ndarray:
    """Objective values of normalised coordinates ``z`` of the objectives ``columns``."""
    U, N = np.asarray(utopia, float)[columns], np.asarray(nadir, float)[columns]
    return U + np.asarray(z, float) * (N - U)


def front_edges(Z) -> list[tuple[int, int]]:
    """Pairs of points that are neighbours on the front, by their epsilon coordinates ``Z[:, 1:]``.

    Two objectives: consecutive points in the order of ``z_2``. More: the edges
    of a Delaunay triangulation of ``Z[:, 1:]`` (scipy); with too few or
    collinear points, the points in the order of their first epsilon coordinate.
    """
    Z = np.asarray(Z, float)
    n = len(Z)
    if n < 2:
        return []
    E = Z[:, 1:]
    if E.shape[1] >= 2 and n > E.shape[1] + 1:
        from scipy.spatial import Delaunay, QhullError

        try:
            tri = Delaunay(E)
        except QhullError:
            pass
        else:
            edges = set()
            for s in tri.simplices:
                for a in range(len(s)):
                    for b in range(a + 1, len(s)):
                        edges.add((int(min(s[a], s[b])), int(max(s[a], s[b]))))
            # a point Qhull left out (it coincides with a vertex): joined to that vertex and to its neighbours
            for q, v in np.asarray(tri.coplanar, int).reshape(-1, 3)[:, [0, 2]]:
                q, v = int(q), int(v)
                near = {v} | {j if i == v else i for i, j in edges if v in (i, j)}
                edges |= {(min(q, k), max(q, k)) for k in near if k != q}
            return sorted(edges)
    order = np.lexsort(E.T[::-1])
    return [(int(order[k]), int(order[k + 1])) for k in range(n - 1)]


def _placed(e, taken) -> bool:
    return any(np.max(np.abs(np.asarray(e) - np.asarray(t))) < MIN_STEP for t in taken)


def largest_gap(Z, taken=()) -> tuple[tuple[int, int], np.ndarray] | None:
    """The longest front edge (normalised Euclidean length) and the epsilon coordinates of its midpoint.

    ``taken``: epsilon coordinates already placed (solved or tried); an edge
    whose midpoint lies within ``MIN_STEP`` of one is skipped (a gap in the
    front that a solve cannot fill). None when no edge can be split.
    """
    Z = np.asarray(Z, float)
    taken = list(taken) + [z[1:] for z in Z]
    best = None
    for i, j in front_edges(Z):
        mid = 0.5 * (Z[i, 1:] + Z[j, 1:])
        if _placed(mid, taken):
            continue
        length = float(np.linalg.norm(Z[i] - Z[j]))
        if best is None or length > best[0]:
            best = (length, (i, j), mid)
    return None if best is None else (best[1], best[2])


def chosen_point(Z) -> int:
    """Index of the point closest to the utopia point (Eq. 11: the norm of the normalised objectives)."""
    return int(np.argmin(np.linalg.norm(np.asarray(Z, float), axis=1)))


def neighbours(Z, c: int) -> list[int]:
    """The points that bracket point ``c`` on the front: for two objectives those sharing a front edge with
    it, for more its :func:`~.placement_nd.cone_neighbours`."""
    Z = np.asarray(Z, float)
    if Z.shape[1] <= 2:
        return sorted({j if i == c else i for i, j in front_edges(Z) if c in (i, j)})
    from .placement_nd import cone_neighbours

    return sorted(j for kind, j in cone_neighbours(Z, c) if kind == "point")


def distance_in_se(theta_from: dict, theta_to: dict, se: dict) -> float:
    """max over parameters of ``|theta_to - theta_from| / se`` (the move in standard errors).

    A parameter with an infinite standard error (not determined) counts 0; one
    without a standard error (nan, at a bound) counts 0 if it did not move
    (relative ``NO_SE_RTOL``), else inf.
    """
    r = 0.0
    for n, s in se.items():
        d = abs(float(theta_to[n]) - float(theta_from[n]))
        if s is not None and s == math.inf:  # not determined by the data: any move is within it
            continue
        if s is not None and math.isfinite(s) and s > 0:
            r = max(r, d / s)
        elif d > NO_SE_RTOL * (1.0 + abs(float(theta_from[n]))):
            r = math.inf
    return r


def probe_fraction(r: float) -> float:
    """How far along the edge from C towards a neighbour ``r`` standard errors away (r > 1) a probe that
    should land about 0.9 standard errors from C goes, if the parameters are linear along the edge:
    ``0.9 / r``, kept within [0.02, 0.5] (the midpoint for a neighbour without a finite distance)."""
    return 0.5 if not math.isfinite(r) else min(max(0.9 / r, 0.02), 0.5)


def predicted_minimum(Z, c: int, nbrs) -> tuple[int, float] | None:
    """Where the Eq. 11 distance is least between C's two neighbours: (the neighbour on whose side, the
    fraction of C's edge to it), from the parabola through the three distances over the normalised arc
    length; None for more or fewer than two neighbours or more than two objectives."""
    Z = np.asarray(Z, float)
    if len(nbrs) != 2 or Z.shape[1] != 2:
        return None
    left, right = nbrs
    s = np.array([-np.linalg.norm(Z[c] - Z[left]), 0.0, np.linalg.norm(Z[right] - Z[c])])
    d = np.linalg.norm(Z[[left, c, right]], axis=1)
    if s[0] == 0.0 or s[2] == 0.0:
        return None
    a = np.polyfit(s, d, 2)
    if a[0] <= 0:
        return None
    vertex = -a[1] / (2 * a[0])
    return (right, vertex / s[2]) if vertex > 0 else (left, vertex / s[0])


def refinement_probes(Z, c: int, r_neighbours: dict, taken=()) -> list[np.ndarray]:
    """Epsilon coordinates of the probes on C's edges to the neighbours more than one SE away.

    ``r_neighbours``: neighbour index -> distance from C in C's standard errors
    (:func:`distance_in_se`). On the side where the parabola of :func:`predicted_minimum` puts the
    minimum, the probe goes there (kept within 5-95 % of the edge, and no nearer C than
    :func:`probe_fraction`); on the other side, or without a prediction, at :func:`probe_fraction`,
    so that it lands within about one standard error of C. Probes within ``MIN_STEP`` of a placed
    point are left out.
    """
    Z = np.asarray(Z, float)
    taken = list(taken) + [z[1:] for z in Z]
    pred = predicted_minimum(Z, c, sorted(r_neighbours))
    out = []
    for n, r in sorted(r_neighbours.items()):
        if r <= 1.0:
            continue
        t = probe_fraction(r)
        if pred is not None and pred[0] == n:
            t = min(max(pred[1], t, 0.05), 0.95)
        e = Z[c, 1:] + t * (Z[n, 1:] - Z[c, 1:])
        if not _placed(e, taken + out):
            out.append(e)
    return out


# ----------------------------------------------------------------------------- driver
@dataclass
class RefinementRound:
    """One look at the chosen point C during refinement."""

    solves: int  # front solves so far (anchors included)
    chosen: int  # C's point index
    move_se: float | None  # how far C moved since the previous round, in C's standard errors (None: first round)
    bracket_se: float  # the farthest neighbour of C, in C's standard errors


@dataclass
class PlacementSummary:
    """How the adaptive placement went (chosen.json ``info.placement``)."""

    placement: str = "adaptive"
    max_solves: int = 0
    solves: int = 0  # front solves, anchors included (the direct Eq. 11 solve is not one of them)
    arc_length_solves: int = 0  # anchors, seed and arc-length points (more objectives: anchors and coarse grid)
    refinement_solves: int = 0
    converged: bool = False  # C's neighbours within one of its standard errors in every parameter
    direct_se: float | None = None  # the direct Eq. 11 solve's distance from C, in C's standard errors
    stop: str = ""
    rounds: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)

    def line(self, first: str = "by arc length") -> str:
        last = self.rounds[-1] if self.rounds else None
        return (f"adaptive placement: {self.solves} front solves ({self.arc_length_solves} {first}, "
                f"{self.refinement_solves} refining around the Eq. 11 choice; cap {self.max_solves}); "
                + (f"chosen point {last.chosen}, neighbours within {last.bracket_se:.3g} of its standard errors, "
                   if last else "") + f"{'converged' if self.converged else 'NOT converged'}: {self.stop}")


class AdaptiveFront:
    """Anchors, seed, arc-length points and refinement on a front solver.

    ``solver``: a :class:`~pyomo_heli.pareto.front.ParetoSolver` (used through
    ``anchors``, ``solve_point``, ``solve_epsilon``, ``anchor_a_start``,
    ``utopia_nadir`` and its ``points``/``snapshots``). ``standard_errors(point)``
    -> {parameter: standard error} at a converged point. ``objectives``: the
    point attributes, the minimised one first; the epsilon coordinates are the
    others (a scalar epsilon for two objectives, a list for more). The anchors
    are the two-objective solver's A and B so far.
    """

    objectives = ("J_time", "J_trim")
    first_phase = "by arc length"  # the summary line's name of the points before the refinement
    sort_points = True  # the solver's points by index at the end (A 0, B 1, then in the order solved)

    def __init__(self, solver, max_solves: int, standard_errors, spacing: str = "geometric", on_point=None,
                 progress=None):
        if max_solves < 4:
            raise ValueError(f"pareto.max_solves must be at least 4 (two anchors, a seed, one more), got {max_solves}")
        self.ps = solver
        self.max_solves = int(max_solves)
        self.standard_errors = standard_errors
        self.spacing = spacing
        self.on_point = on_point or (lambda p: None)
        self.progress = progress or get_logger("pareto").info
        self.taken: list[np.ndarray] = []  # normalised epsilon coordinates tried (also failed solves)
        self._se: dict[int, dict] = {}
        self.summary = PlacementSummary(max_solves=self.max_solves)

    # -- helpers
    def _F(self, points) -> np.ndarray:
        return np.array([[getattr(p, o) for o in self.objectives] for p in points], float)

    def _ok(self):
        return [p for p in self.ps.points if p.success and np.all(np.isfinite(self._F([p])))]

    def _se_of(self, p) -> dict:
        if p.index not in self._se:
            self._se[p.index] = dict(self.standard_errors(p))
        return self._se[p.index]

    def _solve(self, eps) -> None:
        """One epsilon point (``eps``: the bounds on the constrained objectives ``objectives[1:]``), warm
        from the converged point nearest in normalised epsilon coordinates."""
        ps = self.ps
        k = len(ps.points)  # index: A 0, B 1, then the order of solving
        eps = np.atleast_1d(np.asarray(eps, float))
        U, N = np.asarray(self.utopia, float), np.asarray(self.nadir, float)
        e = (eps - U[1:]) / (N[1:] - U[1:])
        self.taken.append(e)
        ok = self._ok()
        zs = normalise(self._F(ok), U, N)[:, 1:]
        near = ok[int(np.argmin(np.linalg.norm(zs - e, axis=1)))]
        start = self._start_a if near.kind == "A" else ps.snapshots[near.index]
        epsilon = float(eps[0]) if len(eps) == 1 else eps.tolist()  # as the solver takes it
        key = f"ada{k:03d}"
        p = ps.solve_point(key, lambda: ps.solve_epsilon(epsilon, k, start, leaving=near.kind == "A"))
        if getattr(p, "from_disk", False) and not np.array_equal(np.atleast_1d(p.epsilon), eps):
            from .store import StoreMismatchError

            raise StoreMismatchError(f"{ps.store.dir / key}.npz: stored at epsilon {p.epsilon!r}, but this run places "
                                     f"point {k} at {epsilon!r} (another placement made the stored points); rerun "
                                     f"with --restart to discard them")
        ps.snapshots[k] = Snapshot(ps.m) if p.success else None
        ps.points.append(p)
        self.on_point(p)

    # -- the run
    def run(self):
        ps, s = self.ps, self.summary
        a, b = ps.anchors()
        ps.points = [a, b]
        ps.snapshots = {a.index: ps._snap_a if hasattr(ps, "_snap_a") else None, b.index: getattr(ps, "_snap_b", None)}
        self.on_point(a)
        self.on_point(b)
        self.utopia, self.nadir = ps.utopia_nadir()
        if not (a.success and b.success):
            s.stop = "an anchor did not converge: no placement"
            return self._finish()
        try:
            normalise(self._F([a, b]), self.utopia, self.nadir)
        except ValueError as exc:
            s.stop = str(exc)
            return self._finish()
        self._start_a = ps.anchor_a_start()
        # seed: the middle of each epsilon range (from nadir to utopia, ``spacing`` as the uniform grid)
        from .front import epsilon_grid

        n = len(self.objectives)
        self._solve([epsilon_grid(self.nadir[j], self.utopia[j], 3, self.spacing)[1] for j in range(1, n)])
        arc_budget = max(3, self.max_solves // 2)
        while len(ps.points) < arc_budget:
            gap = largest_gap(self._normalised(), self.taken)
            if gap is None:
                break
            self._solve(denormalise(gap[1], self.utopia, self.nadir, list(range(1, n))))
        s.arc_length_solves = len(ps.points)
        self._refine()
        return self._finish()

    def _scaling(self):
        """(utopia, nadir) for this look at the front: the anchors', fixed."""
        return self.utopia, self.nadir

    def _taken(self) -> list:
        """Epsilon coordinates tried, normalised as the front is now."""
        return self.taken

    def _place(self, e) -> None:
        """Solve the point at the normalised epsilon coordinates ``e``."""
        self._solve(denormalise(e, self.utopia, self.nadir, list(range(1, len(self.objectives)))))

    def _bracket(self, Z, c, ok, se):
        """({neighbour: distance from C in C's standard errors}, [(edge, its estimated distance)]) of C."""
        return {n: distance_in_se(ok[c].parameters, ok[n].parameters, se) for n in neighbours(Z, c)}, []

    def _confirmation(self, Z, c):
        """A point that could still beat a bracketed C (placed before the refinement stops), or None: none here."""
        return None

    def _probes(self, Z, c, r, gaps, use_model):
        """(the points to place next, whether they are a model's minimum): the bracket probes."""
        return refinement_probes(Z, c, r, self._taken()), False

    def _normalised(self):
        return normalise(self._F(self._ok()), self.utopia, self.nadir)

    def _look(self, previous):
        """One refinement round's look at the front: (converged points, Z, C, {neighbour: SE distance},
        [(infeasible edge, SE distance)], round)."""
        ps, s = self.ps, self.summary
        self._scaling()
        ok = self._ok()
        Z = normalise(self._F(ok), self.utopia, self.nadir)
        c = chosen_point(Z)
        se = self._se_of(ok[c])
        r, gaps = self._bracket(Z, c, ok, se)
        move = None if previous is None else distance_in_se(previous.parameters, ok[c].parameters, se)
        rnd = RefinementRound(solves=len(ps.points), chosen=ok[c].index, move_se=move,
                              bracket_se=max(list(r.values()) + [g for _, g in gaps], default=0.0))
        s.rounds.append(rnd)
        self.progress(f"  refinement: chosen point {rnd.chosen}"
                      + (f" moved {move:.3g} standard errors;" if move is not None else ";")
                      + f" its neighbours lie within {rnd.bracket_se:.3g} of its standard errors")
        return ok, Z, c, r, gaps, rnd

    def _refine(self):
        """Rounds until C's neighbours lie within one of its standard errors, each placing :meth:`_probes`.
        ``use_model`` (for solvers that model the distance, :mod:`.placement_nd`): in the first round, after a
        round that moved C, and after a model's point that became C. A bracketed C is first checked once by
        :meth:`_confirmation` (again only after other points were placed)."""
        ps, s = self.ps, self.summary
        previous, model_point, confirming = None, None, False
        while True:
            ok, Z, c, r, gaps, rnd = self._look(previous)
            use_model = (ok[c].index == model_point if model_point is not None
                         else previous is None or ok[c].index != previous.index)
            previous, model_point = ok[c], None
            e = self._confirmation(Z, c) if rnd.bracket_se <= 1.0 and not confirming else None
            if rnd.bracket_se <= 1.0 and e is None:
                s.converged, s.stop = True, "the chosen point's neighbours lie within one of its standard errors"
                return
            confirming = e is not None  # one check of a bracket, until other points are placed
            probes, from_model = ([e], True) if e is not None else self._probes(Z, c, r, gaps, use_model)
            if not probes:
                s.stop = "the chosen point's edges cannot be split further"
                return
            placed = False
            for e in probes:
                if len(ps.points) >= self.max_solves:
                    s.stop = f"cap of {self.max_solves} front solves reached"
                    if placed:  # the summary's last round must name the chosen point of the front as it ends
                        self._look(previous)
                    return
                self._place(e)
                placed = True
            if from_model:
                model_point = ps.points[-1].index

    def compare_direct(self, chosen, direct) -> float | None:
        """The direct Eq. 11 solve's distance from the chosen point in the chosen point's standard errors
        (kept in the summary); None if the direct solve failed."""
        if chosen is None or direct is None or not direct.success:
            return None
        self.summary.direct_se = distance_in_se(chosen.parameters, direct.parameters, self._se_of(chosen))
        self.progress(f"  direct Eq. 11 solve: {self.summary.direct_se:.3g} standard errors of the chosen point "
                      f"{chosen.index} from it (max over parameters); {self.summary.solves} front solves + 1 direct")
        return self.summary.direct_se

    def _finish(self):
        s = self.summary
        s.solves = len(self.ps.points)
        s.refinement_solves = s.solves - s.arc_length_solves if s.arc_length_solves else 0
        if self.sort_points:
            self.ps.points.sort(key=lambda p: p.index)
        self.progress("  " + s.line(self.first_phase))
        return self.ps.points
