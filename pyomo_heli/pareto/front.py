"""Pareto front of (J_time, J_trim) by the epsilon-constraint method (paper Eq. 10-11).

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
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import pyomo.environ as pyo

from .. import interrupts
from ..log import get_logger
from ..nlp.parameters import free_parameter_values
from ..nlp.scaling import apply_scaling
from ..solvers import MULTIPLIER_MODES, SolverError, make_solver, scale_multipliers
from .snapshot import Snapshot as _Snapshot


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

    def row(self) -> dict:
        d = asdict(self)
        params = d.pop("parameters")
        d.update(params)
        return d


WARM_STARTS = ("continuation", "full", "primal", "none")
PREDICTORS = ("secant", "none")


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

    def __post_init__(self):
        if self.points < 2:
            raise ValueError(f"pareto.points must be at least 2 (the two anchors), got {self.points}")
        if self.spacing not in ("geometric", "linear"):
            raise ValueError(f"pareto.spacing must be 'geometric' or 'linear', got {self.spacing!r}")
        if self.warm_start not in WARM_STARTS:
            raise ValueError(f"pareto.warm_start must be one of {', '.join(WARM_STARTS)}, got {self.warm_start!r}")
        if self.predictor not in PREDICTORS:
            raise ValueError(f"pareto.predictor must be one of {', '.join(PREDICTORS)}, got {self.predictor!r}")


def epsilon_grid(j_trim_a: float, j_trim_b: float, points: int, spacing: str = "geometric") -> np.ndarray:
    """Bounds from J_trim(A) (inactive) down to J_trim(B), ``points`` values, both ends included."""
    if j_trim_b <= 0 or spacing == "linear":
        return np.linspace(j_trim_a, j_trim_b, points)
    return np.geomspace(j_trim_a, j_trim_b, points)


def utopia_distance(j_time, j_trim, utopia, nadir) -> np.ndarray:
    """Eq. 11: normalised distance to the utopia point."""
    jt = (np.asarray(j_time, float) - utopia[0]) / (nadir[0] - utopia[0])
    jr = (np.asarray(j_trim, float) - utopia[1]) / (nadir[1] - utopia[1])
    return np.sqrt(jt**2 + jr**2)


#: Options of a step that starts from anchor A (the first interior point, or the next one while
#: every earlier one failed). There the active set changes (the epsilon bound becomes
#: active, a parameter at its bound in A may leave it), and the small bound pushes of a warm start
#: pin the iterate: with 1e-6 that step took 20 Ipopt iterations, with Ipopt's default 1e-3 four,
#: while the later steps take 3 with 1e-6 and 5 with 1e-3 (Case 1, full size, docs/performance.md).
LEAVE_ANCHOR_OPTIONS = {"warm_start_bound_push": 1e-3, "warm_start_mult_bound_push": 1e-3}

#: Options of the later steps with ``"continuation"``: the start is (nearly) the solution, on the same
#: active set, so it is left where it is: bound and slack pushes 1e-8 instead of 1e-6 (primal) and 1e-3
#: (fractions and slacks). Case 1, full size, with the secant predictor: 29 -> 25 iterations over the
#: 9 interior points, the same front (studies/warm_start_study.py, docs/performance.md).
FRONT_STEP_OPTIONS = {"warm_start_bound_push": 1e-8, "warm_start_mult_bound_push": 1e-8,
                      "warm_start_slack_bound_push": 1e-8, "warm_start_bound_frac": 1e-8,
                      "warm_start_slack_bound_frac": 1e-8}


def solve_with_fallback(solve, mode: str, start: _Snapshot):
    """``solve(mode)``; if a multiplier warm start fails, once more from ``start`` with ``solve("primal")``.

    A warm start from a neighbouring solution can mislead the barrier method
    (see ../shared/research/solvers.md: a full warm start stalled on a 50k
    problem); the primal re-solve is the robust fallback. The returned point's
    iterations and wall time include both attempts, and its ``warm_start``
    says what happened.
    """
    p = solve(mode)
    if p.success or mode not in MULTIPLIER_MODES:
        return p
    start.restore()
    retry = solve("primal")
    retry.iterations += max(p.iterations, 0)
    retry.wall_time += p.wall_time
    retry.setup_time += p.setup_time
    retry.warm_start = f"{mode} ({p.status}), then primal"
    return retry


def pin_objective_settings(m, **values) -> None:
    """Pin every objective setting of ``m.objective_settings`` (unnamed ones to 0) by equal bounds."""
    w = m.objective_settings
    for k in w:
        v = float(values.get(k, 0.0))
        w[k].setlb(v)
        w[k].setub(v)
        w[k].set_value(v)


class ParetoSolver:
    """Anchors, front and choice on one identification NLP built by nlp.identification."""

    def __init__(self, m, settings: ParetoSettings | None = None, on_point=None, store=None):
        self.m = m
        self.settings = settings or ParetoSettings()
        self.on_point = on_point or (lambda p: None)
        self.store = store  # a PointStore: finished points to disk, resume from them
        self.s_time = max(abs(pyo.value(m.J_time)), 1.0)
        self.s_trim = max(pyo.value(m.J_trim), 1e-12)
        m.del_component("eps_con")
        m.eps_con = pyo.Constraint(expr=m.J_trim / self.s_trim <= m.eps_trim)
        names = ("w_time", "w_trim", "w_utopia", "U_time", "U_trim", "r_time", "r_trim")
        m.objective_settings = pyo.Var(names, initialize=0.0)
        w = m.objective_settings
        utopia = ((m.J_time - w["U_time"]) * w["r_time"]) ** 2 + ((m.J_trim - w["U_trim"]) * w["r_trim"]) ** 2
        if m.component("objective") is not None:
            m.objective.deactivate()
        m.selected_objective = pyo.Objective(expr=w["w_time"] * m.J_time + w["w_trim"] * m.J_trim
                                             + w["w_utopia"] * utopia)
        self._pin(w_time=1.0 / self.s_time)
        self._snap_initial = _Snapshot(m)
        log = get_logger("pareto")
        log.info(f"setting up solver {self.settings.solver} (NL file, casadi functions; the first solve adds the "
                 f"derivatives): up to minutes on a full-size problem")
        t0 = time.perf_counter()
        apply_scaling(m, self.settings.solver, self.settings.solver_options)  # IDAES Scaler, when asked for
        self.solver = make_solver(m, self.settings.solver, self.settings.solver_options)
        log.debug(f"solver object made in {time.perf_counter() - t0:.1f} s")
        self.points: list[FrontPoint] = []

    def _pin(self, **values):
        pin_objective_settings(self.m, **values)

    def _set_objective(self, kind: str, scale: float | None = None, utopia=None, nadir=None):
        if kind == "time":
            self._pin(w_time=1.0 / (scale or self.s_time))
        elif kind == "trim":
            self._pin(w_trim=1.0 / (scale or self.s_trim))
        else:
            self._pin(w_utopia=1.0, U_time=utopia[0], U_trim=utopia[1], r_time=1.0 / (nadir[0] - utopia[0]),
                      r_trim=1.0 / (nadir[1] - utopia[1]))
        return self.solver

    def _solve(self, kind, index, point_kind, epsilon, warm_start, options=None, **obj):
        solver = self._set_objective(kind, **obj)
        self.m.eps_trim = (epsilon / self.s_trim) if math.isfinite(epsilon) else 1e20
        try:
            res = solver.solve(warm_start=warm_start, options=options)
            success, status, iterations, wall, setup = (res.success, res.status, res.iterations, res.wall_time,
                                                        res.setup_time)
        except SolverError as exc:  # no solution at all: record it, the sweep goes on
            success, status, iterations, wall, setup = False, f"{type(exc).__name__}: {exc}", -1, 0.0, 0.0
        p = FrontPoint(index=index, kind=point_kind, epsilon=epsilon, J_time=_value(self.m.J_time),
                       J_trim=_value(self.m.J_trim), parameters=free_parameter_values(self.m),
                       success=success, status=status, iterations=iterations,
                       wall_time=wall, setup_time=setup, warm_start=warm_start)
        return p

    def _solve_warm(self, kind, index, point_kind, epsilon, start: "_Snapshot", options=None, **obj):
        """A re-solve with the configured warm start, retried with the primal one if it fails."""
        return solve_with_fallback(lambda ws: self._solve(kind, index, point_kind, epsilon, ws,
                                                          options if ws in MULTIPLIER_MODES else None, **obj),
                                   self.settings.warm_start, start)

    def _near_start_options(self) -> dict | None:
        """Anchor B's stages start from a feasible solution (no multipliers for the new objective):
        with ``continuation`` the barrier starts at 100 tol instead of 0.1. Measured on Case 1 (full
        size, one run): first stage 9 iterations instead of 17, second 11 instead of 16 (tol/10: 16)."""
        if self.settings.warm_start != "continuation":
            return None
        return {"mu_init": 100.0 * float(self.settings.solver_options.get("tol", 1e-8))}

    def solve_objective(self, objective: str = "time", epsilon: float = math.inf, index: int = 0,
                        kind: str = "single", warm_start: str = "none") -> FrontPoint:
        """One solve of min J_time (``"time"``) or J_trim (``"trim"``) s.t. J_trim <= epsilon, from the
        model's current values (multi-start); a failure is returned as a point with its status."""
        return self._solve(objective, index, kind, epsilon, warm_start)

    def solve_point(self, key: str, solve) -> FrontPoint:
        """``solve()`` a point, or load it from the store when an earlier run finished it.

        A loaded point's stored solution is put back into the model, so what
        follows starts from the same values as in an uninterrupted run. A
        solved point is written to the store at once.
        """
        if self.store is not None and self.store.has(key):
            p = FrontPoint(**self.store.record(key))
            self.store.restore(key, self.m)
            p.from_disk = True
            return p
        try:
            p = solve()
        except interrupts.Interrupted as exc:  # not stored: a rerun solves it again from the same start
            exc.point = exc.point or key
            raise
        self._save(key, p)
        return p

    def _save(self, key: str, p: FrontPoint) -> None:
        if self.store is not None:
            self.store.save(key, asdict(p), self.m, duals=self.settings.warm_start in MULTIPLIER_MODES)

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
                    self._cold_check(p, last_good, scale=scale)
                return p

            p = self.solve_point(f"eps{k:03d}", solve_k)
            if p.success:
                previous = (last_good, float(eps[k - 1])) if k > 1 and self.points[-1].success else None
                last_good = self.snapshots[k] = _Snapshot(self.m)
                leaving = False
            else:
                previous = None
                last_good.restore()
            self.points.append(p)
            self.on_point(p)
        self.points.sort(key=lambda p: p.index)
        return self.points

    def restore_initial_guess(self) -> None:
        """Put the model's values back to the initial guess it had when this solver was made (cold starts)."""
        self._snap_initial.restore()

    def _cold_check(self, p: FrontPoint, back, scale: float) -> None:
        """Solve the same epsilon point from the initial guess; keep the warm solution in the model."""
        warm = _Snapshot(self.m)
        self.restore_initial_guess()
        cold = self._solve("time", p.index, "eps", p.epsilon, "none", scale=scale)
        p.cold_iterations, p.cold_status, p.cold_J_time = cold.iterations, cold.status, cold.J_time
        p.cold_wall_time = cold.wall_time
        warm.restore()

    # ------------------------------------------------------------- choosing
    def utopia_nadir(self):
        a = next(p for p in self.points if p.kind == "A")
        b = next(p for p in self.points if p.kind == "B")
        return (a.J_time, b.J_trim), (b.J_time, a.J_trim)

    def choose(self) -> tuple[FrontPoint | None, np.ndarray]:
        """The converged front point closest to utopia (Eq. 11, post hoc), and all distances.

        None when no point converged.
        """
        utopia, nadir = self.utopia_nadir()
        ok = [p for p in self.points if p.success]
        if not ok:
            return None, np.array([])
        d = utopia_distance([p.J_time for p in ok], [p.J_trim for p in ok], utopia, nadir)
        return ok[int(np.argmin(d))], d

    def direct_choice(self, start: FrontPoint | None = None) -> FrontPoint:
        """Eq. 11 as one NLP (squared distance: same minimiser, smooth), warm from the post-hoc choice."""
        utopia, nadir = self.utopia_nadir()
        start = start or self.choose()[0]
        self.snapshots[start.index].restore()
        return self.solve_point("direct", lambda: self._solve("utopia", -1, "direct", math.inf, "primal",
                                                             utopia=utopia, nadir=nadir))


def _retried(first: FrontPoint, retry: FrontPoint, how: str) -> FrontPoint:
    """The retry of a failed anchor, with both attempts' iterations and times; ``warm_start`` names them."""
    retry.iterations += max(first.iterations, 0)
    retry.wall_time += first.wall_time
    retry.setup_time += first.setup_time
    retry.warm_start = f"{first.warm_start} ({first.status}), then {how}"
    return retry


def _value(expr) -> float:
    """Value of an objective expression at the model's current values; NaN if it cannot be evaluated."""
    try:
        return float(pyo.value(expr))
    except (ValueError, ZeroDivisionError, OverflowError, TypeError):
        return float("nan")
