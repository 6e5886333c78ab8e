"""Adaptive epsilon placement for three or more objectives (issue 31 point 5): :class:`AdaptiveFrontN`.

The two-objective placement (:mod:`.placement`) in a plane of epsilon coordinates instead of along a line,
on the N-objective solver :class:`~.epsilon.EpsilonConstraintSolver` (the tri-objective front of
:mod:`.tri_front`), with the same settings (``[pareto] placement = "adaptive"``, ``max_solves``):

1. **Anchors and a coarse grid.** The payoff-table anchors (A, B, C, ...), then a grid of 3 bounds per
   epsilon axis, on the axes of the uniform grid (from A's values to 5 % of each range above its
   minimum, ``[pareto] spacing``), less A's own corner: 8 points for three objectives. It takes the place
   of the arc-length phase: it spans the whole front, so that the refinement starts near the choice.
2. **Refinement around the Eq. 11 choice C** (normalised by ``[pareto] nadir``, the non-dominated rule
   following the points), in rounds, as for two objectives, with these counterparts:

   - *Neighbours* (:func:`cone_neighbours`): in each compass direction of the epsilon coordinates (+-z_k),
     the nearest point whose largest difference from C lies along that axis that way; a bound found
     infeasible that is nearer stands for the edge of the front in that direction.
   - *Bracket*: every neighbour within one of C's standard errors in every parameter, and every infeasible
     edge within one standard error as estimated from the neighbours (:func:`edge_gaps`). Then no point
     inside the bracket can move the choice by more than its own standard error; a direction without
     points or infeasible bounds is the end of the epsilon range (the uniform grid's box).
   - *Probes*: on the edge to each neighbour farther than a standard error, at the fraction ``0.9 / r``
     (:func:`~.placement.refinement_probes`), and halfway to an infeasible edge farther than one.
   - *Model step* (the counterpart of the parabola): in the first round, after a round that moved C, and
     after a model point that became C, one point is placed instead at the minimum of a model of the
     distance (:func:`model_minimum`): ``|z|^2 = z_1^2 + sum_k z_k^2`` with ``z_1``, the minimised objective
     over the front, a quadratic fitted to the points nearest C.

   Before it stops on a bracket, one more model point checks it (a bracket along the compass directions
   can miss a valley of the distance between them); it stops when the bracket holds after that check
   (converged), at ``max_solves``, or when nothing new can be placed.

Each point is one :meth:`~.epsilon.EpsilonConstraintSolver.solve_at`: warm from the nearest solved point,
capped at ``[pareto] max_iter``, infeasible bounds reported as infeasible (a priori or by Ipopt), as on the
grid. Limitation: the compass directions follow the epsilon axes, so a choice on an infeasible edge that
runs diagonally is bracketed only along the axes.
"""
from __future__ import annotations

import math

import numpy as np

from .placement import MIN_STEP, AdaptiveFront, _placed, denormalise, distance_in_se, normalise, refinement_probes
from .steps import INFEASIBLE, grid_bound_values, snake


def cone_neighbours(Z, c: int, infeasible=()) -> list[tuple]:
    """Three or more objectives: what bounds C in each of the ``2 (N - 1)`` compass directions of the epsilon
    coordinates ``Z[:, 1:]``: the nearest of the points, and of the bounds found ``infeasible`` (normalised
    epsilon coordinates), whose largest coordinate difference from C lies along that axis, that way (a
    cone of 45 degrees either side in 2-D). ``("point", j)`` or ``("edge", x)``; a direction with
    neither (the end of the epsilon range) has no entry. Points within ``MIN_STEP`` of C count as C."""
    Z = np.asarray(Z, float)
    E = Z[:, 1:]
    cands = [("point", j, E[j]) for j in range(len(Z))] + [("edge", None, np.asarray(x, float)) for x in infeasible]
    out = []
    for k in range(E.shape[1]):
        for sign in (-1.0, 1.0):
            best = None
            for kind, j, x in cands:
                d = x - E[c]
                dist = float(np.linalg.norm(d))
                if dist >= MIN_STEP and sign * d[k] >= np.max(np.abs(d)) and (best is None or dist < best[0]):
                    best = (dist, kind, j if kind == "point" else x)
            if best is not None and not any(o[0] == best[1] and np.array_equal(o[1], best[2]) for o in out):
                out.append((best[1], best[2]))  # a point on a cone's border bounds both cones: once
    return out


