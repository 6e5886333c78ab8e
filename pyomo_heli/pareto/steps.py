"""The parts of one front solve: outcome and point records, warm-start options and fallback, the grid's path.

Used by :mod:`.epsilon` (the N-objective solver) and the fronts built on it (:mod:`.front`,
:mod:`.tri_front`).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
import pyomo.environ as pyo

from ..solvers import MULTIPLIER_MODES
from .snapshot import Snapshot

#: status of a point found infeasible (a priori, or by Ipopt under active bounds)
INFEASIBLE = "infeasible"
#: Ipopt statuses recorded as :data:`INFEASIBLE` when at least one epsilon bound is set
IPOPT_INFEASIBLE = frozenset({"Infeasible_Problem_Detected", "Restoration_Failed"})
#: fraction of the anchor range kept above each bounded objective's minimum at the tight end of a grid
TIGHT_MARGIN = 0.05
#: anchor names: A for the minimised objective, then one per bounded objective
ANCHOR_NAMES = "ABCDEFGH"

#: Options of a step that starts from anchor A (the first interior point, or the next one while
#: every earlier one failed). There the active set changes (the epsilon bound becomes
#: active, a parameter at its bound in A may leave it), and the small bound pushes of a warm start
#: pin the iterate: with 1e-6 that step took 20 Ipopt iterations, with Ipopt's default 1e-3 four,
#: while the later steps take 3 with 1e-6 and 5 with 1e-3 (Case 1, full size, docs/performance.md).
LEAVE_ANCHOR_OPTIONS = {"warm_start_bound_push": 1e-3, "warm_start_mult_bound_push": 1e-3}

#: Options of the later steps with ``"continuation"``: the start is (nearly) the solution, on the same
#: active set, so it is left where it is: bound and slack pushes 1e-8 instead of 1e-6 (primal) and 1e-3
#: (fractions and slacks). Case 1, full size, with the secant predictor: 29 -> 25 iterations over the
#: 9 interior points, the same front (docs/performance.md; the one-off study is in CHANGELOG.md).
FRONT_STEP_OPTIONS = {"warm_start_bound_push": 1e-8, "warm_start_mult_bound_push": 1e-8,
                      "warm_start_slack_bound_push": 1e-8, "warm_start_bound_frac": 1e-8,
                      "warm_start_slack_bound_frac": 1e-8}


def snake(counts) -> list[tuple[int, ...]]:
    """Grid positions of ``counts`` (one count per axis) along a boustrophedon path: neighbours follow each other."""
    counts = tuple(int(c) for c in counts)
    if len(counts) == 1:
        return [(i,) for i in range(counts[0])]
    inner = snake(counts[1:])
    return [(i,) + t for i in range(counts[0]) for t in (inner if i % 2 == 0 else inner[::-1])]


def epsilon_grid(loose: float, tight: float, points: int, spacing: str = "geometric") -> np.ndarray:
    """Bounds from ``loose`` (the value at anchor A, inactive) down to ``tight``: ``points`` values, ends included."""
    if tight <= 0 or spacing == "linear":
        return np.linspace(loose, tight, points)
    return np.geomspace(loose, tight, points)


def solve_with_fallback(solve, mode: str, start: Snapshot):
    """``solve(mode)``; if a multiplier warm start fails, once more from ``start`` with ``solve("primal")``.

    A warm start from a neighbouring solution can mislead the barrier method
    (see ../shared/research/solvers.md: a full warm start stalled on a 50k
    problem); the primal re-solve is the robust fallback. The returned point's
    iterations and wall time include both attempts, and its ``warm_start``
    says what happened. A point found infeasible (a priori, or by Ipopt's infeasibility detection)
    is not retried: the retry would be a second run towards the same verdict.
    """
    p = solve(mode)
    if p.success or mode not in MULTIPLIER_MODES or p.status == INFEASIBLE:
        return p
    start.restore()
    return retried(p, solve("primal"), f"{mode} ({p.status}), then primal")


def solve_from_starts(solve, starts):
    """``solve()`` from each ``(label, snapshot)`` of ``starts`` in turn until one converges.

    The one retry of a solve whose start alone may be at fault (the direct Eq. 11 solve: its
    objective, a squared distance of objectives normalised by their ranges, is badly conditioned
    where a front is flat, and Ipopt can stop in a step-computation or restoration failure from one
    start and converge from another). The returned point carries every attempt's iterations and
    times, and its ``warm_start`` names the starts and their statuses.
    """
    p, tried = None, []
    for label, snapshot in starts:
        snapshot.restore()
        q = solve()
        mode = q.warm_start
        tried.append(f"{label} ({q.status})" if not q.success else label)
        p = retried(p, q, "") if p is not None else q
        p.warm_start = f"{mode} from " + ", then ".join(tried)
        if q.success:
            break
    return p


def starts_note(p) -> str:
    """`` (started from ...)`` when a solve of :func:`solve_from_starts` needed more than one start, `` (not
    solved: ...)`` when none was needed, else ''."""
    ws = str(getattr(p, "warm_start", ""))
    return f" ({ws})" if ", then " in ws or ws.startswith("not solved") else ""


def retried(first, retry, warm_start: str):
    """``retry`` (a point or outcome) carrying the failed ``first`` attempt's iterations and times, its
    ``warm_start`` saying what happened: the one bookkeeping of every retry of a front or anchor solve."""
    retry.iterations += max(first.iterations, 0)
    retry.wall_time += first.wall_time
    retry.setup_time += first.setup_time
    retry.warm_start = warm_start
    return retry


def pin_objective_settings(m, **values) -> None:
    """Pin every objective setting of ``m.objective_settings`` (unnamed ones to 0) by equal bounds."""
    w = m.objective_settings
    for k in w:
        v = float(values.get(k, 0.0))
        w[k].setlb(v)
        w[k].setub(v)
        w[k].set_value(v)


def _value(expr) -> float:
    """Value of an objective expression at the model's current values; NaN if it cannot be evaluated."""
    try:
        return float(pyo.value(expr))
    except (ValueError, ZeroDivisionError, OverflowError, TypeError):
        return float("nan")


@dataclass
class Outcome:
    """What one solve gave: objective values, parameters, and how it went."""

    J: dict
    parameters: dict
    success: bool
    status: str
    iterations: int
    wall_time: float
    setup_time: float
    note: str = ""
    #: bounded objective -> -dJ_0/dJ_k at the solution, from the epsilon constraint's multiplier (0: bound inactive;
    #: only for a solve that minimises J_0); the weight ratio b/a of a J_0 + b J_k the point is stationary for
    multipliers: dict = field(default_factory=dict)


@dataclass
class EpsilonPoint:
    """One point of an N-objective front: objective values ``J`` and bounds ``epsilon`` by name (inf: inactive).

    ``p.J_time`` reads ``p.J["time"]``, as on the two- and three-objective point types.
    """

    index: int
    kind: str  # "A", "B", ... (anchors), "eps" (grid or solve_at), "direct"
    J: dict
    epsilon: dict
    parameters: dict
    success: bool
    status: str
    iterations: int
    wall_time: float
    setup_time: float = 0.0
    warm_start: str = "primal"
    grid: tuple = ()
    note: str = ""
    first_stage_min: float = math.nan  # anchors of bounded objectives: the objective's own minimum
    multipliers: dict = field(default_factory=dict)  # bounded objective -> -dJ_0/dJ_k (Outcome.multipliers)
    start: str = ""  # grid points: the solution the solve started from (EpsilonConstraintSolver.grid_start)

    def __getattr__(self, name):
        if name.startswith("J_") and "J" in self.__dict__ and name[2:] in self.__dict__["J"]:
            return self.__dict__["J"][name[2:]]
        raise AttributeError(name)

    def row(self) -> dict:
        d = asdict(self)
        for k in ("J", "epsilon", "parameters", "multipliers"):
            d.pop(k)
        d.update({f"J_{k}": v for k, v in self.J.items()})
        d.update({f"epsilon_{k}": v for k, v in self.epsilon.items()})
        d.update({f"multiplier_{k}": v for k, v in self.multipliers.items()})
        d["grid"] = ",".join(str(i) for i in self.grid)
        d.update(self.parameters)
        return d


def grid_bound_values(axes, pos) -> list:
    """The bounds at grid position ``pos``, one per axis: ``axes[k][pos[k]]``, except that position 0 of every axis
    after the first leaves that objective free (inf); see :meth:`EpsilonConstraintSolver.grid_bounds`."""
    return [math.inf if n > 0 and i == 0 else float(ax[i]) for n, (ax, i) in enumerate(zip(axes, pos))]
