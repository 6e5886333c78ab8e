"""Pareto front of (J_time, J_trim) by the epsilon-constraint method (paper Eq. 10-11).

:class:`ParetoSolver` is the two-objective use of the N-objective solver
:class:`~.epsilon.EpsilonConstraintSolver` (model, objective, one solve, store,
``solve_at``, Eq. 11 with either nadir rule); what is its own here: the anchors
with their retries, and the 1-D front with the secant predictor.

The NLP is built and written for the solver once. Three objectives are
needed:

- ``time``:   J_time                       (anchor A, the front, anchor B's 2nd stage)
- ``trim``:   J_trim                       (anchor B, 1st stage)
- ``utopia``: Eq. 11 squared, normalised   (the direct choice as one NLP)

One objective serves them all,
    f = w_time J_time + w_trim J_trim + w_utopia [((J_time - U_t) r_t)^2 + ((J_trim - U_r) r_r)^2],
whose weights, utopia values U and inverse ranges r are *variables pinned by
equal bounds*. A solver adapter refreshes bounds on every re-solve, so
switching objective, rescaling it or moving the epsilon bound
(``m.eps_trim``, a mutable Param in a constraint bound) never rewrites the
NL file: every point is a re-solve from the previous point's solution.
Ipopt treats the pinned variables as parameters.

Warm starts (``ParetoSettings.warm_start``): ``"continuation"`` (default)
passes the previous point's primal values *and* multipliers and starts the
barrier parameter at tol/10, so each interior point is a few corrector steps
from its neighbour (2-4 Ipopt iterations per point on the identification
NLPs, against 20-30 with ``"primal"``, the previous default; measured in
docs/performance.md). The multipliers are rescaled when the objective scale
changes (A is scaled by J(theta_0), the front by J_time(A)). A warm solve that
fails is retried once from the same start with the primal warm start, so a
warm start can cost time but never a point. From the third interior point on,
the start is the secant predictor (``ParetoSettings.predictor = "secant"``):
the last two solutions, primal and multipliers, extrapolated linearly in
epsilon, which saves about one Ipopt iteration per point; the steps after the
first one off anchor A keep that start with bound pushes of 1e-8
(``FRONT_STEP_OPTIONS``; docs/performance.md).
Anchor B's two stages start from
a feasible solution (A's, then the first stage's): with ``"continuation"``
their barrier starts at 100 tol instead of Ipopt's 0.1.

Scaling lives at optimizer level only (paper Fig. 4): a single-objective
solve is divided by |J(theta_0)|, and each objective of a multi-objective
solve by its utopia value.

A solve that fails or does not converge is recorded with its status and
never stops the sweep (an anchor included: the sweep goes on from its last
iterate, and the choice only considers converged points). With a
:class:`~pyomo_heli.pareto.store.PointStore`, every finished point is written
to disk as it finishes, and a rerun loads the finished points instead of
solving them (see store.py): the warm-start chain restarts from the last
finished point's stored solution and gives the same numbers.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from .. import interrupts
from ..log import get_logger
from ..solvers import MULTIPLIER_MODES, scale_multipliers
from .epsilon import (FRONT_STEP_OPTIONS, INFEASIBLE, LEAVE_ANCHOR_OPTIONS, NADIR_RULES, EpsilonConstraintSolver,  # noqa: F401
                      pin_objective_settings, solve_with_fallback, utopia_distance_n, _value)
from .epsilon import epsilon_grid as _grid
from .snapshot import Snapshot as _Snapshot
from .steps import retried


@dataclass
class FrontPoint:
    """One solved point: objectives, parameters (SI) and how the solve went."""

    index: int
    kind: str  # "A", "B", "eps", "direct"
    epsilon: float  # bound on J_trim (inf for unconstrained)
    J_time: float
    J_trim: float
    parameters: dict
    success: bool
    status: str
    iterations: int
    wall_time: float
    setup_time: float = 0.0
    warm_start: str = "primal"
    cold_iterations: int | None = None  # filled by the cold check only
    cold_status: str | None = None
    cold_J_time: float | None = None
    cold_wall_time: float | None = None
    multiplier_trim: float = math.nan  # -dJ_time/dJ_trim from the J_trim bound's multiplier (0: inactive; nan: none)

    def row(self) -> dict:
        d = asdict(self)
        params = d.pop("parameters")
        d.update(params)
        return d


WARM_STARTS = ("continuation", "full", "primal", "none")
PREDICTORS = ("secant", "none")
PLACEMENTS = ("uniform", "adaptive")


@dataclass
class ParetoSettings:
    points: int = 11
    spacing: str = "geometric"  # or "linear"
    warm_start: str = "continuation"  # "continuation", "full", "primal" or "none" (module docstring)
    lexicographic_tol: float = 1e-6  # relative slack on J_trim(B) for B's second stage
    solver: str = "casadi-ipopt"
    solver_options: dict = field(default_factory=dict)
    cold_check: bool = False  # also solve every interior point cold, to measure what warm starts save
    predictor: str = "secant"  # start of interior point k>=3: "secant" extrapolation of points k-1, k-2, or "none"
    max_iter: int | None = None  # Ipopt iteration cap of each front point's solve (grid, solve_at); None: the solver's
    nadir: str = "payoff"  # nadir of Eq. 11: "payoff" (anchors) or "nondominated" (front points), pareto.epsilon
    grid: tuple | None = None  # points per bounded objective (tri-objective: (J_trim, J_linear)); from points = [n, m]
    placement: str = "uniform"  # "uniform" epsilon grid of ``points``, or "adaptive" (pareto/placement.py)
    max_solves: int = 14  # "adaptive": front solves, anchors included (the direct Eq. 11 solve is one more)

    def __post_init__(self):
        if isinstance(self.points, (list, tuple)):
            if not self.points or not all(isinstance(n, int) and not isinstance(n, bool) for n in self.points):
                raise ValueError(f"pareto.points must be an integer or a list of integers, got {self.points!r}")
            self.grid, self.points = tuple(self.points), self.points[0]
        if self.grid is not None and any(n < 2 for n in self.grid):
            raise ValueError(f"pareto.points: every axis needs at least 2 points, got {list(self.grid)}")
        if self.points < 2:
            raise ValueError(f"pareto.points must be at least 2 (the two anchors), got {self.points}")
        if self.spacing not in ("geometric", "linear"):
            raise ValueError(f"pareto.spacing must be 'geometric' or 'linear', got {self.spacing!r}")
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"pareto.warm_start must be one of {', '.join(WARM_STARTS)}, got {self.warm_start!r}")
        if self.predictor not in PREDICTORS:
            raise ValueError(f"pareto.predictor must be one of {', '.join(PREDICTORS)}, got {self.predictor!r}")
        if self.nadir not in NADIR_RULES:
            raise ValueError(f"pareto.nadir must be one of {', '.join(NADIR_RULES)}, got {self.nadir!r}")
        if self.max_iter is not None and (isinstance(self.max_iter, bool) or not isinstance(self.max_iter, int)
                                          or self.max_iter < 1):
            raise ValueError(f"pareto.max_iter must be a positive integer, got {self.max_iter!r}")
        if self.placement not in PLACEMENTS:
            raise ValueError(f"pareto.placement must be one of {', '.join(PLACEMENTS)}, got {self.placement!r}")
        if not 4 <= self.max_solves <= 1000:
            raise ValueError(f"pareto.max_solves must be 4 to 1000, got {self.max_solves}")


def epsilon_grid(j_trim_a: float, j_trim_b: float, points: int, spacing: str = "geometric") -> np.ndarray:
    """Bounds from J_trim(A) (inactive) down to J_trim(B), ``points`` values, both ends included."""
    return _grid(j_trim_a, j_trim_b, points, spacing)


def utopia_distance(j_time, j_trim, utopia, nadir) -> np.ndarray:
    """Eq. 11 for (J_time, J_trim): :func:`.epsilon.utopia_distance_n` of the two columns."""
    shape = np.shape(np.asarray(j_time, float))
    J = np.column_stack([np.ravel(np.asarray(j_time, float)), np.ravel(np.asarray(j_trim, float))])
    return utopia_distance_n(J, utopia, nadir).reshape(shape)


class ParetoSolver(EpsilonConstraintSolver):
    """Anchors, front and choice of (J_time, J_trim) on one identification NLP built by nlp.identification.

    The two-objective use of :class:`~.epsilon.EpsilonConstraintSolver`: its own anchors (with the
    retries of a failed anchor and the store), its 1-D front with the secant predictor, and the
    Eq. 11 choice; :meth:`solve_at` (inherited) solves one more point at a J_trim bound.
    """

    point_class = FrontPoint

    def __init__(self, m, settings: ParetoSettings | None = None, on_point=None, store=None):
        settings = settings or ParetoSettings()
        if settings.grid is not None and len(settings.grid) != 1:
            raise ValueError(f"pareto.points: the bi-objective front has one bounded objective, "
                             f"got {list(settings.grid)}")
        super().__init__(m, ("time", "trim"), settings, on_point, store)
        self.s_time, self.s_trim = self.scale["time"], self.scale["trim"]
        self._snap_initial = self.initial_guess
        self.points: list[FrontPoint] = []

    def _pin(self, **values):
        self.pin(**values)

    def _set_objective(self, kind: str, scale: float | None = None, utopia=None, nadir=None):
        self.set_objective(kind, scale, utopia, nadir)
        return self.solver

    def _solve(self, kind, index, point_kind, epsilon, warm_start, options=None, **obj):
        out = self.solve_once(kind, {"trim": epsilon}, warm_start, options, **obj)
        if out.note:
            get_logger("pareto").info(f"point {index} ({point_kind}, eps_trim={epsilon:.6g}): {out.status}: {out.note}")
        return FrontPoint(index=index, kind=point_kind, epsilon=epsilon, J_time=out.J["time"], J_trim=out.J["trim"],
                          parameters=out.parameters, success=out.success, status=out.status,
                          iterations=out.iterations, wall_time=out.wall_time, setup_time=out.setup_time,
                          warm_start=warm_start, multiplier_trim=out.multipliers.get("trim", math.nan))

    def solve_eps(self, index: int, eps: dict, warm_start: str, options=None, grid=()):
        return self._solve("time", index, "eps", float(eps.get("trim", math.inf)), warm_start, options,
                           scale=self.front_scale)

    def _solve_warm(self, kind, index, point_kind, epsilon, start: "_Snapshot", options=None, **obj):
        """A re-solve with the configured warm start, retried with the primal one if it fails (iterations capped)."""
        return solve_with_fallback(lambda ws: self._solve(kind, index, point_kind, epsilon, ws,
                                                          self.capped(options if ws in MULTIPLIER_MODES else None),
                                                          **obj),
                                   self.settings.warm_start, start)

    def solve_objective(self, objective: str = "time", epsilon: float = math.inf, index: int = 0,
                        kind: str = "single", warm_start: str = "none") -> FrontPoint:
        """One solve of min J_time (``"time"``) or J_trim (``"trim"``) s.t. J_trim <= epsilon, from the
        model's current values (multi-start); a failure is returned as a point with its status."""
        return self._solve(objective, index, kind, epsilon, warm_start)

    def point_a(self) -> FrontPoint:
        """Anchor A alone (min J_time, the classic time-domain estimate) from the model's current values."""
        return self._solve("time", 0, "A", math.inf, "none")

    def anchors(self) -> tuple[FrontPoint, FrontPoint]:
        """A: min J_time. B: min J_trim, then min J_time keeping J_trim at its minimum (lexicographic).

        An anchor that does not converge is retried: B (first from A's solution) once cold, from the
        initial guess; A (first cold) once from B's solution. The attempts are summed into the point
        (iterations, wall time) and named in its ``warm_start``. An anchor still failing is recorded
        with its status (``success`` False); :meth:`anchor_failures` names it, and everything derived
        from the anchors (utopia, nadir, epsilon grid, the Eq. 11 choice) is then unreliable.

        A is written to the store once its outcome is final (after B, when A needs the retry), so a
        resumed run repeats exactly the attempts of an uninterrupted one.
        """
        self.minima, self._infeasible, self._witnesses = {}, [], []  # known again once B is (a rerun may find
        # another minimum; a Monte Carlo realization has other data)
        a_final = self.store is not None and self.store.has("A")
        if a_final:
            a = self.solve_point("A", self.point_a)
        else:
            a = self._unstored("A", self.point_a)
            if a.success:
                self._save("A", a)
                a_final = True
        snap_a = _Snapshot(self.m)

        def two_stages(options, scale):
            b1 = self._solve("trim", -1, "B1", math.inf, "primal", options)
            eps_b = b1.J_trim * (1 + self.settings.lexicographic_tol) + 1e-12
            b = self._solve("time", self.settings.points - 1, "B", eps_b, "primal", options, scale=scale)
            b.iterations += b1.iterations
            b.wall_time += b1.wall_time
            b.setup_time += b1.setup_time
            if not b1.success:
                b.success, b.status = False, f"first stage (min J_trim): {b1.status}; second stage: {b.status}"
            return b

        def solve_b():
            scale = self._front_scale(a)
            if not a.success:  # A's last iterate is no start: B cold, from the initial guess
                self._snap_initial.restore()
                b = two_stages(None, scale)
                b.warm_start = "none"
                return b
            # both stages start from a feasible solution (A's, then the first stage's)
            b = two_stages(self._near_start_options(), scale)
            if b.success:
                return b
            self._snap_initial.restore()  # retry cold
            return _retried(b, two_stages(None, scale), "none")

        b = self.solve_point("B", solve_b)
        snap_b = _Snapshot(self.m)
        if not a_final:
            if b.success:  # retry A from B's solution (in the model now, solved or loaded)
                a = self._unstored("A", lambda: _retried(a, self._solve("time", 0, "A", math.inf, "primal"),
                                                          "primal from anchor B"))
            else:
                snap_a.restore()  # the stored values of a failed A are its last iterate
            self._save("A", a)
            snap_a = _Snapshot(self.m)
        self._snap_a, self._snap_b = snap_a, snap_b
        self.anchor_points = {"A": a, "B": b}
        if b.success and math.isfinite(b.J_trim):  # at most J_trim's own minimum (B's bound is min (1 + tol) + 1e-12)
            self.minima["trim"] = (b.J_trim - 1e-12) / (1 + self.settings.lexicographic_tol)
        return a, b

    def _unstored(self, key: str, solve) -> FrontPoint:
        """``solve()`` without storing; an interrupt names ``key`` as the point being solved."""
        try:
            return solve()
        except interrupts.Interrupted as exc:
            exc.point = exc.point or key
            raise

    def anchor_failures(self) -> list[str]:
        """One line per anchor that did not converge after its retries (empty when both did)."""
        return [f"anchor {p.kind} did not converge ({p.status}; attempts: {p.warm_start})"
                for p in self.points if p.kind in ("A", "B") and not p.success]

    def _front_scale(self, a: FrontPoint) -> float:
        """Objective scale of the multi-objective solves: J_time at its utopia value (anchor A)."""
        return max(abs(a.J_time), 1.0) if math.isfinite(a.J_time) else self.s_time

    def front(self) -> list[FrontPoint]:
        """Anchors, then the interior points from A towards B, each warm-started from the previous.

        Each point is handed to ``on_point`` as soon as it is finished (A, B,
        then the interior points). A failed point is recorded with its status
        and the sweep goes on from the last point that succeeded (from the
        initial guess if that is none).
        """
        s = self.settings
        if s.placement != "uniform":  # never a uniform grid silently in place of the configured placement
            raise ValueError(f"pareto.placement = {s.placement!r}: ParetoSolver.front() traces the uniform grid; "
                             f"the adaptive placement runs through pareto.placement.AdaptiveFront (identify)")
        a, b = self.anchors()
        self.points = [a, b]
        self.snapshots = {a.index: self._snap_a, b.index: self._snap_b}
        self.on_point(a)
        self.on_point(b)
        eps = epsilon_grid(a.J_trim, b.J_trim, s.points, s.spacing)
        last_good = self._snap_a if a.success else self._snap_initial
        last_good.restore()
        # objectives of multi-objective solves are scaled by their utopia value; A's multipliers
        # belong to A's scale (J(theta_0))
        scale = self._front_scale(a)
        scale_multipliers(self.m, self.s_time / scale)
        last_good = _Snapshot(self.m)
        self.front_scale, self._solved, self._infeasible = scale, [(self.loosest(), last_good)], []
        previous = None  # (snapshot, epsilon) of the interior point before last_good, for the predictor
        leaving = True  # the next start is anchor A's solution (no interior point solved yet)
        for k in range(1, s.points - 1):
            start = last_good
            if previous is not None and s.predictor == "secant" and s.warm_start != "none":
                # the front is smooth in epsilon: extrapolating the last two solutions lands nearer to
                # the next one than the last solution does (docs/performance.md)
                (snap_prev, eps_prev), eps_last = previous, float(eps[k - 1])
                start = last_good.extrapolated(snap_prev, (float(eps[k]) - eps_last) / (eps_last - eps_prev))
                start.restore()

            def solve_k(k=k, start=start, leaving=leaving):
                step = FRONT_STEP_OPTIONS if s.warm_start == "continuation" else None
                p = self._solve_warm("time", k, "eps", float(eps[k]), start,
                                     LEAVE_ANCHOR_OPTIONS if leaving else step, scale=scale)
                if s.cold_check:
                    self._cold_check(p, scale=scale)
                return p

            p = self.solve_point(f"eps{k:03d}", solve_k)
            if p.success:
                previous = (last_good, float(eps[k - 1])) if k > 1 and self.points[-1].success else None
                last_good = self.snapshots[k] = _Snapshot(self.m)
                self._solved.append(((float(eps[k]),), last_good))
                leaving = False
            else:
                if p.status == INFEASIBLE:
                    self._infeasible.append((float(eps[k]),))
                previous = None
                last_good.restore()
            self.points.append(p)
            self.on_point(p)
        if b.success:
            self._solved.append(((b.J_trim,), self._snap_b))
        self.points.sort(key=lambda p: p.index)
        return self.points

    def anchor_a_start(self) -> _Snapshot:
        """Anchor A's solution with its multipliers rescaled to the front's objective scale (as :meth:`front`
        does before its first step): the start of a step off A. Call after :meth:`anchors`, with
        ``self.points`` holding A."""
        a = next(p for p in self.points if p.kind == "A")
        self._snap_a.restore()
        scale_multipliers(self.m, self.s_time / self._front_scale(a))
        return _Snapshot(self.m)

    def solve_epsilon(self, epsilon: float, index: int, start: _Snapshot, leaving: bool = False) -> FrontPoint:
        """One front point: min J_time s.t. J_trim <= ``epsilon``, from ``start`` with the configured warm start
        (``leaving``: the start is anchor A, :data:`LEAVE_ANCHOR_OPTIONS`), retried primal if it fails. The
        per-epsilon solve of the adaptive placement (pareto/placement.py); ``self.points`` must hold A."""
        s = self.settings
        start.restore()
        step = FRONT_STEP_OPTIONS if s.warm_start == "continuation" else None
        scale = self._front_scale(next(p for p in self.points if p.kind == "A"))
        return self._solve_warm("time", index, "eps", float(epsilon), start,
                                LEAVE_ANCHOR_OPTIONS if leaving else step, scale=scale)

    def restore_initial_guess(self) -> None:
        """Put the model's values back to the initial guess it had when this solver was made (cold starts)."""
        self._snap_initial.restore()

    def _cold_check(self, p: FrontPoint, scale: float) -> None:
        """Solve the same epsilon point from the initial guess; keep the warm solution in the model."""
        warm = _Snapshot(self.m)
        self.restore_initial_guess()
        cold = self._solve("time", p.index, "eps", p.epsilon, "none", scale=scale)
        p.cold_iterations, p.cold_status, p.cold_J_time = cold.iterations, cold.status, cold.J_time
        p.cold_wall_time = cold.wall_time
        warm.restore()

    # ------------------------------------------------------------- choosing
    def payoff_utopia_nadir(self):
        """Utopia (J_time(A), J_trim(B)) and the payoff-table nadir (J_time(B), J_trim(A))."""
        a = next(p for p in self.points if p.kind == "A")
        b = next(p for p in self.points if p.kind == "B")
        return (a.J_time, b.J_trim), (b.J_time, a.J_trim)

    def choose(self, rule: str | None = None) -> tuple[FrontPoint | None, np.ndarray]:
        """The converged front point closest to utopia (Eq. 11, post hoc), and all distances.

        None when no point converged. ``rule``: the nadir rule (default ``settings.nadir``).
        """
        p, d, _, _ = self.eq11(rule)
        return p, d

    direct_index = -1  # the direct Eq. 11 solve's point

    def _direct_once(self, utopia, nadir) -> FrontPoint:
        return self._solve("utopia", self.direct_index, "direct", math.inf, "primal", utopia=utopia, nadir=nadir)

    def _snapshot_of(self, p: FrontPoint):
        return self.snapshots.get(p.index)


def _retried(first: FrontPoint, retry: FrontPoint, how: str) -> FrontPoint:
    """The retry of a failed anchor, with both attempts' iterations and times; ``warm_start`` names them."""
    return retried(first, retry, f"{first.warm_start} ({first.status}), then {how}")