def edge_gaps(Z, c: int, r_neighbours: dict, edges) -> list[tuple[np.ndarray, float]]:
    """How far C is from each infeasible bound ``x`` that bounds it (:func:`cone_neighbours`), in C's standard
    errors as estimated from its neighbours: ``|x - C| / L`` with ``L`` the least epsilon distance per standard
    error over the neighbours ``r_neighbours`` (index -> distance in standard errors, linear along the edge);
    inf without a neighbour that moved. The edge of the front lies within that distance of C."""
    Z = np.asarray(Z, float)
    E = Z[:, 1:]
    per_se = [float(np.linalg.norm(E[j] - E[c])) / r for j, r in r_neighbours.items() if 0 < r < math.inf]
    L = min(per_se) if per_se else 0.0
    return [(np.asarray(x, float), float(np.linalg.norm(np.asarray(x) - E[c])) / L if L > 0 else math.inf)
            for x in edges]


def model_minimum(Z, c: int, taken=()) -> np.ndarray | None:
    """Three or more objectives: the epsilon coordinates where a model of the Eq. 11 distance is least
    (the 2-D counterpart of :func:`~.placement.predicted_minimum`'s parabola).

    The squared distance is ``z_1^2 + sum_k z_k^2``: exact in the epsilon coordinates ``z_2 ..``, with
    ``z_1`` (the minimised objective along the front) modelled by a quadratic in them, fitted (weighted least
    squares, the nearer points weighing more) to C and the points nearest it, six more than the quadratic's
    coefficients. The model is minimised within the distance from C of the farthest fitted point (a trust
    region). None with too few points, a rank-deficient fit, or a minimiser within ``MIN_STEP`` of a placed
    point.
    """
    from scipy.optimize import minimize

    Z = np.asarray(Z, float)
    E = Z[:, 1:]
    m = E.shape[1]
    if m < 2:
        return None
    iu = np.triu_indices(m)
    n_coef = 1 + m + len(iu[0])
    dist = np.linalg.norm(E - E[c], axis=1)
    use = np.argsort(dist, kind="stable")[:n_coef + 6]
    if len(use) < n_coef + 1:
        return None
    h = float(np.max(dist[use]))
    if h == 0.0:
        return None

    def basis(X):
        X = np.atleast_2d(X)
        return np.column_stack([np.ones(len(X)), X, (X[:, :, None] * X[:, None, :])[:, iu[0], iu[1]]])

    X = (E[use] - E[c]) / h  # conditioning: C at 0, the farthest fitted point at distance 1
    dref = np.sort(dist[use])[n_coef - 1]
    w = 1.0 / (1.0 + (dist[use] / dref) ** 2) ** 2  # the nearer points count more
    coef, _, rank, _ = np.linalg.lstsq(basis(X) * w[:, None], Z[use, 0] * w, rcond=None)
    if rank < n_coef:
        return None

    def d2(x):
        return float((basis(x) @ coef)[0] ** 2 + np.sum((E[c] + h * np.asarray(x)) ** 2))

    res = minimize(d2, np.zeros(m), method="SLSQP",
                   constraints=[{"type": "ineq", "fun": lambda x: 1.0 - float(np.dot(x, x))}])
    e = E[c] + h * np.asarray(res.x, float)
    return None if _placed(e, list(taken) + list(E)) else e


