"""Exceptions of the solver layer.

A solver that *runs* and ends non-optimally (infeasible, iteration limit,
...) is not an error: it returns a :class:`~pyomo_heli.solvers.result.SolveResult`
with ``success=False``, because a Pareto sweep has to keep going and decide
what to do (retry with a full warm start, halve the epsilon step, ...).
Exceptions are kept for the cases where no result exists at all.
"""


class SolverError(RuntimeError):
    """Base class of the solver-layer errors."""


class SolverUnavailableError(SolverError):
    """The requested backend cannot run on this machine (missing package or executable)."""


class SolverFailedError(SolverError):
    """The backend crashed or produced no solution to read back."""


class ModelChangedError(SolverError, ValueError):
    """The Pyomo model changed in a way a cached NL/casadi problem cannot follow.

    Raised by :class:`~pyomo_heli.solvers.casadi_ipopt.CasadiIpoptSolver`;
    the remedy is ``solver.rebuild()``.
    """
