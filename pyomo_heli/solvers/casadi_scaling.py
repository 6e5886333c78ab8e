"""Scaling inside the casadi-Ipopt adapter, read from the model's ``scaling_factor`` suffixes.

casadi's Ipopt interface does not hand user scaling to Ipopt (its TNLP keeps Ipopt's default
``get_scaling_parameters``, so ``nlp_scaling_method = user-scaling`` would find none). The adapter
therefore gives Ipopt the scaled problem itself, the problem Pyomo's ``core.scale_model`` would write:

    x_s = s_x x,    f_s = s_f f(x),    g_s = s_g g(x)    (bounds scaled alike),

with the derivatives from the unscaled functions (element-wise, the sparsity unchanged):

    grad f_s[j] = s_f grad f[j] / s_x[j],    J_s[i, j] = s_g[i] J[i, j] / s_x[j],
    H_s(lam_f, lam_s)[j, k] = H(s_f lam_f, s_g lam_s)[j, k] / (s_x[j] s_x[k]).

Ipopt's own gradient-based scaling still acts on top (``nlp_scaling_method``). The solution comes back
unscaled: x = x_s / s_x, f = f_s / s_f, and the multipliers of the unscaled KKT conditions (those of the
scaled problem divided by s_f): lam_g = s_g lam_s / s_f, lam_x = s_x lam_x_s / s_f; a multiplier warm
start goes the other way.

Ipopt's ``constr_mult_init_max`` (default 1000) is a bound on the least-squares estimate of the row
multipliers at the start, in the units of the problem Ipopt sees: a larger estimate is discarded and the
solve starts from zero multipliers. The scaled problem's multipliers are the unscaled ones times s_f / s_g,
so at a re-solve from a solution (warm start ``"primal"``) the adapter gives Ipopt the bound times
max(s_f / s_g) (:meth:`NLPScaling.primal_restart_options`): an estimate kept unscaled is kept scaled. A cold
start keeps Ipopt's bound: there the estimate at the initial guess is a poor one (translated, Case 1's
anchor A took 38 iterations instead of 26).

A row without a finite bound at a solve (an epsilon row at eps = 1e20) constrains nothing; the adapter solves with
factor 1 on it (``CasadiIpoptSolver._select_scaling``): Ipopt still carries the row, and its factor would change
the solve (docs/performance.md, "Scaling").

The factors are found as Pyomo finds them (``SuffixFinder("scaling_factor")``, the lookup of
``core.scale_model``; IDAES's scalers write the same suffixes): the ``scaling_factor`` Suffix of the
component's block or of a block above it; missing: 1. They are read when the adapter (re)builds.
"""

from __future__ import annotations

import numpy as np
from pyomo.core.base.suffix import SuffixFinder


#: Ipopt's default ``constr_mult_init_max``
IPOPT_CONSTR_MULT_INIT_MAX = 1000.0


