"""Tri-objective front (J_time, J_trim, J_linear): the three-objective use of :mod:`.epsilon`.

Minimise J_time subject to J_trim <= eps_trim and J_linear <= eps_linear on a
2-D grid of bounds (paper Eq. 10 with two epsilon constraints). The grid runs
from the unconstrained values at anchor A (min J_time) down to the anchors'
minima: eps_trim from J_trim(A) towards J_trim(B), eps_linear from J_linear(A)
towards J_linear(C), stopping :data:`~.epsilon.TIGHT_MARGIN` of the range short
of each minimum. Points are visited along a snake path (row 0 left to right,
row 1 right to left, ...), each warm-started from the solved solution nearest
to being one at its bounds (:meth:`~.epsilon.EpsilonConstraintSolver.grid_start`,
recorded in the point's ``start``). A grid point whose bounds are infeasible is reported as
``infeasible`` (found a priori, or by Ipopt) and the sweep goes on.

Row ``i_linear = 0`` (J_linear bound inactive) is the bi-objective front of
J_time and J_trim, so the same run also gives the two-objective choice.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .epsilon import TIGHT_MARGIN, EpsilonConstraintSolver, Outcome, utopia_distance_n  # noqa: F401
from .front import FrontPoint, ParetoSettings

OBJECTIVES = ("time", "trim", "linear")


@dataclass
class TriFrontPoint(FrontPoint):
    """A front point with the third objective and its bound."""

    J_linear: float = math.nan
    epsilon_linear: float = math.inf
    i_trim: int = -1  # grid position (-1: anchors and choices off the grid)
    i_linear: int = -1
    note: str = ""  # why a point is infeasible (Ipopt's status, or the a-priori reason)
    start: str = ""  # grid points: the solution the solve started from (EpsilonConstraintSolver.grid_start)
    multiplier_linear: float = math.nan  # -dJ_time/dJ_linear from the J_linear bound's multiplier (multiplier_trim)


class TriParetoSolver(EpsilonConstraintSolver):
    """Anchors A, B, C, the 2-D epsilon grid and the Eq. 11 choices on one NLP with J_time, J_trim, J_linear.

    ``linear_points``: grid points on J_linear, used unless ``settings.grid`` gives both counts.
    """

    point_class = TriFrontPoint

    def __init__(self, m, settings: ParetoSettings | None = None, linear_points: int = 3, on_point=None,
                 store=None):
        if m.component("J_linear") is None:
            raise ValueError("the NLP has no J_linear: build it with frequency responses")
        settings = settings or ParetoSettings()
        super().__init__(m, OBJECTIVES, settings, on_point, store)
        grid = settings.grid
        if grid is not None and len(grid) != 2:
            raise ValueError(f"pareto.points: the tri-objective grid needs 2 counts (J_trim, J_linear), "
                             f"got {list(grid)}")
        self.counts = tuple(grid) if grid is not None else (settings.points, int(linear_points))

    def _point(self, index: int, kind: str, eps: dict, out: Outcome, warm_start: str, grid=()):
        i_trim, i_linear = grid if len(grid) == 2 else (-1, -1)
        return TriFrontPoint(index=index, kind=kind, epsilon=eps.get("trim", math.inf), J_time=out.J["time"],
                             J_trim=out.J["trim"], parameters=out.parameters, success=out.success,
                             status=out.status, iterations=out.iterations, wall_time=out.wall_time,
                             setup_time=out.setup_time, warm_start=warm_start, J_linear=out.J["linear"],
                             epsilon_linear=eps.get("linear", math.inf), i_trim=i_trim, i_linear=i_linear,
                             note=out.note, multiplier_trim=out.multipliers.get("trim", math.nan),
                             multiplier_linear=out.multipliers.get("linear", math.nan))

    def front(self) -> list[TriFrontPoint]:
        """Anchors A, B, C, then the grid (:meth:`~.epsilon.EpsilonConstraintSolver.grid_front`)."""
        pts = self.grid_front(self.counts)
        self.eps_trim, self.eps_linear = self.axes
        return pts

    # ------------------------------------------------------------- choosing
    def utopia_nadir(self, objectives=OBJECTIVES, rule: str | None = None):
        """Utopia: each objective's own minimum; nadir by ``rule`` (payoff table or non-dominated points)."""
        utopia, nadir = super().utopia_nadir(rule)
        pick = [OBJECTIVES.index(k) for k in objectives]
        return tuple(utopia[i] for i in pick), tuple(nadir[i] for i in pick)

    def choose(self, objectives=OBJECTIVES, row_linear: int | None = None, rule: str | None = None):
        """Eq. 11 over the successful points (all, or only grid row ``i_linear == row_linear``).

        ``objectives=("time", "trim")`` with ``row_linear=0`` is the bi-objective choice: the
        J_linear bound is inactive on that row, so it is the (J_time, J_trim) front, anchored by A
        and B as in :class:`.front.ParetoSolver` (nadir (J_time(B), J_trim(A))).
        """
        utopia, nadir = self.utopia_nadir(objectives, rule)
        if objectives == ("time", "trim"):
            b = self.anchor_points["B"]
            nadir = self.resolved_nadir(utopia, (b.J_time, self.anchor_points["A"].J_trim), objectives)
        pts = [p for p in self.points if p.success and p.kind in ("A", "B", "C", "eps")]
        if row_linear is not None:
            pts = [p for p in pts if p.i_linear == row_linear or p.kind in ("A", "B")]
        J = np.array([[getattr(p, f"J_{k}") for k in objectives] for p in pts])
        d = utopia_distance_n(J, utopia, nadir)
        return pts[int(np.argmin(d))], d, utopia, nadir
