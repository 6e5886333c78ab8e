"""The epsilon-constraint method for any number of objectives (paper Eq. 10) and Eq. 11 written once.

Objectives are named; the first is minimised, every other one is bounded,

    min J_0   s.t.   J_k / s_k <= eps_k,   k = 1 .. N-1                      (Eq. 10)

with ``s_k`` the objective's value at the initial guess (optimizer-level scaling). The bounds are
mutable Params (``m.eps_trim`` of ``m.eps_con`` for J_trim, ``m.eps_<name>`` of
``m.eps_<name>_con`` for the others), and one objective serves every solve,

    f = sum_k w_k J_k + w_utopia sum_k ((J_k - U_k) r_k)^2,

whose weights, utopia values U and inverse ranges r are *variables pinned by equal bounds*: the
model is built and handed to the solver once, and switching objective or moving a bound is a
re-solve, never a rewrite.

:class:`EpsilonConstraintSolver` holds the model and its one solver and gives

- :meth:`~EpsilonConstraintSolver.anchors`: the payoff table, one lexicographic anchor per objective
  (A: min J_0; then for each bounded J_k: min J_k, then min J_0 keeping J_k at its minimum);
- :meth:`~EpsilonConstraintSolver.grid_front`: a grid of bounds, one axis per bounded objective,
  visited along a snake path, each point warm-started from the solved solution nearest to being a
  solution at its bounds (:meth:`~EpsilonConstraintSolver.grid_start`);
- :meth:`~EpsilonConstraintSolver.solve_at`: one point at a given vector of bounds, warm-started
  from the nearest solved point (in bounds normalised by the anchors' ranges): what adaptive
  placement calls;
- :meth:`~EpsilonConstraintSolver.choose` / :meth:`~EpsilonConstraintSolver.direct_choice`: Eq. 11
  post hoc over the converged points and as one NLP, with either nadir rule (:data:`NADIR_RULES`).

Infeasible points (:data:`INFEASIBLE`) are found without an iteration-limit solve: a bound below
the anchor minimum of its objective, below the least J_2 under a grid row's J_1 bound (two bounded
objectives: one solve per row, :meth:`~EpsilonConstraintSolver.row_minimum`), or at most as loose as
a grid point already found infeasible in every bound, is infeasible a priori (not solved); an Ipopt solve that ends in
``Infeasible_Problem_Detected`` or ``Restoration_Failed`` under active bounds is recorded as
infeasible, with Ipopt's status in the point's ``note``. ``settings.max_iter`` caps the iterations of
each front solve.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import pyomo.environ as pyo

from .. import interrupts
from ..log import get_logger
from ..nlp.parameters import free_parameter_values
from ..nlp.scaling import apply_scaling
from ..solvers import MULTIPLIER_MODES, SolverError, make_solver, scale_multipliers
from .eq11 import (NADIR_RULES, dominating, nondominated, nondominated_nadir,  # noqa: F401 - re-exported
                   payoff_nadir, utopia_distance_n)
from .snapshot import Snapshot
from .steps import (ANCHOR_NAMES, FRONT_STEP_OPTIONS, INFEASIBLE, IPOPT_INFEASIBLE, grid_bound_values,  # noqa: F401 - re-exported
                    LEAVE_ANCHOR_OPTIONS, TIGHT_MARGIN, EpsilonPoint, Outcome, _value, epsilon_grid,
                    pin_objective_settings, retried, snake, solve_from_starts, solve_with_fallback)


#: a start whose objective vector exceeds the new bounds by at most this (in anchor ranges) counts as feasible, a
#: bound it exceeds by at most this as active: Ipopt keeps an active bound only to its relaxation (bound_relax_factor
#: 1e-8), so a solution exceeds its own J_linear bound by ~3e-7 = 2e-6 of Case 1's range
FEASIBLE_TOL = 1e-4


@dataclass
class GridStart:
    """A solved solution a grid point can start from (:meth:`EpsilonConstraintSolver.grid_start`).

    ``J``: its bounded objectives' values; ``bounds``: the bounds it is the solution of (name -> bound, inf: free);
    ``front``: a min-J_0 solution at the front's scale, whose multipliers fit a warm start (else primal only).
    """

    label: str
    J: dict
    bounds: dict
    snapshot: Snapshot = field(repr=False)
    front: bool = True


# ------------------------------------------------------------------------------------------ solver
class EpsilonConstraintSolver:
    """Eq. 10 for the objectives ``names`` (``m.J_<name>``; the first is minimised) on one model and one solver.

    ``settings`` is a :class:`~pyomo_heli.pareto.front.ParetoSettings` (or any object with its fields).
    Subclasses choose the point type by overriding :meth:`_point`.
    """

    def __init__(self, m, names, settings, on_point=None, store=None):
        self.m, self.names = m, tuple(names)
        self.primary, self.bounded = self.names[0], self.names[1:]
        missing = [k for k in self.names if m.component(f"J_{k}") is None]
        if missing:
            raise ValueError(f"the NLP has no {', '.join('J_' + k for k in missing)}")
        self.settings = settings
        self.on_point = on_point or (lambda p: None)
        self.store = store  # a PointStore: finished points to disk, resume from them
        self.J = {k: m.component(f"J_{k}") for k in self.names}
        self.scale = {k: (max(abs(pyo.value(e)), 1.0) if k == self.primary else max(pyo.value(e), 1e-12))
                      for k, e in self.J.items()}
        self.eps_params = {}
        for k in self.bounded:
            pname, cname = ("eps_trim", "eps_con") if k == "trim" else (f"eps_{k}", f"eps_{k}_con")
            if m.component(pname) is None:
                m.add_component(pname, pyo.Param(initialize=1e20, mutable=True))
            m.del_component(cname)
            m.add_component(cname, pyo.Constraint(expr=self.J[k] / self.scale[k] <= m.component(pname)))
            self.eps_params[k] = m.component(pname)
        pins = ([f"w_{k}" for k in self.names] + ["w_utopia"] + [f"U_{k}" for k in self.names]
                + [f"r_{k}" for k in self.names])
        m.objective_settings = pyo.Var(pins, initialize=0.0)
        w = m.objective_settings
        utopia = None
        for k in self.names:
            term = ((self.J[k] - w[f"U_{k}"]) * w[f"r_{k}"]) ** 2
            utopia = term if utopia is None else utopia + term
        if m.component("objective") is not None:
            m.objective.deactivate()
        expr = None
        for k in self.names:
            expr = w[f"w_{k}"] * self.J[k] if expr is None else expr + w[f"w_{k}"] * self.J[k]
        m.selected_objective = pyo.Objective(expr=expr + w["w_utopia"] * utopia)
        self.pin(**{f"w_{self.primary}": 1.0 / self.scale[self.primary]})
        self.initial_guess = Snapshot(m)
        log = get_logger("pareto")
        log.info(f"setting up solver {settings.solver} (NL file, casadi functions; the first solve adds the "
                 f"derivatives): up to minutes on a full-size problem")
        t0 = time.perf_counter()
        apply_scaling(m, settings.solver, settings.solver_options)  # IDAES Scaler, when asked for
        self.solver = make_solver(m, settings.solver, settings.solver_options)
        log.debug(f"solver object made in {time.perf_counter() - t0:.1f} s")
        self.points: list = []
        self.snapshots: dict = {}
        self.minima: dict = {}  # bounded objective -> its own minimum (from the anchors)
        self.anchor_points: dict = {}
        self._solved: list = []  # (bounds tuple, snapshot at the front's scale) of every converged front point
        self._infeasible: list = []  # bounds tuples of points found infeasible
        self._witnesses: list = []  # objective values of every converged solve: bounds they meet are feasible
        self.row_minima: dict = {}  # grid row -> least J_2 under that row's J_1 bound (two bounded objectives)
        self.row_solves: list = []  # the solves that found them (records for the run's info)
        self._row_snapshots: dict = {}
        self.starts: list = []  # GridStart of every solved solution a grid point may start from
        self.front_scale = self.scale[self.primary]

    # -------------------------------------------------------------- one solve
    def pin(self, **values) -> None:
        pin_objective_settings(self.m, **values)

    def set_objective(self, objective: str, scale: float | None = None, utopia=None, nadir=None) -> None:
        """Pin the objective: ``objective`` (a name) divided by ``scale``, or "utopia" (Eq. 11 squared)."""
        if objective == "utopia":
            pins = {"w_utopia": 1.0}
            for k, u, n in zip(self.names, utopia, nadir):
                pins[f"U_{k}"], pins[f"r_{k}"] = u, (1.0 / (n - u) if n != u else 0.0)  # as utopia_distance_n
            self.pin(**pins)
        else:
            self.pin(**{f"w_{objective}": 1.0 / (scale or self.scale[objective])})

    def set_bounds(self, eps: dict) -> None:
        for k in self.bounded:
            v = eps.get(k, math.inf)
            self.eps_params[k].set_value(v / self.scale[k] if math.isfinite(v) else 1e20)

    def a_priori_infeasible(self, eps: dict) -> str:
        """Why the bounds ``eps`` are infeasible without a solve ('' when that is not known, or when a converged
        solve meets them: :meth:`witnessed`)."""
        if self.witnessed(eps):
            return ""
        for k, v in eps.items():
            lo = self.minima.get(k)
            if lo is not None and math.isfinite(v) and v < lo - 1e-12 * max(abs(lo), 1.0):
                return f"eps_{k} = {v:.6g} is below the minimum of J_{k}, {lo:.6g} (its anchor)"
        if len(self.bounded) == 2 and self.row_minima:
            (k1, k2), e1, e2 = self.bounded, eps.get(self.bounded[0], math.inf), eps.get(self.bounded[1], math.inf)
            for i, lo in self.row_minima.items():
                bound = float(self.axes[0][i])
                if e1 <= bound * (1 + 1e-12) and math.isfinite(e2) and e2 < lo - 1e-9 * max(abs(lo), 1.0):
                    return (f"eps_{k2} = {e2:.6g} is below the minimum of J_{k2} under J_{k1} <= {bound:.6g}, "
                            f"{lo:.6g}")
        vec = self.bounds_vector(eps)
        for bad in self._infeasible:
            if all(v <= b for v, b in zip(vec, bad)):
                return "every bound at most that of a point found infeasible"
        return ""

    def witnessed(self, eps: dict) -> bool:
        """Whether a converged solve of this model (since the anchors) meets every finite bound of ``eps``."""
        tight = {k: v for k, v in eps.items() if math.isfinite(v)}
        return bool(tight) and any(
            all(math.isfinite(J.get(k, math.nan)) and J[k] <= v + 1e-9 * max(abs(v), 1.0) for k, v in tight.items())
            for J in self._witnesses)

    def solve_once(self, objective: str, eps: dict | None = None, warm_start: str = "primal", options=None,
                   scale: float | None = None, utopia=None, nadir=None) -> Outcome:
        """One solve of ``objective`` under the bounds ``eps`` (name -> bound; missing or inf: inactive).

        Bounds known infeasible are not solved (status :data:`INFEASIBLE`, 0 iterations); an Ipopt
        infeasibility under active bounds is recorded as :data:`INFEASIBLE`, Ipopt's status in ``note``.
        A solver that gives no solution at all is recorded with its error; the caller goes on.
        """
        eps = dict(eps or {})
        self.set_objective(objective, scale, utopia, nadir)
        self.set_bounds(eps)
        why = self.a_priori_infeasible(eps)
        if why:
            return Outcome(J={k: math.nan for k in self.names}, parameters=free_parameter_values(self.m),
                           success=False, status=INFEASIBLE, iterations=0, wall_time=0.0, setup_time=0.0,
                           note=f"not solved: {why}")
        note = ""
        try:
            res = self.solver.solve(warm_start=warm_start, options=options)
            success, status, iterations, wall, setup = (res.success, res.status, res.iterations, res.wall_time,
                                                        res.setup_time)
        except SolverError as exc:  # no solution at all: record it, the sweep goes on
            success, status, iterations, wall, setup = False, f"{type(exc).__name__}: {exc}", -1, 0.0, 0.0
        J = {k: _value(e) for k, e in self.J.items()}
        if success:
            self._witnesses.append(J)
        elif status in IPOPT_INFEASIBLE and any(math.isfinite(v) for v in eps.values()):
            # Ipopt's verdict is local (Restoration_Failed is often a numerical failure): bounds that a converged
            # solve meets are feasible, and the point is a failure to retry, not an infeasible one
            if self.witnessed(eps):
                note = "a converged solve meets these bounds: not infeasible"
            else:
                status, note = INFEASIBLE, status
        multipliers = self.multipliers(scale or self.scale[objective]) if success and objective == self.primary else {}
        return Outcome(J=J, parameters=free_parameter_values(self.m),
                       success=success, status=status, iterations=iterations, wall_time=wall, setup_time=setup,
                       note=note, multipliers=multipliers)

    def multipliers(self, primary_scale: float) -> dict:
        """bounded objective -> -dJ_0/dJ_k at the solution in the model, from its epsilon constraint's multiplier.

        The solve minimised J_0 / primary_scale subject to J_k / s_k <= eps_k, and the solver's ``dual`` is
        d(objective)/d(bound) (pyomo_heli.solvers), so -dJ_0/dJ_k = -dual primary_scale / s_k: the weight ratio b/a
        of the a J_0 + b J_k the point is stationary for (KKT), and the front's slope (envelope theorem). NaN when
        the solver wrote no multipliers."""
        dual = self.m.component("dual")
        out = {}
        for k in self.bounded:
            con = self.m.component("eps_con" if k == "trim" else f"eps_{k}_con")
            lam = dual.get(con) if isinstance(dual, pyo.Suffix) else None
            out[k] = -float(lam) * primary_scale / self.scale[k] if lam is not None else math.nan
        return out

    def _point(self, index: int, kind: str, eps: dict, out: Outcome, warm_start: str, grid=()):
        """The point record of a solve (subclasses return their own point type)."""
        return EpsilonPoint(index=index, kind=kind, J=out.J, epsilon={k: eps.get(k, math.inf) for k in self.bounded},
                            parameters=out.parameters, success=out.success, status=out.status,
                            iterations=out.iterations, wall_time=out.wall_time, setup_time=out.setup_time,
                            warm_start=warm_start, grid=tuple(grid), note=out.note, multipliers=dict(out.multipliers))

    def solve_eps(self, index: int, eps: dict, warm_start: str, options=None, grid=()):
        """min J_0 under the bounds ``eps`` at the front's objective scale: one point."""
        out = self.solve_once(self.primary, eps, warm_start, options, scale=self.front_scale)
        return self._point(index, "eps", eps, out, warm_start, grid)

    def capped(self, options: dict | None) -> dict | None:
        """``options`` with the front's iteration cap (``settings.max_iter``) when one is set."""
        cap = getattr(self.settings, "max_iter", None)
        return {**(options or {}), "max_iter": int(cap)} if cap else options

    # -------------------------------------------------------------- the store
    point_class = EpsilonPoint

    def solve_point(self, key: str, solve):
        """``solve()`` a point, or load it from the store when an earlier run finished it.

        A loaded point's stored solution is put back into the model, so what
        follows starts from the same values as in an uninterrupted run, and a
        converged one is a witness of the bounds it meets (:meth:`witnessed`), as
        its solve was. A solved point is written to the store at once.
        """
        if self.store is not None and self.store.has(key):
            p = self.point_class(**self.store.record(key))
            self.store.restore(key, self.m)
            p.from_disk = True
            if p.success:
                self._witnesses.append({k: _get(p, k) for k in self.names})
            return p
        try:
            p = solve()
        except interrupts.Interrupted as exc:  # not stored: a rerun solves it again from the same start
            exc.point = exc.point or key
            raise
        self._save(key, p)
        return p

    def _save(self, key: str, p) -> None:
        if self.store is not None:
            self.store.save(key, asdict(p), self.m, duals=self.settings.warm_start in MULTIPLIER_MODES)

    # -------------------------------------------------------------- anchors (payoff table)
    def _near_start_options(self) -> dict | None:
        """A solve from a feasible solution (no multipliers for the new objective): with ``continuation`` the
        barrier starts at 100 tol instead of 0.1. Measured on Case 1 (full size, one run), anchor B of the
        two-objective front: first stage 9 iterations instead of 17, second 11 instead of 16 (tol/10: 16)."""
        if self.settings.warm_start != "continuation":
            return None
        return {"mu_init": 100.0 * float(self.settings.solver_options.get("tol", 1e-8))}

    def _lexicographic(self, objective: str, kind: str, index: int, start: Snapshot):
        """Min ``objective``, then min J_0 keeping it at its minimum (a non-dominated anchor).

        Both stages start from a feasible solution (``start``, anchor A's, then the first stage's), with
        :meth:`_near_start_options`, as anchor B of the two-objective front; if that fails, the anchor is
        solved once more from ``start`` with Ipopt's default barrier start (both attempts counted)."""
        options = self._near_start_options()
        p = self._two_stages(objective, kind, index, start, options)
        if not p.success and options is not None:
            p = retried(p, self._two_stages(objective, kind, index, start, None),
                        f"primal, mu_init {options['mu_init']:g} ({p.status}), then primal")
        if not p.success:
            raise RuntimeError(f"anchor {kind} failed: {p.status}")
        return p

    def _two_stages(self, objective: str, kind: str, index: int, start: Snapshot, options):
        start.restore()
        first = self.solve_once(objective, warm_start="primal", options=options)
        bound = first.J[objective] * (1 + self.settings.lexicographic_tol) + 1e-12
        if first.success:
            out = self.solve_once(self.primary, {objective: bound}, "primal", options)
        else:
            out = Outcome(**{**asdict(first), "status": f"first stage (J_{objective} alone): {first.status}",
                             "iterations": 0, "wall_time": 0.0})
        p = self._point(index, kind, {objective: bound}, out, "primal", ())
        p.iterations += max(first.iterations, 0)
        p.wall_time += first.wall_time
        p.first_stage_min = first.J[objective]
        if options:
            p.warm_start = f"primal, mu_init {options['mu_init']:g}"
        if first.success and not p.success:
            p.status = f"second stage: {p.status}"
        return p

    def anchors(self) -> list:
        """The payoff table: A = min J_0 from the model's values, then one lexicographic anchor per bounded objective.

        Raises RuntimeError naming the anchor when one fails: everything after rests on them.
        """
        self.minima, self._infeasible, self._solved, self._witnesses = {}, [], [], []
        self.row_minima, self.row_solves, self._row_snapshots = {}, [], {}
        out = self.solve_once(self.primary, warm_start="none")
        a = self._point(0, "A", {}, out, "none", (0,) * len(self.bounded))
        if not a.success:
            raise RuntimeError(f"anchor A (J_{self.primary} alone) failed: {a.status}")
        snap_a = Snapshot(self.m)
        self.anchor_points, self.snapshots = {"A": a}, {"A": snap_a}
        for n, k in enumerate(self.bounded, start=1):
            name = ANCHOR_NAMES[n]
            self.anchor_points[name] = self._lexicographic(k, name, -n, snap_a)
            self.snapshots[name] = Snapshot(self.m)
            self.minima[k] = self.anchor_points[name].first_stage_min
        for p in self.anchor_points.values():
            self.on_point(p)
        self.points = list(self.anchor_points.values())
        return self.points

    def _enter_front(self) -> Snapshot:
        """Anchor A's solution at the front's objective scale (J_0 at A), registered as a solved front point."""
        a = self.anchor_points["A"]
        self.front_scale = max(abs(_get(a, self.primary)), 1.0) if math.isfinite(_get(a, self.primary)) else \
            self.scale[self.primary]
        self.snapshots["A"].restore()
        scale_multipliers(self.m, self.scale[self.primary] / self.front_scale)  # A's multipliers: A's scale
        snap = Snapshot(self.m)
        self._solved.append((self.loosest(), snap))
        return snap

    def loosest(self) -> tuple:
        """The bounds at anchor A: each bounded objective's value there (looser bounds are inactive)."""
        a = self.anchor_points["A"]
        return tuple(float(_get(a, k)) for k in self.bounded)

    def bounds_vector(self, eps: dict) -> tuple:
        """``eps`` as a tuple over the bounded objectives, an inactive bound read as its value at anchor A."""
        loose = self.loosest() if "A" in self.anchor_points else (math.inf,) * len(self.bounded)
        return tuple(min(float(eps.get(k, math.inf)), lo) for k, lo in zip(self.bounded, loose))

    # -------------------------------------------------------------- the front
    def nearest_start(self, eps: dict) -> Snapshot:
        """The solved front point nearest to ``eps``, in bounds normalised by the anchors' ranges; the last on ties."""
        vec = np.array(self.bounds_vector(eps))
        rng = np.array([max(lo - self.minima.get(k, 0.0), 1e-300) for k, lo in zip(self.bounded, self.loosest())])
        dist = [float(np.sum(np.abs((np.array(v) - vec) / rng))) for v, _ in self._solved]
        best = min(range(len(dist)), key=lambda i: (dist[i], -i))
        return self._solved[best][1]

    def _solve_from(self, index: int, eps: dict, start: Snapshot, grid=(), multipliers: bool = True):
        """One front point from ``start`` with the configured warm start (primal retry on failure), capped.

        ``multipliers=False``: ``start`` is no min-J_0 solution (a row minimum's), so its multipliers do not
        fit; the solve starts from its primal values, with :meth:`_near_start_options` (it is feasible or
        nearly), once more with Ipopt's default barrier start if that fails."""
        s = self.settings
        leaving = start is self._solved[0][1]  # anchor A's solution: the active set changes
        options = LEAVE_ANCHOR_OPTIONS if leaving else (FRONT_STEP_OPTIONS if s.warm_start == "continuation" else None)
        start.restore()
        if multipliers:
            p = solve_with_fallback(
                lambda ws: self.solve_eps(index, eps, ws, self.capped(options if ws in MULTIPLIER_MODES else None),
                                          grid), s.warm_start, start)
        else:
            near = self._near_start_options()
            p = self.solve_eps(index, eps, "primal", self.capped(near), grid)
            if not p.success and p.status != INFEASIBLE and near is not None:
                start.restore()
                p = retried(p, self.solve_eps(index, eps, "primal", self.capped(None), grid),
                            f"primal, mu_init {near['mu_init']:g} ({p.status}), then primal")
            elif near is not None:
                p.warm_start = f"primal, mu_init {near['mu_init']:g}"
        vec = self.bounds_vector(eps)
        if p.success:
            self._solved.append((vec, Snapshot(self.m)))
        else:
            if p.status == INFEASIBLE:
                self._infeasible.append(vec)
            start.restore()
        return p

    def solve_at(self, eps, index: int | None = None, key: str | None = None, grid=()):
        """Solve the front point at the bounds ``eps`` (name -> bound, or a sequence over the bounded objectives).

        Warm-started from the nearest solved front point (:meth:`nearest_start`); needs the anchors.
        The point is appended to ``points`` and handed to ``on_point``; with a store and a ``key``
        it is stored (and loaded on a rerun). ``grid``: the point's position on a grid, if any. This is
        the entry point of adaptive epsilon placement (pareto/placement.py).
        """
        if not self._solved:
            if "A" not in self.anchor_points:
                raise RuntimeError("solve_at needs the anchors: call anchors() or a front first")
            self._enter_front()
        if not isinstance(eps, dict):
            eps = dict(zip(self.bounded, np.atleast_1d(np.asarray(eps, float)).tolist()))
        index = index if index is not None else max([p.index for p in self.points] + [0]) + 1
        start = self.nearest_start(eps)
        p = (self.solve_point(key, lambda: self._solve_from(index, eps, start, grid)) if key
             else self._solve_from(index, eps, start, grid))
        if p.success:
            self.snapshots[index] = self._solved[-1][1] if not getattr(p, "from_disk", False) else Snapshot(self.m)
            if getattr(p, "from_disk", False):
                self._solved.append((self.bounds_vector(eps), self.snapshots[index]))
        elif getattr(p, "from_disk", False) and p.status == INFEASIBLE:  # as _solve_from records one it solves
            self._infeasible.append(self.bounds_vector(eps))
        self.points.append(p)
        self.on_point(p)
        return p

    def grid_front(self, counts, margin: float = TIGHT_MARGIN) -> list:
        """Anchors, then a grid of ``counts`` bounds per bounded objective along a snake path.

        Axis k runs from J_k at anchor A (inactive) down to ``margin`` of the anchor range above J_k's
        minimum, with ``settings.spacing``: with every bound at its minimum the corner is infeasible or
        degenerate, and the anchors already hold the minima. Position (0, ..., 0) is anchor A itself; position 0
        of every axis after the first is no bound at all (:meth:`grid_bounds`).

        Each point starts from :meth:`grid_start` (recorded in the point's ``start``). With two bounded
        objectives a row's least J_2 (:meth:`row_minimum`) is solved when a point of the row needs it: when
        the point is neither infeasible a priori nor known feasible (a solved solution meets its bounds).
        """
        counts = tuple(int(c) for c in counts)
        if len(counts) != len(self.bounded):
            raise ValueError(f"a grid needs one count per bounded objective ({len(self.bounded)}), got {counts}")
        self.anchors()
        self.axes = self.grid_axes(counts, margin)
        a_snap = self._enter_front()
        self.starts = [GridStart("anchor A", {k: _get(self.anchor_points["A"], k) for k in self.bounded},
                                 {k: math.inf for k in self.bounded}, a_snap)]
        index = 1
        self.row_minima = {}
        for pos in snake(counts):
            if not any(pos):
                continue  # anchor A itself (every bound inactive)
            eps = self.grid_bounds(pos)
            why = self.a_priori_infeasible(eps)
            if len(self.bounded) == 2 and pos[0] not in self.row_minima and not why and not self.known_feasible(eps):
                self.row_minima[pos[0]] = self.row_minimum(pos[0])
                why = self.a_priori_infeasible(eps)
            if why:  # not solved, nothing to start from
                p = self.solve_eps(index, eps, "none", None, pos)
                self._infeasible.append(self.bounds_vector(eps))
            else:
                start = self.grid_start(eps)
                p = self._solve_from(index, eps, start.snapshot, pos, multipliers=start.front)
                p.start = start.label
            if p.success:
                self.snapshots[index] = self._solved[-1][1]
                self.starts.append(GridStart(f"point {index} {tuple(pos)}", {k: _get(p, k) for k in self.bounded},
                                             dict(eps), self._solved[-1][1]))
            self.points.append(p)
            self.on_point(p)
            index += 1
        return self.points

    def _ranges(self) -> dict:
        """Each bounded objective's anchor range, J_k(A) - min J_k (1 where that is not positive)."""
        a = self.anchor_points["A"]
        return {k: (_get(a, k) - self.minima[k]) if _get(a, k) > self.minima[k] else 1.0 for k in self.bounded}

    def start_violation(self, start: GridStart, eps: dict) -> float:
        """How far ``start``'s objective vector lies outside the bounds ``eps``: sum_k max(0, J_k - eps_k) / range_k."""
        r = self._ranges()
        return sum(max(0.0, start.J[k] - eps[k]) / r[k] for k in self.bounded if math.isfinite(eps.get(k, math.inf)))

    def start_distance(self, start: GridStart, eps: dict) -> float:
        """How far the bounds ``eps`` are from those at which ``start``'s solution is still a solution.

        That set is a box: J_k(start) <= eps_k for every k (the solution is feasible), and eps_k <= the bound
        it was solved under for every bound active there (an inactive bound may loosen freely). The distance
        to it, in anchor ranges (bounds above J_k(A) read as J_k(A)), is the violation of the new bounds
        (:meth:`start_violation`) plus the loosening of the bounds active at the start. Zero: the start is
        already a solution at ``eps`` (one iteration confirms it).
        """
        r, a = self._ranges(), self.anchor_points["A"]
        loosen = 0.0
        for k in self.bounded:
            b = start.bounds.get(k, math.inf)
            if math.isfinite(b) and start.J[k] >= b - FEASIBLE_TOL * r[k]:  # active at the start
                cap = _get(a, k)
                loosen += max(0.0, min(eps.get(k, math.inf), cap) - min(b, cap)) / r[k]
        return self.start_violation(start, eps) + loosen

    def known_feasible(self, eps: dict) -> bool:
        """Whether a solved solution meets the bounds ``eps`` (to :data:`FEASIBLE_TOL` of the anchor ranges)."""
        return any(self.start_violation(s, eps) <= FEASIBLE_TOL for s in self.starts)

    def grid_start(self, eps: dict) -> GridStart:
        """The start of the grid point at ``eps``: of the solved grid points, anchor A and the row minima's
        solutions (:attr:`starts`), the one with the least :meth:`start_distance` (the latest on ties).

        The nearest grid neighbour may lie on another branch of the front (Case 2: the J_linear-tightest
        column's solutions sit at a twist of -2.1 deg/m, its neighbour's at -0.3, and the step took 123-140
        iterations); a solution that already meets the new bounds, or nearly, is closer to the answer.
        Anchors B and C are left out (but C as row 0's minimum): at the ends of the front, where J_0 moves
        most per bound, a distance in the bounds says little about the distance to the solution.
        """
        d = [self.start_distance(s, eps) for s in self.starts]
        return self.starts[min(range(len(d)), key=lambda i: (d[i], -i))]

    def grid_bounds(self, pos) -> dict:
        """The bounds at grid position ``pos`` (name -> bound): ``axes[k][pos[k]]``, except that position 0 of every
        axis after the first leaves that objective free (inf). Column 0 of a two-bound grid is then the
        two-objective front of J_0 and J_1 wherever it goes, not only as far as J_2 stays below its value at A
        (bounded there, the rows where the least J_2 exceeds J_2(A) would be infeasible in every column)."""
        return dict(zip(self.bounded, grid_bound_values(self.axes, pos)))

    def grid_axes(self, counts, margin: float = TIGHT_MARGIN) -> list:
        """The grid's bounds per bounded objective (needs the anchors): ``counts[k]`` values from J_k at
        anchor A down to ``margin`` of the anchor range above J_k's minimum, ``settings.spacing``."""
        a = self.anchor_points["A"]
        return [epsilon_grid(_get(a, k), self.minima[k] + margin * (_get(a, k) - self.minima[k]), int(n),
                             self.settings.spacing) for k, n in zip(self.bounded, counts)]

    def row_minimum(self, i: int) -> float:
        """The least value of the second bounded objective under the first one's bound on grid row ``i``.

        With two bounded objectives (J_1 on the grid's rows, J_2 on its columns) the bounds (e_1, e_2) are
        feasible exactly when min J_2 s.t. J_1 <= e_1 is at most e_2, whatever J_0 does: one solve per row
        (row 0: anchor C's first stage when C keeps J_1 <= J_1(A), else a solve from C; row i: from the nearest
        row solved above, a continuation along the J_1-J_2 front) settles every point of the row, and a point
        below it is reported infeasible without a solve (:meth:`a_priori_infeasible`). The solve is
        ``settings.max_iter``-capped; if it fails, nothing is known a priori (returns -inf) and the row's points
        are solved as they come. Its solution joins the grid's starts (:meth:`grid_start`).
        """
        k1, k2 = self.bounded
        c = self.anchor_points[ANCHOR_NAMES[2]]
        if i == 0 and _get(c, k1) <= float(self.axes[0][0]) * (1 + 1e-12):  # row 0's bound J_1(A) is inactive at C
            self.starts.append(GridStart("row 0 minimum (anchor C)", {k: _get(c, k) for k in self.bounded},
                                         {k1: math.inf, k2: _get(c, k2)}, self.snapshots[ANCHOR_NAMES[2]], front=False))
            return self.minima[k2]
        below = [j for j in self._row_snapshots if j < i]  # the nearest row solved above (rows may be skipped)
        snap = self._row_snapshots[max(below)] if below else self.snapshots[ANCHOR_NAMES[2]]  # C: min J_2, J_1 free
        here = Snapshot(self.m)
        snap.restore()
        bound = float(self.axes[0][i])
        out = self.solve_once(k2, {k1: bound}, "primal", self.capped(dict(LEAVE_ANCHOR_OPTIONS)))
        self.row_solves.append({"row": i, f"epsilon_{k1}": bound, f"min_J_{k2}": out.J[k2], f"J_{k1}": out.J[k1],
                                "status": out.status,
                                "iterations": out.iterations, "wall_time": out.wall_time})
        get_logger("pareto").info(f"row {i}: min J_{k2} under J_{k1} <= {bound:.6g} is {out.J[k2]:.6g} "
                                  f"[{out.status}, {out.iterations} it, {out.wall_time:.1f} s]")
        value = out.J[k2] if out.success else -math.inf
        if out.success:
            self._row_snapshots[i] = Snapshot(self.m)
            # the solution at the bounds (e_1, its J_2): there it is the only feasible point (if unique)
            self.starts.append(GridStart(f"row {i} minimum", {k: out.J[k] for k in self.bounded},
                                         {k1: bound, k2: out.J[k2]}, self._row_snapshots[i], front=False))
        here.restore()
        return value

    # -------------------------------------------------------------- choosing (Eq. 11)
    def payoff_utopia_nadir(self):
        """Utopia: each objective's own minimum; nadir: its worst value over the anchors (payoff table)."""
        anchors = list(self.anchor_points.values())
        utopia = (_get(self.anchor_points["A"], self.primary),) + tuple(self.minima[k] for k in self.bounded)
        return utopia, payoff_nadir([[_get(p, k) for k in self.names] for p in anchors])

    def front_candidates(self) -> list:
        """The converged anchors and front points (not the direct Eq. 11 solve)."""
        return [p for p in self.points if p.success and p.kind != "direct"]

    def nondominated_nadir(self, utopia) -> tuple:
        """Each objective's worst value over the non-dominated converged points inside the grid's box
        (every bounded objective at most its value at anchor A: the anchors of the other objectives
        lie outside it when they have more than one bound)."""
        loose = self.loosest()
        J = np.array([[_get(p, k) for k in self.names] for p in self.front_candidates()
                      if all(_get(p, k) <= lo * (1 + 1e-9) + 1e-12 for k, lo in zip(self.bounded, loose))])
        return nondominated_nadir(J) if len(J) else tuple(utopia)

    def utopia_nadir(self, rule: str | None = None):
        """(utopia, nadir) of Eq. 11 with the nadir ``rule`` (:data:`NADIR_RULES`; default ``settings.nadir``).

        An objective whose range on the front is below what the solver resolves (:meth:`resolved_nadir`) gets
        its utopia value as nadir: it adds nothing to Eq. 11."""
        rule = rule or getattr(self.settings, "nadir", "payoff")
        utopia, nadir = self.payoff_utopia_nadir()
        if rule == "nondominated":
            nadir = self.nondominated_nadir(utopia)
        return utopia, self.resolved_nadir(utopia, nadir)

    def resolved_nadir(self, utopia, nadir, names=None) -> tuple:
        """``nadir`` with each objective whose range ``N_k - U_k`` is at most :data:`RANGE_RTOL` times
        max(|U_k|, |N_k|, its scale in the NLP) set to ``U_k`` (``names``: the objectives, default all).

        Such a range is solver noise (on noise-free data every front point is the truth: J_trim from 2e-10 to
        2e-9, J_time within 1.3e-3 of -36125, tests/test_identification.py); divided by it, Eq. 11 is a problem
        of condition up to 1e18 that Ipopt fails on. The scale (the objective's size at the initial guess) is the
        floor only of a front whose primary objective has no range beyond RANGE_RTOL of its own size: where the
        primary's range is real, the front is, and a start far from it (a scale many times the front's values)
        must not flatten the other objectives' ranges (Eq. 11 would silently choose anchor A).
        """
        names = tuple(names or self.names)
        finite = [math.isfinite(u) and math.isfinite(n) for u, n in zip(utopia, nadir)]
        primary_has_range = any(k == self.primary and ok and n - u > RANGE_RTOL * max(abs(u), abs(n))
                                for k, u, n, ok in zip(names, utopia, nadir, finite))
        out = []
        for k, u, n, ok in zip(names, utopia, nadir, finite):
            floor = RANGE_RTOL * max(abs(u), abs(n), 0.0 if primary_has_range else self.scale[k])
            out.append(float(u) if ok and n - u <= floor else n)
        return tuple(out)

    @property
    def direct_index(self) -> int:
        """The index of the direct Eq. 11 solve's point."""
        return -len(self.names)

    def eq11(self, rule: str | None = None, points=None):
        """Eq. 11 post hoc: (the converged point closest to utopia, all distances, utopia, nadir); None if none."""
        utopia, nadir = self.utopia_nadir(rule=rule)
        pts = self.front_candidates() if points is None else points
        if not pts:
            return None, np.array([]), utopia, nadir
        d = utopia_distance_n([[_get(p, k) for k in self.names] for p in pts], utopia, nadir)
        return pts[int(np.argmin(d))], d, utopia, nadir

    def choices(self) -> dict:
        """The Eq. 11 choice under each nadir rule: rule -> {nadir, index, kind, distance, parameters}."""
        out = {}
        for rule in NADIR_RULES:
            p, d, _, nadir = self.eq11(rule)
            out[rule] = {"nadir": [float(v) for v in nadir], "index": None if p is None else p.index,
                         "kind": None if p is None else p.kind, "distance": float(d.min()) if len(d) else None,
                         "parameters": None if p is None else dict(p.parameters)}
        return out

    choose = eq11

    def direct_choice(self, start=None, rule: str | None = None):
        """Eq. 11 as one NLP (squared distance: same minimiser, smooth), warm from the post-hoc choice ``start``
        (default: :meth:`eq11`'s), and from the next starts of :meth:`direct_starts` while it fails. Stored
        under ``"direct"`` once final, so a resumed run repeats no attempt."""
        utopia, nadir = self.utopia_nadir(rule=rule)
        start = start or self.eq11(rule)[0]
        if all(u == n for u, n in zip(utopia, nadir)):  # a one-point front: every point is the Eq. 11 minimiser
            return self.solve_point("direct", lambda: self._one_point_direct(start))
        ranged = [k for k, u, n in zip(self.names, utopia, nadir) if u != n]
        if len(ranged) == 1:  # Eq. 11 weighs one objective only: its own anchor is at utopia, distance 0
            k = ranged[0]
            anchor = self.anchor_points["A" if k == self.primary else ANCHOR_NAMES[1 + self.bounded.index(k)]]
            if anchor.success:
                return self.solve_point("direct", lambda: self._one_point_direct(anchor, ONE_RANGE.format(
                    k=k, anchor=anchor.kind, others=", ".join(f"J_{n}" for n in self.names if n != k))))
        starts = self.direct_starts(start, rule)
        d_start = float(utopia_distance_n([[_get(start, k) for k in self.names]], utopia, nadir)[0])
        front = self.front_candidates()

        def once():
            # a solve that ends farther from utopia than its post-hoc start is a worse local minimum; one that a
            # front point dominates has left the front along an objective Eq. 11 does not weigh (its range on
            # the front is solver noise, so nadir = utopia there): neither is the Eq. 11 choice
            q = self._direct_once(utopia, nadir)
            if q.success:
                J = [_get(q, k) for k in self.names]
                d = float(utopia_distance_n([J], utopia, nadir)[0])
                by = dominating(J, [[_get(p, k) for k in self.names] for p in front], DIRECT_RTOL)
                if d > d_start * (1 + DIRECT_RTOL) + DIRECT_RTOL:
                    q.success, q.status = False, (f"{q.status} but farther from utopia than the post-hoc choice "
                                                  f"(Eq. 11 distance {d:.4g} > {d_start:.4g}): not the minimiser")
                elif by is not None:
                    p = front[by]
                    q.success, q.status = False, (
                        f"{q.status} but dominated by front point {p.index} ({p.kind}: "
                        + ", ".join(f"J_{k} {_get(p, k):.6g} against {v:.6g}" for k, v in zip(self.names, J))
                        + "): off the front, not the Eq. 11 choice")
            return q

        return self.solve_point("direct", lambda: solve_from_starts(once, starts))

    def _one_point_direct(self, start, why: str = ""):
        """The direct choice where Eq. 11 needs no solve, ``start`` itself (``why``: the point's ``warm_start``):
        a front whose every objective range is solver noise (:meth:`resolved_nadir`; Eq. 11 is zero on the whole
        front), or one where a single objective has a range (its anchor: Eq. 11 is zero there)."""
        snap = self._snapshot_of(start)
        if snap is not None:
            snap.restore()
        return replace(start, index=self.direct_index, kind="direct", iterations=0, wall_time=0.0, setup_time=0.0,
                       warm_start=why or ONE_POINT_FRONT)

    def _direct_once(self, utopia, nadir):
        """One solve of Eq. 11 squared from the model's current values."""
        out = self.solve_once("utopia", {}, "primal", utopia=utopia, nadir=nadir)
        return self._point(self.direct_index, "direct", {}, out, "primal", ())

    def _snapshot_of(self, p):
        """The stored solution of the converged point ``p`` (None if there is none)."""
        return self.snapshots.get(p.kind if p.kind in self.anchor_points else p.index)

    def direct_starts(self, start, rule: str | None = None) -> list:
        """Where the direct Eq. 11 solve starts, in turn while it fails: ``start`` (the post-hoc choice),
        the other converged points by their distance to utopia (:data:`DIRECT_STARTS` points in all),
        then midway between the first two; the model's current values when no point has its solution kept.
        ``(label, snapshot)`` pairs."""
        pts = self.front_candidates()
        _, d, _, _ = self.eq11(rule, pts)
        order = [start] + [pts[i] for i in np.argsort(d, kind="stable") if pts[i] is not start]
        starts = [(f"point {p.index} ({p.kind})", self._snapshot_of(p)) for p in order]
        starts = [s for s in starts if s[1] is not None][:DIRECT_STARTS]
        if len(starts) >= 2:
            (l0, s0), (l1, s1) = starts[:2]
            starts.append((f"midway between {l0} and {l1}", s0.extrapolated(s1, -0.5)))
        return starts or [("the current values", Snapshot(self.m))]


