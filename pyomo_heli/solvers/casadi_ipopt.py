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
from dataclasses import dataclass, replace

import numpy as np
import pyomo.environ as pyo
from pyomo.common.collections import ComponentMap, ComponentSet
from pyomo.common.gc_manager import PauseGC
from pyomo.core.expr.visitor import identify_mutable_parameters
from pyomo.repn.plugins.nl_writer import NLWriter

from .. import interrupts
from ..ioerrors import writing
from .casadi_derivatives import DerivativeFunctions
from .casadi_scaling import NLPScaling
from .common import (  # noqa: F401 - DEFAULT_OPTIONS ... ensure_suffix: the adapter's public names since its start
    DEFAULT_OPTIONS, MULTIPLIER_MODES, WARM_START_MODES, WARM_START_OPTIONS, _active_objective, _bound,
    ensure_suffix, resolve_options, scale_multipliers,
)
from .errors import ModelChangedError, SolverFailedError, SolverUnavailableError
from .point_rows import PointRowsAssembly, find_point_rows
from .result import IPOPT_EXIT_MESSAGES, SUCCESS_STATUSES, SolveResult

#: Ipopt's default ``nlp_lower_bound_inf`` / ``nlp_upper_bound_inf`` magnitude: a bound beyond it is none
IPOPT_INFINITY = 1e19


@dataclass(frozen=True)
class CasadiSettings:
    """Switches of the casadi-ipopt adapter (how it builds derivatives, not Ipopt options).

    Passed to :class:`CasadiIpoptSolver` (``settings=``); ``point_rows`` can also come from the
    solver options (``[solver] point_rows``). The defaults are the production route; the other
    values are kept for comparison (benchmark, tests).
    """

    #: A Jacobian row or column, or a Hessian column, is *dense* when it has
    #: more nonzeros than this and than ``dense_factor`` times the 99th
    #: percentile of its kind; dense ones get their own derivative blocks
    #: (see :meth:`_jacobian_function`, :meth:`_hessian_function`). A huge
    #: value gives casadi's own Jacobian and Hessian.
    dense_row_threshold: int = 20
    dense_factor: float = 3.0
    #: False: let casadi derive the Lagrangian Hessian (slow with dense
    #: columns; kept for comparison).
    custom_hessian: bool = True
    #: percentile of the Hessian column degrees that defines "typical" (see _hessian_function)
    hessian_dense_percentile: int = 90
    #: named Pyomo Expressions (the collocation blocks' shared intermediates) go to the NL file
    #: as defined variables, written and differentiated once; False inlines them into every
    #: equation that uses them (the same functions, a graph about twice as large; kept for
    #: comparison; the measurement is in CHANGELOG.md, its one-off study deleted)
    export_defined_variables: bool = True
    #: blocks that describe their rows point by point (``blk.point_rows``, the maneuver blocks) get
    #: those rows from one compiled function per point mapped over the points instead of from the
    #: NL file (solvers/point_rows.py); False: everything through the NL file (kept for comparison)
    point_rows: bool = True
    #: with point rows: their rows and their own variables first, the NL file's after. The NL route
    #: puts the nonlinear rows and variables (these) first too; with them last, point A took 13.5 s
    #: instead of 11.3 s on Case 1, same iterations (MUMPS' pivoting; docs/performance.md)
    point_rows_first: bool = True
    #: hand Ipopt the problem scaled by the model's ``scaling_factor`` suffixes (variables, rows,
    #: objective; solvers/casadi_scaling.py), as IDAES's scalers and Pyomo's core.scale_model read
    #: them; also the solver option ``scaling`` (``[solver] options = { scaling = true }``).
    #: False: the suffixes are ignored
    scaling: bool = False


