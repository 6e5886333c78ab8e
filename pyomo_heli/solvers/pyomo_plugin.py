"""The casadi-Ipopt adapter as a Pyomo solver: ``SolverFactory("casadi_ipopt")``.

Registered when :mod:`pyomo_heli` is imported::

    import pyomo.environ as pe
    import pyomo_heli  # noqa: F401  (registers the solver)

    res = pe.SolverFactory("casadi_ipopt").solve(model, tee=False, options={"tol": 1e-10})
    pe.assert_optimal_termination(res)

It is Ipopt 3.14 with MUMPS from the ``casadi`` wheel, so it needs no ``ipopt`` executable. Each
``solve`` writes the model's NL file and builds the casadi problem
(:class:`~pyomo_heli.solvers.casadi_ipopt.CasadiIpoptSolver`); for many re-solves of one model with changed
bounds use :func:`pyomo_heli.solvers.make_solver`, which builds once.

``solve`` returns Pyomo :class:`~pyomo.opt.SolverResults`. Ipopt's return status maps to Pyomo's
termination condition as Pyomo's own ``ipopt`` plugin reports it (:data:`TERMINATION`): an infeasible problem
gives ``infeasible``, the iteration limit ``maxIterations``, and so on. With ``load_solutions=True`` (the
default) the primal values go into the variables and, where the model has import ``dual``/``ipopt_zL_out``/
``ipopt_zU_out`` suffixes, the multipliers into them (Ipopt's AMPL sign convention); with
``load_solutions=False`` the model is left unchanged and ``model.solutions.load_from(results)`` loads the
solution later (as parmest does).

parmest asks ``SolverFactory("ipopt")`` for its solver whatever it is given; :func:`as_ipopt` makes that name
mean this solver for the duration of a ``with`` block (docs/api.md).
"""
from __future__ import annotations

import contextlib
import math
import time

from pyomo.common.collections import Bunch
from pyomo.opt import (
    SolutionStatus,
    SolverFactory,
    SolverResults,
    SolverStatus,
    TerminationCondition,
)
from pyomo.opt.results.solution import Solution

#: the name under which the solver is registered (and the hyphenated spelling of this project's configs)
NAMES = ("casadi_ipopt", "casadi-ipopt")

_TC, _SS, _SOL = TerminationCondition, SolverStatus, SolutionStatus
#: Ipopt return status -> (termination condition, solver status, solution status)
TERMINATION = {
    # Ipopt's AMPL driver reports an acceptable point as solved (solve_result_num 1, "optimal" in Pyomo);
    # results.solver.message says which
    "Solve_Succeeded": (_TC.optimal, _SS.ok, _SOL.optimal),
    "Solved_To_Acceptable_Level": (_TC.optimal, _SS.ok, _SOL.optimal),
    "Feasible_Point_Found": (_TC.feasible, _SS.ok, _SOL.feasible),
    "Infeasible_Problem_Detected": (_TC.infeasible, _SS.warning, _SOL.infeasible),
    "Diverging_Iterates": (_TC.unbounded, _SS.warning, _SOL.unbounded),
    "User_Requested_Stop": (_TC.userInterrupt, _SS.aborted, _SOL.stoppedByLimit),
    "Maximum_Iterations_Exceeded": (_TC.maxIterations, _SS.warning, _SOL.stoppedByLimit),
    "Maximum_CpuTime_Exceeded": (_TC.maxTimeLimit, _SS.warning, _SOL.stoppedByLimit),
    "Maximum_WallTime_Exceeded": (_TC.maxTimeLimit, _SS.warning, _SOL.stoppedByLimit),
    "Search_Direction_Becomes_Too_Small": (_TC.other, _SS.warning, _SOL.other),
    "Restoration_Failed": (_TC.other, _SS.warning, _SOL.other),
    "Error_In_Step_Computation": (_TC.error, _SS.error, _SOL.error),
    "Not_Enough_Degrees_Of_Freedom": (_TC.invalidProblem, _SS.error, _SOL.error),
    "Invalid_Problem_Definition": (_TC.invalidProblem, _SS.error, _SOL.error),
    "Invalid_Option": (_TC.error, _SS.error, _SOL.error),
    "Invalid_Number_Detected": (_TC.internalSolverError, _SS.error, _SOL.error),
}
_UNKNOWN = (_TC.error, _SS.error, _SOL.error)
#: suffixes the adapter writes; created on the model only for the solve if it has none of that name
_SUFFIXES = ("dual", "ipopt_zL_out", "ipopt_zU_out")