class AdaptiveFrontN(AdaptiveFront):
    """Anchors, a coarse grid and the refinement (module docstring) on an N-objective solver.

    ``solver``: an :class:`~.epsilon.EpsilonConstraintSolver` (used through ``names``, ``anchors``,
    ``grid_axes``, ``solve_at``, ``utopia_nadir``, ``points`` and ``store``); each point goes to the
    solver's own ``on_point``. ``standard_errors`` as for :class:`~.placement.AdaptiveFront`. The grid's
    axes are left in ``solver.axes`` and the coarse grid's counts in :attr:`coarse`.
    """

    first_phase = "on anchors and a coarse grid"
    sort_points = False  # in the order solved, anchors first, as the grid leaves them

    def __init__(self, solver, max_solves: int, standard_errors, spacing: str = "geometric", progress=None):
        super().__init__(solver, max_solves, standard_errors, spacing, progress=progress)
        self.objectives = tuple(f"J_{k}" for k in solver.names)
        self.coarse = (3,) * (len(self.objectives) - 1)
        self.tried: list[np.ndarray] = []  # bounds tried, in the objectives' units (the nadir may move)
        self.infeasible_tried: list[np.ndarray] = []  # those of them found infeasible

    def run(self):
        ps, s = self.ps, self.summary
        ps.anchors()  # a failed anchor raises, naming it (as for the grid)
        ps.axes = ps.grid_axes(self.coarse)
        for pos in snake(self.coarse):
            if any(pos) and len(ps.points) < self.max_solves:
                # solved as on the grid: position 0 of a later axis leaves that objective free, so the two-objective
                # row of the choice is not capped
                self._solve_n([float(ax[i]) for ax, i in zip(ps.axes, pos)], pos,
                              solve=grid_bound_values(ps.axes, pos))
        s.arc_length_solves = len(ps.points)
        try:
            self._scaling()
        except ValueError as exc:
            s.stop = str(exc)
            return self._finish()
        self._refine()
        return self._finish()

    def _solve_n(self, eps, grid=(), solve=None) -> None:
        """Solve at the bounds ``solve`` (default ``eps``); ``eps``, finite, is where the placement counts the point
        as tried (a grid point's free objective at the value of its axis)."""
        self.tried.append(np.asarray(eps, float))
        key = f"ada{len(self.ps.points):03d}" if getattr(self.ps, "store", None) is not None else None
        p = self.ps.solve_at([float(v) for v in (eps if solve is None else solve)], key=key, grid=tuple(grid))
        if p.status == INFEASIBLE:
            self.infeasible_tried.append(self.tried[-1])

    def _normalised_bounds(self, bounds) -> list:
        U, N = np.asarray(self.utopia, float)[1:], np.asarray(self.nadir, float)[1:]
        return [(e - U) / (N - U) for e in bounds]

    def _scaling(self):
        """The solver's (utopia, nadir) under ``[pareto] nadir`` (the non-dominated rule follows the points), the
        payoff table's while that is degenerate; raises ValueError (:func:`normalise`) when both are."""
        U, N = self.ps.utopia_nadir()
        if not np.all(np.asarray(N, float) > np.asarray(U, float)):
            U, N = self.ps.utopia_nadir(rule="payoff")
        normalise(np.asarray(U, float), U, N)
        self.utopia, self.nadir = tuple(U), tuple(N)
        return self.utopia, self.nadir

    def _taken(self) -> list:
        return self._normalised_bounds(self.tried)

    def _place(self, e) -> None:
        self._solve_n(denormalise(e, self.utopia, self.nadir, list(range(1, len(self.objectives)))))

    def _bracket(self, Z, c, ok, se):
        cones = cone_neighbours(Z, c, self._normalised_bounds(self.infeasible_tried))
        r = {j: distance_in_se(ok[c].parameters, ok[j].parameters, se) for kind, j in cones if kind == "point"}
        return r, edge_gaps(Z, c, r, [x for kind, x in cones if kind == "edge"])

    def _confirmation(self, Z, c):
        """The model's minimum (:func:`model_minimum`): a bracket along the compass directions can miss a valley
        of the distance between them, which the model sees."""
        return model_minimum(Z, c, self._taken())

    def _probes(self, Z, c, r, gaps, use_model):
        taken = self._taken()
        e = model_minimum(Z, c, taken) if use_model else None
        if e is not None:
            return [e], True
        probes = refinement_probes(Z, c, r, taken)
        probes += [p for p in (0.5 * (Z[c, 1:] + x) for x, g in gaps if g > 1.0) if not _placed(p, taken + probes)]
        return probes, False