class CasadiIpoptSolver(DerivativeFunctions):
    """Ipopt-in-casadi adapter for one Pyomo model; build once, re-solve often.

    Parameters
    ----------
    model:
        The Pyomo model. Its NL representation is written at construction.
    options:
        Ipopt options (e.g. ``tol``, ``max_iter``, ``max_wall_time``,
        ``mu_strategy``) plus ``verbose`` (True prints Ipopt's iteration log)
        and ``point_rows`` (a :class:`CasadiSettings` switch).
    settings:
        The adapter's switches (:class:`CasadiSettings`; default: the production route).
    """

    name = "casadi-ipopt"

    def __init__(self, model, options: dict | None = None, settings: CasadiSettings | None = None):
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
        self.settings = settings or CasadiSettings()
        if "point_rows" in self.options:  # our own switch, not an Ipopt option ([solver] point_rows)
            self.settings = replace(self.settings, point_rows=bool(self.options.pop("point_rows")))
        if "scaling" in self.options:  # likewise ([solver] options = { scaling = ... })
            self.settings = replace(self.settings, scaling=bool(self.options.pop("scaling")))
        self._pending_setup = 0.0
        #: seconds spent per set-up stage, summed over rebuilds (for the benchmark)
        self.setup_breakdown = {"nl_write": 0.0, "casadi_import": 0.0, "expand": 0.0, "point_rows": 0.0,
                                "jacobian": 0.0, "hessian": 0.0, "nlpsol": 0.0}
        self.rebuild()

    # ------------------------------------------------------------------ build
    def rebuild(self) -> None:
        """Rewrite the NL file and re-import it; needed after structural changes."""
        # The cyclic garbage collector is paused while the model's components are listed and read
        # (per-variable and per-row Python lists at 100k rows; see pareto.snapshot).
        with PauseGC():
            self._rebuild()

    def _rebuild(self) -> None:
        ca = self._ca
        t0 = time.perf_counter()
        blocks = find_point_rows(self.model) if self.settings.point_rows else []
        # the point-described rows are evaluated by their blocks' compiled functions, not the NL file
        handled = [con for pr in blocks for con, _, _ in pr.rows if con.active]
        with tempfile.TemporaryDirectory(prefix="pyomo_heli_nl_") as tmp:
            path = os.path.join(tmp, "model.nl")
            # casadi's NL import refuses suffix sections ("Suffix values unsupported"): exported suffixes
            # (IDAES's scaling_factor, an AMPL backend's duals) stay out of the file; scaling is read below
            exported = [sfx for sfx in self.model.component_data_objects(pyo.Suffix, descend_into=True)
                        if sfx.export_enabled()]
            directions = [sfx.direction for sfx in exported]
            try:
                for con in handled:
                    con.deactivate()
                for sfx in exported:
                    sfx.direction = pyo.Suffix.LOCAL
                with writing(path), open(path, "w") as ostream:  # a full temporary folder names the file
                    info = NLWriter().write(
                        self.model, ostream, linear_presolve=False, scale_model=False,
                        export_defined_variables=self.settings.export_defined_variables,
                    )
            finally:
                for con in handled:
                    con.activate()
                for sfx, direction in zip(exported, directions):
                    sfx.direction = direction
            t_nl = time.perf_counter()
            nl = ca.NlpBuilder()
            nl.import_nl(path)
            t_import = time.perf_counter()
        self.variables = list(info.variables)
        self.constraints = list(info.constraints)
        self._n_nl, self._m_nl = len(self.variables), len(self.constraints)
        #: where the NL part's variables and rows sit in the NLP vectors (see point_rows_first)
        self._nl_col0, self._nl_row0 = 0, 0
        self._assembly = None
        if blocks:
            column_of = {id(v): i for i, v in enumerate(self.variables)}
            A = self._assembly = PointRowsAssembly(ca, blocks, column_of, len(self.variables))
            if self.settings.point_rows_first:
                A.shift_columns(self._n_nl, len(A.extra))
                self.variables = A.extra + self.variables
                self.constraints = A.constraints + self.constraints
                self._nl_col0, self._nl_row0 = len(A.extra), A.m
            else:
                self.variables += A.extra
                self.constraints += A.constraints
        t_rows = time.perf_counter()
        self._scan_expressions()
        self.objective = info.objectives[0] if info.objectives else None
        # casadi's import_nl already negates a maximisation objective (it
        # always minimises); sense_sign converts back to the user's objective.
        self.sense_sign = -1.0 if self.objective is not None and self.objective.sense == pyo.maximize else 1.0

        # The NL row bound differs from con.lb/ub by the constants Pyomo moved
        # out of the body; remember that offset to shift bounds on re-solve.
        n_more = len(self.constraints) - self._m_nl  # point-described rows: body == 0
        r0 = self._nl_row0
        g_lb = np.concatenate([np.zeros(r0), np.array(nl.g_lb, float), np.zeros(n_more - r0)])
        g_ub = np.concatenate([np.zeros(r0), np.array(nl.g_ub, float), np.zeros(n_more - r0)])
        self._g_lb, self._g_ub = g_lb, g_ub  # constant rows keep these; Param rows are refreshed
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
        #: size of the expanded expression graph (casadi instructions), for the benchmark
        self.graph_instructions = int(fun.n_instructions())
        x = ca.SX.sym("x", self._n_nl)
        f, g = fun(x)
        self._nlp = {"x": x, "f": f, "g": g}
        t_expand = time.perf_counter()
        # Jacobian structure (cheap: bitwise propagation, no derivatives).
        jsp = ca.Function("nlp_g", [x], [g]).jac_sparsity(0, 0)
        self._dense_rows = self._dense(np.bincount(np.array(jsp.row(), dtype=int), minlength=g.shape[0]))
        self._dense_cols = self._dense(np.diff(np.array(jsp.colind(), dtype=int)))
        self._jac_g = self._jacobian_function(x, g)
        if self._assembly is not None:
            self._jac_g = self._full_jacobian(self._jac_g)
        #: the scaling the solves use (None: unscaled), read from the suffixes at this build; a solve uses it with
        #: factor 1 on the rows that have no finite bound at that solve (:meth:`_select_scaling`)
        self._scaling = self._scaling_read = None
        if self.settings.scaling:
            scaling = NLPScaling.from_suffixes(self.model, self.variables, self.constraints, self.objective)
            self._scaling_read = None if scaling.trivial else scaling
        self._hess_lag = False  # not built yet; built at the first exact-Hessian solve
        self._hessian_split = None  # block sizes {"S", "D2", "D1"} once a custom Hessian is built
        self._solvers = {}
        self._nlp_function = self._grad_f = None  # the NLP as one casadi Function, made with the first solver
        # scaled: the unscaled functions (the Hessian and the NLP made with the first solver), and the scaled
        # function sets by the rows left unscaled (key), the current one under self._scaling_key
        self._jac_unscaled, self._hess_unscaled, self._nlp_unscaled = self._jac_g, False, None
        self._scaled_sets, self._scaling_key = {}, None
        if self._scaling_read is not None:
            self._select_scaling(self._g_lb, self._g_ub)
        t_end = time.perf_counter()
        self._pending_setup += t_end - t0
        b = self.setup_breakdown
        b["nl_write"] += t_nl - t0
        b["casadi_import"] += t_import - t_nl
        b["point_rows"] += t_rows - t_import
        b["expand"] += t_expand - t_rows
        b["jacobian"] += t_end - t_expand

    def _scan_expressions(self) -> None:
        """Record what the NL file holds as numbers.

        Fixed-var and mutable-Param values are baked into the NL; remembering
        them lets solve() refuse to run on a stale problem. Params that appear
        in constraint bounds are the ones a re-solve refreshes. Nothing here
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
        self._param_rows = []
        for i, con in enumerate(self.constraints):
            for bound in (con.lower, con.upper):
                if bound is not None and not isinstance(bound, (int, float)) and not bound.is_constant():
                    self._bound_params.update(identify_mutable_parameters(bound))
                    self._param_rows.append(i)
        self._param_rows = sorted(set(self._param_rows))

    def _solver_for(self, ipopt_options: dict, verbose: bool):
        ipopt = dict(ipopt_options)
        ipopt.setdefault("linear_solver", "mumps")
        # MUMPS' MC64 permuting scaling fails (INFO -9, workspace blow-up, then a
        # failed restoration) on the collocation KKT systems of this project,
        # while without it the same solve takes 3 iterations (measured on a
        # 15k-variable 80 kt maneuver: 41 s and failure vs 0.3 s).
        ipopt.setdefault("mumps_permuting_scaling", 0)
        # QAMD ordering: it detects the quasi-dense rows and columns of these NLPs (the covariance
        # rows sum over every sample, the parameters enter every collocation point). The automatic
        # choice spent 8.5 s of a 31.7 s point-A solve in the symbolic analysis, which every
        # re-solve repeats; QAMD 0.3 s, same 26 iterations, 10.9 s in all (Case 1, 106k variables,
        # one run; docs/performance.md).
        ipopt.setdefault("mumps_pivot_order", 6)
        # Ipopt options the NLP itself asks for (``model.ipopt_defaults``, e.g. the AR-weighed J_time's pivot
        # tolerance, nlp/identification.py), below the caller's
        for key, value in getattr(self.model, "ipopt_defaults", {}).items():
            ipopt.setdefault(key, value)
        ipopt.setdefault("print_level", 5 if verbose else 0)
        if not verbose:
            ipopt.setdefault("sb", "yes")
        key = tuple(sorted((k, repr(v)) for k, v in ipopt.items()))
        if key not in self._solvers:
            t0 = time.perf_counter()
            # no_nlp_grad: the Lagrangian-gradient function casadi builds by
            # default only serves lam_p (there is no p) and calc_lam_x (off);
            # it cost 3.5 s at 25k variables.
            opts = {"ipopt": ipopt, "print_time": False, "error_on_fail": False, "no_nlp_grad": True}
            if self._jac_g is not None:
                opts["jac_g"] = self._jac_g
            if self.settings.custom_hessian and str(ipopt.get("hessian_approximation", "exact")) == "exact":
                if self._hess_lag is False:
                    t_h = time.perf_counter()
                    if self._scaling is None:
                        self._hess_lag = self._hessian_function()
                    else:
                        if self._hess_unscaled is False:
                            self._hess_unscaled = self._hessian_function()
                        self._hess_lag = (None if self._hess_unscaled is None
                                          else self._scaling.hessian_function(self._ca, self._hess_unscaled))
                    self.setup_breakdown["hessian"] += time.perf_counter() - t_h
                if self._hess_lag is not None:
                    opts["hess_lag"] = self._hess_lag
            t_n = time.perf_counter()
            if self._nlp_function is None:
                # One NLP Function and one objective gradient for every option set: from the
                # expression dict, each nlpsol sorted the whole graph again and derived its own
                # gradient (docs/performance.md, "What was done" 7).
                if self._scaling is None:
                    self._nlp_function, self._grad_f = self._nlp_functions()
                else:  # casadi derives what is not given from the scaled NLP
                    if self._nlp_unscaled is None:
                        self._nlp_unscaled = self._nlp_functions()
                    self._nlp_function, self._grad_f = self._scaling.nlp_functions(self._ca, *self._nlp_unscaled)
            opts["grad_f"] = self._grad_f
            self._solvers[key] = self._ca.nlpsol("solver", "ipopt", self._nlp_function, opts)
            self.setup_breakdown["nlpsol"] += time.perf_counter() - t_n
            self._pending_setup += time.perf_counter() - t0
        return self._solvers[key]

    # ---------------------------------------------------------------- refresh
    def _check_unchanged(self) -> None:
        hint = "call solver.rebuild() to rewrite the NL file"
        for var in self.variables:
            if var.fixed:
                raise ModelChangedError(f"variable {var.name} was free when the NL was written and is now fixed; "
                                        f"{hint}")
        for var, val in self._fixed_at_write.items():
            if not var.fixed:
                raise ModelChangedError(f"variable {var.name} was fixed when the NL was written and is now free; "
                                        f"{hint}")
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
        """x0 and the bounds, read from the model (list comprehensions: ~0.1 s at 100k variables).

        Every variable bound is read again (pinned objective settings and measurements change
        them); constraint bounds are constants in the NL except the rows whose bound holds a
        mutable Param (``self._param_rows``), which are re-evaluated.
        """
        bounds = [v.bounds for v in self.variables]
        lbx = np.array([b[0] for b in bounds], dtype=float)  # None -> nan
        ubx = np.array([b[1] for b in bounds], dtype=float)
        lbx[np.isnan(lbx)] = -np.inf
        ubx[np.isnan(ubx)] = np.inf
        x0 = np.array([v.value for v in self.variables], dtype=float)
        x0[np.isnan(x0)] = 0.0
        x0 = np.clip(x0, lbx, ubx)
        lbg, ubg = self._g_lb.copy(), self._g_ub.copy()
        for i in self._param_rows:
            con = self.constraints[i]
            lbg[i] = _bound(con.lb, -np.inf) + self._row_offset[i]
            ubg[i] = _bound(con.ub, np.inf) + self._row_offset[i]
        self._bounded = np.flatnonzero(np.isfinite(lbx) | np.isfinite(ubx))
        return {"x0": x0, "lbx": lbx, "ubx": ubx, "lbg": lbg, "ubg": ubg}

    def _multipliers_from_model(self) -> dict:
        """casadi ``lam_x0``/``lam_g0`` from the model suffixes (any backend wrote them)."""
        s = self.sense_sign
        dual = self.model.component("dual")
        zl = self.model.component("ipopt_zL_out")
        zu = self.model.component("ipopt_zU_out")
        lam_g = np.zeros(len(self.constraints))
        if dual is not None:
            lam_g = -s * np.array([dual.get(c, 0.0) for c in self.constraints], dtype=float)
        lam_x = np.zeros(len(self.variables))
        bounded = [self.variables[i] for i in self._bounded]  # bound multipliers exist only there
        z = np.zeros(len(bounded))
        for suffix in (zl, zu):
            if suffix is not None:
                z += np.array([suffix.get(v, 0.0) for v in bounded], dtype=float)
        lam_x[self._bounded] = -s * z
        return {"lam_x0": lam_x, "lam_g0": lam_g}

    # ------------------------------------------------------------------ solve
    def solve(self, warm_start: str = "primal", options: dict | None = None) -> SolveResult:
        """Solve from the current Pyomo values and load the solution back.

        ``warm_start``: ``"none"``/``"primal"`` start from the variable values
        in the model (``"primal"`` names the re-solve-from-previous-solution
        intent); ``"full"`` also passes the multipliers stored in the
        ``dual``/``ipopt_zL_out``/``ipopt_zU_out`` suffixes and switches on
        Ipopt's warm-start options; ``"continuation"`` does the same with the
        barrier parameter starting at ``tol / 10``. ``options`` override the constructor
        options for this call only.

        The final iterate is loaded even when the solve fails, as Ipopt's AMPL
        driver does; check ``result.success``. A solve stopped by SIGINT or
        SIGTERM raises :class:`~pyomo_heli.interrupts.Interrupted` and loads
        nothing (see :mod:`pyomo_heli.interrupts`).
        """
        with PauseGC():  # per-variable Python lists in and out (see rebuild)
            return self._solve(warm_start, options)

    def unscaled_derivative_functions(self):
        """The Lagrangian Hessian (upper triangle; built if needed; None: none of the adapter's own) and the row
        Jacobian function (None: none) of the unscaled NLP, whatever the solves use (the reduced Hessian's)."""
        if self._scaling_read is None:
            if self._hess_lag is False:
                self._hess_lag = self._hessian_function()
            return self._hess_lag, self._jac_g
        if self._hess_unscaled is False:
            self._hess_unscaled = self._hessian_function()
        return self._hess_unscaled, self._jac_unscaled

    def _select_scaling(self, lbg, ubg) -> None:
        """Use the suffixes' scaling with factor 1 on the rows that have no finite bound at this solve.

        Such a row constrains nothing (the Pareto solver's epsilon rows J_k / J_k(theta_0) <= eps with
        eps = 1e20, Ipopt's infinity being 1e19), but Ipopt still carries it with a free slack, and its
        factor changes the solve: the epsilon row's factor 20 (nlp/scaling.py) took Case 1's anchor A to 73
        Ipopt iterations instead of 26. Each set of rows left unscaled keeps its own scaled functions and
        solvers (made on first use)."""
        sg = self._scaling_read.sg
        free = (np.asarray(lbg) <= -IPOPT_INFINITY) & (np.asarray(ubg) >= IPOPT_INFINITY) & (sg != 1.0)
        key = tuple(np.flatnonzero(free).tolist())
        if key == self._scaling_key:
            return
        if self._scaling_key is not None:
            self._scaled_sets[self._scaling_key] = (self._scaling, self._jac_g, self._hess_lag, self._nlp_function,
                                                    self._grad_f, self._solvers)
        if key in self._scaled_sets:
            (self._scaling, self._jac_g, self._hess_lag, self._nlp_function, self._grad_f,
             self._solvers) = self._scaled_sets.pop(key)
        else:
            read = self._scaling_read
            self._scaling = read if not key else NLPScaling(read.sx, np.where(free, 1.0, sg), read.sf)
            self._jac_g = (None if self._jac_unscaled is None
                           else self._scaling.jacobian_function(self._ca, self._jac_unscaled))
            self._hess_lag, self._nlp_function, self._grad_f, self._solvers = False, None, None, {}
        self._scaling_key = key

    def _solve(self, warm_start: str, options: dict | None) -> SolveResult:
        ipopt_options, verbose, _ = resolve_options(self.options, options, warm_start)
        self._check_unchanged()
        args = self._numeric_inputs()
        if self._scaling_read is not None:
            self._select_scaling(args["lbg"], args["ubg"])
        if self._scaling is not None and warm_start == "primal":  # Ipopt's multiplier bound in scaled units
            ipopt_options = self._scaling.primal_restart_options(ipopt_options)
        solver = self._solver_for(ipopt_options, verbose)
        if warm_start in MULTIPLIER_MODES:
            args.update(self._multipliers_from_model())
        if self._scaling is not None:
            args = self._scaling.scale_inputs(args)
        t0 = time.perf_counter()
        # Ipopt polls Python for signals and swallows the exception (NonIpopt_Exception_Thrown): the guard
        # records the signal, and an interrupted solve raises Interrupted instead of returning an iterate
        with interrupts.guard():
            try:
                sol = solver(**args)
            except RuntimeError as exc:
                interrupts.check()
                raise SolverFailedError(f"casadi-ipopt failed to run: {exc}") from exc
            interrupts.check()
        wall = time.perf_counter() - t0
        stats = solver.stats()
        self.last_stats = stats  # casadi's solver statistics of this call (iterations, t_wall_* per function)
        if self._scaling is not None:
            sol = self._scaling.unscale_solution(sol)
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
        x = np.asarray(sol["x"]).ravel().tolist()
        neg_lam_x = -np.asarray(sol["lam_x"]).ravel()
        lam_g = (-s * np.asarray(sol["lam_g"]).ravel()).tolist()
        for var, val in zip(self.variables, x):
            var.set_value(val, skip_validation=True)
        dual = ensure_suffix(self.model, "dual", self._import_direction("dual"))
        for con, lam in zip(self.constraints, lam_g):
            dual[con] = lam
        zl = ensure_suffix(self.model, "ipopt_zL_out", pyo.Suffix.IMPORT)
        zu = ensure_suffix(self.model, "ipopt_zU_out", pyo.Suffix.IMPORT)
        # Only bounded variables have bound multipliers; the others stay absent (read as 0).
        lam_b = neg_lam_x[self._bounded]
        for i, lo, up in zip(self._bounded.tolist(), np.maximum(lam_b, 0.0).tolist(), np.minimum(lam_b, 0.0).tolist()):
            var = self.variables[i]
            zl[var] = s * lo
            zu[var] = s * up

    def _import_direction(self, name: str):
        """Keep an existing IMPORT_EXPORT direction (an AMPL backend may share the model)."""
        suffix = self.model.component(name)
        if isinstance(suffix, pyo.Suffix) and suffix.import_enabled():
            return suffix.direction
        return pyo.Suffix.IMPORT
