"""NLP solver layer: one interface over Ipopt-in-casadi, pounce and an ipopt executable.

Usage::

    from pyomo_heli.solvers import make_solver
    solver = make_solver(model)                 # "casadi-ipopt", built once
    res = solver.solve(warm_start="none")       # anchor
    model.eps = 0.5 * J2_anchor                 # Param in a constraint bound
    res = solver.solve(warm_start="primal")     # re-solve, no NL rewrite
    print(res)

Every backend loads primal values into the Pyomo Vars and multipliers into
the ``dual``/``ipopt_zL_out``/``ipopt_zU_out`` suffixes with Ipopt's AMPL sign
convention, and returns a :class:`SolveResult`.
"""

from __future__ import annotations

from .errors import ModelChangedError, SolverError, SolverFailedError, SolverUnavailableError
from .common import MULTIPLIER_MODES, scale_multipliers
from .options import validate_solver_options
from .result import SUCCESS_STATUSES, SolveResult

#: Valid names for make_solver, the default first.
SOLVER_NAMES = ("casadi-ipopt", "pounce", "ipopt")

__all__ = [
    "MULTIPLIER_MODES",
    "SOLVER_NAMES",
    "SUCCESS_STATUSES",
    "ModelChangedError",
    "SolveResult",
    "SolverError",
    "SolverFailedError",
    "SolverUnavailableError",
    "available_solvers",
    "make_solver",
    "scale_multipliers",
    "validate_solver_options",
]


def make_solver(model, name: str = "casadi-ipopt", options: dict | None = None, settings=None):
    """Create a solver object for ``model``; it has ``solve(warm_start=..., options=...)``.

    ``settings``: the casadi-ipopt adapter's switches (:class:`.casadi_ipopt.CasadiSettings`; None: defaults).

    Raises ValueError for an unknown name and SolverUnavailableError when the
    backend cannot run here.
    """
    if name == "casadi-ipopt":
        from .casadi_ipopt import CasadiIpoptSolver

        return CasadiIpoptSolver(model, options, settings)
    if settings is not None:
        raise ValueError(f"solver {name!r}: settings apply to casadi-ipopt only")
    if name in ("pounce", "ipopt"):
        from .ampl import AmplSolver

        return AmplSolver(model, name, options)
    raise ValueError(f"unknown solver {name!r}; valid choices: {', '.join(SOLVER_NAMES)}")


def available_solvers() -> list[str]:
    """The names in SOLVER_NAMES that can run on this machine."""
    names = []
    try:
        import casadi

        if casadi.has_nlpsol("ipopt"):
            names.append("casadi-ipopt")
    except ImportError:
        pass
    from .ampl import _load_factory

    for name in ("pounce", "ipopt"):
        try:
            _load_factory(name)
        except SolverUnavailableError:
            continue
        names.append(name)
    return names
