"""Tri-objective front (J_time, J_trim, J_linear) by the epsilon-constraint method.

Minimise J_time subject to J_trim <= eps_trim and J_linear <= eps_linear on a
2-D grid of bounds (paper Eq. 10 with two epsilon constraints). The grid runs
from the unconstrained values at anchor A (min J_time) down to the anchors'
minima: eps_trim from J_trim(A) to J_trim(B), eps_linear from J_linear(A) to
J_linear(C), geometric spacing. Points are visited along a snake path
(row 0 left to right, row 1 right to left, ...), so every solve is warm-started
from a neighbour on the grid. A grid corner where both bounds are tight can be
infeasible; such a point is recorded with its status and the sweep goes on
from the last point that succeeded.

Row ``i_linear = 0`` (J_linear bound inactive) is the bi-objective front of
J_time and J_trim, so the same run also gives the two-objective choice.

As in :mod:`.front`, one objective serves every solve: its weights, utopia
values and inverse ranges are variables pinned by equal bounds, and the
epsilon bounds are mutable Params, so the NL file is written once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyomo.environ as pyo

from ..nlp.parameters import free_parameter_values
from ..nlp.scaling import apply_scaling
from ..solvers import make_solver, scale_multipliers
from .front import (LEAVE_ANCHOR_OPTIONS, FrontPoint, ParetoSettings, epsilon_grid, pin_objective_settings,
                    solve_with_fallback)
from .snapshot import Snapshot

OBJECTIVES = ("time", "trim", "linear")
#: fraction of the anchor range kept above each objective's minimum at the tight end of the grid
TIGHT_MARGIN = 0.05


@dataclass
class TriFrontPoint(FrontPoint):
    """A front point with the third objective and its bound."""

    J_linear: float = math.nan
    epsilon_linear: float = math.inf
    i_trim: int = -1  # grid position (-1: anchors and choices off the grid)
    i_linear: int = -1


def utopia_distance_n(J: np.ndarray, utopia, nadir) -> np.ndarray:
    """Eq. 11 for any number of objectives: sqrt(sum_k ((J_k - U_k)/(N_k - U_k))^2); J is (points, k)."""
    J = np.atleast_2d(np.asarray(J, float))
    U, N = np.asarray(utopia, float), np.asarray(nadir, float)
    rng = np.where(N - U > 0, N - U, 1.0)
    return np.sqrt(np.sum(((J - U) / rng) ** 2, axis=1))


class TriParetoSolver:
    """Anchors, the 2-D epsilon grid and the Eq. 11 choices on one NLP with J_time, J_trim, J_linear."""

    def __init__(self, m, settings: ParetoSettings | None = None, linear_points: int = 3, on_point=None):
        if m.component("J_linear") is None:
            raise ValueError("the NLP has no J_linear: build it with frequency responses")
        self.m = m
        self.settings = settings or ParetoSettings()
        self.linear_points = int(linear_points)
        self.on_point = on_point or (lambda p: None)
        self.scale = {"time": max(abs(pyo.value(m.J_time)), 1.0), "trim": max(pyo.value(m.J_trim), 1e-12),
                      "linear": max(pyo.value(m.J_linear), 1e-12)}
        J = self._J_expr()
        m.del_component("eps_con")
        m.eps_con = pyo.Constraint(expr=m.J_trim / self.scale["trim"] <= m.eps_trim)
        m.eps_linear = pyo.Param(initialize=1e20, mutable=True)
        m.eps_linear_con = pyo.Constraint(expr=m.J_linear / self.scale["linear"] <= m.eps_linear)
        names = [f"w_{k}" for k in OBJECTIVES] + ["w_utopia"] + [f"U_{k}" for k in OBJECTIVES] + \
                [f"r_{k}" for k in OBJECTIVES]
        m.objective_settings = pyo.Var(names, initialize=0.0)
        w = m.objective_settings
        utopia = sum(((J[k] - w[f"U_{k}"]) * w[f"r_{k}"]) ** 2 for k in OBJECTIVES)
        if m.component("objective") is not None:
            m.objective.deactivate()
        m.selected_objective = pyo.Objective(expr=sum(w[f"w_{k}"] * J[k] for k in OBJECTIVES) + w["w_utopia"] * utopia)
        self._pin(w_time=1.0 / self.scale["time"])
        apply_scaling(m, self.settings.solver, self.settings.solver_options)  # IDAES Scaler, when asked for
        self.solver = make_solver(m, self.settings.solver, self.settings.solver_options)
        self.points: list[TriFrontPoint] = []
        self.snapshots: dict = {}

    def _J_expr(self):
        return {"time": self.m.J_time, "trim": self.m.J_trim, "linear": self.m.J_linear}

    def _pin(self, **values):
        pin_objective_settings(self.m, **values)

    def _solve(self, objective: str, index: int, kind: str, eps_trim=math.inf, eps_linear=math.inf,
               warm_start="primal", scale=None, utopia=None, nadir=None, grid=(-1, -1),
               options=None) -> TriFrontPoint:
        if objective == "utopia":
            pins = {"w_utopia": 1.0}
            for k, u, n in zip(OBJECTIVES, utopia, nadir):
                pins[f"U_{k}"], pins[f"r_{k}"] = u, 1.0 / (n - u) if n > u else 1.0
            self._pin(**pins)
        else:
            self._pin(**{f"w_{objective}": 1.0 / (scale or self.scale[objective])})
        self.m.eps_trim = eps_trim / self.scale["trim"] if math.isfinite(eps_trim) else 1e20
        self.m.eps_linear = eps_linear / self.scale["linear"] if math.isfinite(eps_linear) else 1e20
        res = self.solver.solve(warm_start=warm_start, options=options)
        return TriFrontPoint(index=index, kind=kind, epsilon=eps_trim, J_time=pyo.value(self.m.J_time),
                             J_trim=pyo.value(self.m.J_trim), parameters=free_parameter_values(self.m),
                             success=res.success, status=res.status, iterations=res.iterations,
                             wall_time=res.wall_time, setup_time=res.setup_time, warm_start=warm_start,
                             J_linear=pyo.value(self.m.J_linear), epsilon_linear=eps_linear, i_trim=grid[0],
                             i_linear=grid[1])

    def _lexicographic(self, objective: str, kind: str, index: int, start) -> TriFrontPoint:
        """Min one objective, then min J_time keeping it at its minimum (a non-dominated anchor)."""
        start.restore()
        first = self._solve(objective, index, kind + "1")
        if not first.success:
            raise RuntimeError(f"anchor {kind} (J_{objective} alone) failed: {first.status}")
        bound = getattr(first, f"J_{objective}") * (1 + self.settings.lexicographic_tol) + 1e-12
        eps = {"eps_trim": bound} if objective == "trim" else {"eps_linear": bound}
        p = self._solve("time", index, kind, **eps)
        p.iterations += first.iterations
        p.wall_time += first.wall_time
        p.first_stage_min = getattr(first, f"J_{objective}")
        if not p.success:
            raise RuntimeError(f"anchor {kind}, second stage, failed: {p.status}")
        return p

    def anchors(self):
        a = self._solve("time", 0, "A", warm_start="none", grid=(0, 0))
        if not a.success:
            raise RuntimeError(f"anchor A (J_time alone) failed: {a.status}")
        snap_a = Snapshot(self.m)
        b = self._lexicographic("trim", "B", -1, snap_a)
        snap_b = Snapshot(self.m)
        c = self._lexicographic("linear", "C", -2, snap_a)
        snap_c = Snapshot(self.m)
        self.anchor_points = {"A": a, "B": b, "C": c}
        self.snapshots.update({"A": snap_a, "B": snap_b, "C": snap_c})
        return a, b, c

    def front(self) -> list[TriFrontPoint]:
        s = self.settings
        a, b, c = self.anchors()
        self.on_point(a)
        self.on_point(b)
        self.on_point(c)
        self.points = [a, b, c]
        n1, n2 = s.points, self.linear_points
        # The tightest bounds stop short of the anchors' minima by ``TIGHT_MARGIN`` of the range:
        # with both bounds at their minima the corner is infeasible or degenerate (measured: 3000
        # Ipopt iterations without convergence on Case 1), and B and C already cover the minima.
        lo_t = b.first_stage_min + TIGHT_MARGIN * (a.J_trim - b.first_stage_min)
        lo_l = c.first_stage_min + TIGHT_MARGIN * (a.J_linear - c.first_stage_min)
        self.eps_trim = epsilon_grid(a.J_trim, lo_t, n1, s.spacing)
        self.eps_linear = epsilon_grid(a.J_linear, lo_l, n2, s.spacing)
        scale = max(abs(a.J_time), 1.0)
        self.snapshots["A"].restore()
        scale_multipliers(self.m, self.scale["time"] / scale)  # A's multipliers belong to A's objective scale
        last_good = Snapshot(self.m)
        index = 1
        for i in range(n1):
            cols = range(n2) if i % 2 == 0 else range(n2 - 1, -1, -1)
            for j in cols:
                if i == 0 and j == 0:
                    continue  # point A itself (both bounds inactive)
                # the first grid point leaves anchor A (see front.LEAVE_ANCHOR_OPTIONS)
                opts = LEAVE_ANCHOR_OPTIONS if index == 1 else None
                p = solve_with_fallback(
                    lambda ws, i=i, j=j, opts=opts: self._solve(
                        "time", index, "eps", float(self.eps_trim[i]), float(self.eps_linear[j]), ws, scale=scale,
                        grid=(i, j), options=opts if ws != "primal" else None),
                    s.warm_start, last_good)
                if p.success:
                    last_good = self.snapshots[index] = Snapshot(self.m)
                else:
                    last_good.restore()
                self.points.append(p)
                self.on_point(p)
                index += 1
        return self.points

    # ------------------------------------------------------------- choosing
    def utopia_nadir(self, objectives=OBJECTIVES):
        """Utopia: each objective's own minimum; nadir: its worst value over the anchors (payoff table)."""
        anchors = [self.anchor_points[k] for k in ("A", "B", "C")]
        first = {"time": self.anchor_points["A"].J_time, "trim": self.anchor_points["B"].first_stage_min,
                 "linear": self.anchor_points["C"].first_stage_min}
        utopia = tuple(first[k] for k in objectives)
        nadir = tuple(max(getattr(p, f"J_{k}") for p in anchors) for k in objectives)
        return utopia, nadir

    def choose(self, objectives=OBJECTIVES, row_linear: int | None = None):
        """Eq. 11 over the successful points (all, or only grid row ``i_linear == row_linear``).

        ``objectives=("time", "trim")`` with ``row_linear=0`` is the bi-objective choice: the
        J_linear bound is inactive on that row, so it is the (J_time, J_trim) front, anchored by A
        and B as in :class:`.front.ParetoSolver`.
        """
        utopia, nadir = self.utopia_nadir(objectives)
        if objectives == ("time", "trim"):
            b = self.anchor_points["B"]
            nadir = (b.J_time, self.anchor_points["A"].J_trim)
        pts = [p for p in self.points if p.success and p.kind in ("A", "B", "C", "eps")]
        if row_linear is not None:
            pts = [p for p in pts if p.i_linear == row_linear or p.kind in ("A", "B")]
        J = np.array([[getattr(p, f"J_{k}") for k in objectives] for p in pts])
        d = utopia_distance_n(J, utopia, nadir)
        return pts[int(np.argmin(d))], d, utopia, nadir

    def direct_choice(self, start: TriFrontPoint) -> TriFrontPoint:
        """Eq. 11 for three objectives as one NLP, warm-started from the post-hoc choice."""
        utopia, nadir = self.utopia_nadir()
        key = {"A": "A", "B": "B", "C": "C"}.get(start.kind, start.index)
        self.snapshots[key].restore()
        return self._solve("utopia", -3, "direct", utopia=utopia, nadir=nadir)
