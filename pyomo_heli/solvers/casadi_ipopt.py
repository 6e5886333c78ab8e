"""Real Ipopt (shipped inside the ``casadi`` wheel) driven from a Pyomo model.

Why this route: this machine has no ``ipopt`` executable and no PyNumero, but
``pip install casadi`` brings Ipopt 3.14 + MUMPS. Pyomo's own NL writer turns
the model into an AMPL NL file, casadi imports it, and the NLP is built
*once*. Re-solves (the epsilon-constraint sweep) then only change numeric
vectors - ``x0``, ``lbx/ubx``, ``lbg/ubg`` and the multipliers - so there is
no NL rewrite (3-5 s at 50k variables) per Pareto point.

What a re-solve picks up from the Pyomo model without :meth:`rebuild`:

* variable values (start point) and variable bounds (``var.lb``/``var.ub``),
* constraint bounds, e.g. ``m.J2 <= m.eps`` with ``m.eps`` a mutable Param
  (the NL row bound is shifted by the change of ``con.lb``/``con.ub``).

What needs :meth:`rebuild` (the NL holds these as numbers):

* the value of a *fixed* variable, fixing or unfixing a variable,
* a mutable Param inside a constraint *body* or the objective
  (write ``m.J2 <= m.eps``, not ``m.J2 - m.eps <= 0``),
* adding, removing, activating or deactivating constraints/objectives.

The first two and deactivation are detected and raise
:class:`~pyomo_heli.solvers.errors.ModelChangedError`; added components are
not detected.

Sign conventions written back into the model (the Ipopt/ASL convention, so
that pounce and ``ipopt`` give the same numbers, see ``tests/test_solvers.py``):

* ``model.dual[con]`` = d(objective)/d(constraint bound), i.e. for a
  minimisation ``-lam_g`` of casadi's Lagrangian ``f + lam_g^T g``, and
  ``+lam_g`` for a maximisation (casadi minimises ``-objective`` then).
* ``model.ipopt_zL_out[var] >= 0`` and ``model.ipopt_zU_out[var] <= 0`` for a
  minimisation, both sign-flipped for a maximisation.
"""

from __future__ import annotations

import os
import tempfile
import time

import numpy as np
import pyomo.environ as pyo
from pyomo.common.collections import ComponentMap, ComponentSet
from pyomo.core.expr.visitor import identify_mutable_parameters
from pyomo.repn.plugins.nl_writer import NLWriter

from .errors import ModelChangedError, SolverFailedError, SolverUnavailableError
from .result import IPOPT_EXIT_MESSAGES, SUCCESS_STATUSES, SolveResult

#: Options every backend gets unless the caller overrides them.
DEFAULT_OPTIONS = {"tol": 1e-8, "max_iter": 3000, "max_wall_time": 3600.0}

#: Options of a *full* warm start (primal + duals). Without the duals,
#: ``warm_start_init_point=yes`` is far worse than a cold start (measured),
#: so these are only used together with the multipliers.
WARM_START_OPTIONS = {
    "warm_start_init_point": "yes",
    "warm_start_bound_push": 1e-6,
    "warm_start_mult_bound_push": 1e-6,
    "mu_init": 1e-4,
}

#: ``"none"``: start from the Pyomo values as given (first solve).
#: ``"primal"``: the same mechanics, meant as a re-solve from the previous
#: solution loaded into the model - the robust default for Pareto sweeps.
#: ``"full"``: primal + multipliers from the model suffixes + WARM_START_OPTIONS.
WARM_START_MODES = ("none", "primal", "full")


def resolve_options(base: dict | None, call: dict | None, warm_start: str) -> tuple[dict, bool, set]:
    """Merge defaults < warm-start options < constructor options < call options.

    Returns ``(ipopt_options, verbose, keys_set_by_user)``; ``verbose`` is our
    own key and is removed from the Ipopt options.
    """
    if warm_start not in WARM_START_MODES:
        raise ValueError(f"warm_start must be one of {WARM_START_MODES}, got {warm_start!r}")
    user = {**(base or {}), **(call or {})}
    verbose = bool(user.pop("verbose", False))
    merged = dict(DEFAULT_OPTIONS)
    if warm_start == "full":
        merged.update(WARM_START_OPTIONS)
    merged.update(user)
    return merged, verbose, set(user)