#: an objective's range on the front below this fraction of its size is solver noise (resolved_nadir)
RANGE_RTOL = 1e-6
#: the direct point's ``warm_start`` when the front is one point and nothing was solved
ONE_POINT_FRONT = ("not solved: every objective's range on the front is solver noise (a one-point front), "
                   "so the post-hoc choice is the Eq. 11 minimiser")
#: the direct point's ``warm_start`` when one objective alone has a range on the front and nothing was solved
ONE_RANGE = ("not solved: only J_{k} has a range on the front beyond solver noise ({others}: nadir = utopia), so "
             "Eq. 11 is J_{k}'s alone and its anchor {anchor}, at utopia, is the minimiser (a solve that weighs J_{k} "
             "only can leave the front along the others)")

#: a direct Eq. 11 solve whose distance exceeds its post-hoc start's by more than this (relative and absolute), or
#: that a front point dominates by more than this (relative), counts as failed
#: (:meth:`EpsilonConstraintSolver.direct_choice`)
DIRECT_RTOL = 1e-6
#: converged points the direct Eq. 11 solve starts from before its last start, midway between the first two
#: (:meth:`EpsilonConstraintSolver.direct_starts`)
DIRECT_STARTS = 3


def _get(p, k: str) -> float:
    return float(getattr(p, f"J_{k}"))