class CasadiIpoptPyomoSolver:
    """Pyomo's (legacy) solver interface over :class:`~pyomo_heli.solvers.casadi_ipopt.CasadiIpoptSolver`.

    ``options`` are Ipopt options (``tol``, ``max_iter``, ``mu_strategy``, ...); the adapter's defaults
    (``tol`` 1e-8, MUMPS with QAMD ordering) apply where none is given.
    """

    def __init__(self, **kwds):
        self.name = NAMES[0]
        self.options = Bunch()
        self.options.update(kwds.pop("options", None) or {})
        self._version = None

    # --- what SolverFactory users call besides solve
    def available(self, exception_flag: bool = True) -> bool:
        try:
            import casadi

            ok = bool(casadi.has_nlpsol("ipopt"))
        except ImportError:
            ok = False
        if not ok and exception_flag:
            from pyomo.common.errors import ApplicationError

            raise ApplicationError("solver casadi_ipopt needs casadi with its Ipopt plugin: pip install casadi")
        return ok

    def license_is_valid(self) -> bool:
        return True

    def version(self) -> tuple:
        """The casadi version (its Ipopt is 3.14)."""
        import casadi

        return tuple(int(x) for x in casadi.__version__.split(".")[:3] if x.isdigit())

    def warm_start_capable(self) -> bool:
        return False  # starts from the variable values in the model, always

    def set_options(self, options) -> None:
        self.options.update(dict(options))

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    # --- solve
    def solve(self, model, tee: bool = False, load_solutions: bool = True, options: dict | None = None,
              timelimit: float | None = None, **kwds) -> SolverResults:
        """Solve ``model`` from its current variable values; return Pyomo SolverResults.

        Keywords of the legacy interface that concern files (``keepfiles``, ``logfile``, ``solnfile``,
        ``symbolic_solver_labels``, ``report_timing``) are accepted and have nothing to do here; any other
        keyword is an error.
        """
        unused = set(kwds) - {"keepfiles", "logfile", "solnfile", "symbolic_solver_labels", "report_timing",
                              "suffixes", "warmstart"}
        if unused:
            raise ValueError(f"solver casadi_ipopt: unknown keyword(s) {', '.join(sorted(unused))}")
        from .casadi_ipopt import CasadiIpoptSolver

        opts = {**self.options, **(options or {})}
        opts["verbose"] = bool(tee) or bool(opts.get("verbose", False))
        if timelimit is not None:
            opts["max_wall_time"] = float(timelimit)
        created = [n for n in _SUFFIXES if model.component(n) is None]
        t0 = time.perf_counter()
        try:
            solver = CasadiIpoptSolver(model, opts)
            before = [v.value for v in solver.variables]
            res = solver.solve(warm_start="none")
            values = [v.value for v in solver.variables]
            duals = model.component("dual")
            duals = {c: duals.get(c) for c in solver.constraints} if duals is not None else {}
            if not load_solutions:  # leave the model as it was: the values go into results.solution
                for v, x in zip(solver.variables, before):
                    v.set_value(x, skip_validation=True)
        finally:
            for n in created:  # the adapter creates them; a Pyomo solver does not add components
                if model.component(n) is not None:
                    model.del_component(n)
        wall = time.perf_counter() - t0
        return self._results(model, solver, res, values, duals, load_solutions, created, wall)

    def _results(self, model, solver, res, values, duals, load_solutions, created, wall) -> SolverResults:
        from pyomo.core.base.label import NumericLabeler
        from pyomo.core.base.symbol_map import SymbolMap

        tc, ss, sol_status = TERMINATION.get(res.status, _UNKNOWN)
        results = SolverResults()
        results.solver.name = self.name
        results.solver.status = ss
        results.solver.termination_condition = tc
        results.solver.message = f"Ipopt {res.status} ({res.message})"
        results.solver.return_code = 0
        results.solver.wallclock_time = wall
        results.solver.statistics.number_of_iterations = res.iterations  # read by some Pyomo tools
        results.problem.name = model.name
        results.problem.number_of_variables = len(solver.variables)
        results.problem.number_of_constraints = len(solver.constraints)
        results.problem.number_of_objectives = 0 if solver.objective is None else 1
        finite = math.isfinite(res.objective)
        if solver.objective is not None:
            results.problem.sense = solver.objective.sense
            if finite and tc in (_TC.optimal, _TC.feasible):
                results.problem.upper_bound = res.objective if solver.sense_sign > 0 else None
                results.problem.lower_bound = res.objective if solver.sense_sign < 0 else None

        results._smap_id = None
        if not load_solutions and sol_status not in (_SOL.error,):
            soln = Solution()
            soln.status = sol_status
            smap = soln.symbol_map = SymbolMap()
            smap.default_labeler = NumericLabeler("x")
            for var, val in zip(solver.variables, values):
                soln.variable[smap.getSymbol(var)] = {"Value": val}
            if solver.objective is not None:
                soln.objective[smap.getSymbol(solver.objective)] = {"Value": res.objective}
            if "dual" not in created:  # the user's own dual suffix: deliver the multipliers with the solution
                for con, lam in duals.items():
                    if lam is not None:
                        soln.constraint[smap.getSymbol(con)] = {"Dual": lam}
            results.solution.insert(soln)
            results._smap_id = id(smap)
            results._smap = smap
        return results


def register() -> None:
    """Register the solver with Pyomo's SolverFactory (done by ``import pyomo_heli``; repeatable)."""
    for name in NAMES:
        if name not in SolverFactory:
            SolverFactory.register(name, doc="Ipopt inside casadi (pyomo_heli); no ipopt executable needed")(
                CasadiIpoptPyomoSolver)


@contextlib.contextmanager
def as_ipopt():
    """Within the block ``SolverFactory("ipopt")`` gives casadi_ipopt (for tools that hard-code "ipopt",
    e.g. parmest's ``theta_est``); the previous meaning of "ipopt" is restored afterwards."""
    import pyomo.environ  # noqa: F401  (registers Pyomo's own "ipopt" first, so that it is restored after)

    register()
    had = "ipopt" in SolverFactory
    previous = SolverFactory._cls.get("ipopt")
    previous_doc = SolverFactory._doc.get("ipopt")
    if had:
        SolverFactory.unregister("ipopt")
    SolverFactory.register("ipopt", doc="casadi_ipopt (pyomo_heli.solvers.pyomo_plugin.as_ipopt)")(
        CasadiIpoptPyomoSolver)
    try:
        yield
    finally:
        SolverFactory.unregister("ipopt")
        if had:
            SolverFactory.register("ipopt", doc=previous_doc)(previous)