def ensure_suffix(model, name: str, direction) -> pyo.Suffix:
    """Return ``model.<name>`` as a Suffix with the given direction, creating it if missing."""
    suffix = model.component(name)
    if suffix is None:
        suffix = pyo.Suffix(direction=direction)
        model.add_component(name, suffix)
    elif not isinstance(suffix, pyo.Suffix):
        raise TypeError(f"model.{name} exists but is not a Suffix; the solver layer needs that name")
    else:
        suffix.direction = direction
    return suffix


def _active_objective(model):
    objs = list(model.component_data_objects(pyo.Objective, active=True, descend_into=True))
    if len(objs) > 1:
        raise ValueError(f"model has {len(objs)} active objectives; exactly one is supported")
    return objs[0] if objs else None


def _bound(value, default):
    return default if value is None else float(value)


class CasadiIpoptSolver:
    """Ipopt-in-casadi adapter for one Pyomo model; build once, re-solve often.

    Parameters
    ----------
    model:
        The Pyomo model. Its NL representation is written at construction.
    options:
        Ipopt options (e.g. ``tol``, ``max_iter``, ``max_wall_time``,
        ``mu_strategy``) plus ``verbose`` (True prints Ipopt's iteration log).
    """

    name = "casadi-ipopt"
    #: Rows with more free variables than this get their own Jacobian block.
    dense_row_threshold = 100

    def __init__(self, model, options: dict | None = None):
        try:
            import casadi
        except ImportError as exc:  # pragma: no cover - casadi is a dependency
            raise SolverUnavailableError(
                "solver 'casadi-ipopt' needs the casadi package: pip install casadi"
            ) from exc
        if not casadi.has_nlpsol("ipopt"):  # pragma: no cover
            raise SolverUnavailableError("this casadi build has no Ipopt plugin: pip install casadi")
        self._ca = casadi
        self.model = model
        self.options = dict(options or {})
        self._pending_setup = 0.0
        self.rebuild()

    # ------------------------------------------------------------------ build
    def rebuild(self) -> None:
        """Rewrite the NL file and re-import it; needed after structural changes."""
        ca = self._ca
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory(prefix="pyomo_heli_nl_") as tmp:
            path = os.path.join(tmp, "model.nl")
            with open(path, "w") as ostream:
                info = NLWriter().write(
                    self.model, ostream, linear_presolve=False, scale_model=False
                )
            nl = ca.NlpBuilder()
            nl.import_nl(path)
            self.variables = list(info.variables)
            self.constraints = list(info.constraints)
            self._scan_expressions(path)
        self.objective = info.objectives[0] if info.objectives else None
        # casadi's import_nl already negates a maximisation objective (it
        # always minimises); sense_sign converts back to the user's objective.
        self.sense_sign = -1.0 if self.objective is not None and self.objective.sense == pyo.maximize else 1.0

        # The NL row bound differs from con.lb/ub by the constants Pyomo moved
        # out of the body; remember that offset to shift bounds on re-solve.
        g_lb, g_ub = np.array(nl.g_lb, float), np.array(nl.g_ub, float)
        self._row_offset = np.zeros(len(self.constraints))
        for i, con in enumerate(self.constraints):
            if con.ub is not None and np.isfinite(g_ub[i]):
                self._row_offset[i] = g_ub[i] - float(con.ub)
            elif con.lb is not None and np.isfinite(g_lb[i]):
                self._row_offset[i] = g_lb[i] - float(con.lb)

        # MX from import_nl -> expanded SX: much faster nlpsol build and solve.
        x_mx = ca.vertcat(*nl.x)
        g_mx = ca.vertcat(*nl.g) if len(nl.g) else ca.MX(0, 1)
        fun = ca.Function("F", [x_mx], [nl.f, g_mx]).expand()
        x = ca.SX.sym("x", len(self.variables))
        f, g = fun(x)
        self._nlp = {"x": x, "f": f, "g": g}
        self._jac_g = self._jacobian_function(x, g)
        self._solvers = {}
        self._pending_setup += time.perf_counter() - t0

    def _scan_expressions(self, nl_path: str) -> None:
        """Record what the NL file holds as numbers, and which rows are dense.

        Fixed-var and mutable-Param values are baked into the NL; remembering
        them lets solve() refuse to run on a stale problem. Params that appear
        in constraint bounds are the ones a re-solve refreshes. Dense rows
        (e.g. an epsilon constraint on a sum over all samples) are read from
        the NL file's Jacobian segments, for _jacobian_function. Nothing here
        walks the constraint bodies: at 100k rows that walk cost more than
        writing the NL file.
        """
        model = self.model
        self._fixed_at_write = ComponentMap(
            (v, v.value) for v in model.component_data_objects(pyo.Var, descend_into=True) if v.fixed)
        self._params_at_write = ComponentMap(
            (p, pyo.value(p)) for comp in model.component_objects(pyo.Param, descend_into=True) if comp.mutable
            for p in comp.values())
        self._bound_params = ComponentSet()
        for con in self.constraints:
            for bound in (con.lower, con.upper):
                if bound is not None and not isinstance(bound, (int, float)) and not bound.is_constant():
                    self._bound_params.update(identify_mutable_parameters(bound))
        self._dense_rows = []
        with open(nl_path) as fh:
            for line in fh:
                if line[0] == "J":
                    row, count = line[1:].split()
                    if int(count) > self.dense_row_threshold:
                        self._dense_rows.append(int(row))

    def _jacobian_function(self, x, g):
        """Constraint Jacobian built row-block-wise, or None for casadi's default.

        casadi colours the whole Jacobian at once; one dense row together with
        a dense column (a model parameter used at every time step) defeats both
        forward and reverse colouring and the build becomes quadratic (15 s at
        4k variables, 64 s at 8k; 0.4 s at 8k this way). The sparse rows are differentiated as
        one block and each dense row by reverse mode alone, which is linear.
        """
        ca = self._ca
        if not self._dense_rows:
            return None
        dense = set(self._dense_rows)
        sparse = [i for i in range(g.shape[0]) if i not in dense]
        blocks = [ca.jacobian(g[sparse], x)] + [ca.jacobian(g[i], x) for i in self._dense_rows]
        back = np.argsort(sparse + self._dense_rows).tolist()  # rows back into NL order
        jac = ca.vertcat(*blocks)[back, :]
        p = ca.SX.sym("p", 0)
        return ca.Function("nlp_jac_g", [x, p], [g, jac], ["x", "p"], ["g", "jac_g_x"])

    def _solver_for(self, ipopt_options: dict, verbose: bool):
        ipopt = dict(ipopt_options)
        ipopt.setdefault("linear_solver", "mumps")
        # MUMPS' MC64 permuting scaling fails (INFO -9, workspace blow-up, then a
        # failed restoration) on the collocation KKT systems of this project,
        # while without it the same solve takes 3 iterations (measured on a
        # 15k-variable 80 kt maneuver: 41 s and failure vs 0.3 s).
        ipopt.setdefault("mumps_permuting_scaling", 0)
        ipopt.setdefault("print_level", 5 if verbose else 0)
        if not verbose:
            ipopt.setdefault("sb", "yes")
        key = tuple(sorted((k, repr(v)) for k, v in ipopt.items()))
        if key not in self._solvers:
            t0 = time.perf_counter()
            opts = {"ipopt": ipopt, "print_time": False, "error_on_fail": False}
            if self._jac_g is not None:
                opts["jac_g"] = self._jac_g
            self._solvers[key] = self._ca.nlpsol("solver", "ipopt", self._nlp, opts)
            self._pending_setup += time.perf_counter() - t0
        return self._solvers[key]

    # ---------------------------------------------------------------- refresh
    def _check_unchanged(self) -> None:
        hint = "call solver.rebuild() to rewrite the NL file"
        for var in self.variables:
            if var.fixed:
                raise ModelChangedError(f"variable {var.name} was free when the NL was written and is now fixed; {hint}")
        for var, val in self._fixed_at_write.items():
            if not var.fixed:
                raise ModelChangedError(f"variable {var.name} was fixed when the NL was written and is now free; {hint}")
            if var.value != val:
                raise ModelChangedError(
                    f"fixed variable {var.name} changed value ({val} -> {var.value}) since the NL was written; {hint}"
                )
        for par, val in self._params_at_write.items():
            if par not in self._bound_params and pyo.value(par) != val:
                raise ModelChangedError(
                    f"mutable Param {par.name} (not a constraint bound) changed "
                    f"({val} -> {pyo.value(par)}); only Params in constraint bounds are refreshed; {hint}"
                )
        for con in self.constraints:
            if not con.active:
                raise ModelChangedError(f"constraint {con.name} was deactivated since the NL was written; {hint}")
        if self.objective is not None and not self.objective.active:
            raise ModelChangedError(f"objective {self.objective.name} was deactivated; {hint}")

    def _numeric_inputs(self) -> dict:
        n = len(self.variables)
        lbx, ubx, x0 = np.empty(n), np.empty(n), np.empty(n)
        for i, var in enumerate(self.variables):
            lbx[i] = _bound(var.lb, -np.inf)
            ubx[i] = _bound(var.ub, np.inf)
            x0[i] = 0.0 if var.value is None else var.value
        x0 = np.clip(x0, lbx, ubx)
        m = len(self.constraints)
        lbg, ubg = np.empty(m), np.empty(m)
        for i, con in enumerate(self.constraints):
            lbg[i] = _bound(con.lb, -np.inf) + self._row_offset[i]
            ubg[i] = _bound(con.ub, np.inf) + self._row_offset[i]
        return {"x0": x0, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}

    def _multipliers_from_model(self) -> dict:
        """casadi ``lam_x0``/``lam_g0`` from the model suffixes (any backend wrote them)."""
        s = self.sense_sign
        dual = self.model.component("dual")
        zl = self.model.component("ipopt_zL_out")
        zu = self.model.component("ipopt_zU_out")
        lam_g = np.array([-s * (dual.get(c, 0.0) if dual is not None else 0.0) for c in self.constraints])
        lam_x = np.array(
            [
                -s * ((zl.get(v, 0.0) if zl is not None else 0.0) + (zu.get(v, 0.0) if zu is not None else 0.0))
                for v in self.variables
            ]
        )
        return {"lam_x0": lam_x, "lam_g0": lam_g}

    # ------------------------------------------------------------------ solve
    def solve(self, warm_start: str = "primal", options: dict | None = None) -> SolveResult:
        """Solve from the current Pyomo values and load the solution back.

        ``warm_start``: ``"none"``/``"primal"`` start from the variable values
        in the model (``"primal"`` names the re-solve-from-previous-solution
        intent); ``"full"`` also passes the multipliers stored in the
        ``dual``/``ipopt_zL_out``/``ipopt_zU_out`` suffixes and switches on
        Ipopt's warm-start options. ``options`` override the constructor
        options for this call only.

        The final iterate is loaded even when the solve fails, as Ipopt's AMPL
        driver does; check ``result.success``.
        """
        ipopt_options, verbose, _ = resolve_options(self.options, options, warm_start)
        self._check_unchanged()
        solver = self._solver_for(ipopt_options, verbose)
        args = self._numeric_inputs()
        if warm_start == "full":
            args.update(self._multipliers_from_model())
        t0 = time.perf_counter()
        try:
            sol = solver(**args)
        except RuntimeError as exc:
            raise SolverFailedError(f"casadi-ipopt failed to run: {exc}") from exc
        wall = time.perf_counter() - t0
        stats = solver.stats()
        self._load(sol)
        status = stats.get("return_status", "unknown")
        setup, self._pending_setup = self._pending_setup, 0.0
        return SolveResult(
            success=status in SUCCESS_STATUSES,
            status=status,
            message=IPOPT_EXIT_MESSAGES.get(status, status),
            iterations=int(stats.get("iter_count", -1)),
            objective=self.sense_sign * float(sol["f"]),
            wall_time=wall,
            setup_time=setup,
            solver=self.name,
        )

    def _load(self, sol) -> None:
        """Write primal values and multipliers (ASL sign convention) into the model."""
        s = self.sense_sign
        x = np.asarray(sol["x"]).ravel()
        lam_x = np.asarray(sol["lam_x"]).ravel()
        lam_g = np.asarray(sol["lam_g"]).ravel()
        for var, val in zip(self.variables, x):
            var.set_value(float(val), skip_validation=True)
        dual = ensure_suffix(self.model, "dual", self._import_direction("dual"))
        for con, lam in zip(self.constraints, lam_g):
            dual[con] = -s * float(lam)
        zl = ensure_suffix(self.model, "ipopt_zL_out", pyo.Suffix.IMPORT)
        zu = ensure_suffix(self.model, "ipopt_zU_out", pyo.Suffix.IMPORT)
        for var, lam in zip(self.variables, lam_x):
            zl[var] = s * max(0.0, -float(lam))
            zu[var] = s * min(0.0, -float(lam))

    def _import_direction(self, name: str):
        """Keep an existing IMPORT_EXPORT direction (an AMPL backend may share the model)."""
        suffix = self.model.component(name)
        if isinstance(suffix, pyo.Suffix) and suffix.import_enabled():
            return suffix.direction
        return pyo.Suffix.IMPORT