class NLPScaling:
    """Positive scaling factors of an NLP's variables ``sx``, rows ``sg`` and objective ``sf``."""

    def __init__(self, sx, sg, sf: float = 1.0):
        self.sx, self.sg, self.sf = np.asarray(sx, dtype=float), np.asarray(sg, dtype=float), float(sf)
        bad = [name for name, v in (("variable", self.sx), ("constraint", self.sg), ("objective", [self.sf]))
               if not np.all(np.isfinite(v) & (np.asarray(v) > 0))]
        if bad:
            raise ValueError(f"scaling_factor of a {bad[0]} must be a positive finite number")

    @classmethod
    def from_suffixes(cls, model, variables, constraints, objective) -> "NLPScaling":
        """The factors of the adapter's variables, rows and objective (in its order) from the suffixes."""
        finder = SuffixFinder("scaling_factor", 1.0, model)
        sx = [finder.find(v) for v in variables]
        sg = [finder.find(c) for c in constraints]
        sf = finder.find(objective) if objective is not None else 1.0
        return cls(sx, sg, sf)

    @property
    def multiplier_factor(self) -> float:
        """The largest factor s_f / s_g by which a row multiplier grows from the unscaled problem to the scaled one."""
        return float(np.max(self.sf / self.sg)) if len(self.sg) else 1.0

    def primal_restart_options(self, ipopt_options: dict) -> dict:
        """Ipopt options of a re-solve from a solution: ``constr_mult_init_max`` (given, else Ipopt's 1000) times
        :attr:`multiplier_factor` (module docstring)."""
        limit = float(ipopt_options.get("constr_mult_init_max", IPOPT_CONSTR_MULT_INIT_MAX))
        return {**ipopt_options, "constr_mult_init_max": limit * self.multiplier_factor}

    @property
    def trivial(self) -> bool:
        return self.sf == 1.0 and bool(np.all(self.sx == 1.0)) and bool(np.all(self.sg == 1.0))

    # ------------------------------------------------------------ functions
    def nlp_functions(self, ca, nlp, grad_f):
        """The scaled (f, g) and (f, grad f) functions of (x_s, p) from the unscaled ones."""
        Xs, P = ca.MX.sym("x", len(self.sx)), ca.MX.sym("p", nlp.size1_in(1))
        X = Xs * ca.DM(1.0 / self.sx)
        f, g = nlp(X, P)
        f_g, gf = grad_f(X, P)
        return (ca.Function("nlp", [Xs, P], [self.sf * f, g * ca.DM(self.sg)], ["x", "p"], ["f", "g"]),
                ca.Function("nlp_grad_f", [Xs, P], [self.sf * f_g, ca.densify(gf * ca.DM(self.sf / self.sx))],
                            ["x", "p"], ["f", "grad_f_x"]))

    def jacobian_function(self, ca, jac_g):
        """The scaled (g, dg/dx) function from the unscaled one (its sparsity kept)."""
        Xs, P = ca.MX.sym("x", len(self.sx)), ca.MX.sym("p", jac_g.size1_in(1))
        g, J = jac_g(Xs * ca.DM(1.0 / self.sx), P)
        sp = jac_g.sparsity_out(1)
        r, c = (np.array(a, dtype=np.int64) for a in sp.get_triplet())
        factors = ca.DM(sp, (self.sg[r] / self.sx[c]).tolist())
        return ca.Function("nlp_jac_g", [Xs, P], [g * ca.DM(self.sg), J * factors], ["x", "p"], ["g", "jac_g_x"])

    def hessian_function(self, ca, hess):
        """The scaled Lagrangian Hessian (upper triangle) from the unscaled one."""
        Xs, P = ca.MX.sym("x", len(self.sx)), ca.MX.sym("p", hess.size1_in(1))
        lf, lg = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", len(self.sg))
        H = hess(Xs * ca.DM(1.0 / self.sx), P, self.sf * lf, lg * ca.DM(self.sg))
        sp = hess.sparsity_out(0)
        r, c = (np.array(a, dtype=np.int64) for a in sp.get_triplet())
        factors = ca.DM(sp, (1.0 / (self.sx[r] * self.sx[c])).tolist())
        return ca.Function("nlp_hess_l", [Xs, P, lf, lg], [H * factors], ["x", "p", "lam_f", "lam_g"],
                           ["triu_hess_gamma_x_x"])

    # ------------------------------------------------------------ numbers
    def scale_inputs(self, args: dict) -> dict:
        """casadi's solver arguments (x0, bounds, multipliers) of the unscaled problem -> the scaled one's."""
        out = dict(args)
        for k in ("x0", "lbx", "ubx"):
            out[k] = args[k] * self.sx
        for k in ("lbg", "ubg"):
            out[k] = args[k] * self.sg
        if "lam_g0" in args:
            out["lam_g0"] = args["lam_g0"] * self.sf / self.sg
        if "lam_x0" in args:
            out["lam_x0"] = args["lam_x0"] * self.sf / self.sx
        return out

    def unscale_solution(self, sol) -> dict:
        """casadi's solution of the scaled problem -> x, f, lam_g, lam_x of the unscaled one."""
        return {"x": np.asarray(sol["x"]).ravel() / self.sx, "f": float(sol["f"]) / self.sf,
                "lam_g": np.asarray(sol["lam_g"]).ravel() * self.sg / self.sf,
                "lam_x": np.asarray(sol["lam_x"]).ravel() * self.sx / self.sf}
