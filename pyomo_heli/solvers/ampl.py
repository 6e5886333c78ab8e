"""AMPL-executable backends (``pounce``, an ``ipopt`` on PATH) behind the same interface.

These go through Pyomo's ``SolverFactory``: the NL file is rewritten on every
solve, so changed Params/fixed values are always honoured (at a cost of a few
seconds per solve at 50k variables). Ipopt's AMPL driver reports iterations
and the exact exit reason only in its log, and "Solved To Acceptable Level"
comes back as ``optimal``, so each solve is logged to a temporary file and
parsed.

Multipliers travel in the Ipopt/ASL suffixes ``dual``, ``ipopt_zL_out`` and
``ipopt_zU_out`` (inputs for a full warm start: ``dual`` exported plus
``ipopt_zL_in``/``ipopt_zU_in``), with the same signs that
:class:`~pyomo_heli.solvers.casadi_ipopt.CasadiIpoptSolver` writes.
"""

from __future__ import annotations

import logging
import math
import os
import re
import tempfile
import time

import pyomo.environ as pyo
from pyomo.common.errors import ApplicationError
from pyomo.common.gc_manager import PauseGC
from pyomo.common.log import LoggingIntercept
from pyomo.opt import TerminationCondition as TC

from .. import interrupts
from .common import MULTIPLIER_MODES, _active_objective, ensure_suffix, resolve_options
from .errors import SolverFailedError, SolverUnavailableError
from .result import IPOPT_EXIT_MESSAGES, SUCCESS_STATUSES, SolveResult, status_from_exit_message

_INSTALL_HINTS = {
    "pounce": "pip install pyomo-pounce (or pip install 'pyomo_heli[pounce]')",
    "ipopt": "put an AMPL-enabled ipopt executable on PATH (e.g. conda install -c conda-forge ipopt, "
    "or 'idaes get-extensions'); on a pip-only machine use the default 'casadi-ipopt'",
}

#: Fallback when the log has no EXIT/Status line.
_TERMINATION_TO_STATUS = {
    TC.optimal: "Solve_Succeeded",
    TC.locallyOptimal: "Solve_Succeeded",
    TC.infeasible: "Infeasible_Problem_Detected",
    TC.maxIterations: "Maximum_Iterations_Exceeded",
    TC.maxTimeLimit: "Maximum_WallTime_Exceeded",
    TC.unbounded: "Diverging_Iterates",
    TC.userInterrupt: "User_Requested_Stop",
    TC.invalidProblem: "Invalid_Problem_Definition",
    TC.internalSolverError: "Internal_Error",
}

_ITER_RE = re.compile(r"^Number of Iterations\.*:\s*(\d+)", re.M)
_EXIT_RE = re.compile(r"^EXIT:\s*(.+)$", re.M)
_STATUS_RE = re.compile(r"^Status:\s*(\w+)\s*$", re.M)  # pounce's final line


def _load_factory(name: str):
    """SolverFactory for ``name``, raising SolverUnavailableError if it cannot run."""
    if name == "pounce":
        try:
            import pyomo_pounce  # noqa: F401  (registers the plugin; without it 'pounce' is a bare ASL shim)
        except ImportError as exc:
            raise SolverUnavailableError(f"solver 'pounce' is not installed: {_INSTALL_HINTS['pounce']}") from exc
    elif name != "ipopt":
        raise ValueError(f"AmplSolver supports 'pounce' and 'ipopt', not {name!r}")
    opt = pyo.SolverFactory(name)
    if opt is None or not opt.available(exception_flag=False):
        raise SolverUnavailableError(f"solver {name!r} is not available here: {_INSTALL_HINTS[name]}")
    return opt


def parse_ipopt_log(text: str) -> tuple[int, str | None, str | None]:
    """(iterations, status, exit message) from an Ipopt/pounce log.

    The *last* block counts: pounce re-solves after a failure and prints a
    summary per attempt, ending with the one it reports.
    """
    iters = _ITER_RE.findall(text)
    exits = _EXIT_RE.findall(text)
    statuses = _STATUS_RE.findall(text)
    message = exits[-1].strip() if exits else None
    status = statuses[-1] if statuses else (status_from_exit_message(message) if message else None)
    return (int(iters[-1]) if iters else -1), status, message


