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
NL file: every point is a re-solve from the previous point's solution
(primal warm start, measured best in ../shared/research/solvers.md;
``warm_start="full"`` adds the duals). Ipopt treats the pinned variables as
parameters.

Scaling lives at optimizer level only (paper Fig. 4): a single-objective
solve is divided by |J(theta_0)|, and each objective of a multi-objective
solve by its utopia value.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
import pyomo.environ as pyo

from ..nlp.parameters import free_parameter_values
from ..solvers import make_solver


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


@dataclass
class ParetoSettings:
    points: int = 11
    spacing: str = "geometric"  # or "linear"
    warm_start: str = "primal"  # "primal" or "full"
    lexicographic_tol: float = 1e-6  # relative slack on J_trim(B) for B's second stage
    solver: str = "casadi-ipopt"
    solver_options: dict = field(default_factory=dict)
    cold_check: bool = False  # also solve every interior point cold, to measure what warm starts save

    def __post_init__(self):
        if self.points < 2:
            raise ValueError(f"pareto.points must be at least 2 (the two anchors), got {self.points}")
        if self.spacing not in ("geometric", "linear"):
            raise ValueError(f"pareto.spacing must be 'geometric' or 'linear', got {self.spacing!r}")
        if self.warm_start not in ("primal", "full", "none"):
            raise ValueError(f"pareto.warm_start must be primal, full or none, got {self.warm_start!r}")


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


class _Snapshot:
    """Values of every variable of the model, to restore a solution as a warm start."""

    def __init__(self, m):
        self.values = [(v, v.value) for v in m.component_data_objects(pyo.Var, descend_into=True)]

    def restore(self):
        for v, val in self.values:
            if not v.fixed:
                v.set_value(val, skip_validation=True)


class ParetoSolver:
    """Anchors, front and choice on one identification NLP built by nlp.identification."""

    def __init__(self, m, settings: ParetoSettings | None = None, on_point=None):
        self.m = m
        self.settings = settings or ParetoSettings()
        self.on_point = on_point or (lambda p: None)
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
        self.solver = make_solver(m, self.settings.solver, self.settings.solver_options)
        self.points: list[FrontPoint] = []

    def _pin(self, **values):
        """Pin every objective setting (unnamed ones to 0) by equal bounds."""
        w = self.m.objective_settings
        for k in w:
            v = float(values.get(k, 0.0))
            w[k].setlb(v)
            w[k].setub(v)
            w[k].set_value(v)

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
        res = solver.solve(warm_start=warm_start, options=options)
        p = FrontPoint(index=index, kind=point_kind, epsilon=epsilon, J_time=pyo.value(self.m.J_time),
                       J_trim=pyo.value(self.m.J_trim), parameters=free_parameter_values(self.m),
                       success=res.success, status=res.status, iterations=res.iterations,
                       wall_time=res.wall_time, setup_time=res.setup_time, warm_start=warm_start)
        return p

    def point_a(self) -> FrontPoint:
        """Anchor A alone (min J_time, the classic time-domain estimate) from the model's current values."""
        return self._solve("time", 0, "A", math.inf, "none")

    def anchors(self) -> tuple[FrontPoint, FrontPoint]:
        """A: min J_time. B: min J_trim, then min J_time keeping J_trim at its minimum (lexicographic)."""
        a = self.point_a()
        if not a.success:
            raise RuntimeError(f"anchor A (J_time alone) failed: {a.status}")
        self._snap_a = _Snapshot(self.m)
        b1 = self._solve("trim", -1, "B1", math.inf, "primal")
        if not b1.success:
            raise RuntimeError(f"anchor B (J_trim alone) failed: {b1.status}")
        eps_b = b1.J_trim * (1 + self.settings.lexicographic_tol) + 1e-12
        b = self._solve("time", self.settings.points - 1, "B", eps_b, "primal")
        b.iterations += b1.iterations
        b.wall_time += b1.wall_time
        b.setup_time += b1.setup_time
        if not b.success:
            raise RuntimeError(f"anchor B, second stage, failed: {b.status}")
        self._snap_b = _Snapshot(self.m)
        return a, b

    def front(self) -> list[FrontPoint]:
        """Anchors, then the interior points from A towards B, each warm-started from the previous.

        A failed point is recorded with its status and the sweep goes on from
        the last point that succeeded.
        """
        s = self.settings
        a, b = self.anchors()
        self.points = [a]
        self.snapshots = {a.index: self._snap_a, b.index: self._snap_b}
        self.on_point(a)
        eps = epsilon_grid(a.J_trim, b.J_trim, s.points, s.spacing)
        last_good = self._snap_a
        last_good.restore()
        # objectives of multi-objective solves are scaled by their utopia value
        for k in range(1, s.points - 1):
            p = self._solve("time", k, "eps", float(eps[k]), s.warm_start, scale=max(abs(a.J_time), 1.0))
            if s.cold_check:
                self._cold_check(p, last_good, scale=max(abs(a.J_time), 1.0))
            if p.success:
                last_good = self.snapshots[k] = _Snapshot(self.m)
            else:
                last_good.restore()
            self.points.append(p)
            self.on_point(p)
        self.points.append(b)
        self.on_point(b)
        return self.points

    def _cold_check(self, p: FrontPoint, back, scale: float) -> None:
        """Solve the same epsilon point from the initial guess; keep the warm solution in the model."""
        warm = _Snapshot(self.m)
        self._snap_initial.restore()
        cold = self._solve("time", p.index, "eps", p.epsilon, "none", scale=scale)
        p.cold_iterations, p.cold_status, p.cold_J_time = cold.iterations, cold.status, cold.J_time
        p.cold_wall_time = cold.wall_time
        warm.restore()

    # ------------------------------------------------------------- choosing
    def utopia_nadir(self):
        a = next(p for p in self.points if p.kind == "A")
        b = next(p for p in self.points if p.kind == "B")
        return (a.J_time, b.J_trim), (b.J_time, a.J_trim)

    def choose(self) -> tuple[FrontPoint, np.ndarray]:
        """The front point closest to utopia (Eq. 11, post hoc), and all distances."""
        utopia, nadir = self.utopia_nadir()
        ok = [p for p in self.points if p.success]
        d = utopia_distance([p.J_time for p in ok], [p.J_trim for p in ok], utopia, nadir)
        return ok[int(np.argmin(d))], d

    def direct_choice(self, start: FrontPoint | None = None) -> FrontPoint:
        """Eq. 11 as one NLP (squared distance: same minimiser, smooth), warm from the post-hoc choice."""
        utopia, nadir = self.utopia_nadir()
        start = start or self.choose()[0]
        self.snapshots[start.index].restore()
        return self._solve("utopia", -1, "direct", math.inf, "primal", utopia=utopia, nadir=nadir)