class AmplSolver:
    """``pounce`` or ``ipopt`` via Pyomo's ASL interface, same API as CasadiIpoptSolver."""

    def __init__(self, model, name: str = "pounce", options: dict | None = None):
        self._opt = _load_factory(name)
        self.name = name
        self.model = model
        self.options = dict(options or {})
        self.last_log = ""

    def rebuild(self) -> None:
        """Nothing to do: the NL file is written afresh on every solve."""

    def _prepare_suffixes(self, warm_start: str) -> None:
        m = self.model
        full = warm_start in MULTIPLIER_MODES
        ensure_suffix(m, "dual", pyo.Suffix.IMPORT_EXPORT if full else pyo.Suffix.IMPORT)
        zl_out = ensure_suffix(m, "ipopt_zL_out", pyo.Suffix.IMPORT)
        zu_out = ensure_suffix(m, "ipopt_zU_out", pyo.Suffix.IMPORT)
        for out, name in ((zl_out, "ipopt_zL_in"), (zu_out, "ipopt_zU_in")):
            if full:
                sfx = ensure_suffix(m, name, pyo.Suffix.EXPORT)
                sfx.clear()
                sfx.update(out.items())
                sfx.activate()
            elif m.component(name) is not None:
                m.component(name).deactivate()  # stale inputs must not reach the solver

    def solve(self, warm_start: str = "primal", options: dict | None = None) -> SolveResult:
        """Solve from the current Pyomo values; see CasadiIpoptSolver.solve for the modes."""
        with PauseGC():  # the model is written and read back row by row (see CasadiIpoptSolver.rebuild)
            return self._solve(warm_start, options)

    def _solve(self, warm_start: str, options: dict | None) -> SolveResult:
        opts, verbose, user_keys = resolve_options(self.options, options, warm_start)
        if "print_level" not in user_keys:
            opts["print_level"] = 5  # goes to the log; verbose only decides whether we tee it
        if self.name == "pounce":
            # Keep pounce on its Ipopt-like NLP path; otherwise LPs/QPs go to
            # its conic engines, which ignore the Ipopt (warm-start) options.
            opts.setdefault("solver_selection", "nlp")
        self._prepare_suffixes(warm_start)
        with tempfile.TemporaryDirectory(prefix="pyomo_heli_ampl_") as tmp:
            logfile = os.path.join(tmp, "solver.log")
            t0 = time.perf_counter()
            with interrupts.guard():  # a terminal's Ctrl-C reaches the solver process too: never a result
                try:
                    results = self._opt.solve(
                        self.model, tee=verbose, logfile=logfile, options=opts, load_solutions=False
                    )
                except ApplicationError as exc:
                    interrupts.check()
                    raise SolverFailedError(f"{self.name} failed to run: {exc}") from exc
                interrupts.check()
            wall = time.perf_counter() - t0
            self.last_log = open(logfile).read() if os.path.exists(logfile) else ""
        iterations, status, message = parse_ipopt_log(self.last_log)
        if status is None:
            tc = results.solver.termination_condition
            status = _TERMINATION_TO_STATUS.get(tc, str(tc))
        if message is None:
            message = IPOPT_EXIT_MESSAGES.get(status, str(results.solver.message))
        if len(results.solution) == 0:
            raise SolverFailedError(f"{self.name} returned no solution ({status}: {message})")
        # Load the final iterate even when not optimal, like casadi-ipopt;
        # Pyomo's "warning status" log message is expected, so swallow it.
        with LoggingIntercept(level=logging.WARNING):
            self.model.solutions.load_from(results)
        obj = _active_objective(self.model)
        return SolveResult(
            success=status in SUCCESS_STATUSES,
            status=status,
            message=message,
            iterations=iterations,
            objective=float(pyo.value(obj)) if obj is not None else math.nan,
            wall_time=wall,
            setup_time=0.0,
            solver=self.name,
        )
