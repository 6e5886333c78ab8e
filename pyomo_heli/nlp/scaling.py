"""Scaling of the identification NLP through IDAES's scaling API: a Scaler beside the model.

:class:`IdentificationScaler` is an IDAES ``CustomScalerBase`` as IDAES unit models have one: it writes
scaling factors into the model's ``scaling_factor`` suffixes (IDAES's convention, read back with
``idaes.core.scaling.get_scaling_factor``; Pyomo's ``core.scale_model`` and the casadi adapter with
``[solver] options = { scaling = true }`` read the same suffixes, solvers/casadi_scaling.py). A factor is
1 / nominal magnitude, the nominals taken from the physics, not from one solve:

- states [SI]: ``STATE_NOMINAL`` (u 40 m/s, w 5 m/s, q 0.2 rad/s, theta 0.1 rad, inflow 0.05), their
  time derivatives nominal / ``TIME_NOMINAL`` (1 s, the time scale of the pitch and heave dynamics),
  flapping angles ``FLAPPING_NOMINAL`` (0.05 rad), the trim inputs ``INPUT_NOMINAL``, the outputs
  ``OUTPUT_NOMINAL``, the trim speed like u;
- free parameters: ``theta_s = p / scale`` has the nominal max(|p_nominal| / scale, 1), p_nominal the
  value of the model's ParameterSpec (``m.theta_nominal``);
- noise: the Cholesky factor of the output covariance and the mean squares by the noise level (the
  known sigmas, else the start's residual level), the input errors by their sigma (bound / 6);
- rows by their nominal residual: an ODE or collocation row of state s (residual in s per time) by
  TIME_NOMINAL / nominal(s), an initial-state row by 1 / nominal(s), an output row by 1 / nominal(output);
  the noise-covariance rows (Cholesky, mean squares) keep 1 (tried: by 1 / (L_aa L_bb) Case 1's point A
  took 38 iterations instead of 26); the other rows (flapping
  equations, the linear-model rows) by IDAES's ``inverseMaximum`` nominal-value walk over those variable
  nominals, once per equation family (the walk expands the shared intermediates: 0.4 s per row); the Pareto
  solver's epsilon row J_trim / J_trim(theta_0) <= eps by the largest factor of its variables
  (:meth:`IdentificationScaler.epsilon_row_factor`; the adapter applies it only while the row has a finite bound);
- objective: 1 / max(|value at the start|, 1), the optimizer-level objective scale of the paper (Fig. 4;
  the Pareto solver's objective is already divided by |J_time(theta_0)|, so its factor is 1).

Variables pinned by equal bounds (objective settings) and anything not named keep factor 1.
"""
from __future__ import annotations

import pyomo.environ as pyo
from pyomo.common.gc_manager import PauseGC
from pyomo.core.expr.visitor import identify_variables
from idaes.core.scaling import CustomScalerBase, get_scaling_factor
from idaes.core.scaling.custom_scaler_base import ConstraintScalingScheme
from idaes.core.scaling.util import get_scaling_factor_suffix

#: nominal magnitudes of the states [m/s, m/s, rad/s, rad, -]
STATE_NOMINAL = {"u": 40.0, "w": 5.0, "q": 0.2, "theta": 0.1, "lambda_i": 0.05}
#: time scale of the state derivatives [s]: nominal(dx_s / dt) = nominal(s) / TIME_NOMINAL
TIME_NOMINAL = 1.0
#: flapping angles [rad]
FLAPPING_NOMINAL = 0.05
#: trim inputs [rad]: collective and longitudinal cyclic
INPUT_NOMINAL = {"col": 0.15, "lon": 0.05}
#: outputs [rad/s, rad, g, g, m/s, rad]
OUTPUT_NOMINAL = {"q": 0.2, "theta": 0.1, "n_x": 0.1, "n_z": 1.0, "TAS": 40.0, "beta_0": 0.05}
#: bound of the input errors in sigmas (nlp.identification.INPUT_ERROR_BOUND)
_ERROR_BOUND = 6.0


def _nominal(name: str) -> float:
    """Nominal of a state, flapping angle, input or output by name (extension states: 1)."""
    if name in STATE_NOMINAL:
        return STATE_NOMINAL[name]
    if name.startswith("beta_"):
        return FLAPPING_NOMINAL
    return INPUT_NOMINAL.get(name, OUTPUT_NOMINAL.get(name, 1.0))


def _name(idx):
    """The first index entry of a component's index (the state, output or channel name), or None."""
    first = idx[0] if isinstance(idx, tuple) else idx
    return first if isinstance(first, str) else None


class IdentificationScaler(CustomScalerBase):
    """Scaling factors of an identification NLP (:func:`~pyomo_heli.nlp.identification.build_identification_nlp`)."""

    # ------------------------------------------------------------------ variables
    def variable_nominal(self, comp: str, block, idx, v) -> float | None:
        """The nominal magnitude of variable ``v`` = ``block.<comp>[idx]`` (module docstring), None: factor 1."""
        name = _name(idx)
        if comp == "x" or comp == "x0":
            return _nominal(name)
        if comp == "dx":
            return _nominal(name) / TIME_NOMINAL
        if comp == "beta":
            return FLAPPING_NOMINAL
        if comp in ("y", "y_meas"):
            return _nominal(name)
        if comp == "trim_meas":  # index (trim point, channel)
            return _nominal(idx[1])
        if comp in ("u_err", "u_ref"):
            return v.ub / _ERROR_BOUND if v.ub is not None else None
        if comp == "V":
            return STATE_NOMINAL["u"]
        if comp in ("col", "lon", "theta", "lambda_i") or comp.startswith("beta_"):
            return _nominal(comp)
        if comp == "theta_s":
            nominal = block.component("theta_nominal")
            return max(abs(pyo.value(nominal[name])) / pyo.value(block.theta_scale[name]), 1.0) if nominal else None
        if comp == "L":
            diag = block.L[idx[0], idx[0]].value
            return abs(diag) if diag else None
        if comp == "mean_square":
            sigma = block.component("noise_sigma")
            return float(sigma[name]) ** 2 if sigma is not None else (abs(v.value) or None)
        return None

    # The factors go into the suffix IDAES's get_scaling_factor_suffix gives for the component's block, where
    # set_variable_scaling_factor puts them, but written directly, one component at a time: IDAES's
    # per-component setters spent about 1.4 ms per component in their option handling (44 s for the 24k
    # variables and rows of small_case1_noisy, minutes at Case 1's 200k).
    def variable_scaling_routine(self, model, overwrite: bool = False, submodel_scalers=None):
        with PauseGC():
            for comp in model.component_objects(pyo.Var, descend_into=True):
                blk, name = comp.parent_block(), comp.local_name
                sfx = get_scaling_factor_suffix(blk)
                for idx, v in comp.items():
                    if v.fixed or not (overwrite or v not in sfx):
                        continue
                    nominal = self.variable_nominal(name, blk, idx, v)
                    if nominal:
                        sfx[v] = 1.0 / nominal

    # ---------------------------------------------------------------- constraints
    def constraint_factor(self, comp: str, block, idx) -> float | None:
        """The factor of row ``block.<comp>[idx]`` from the physics (module docstring), None: IDAES's walk."""
        name = _name(idx)
        if comp in ("ode", "dx_disc_eq", "equilibrium"):
            return TIME_NOMINAL / _nominal(name)
        if comp == "initial":
            return 1.0 / _nominal(name)
        if comp == "lead_in_mean":  # the mean of a record's input errors over its lead-in, in their sigmas
            return _ERROR_BOUND / block.u_ref[name].ub
        if comp == "output_eq":
            return 1.0 / OUTPUT_NOMINAL.get(name, 1.0)
        if comp == "V_spec":
            return 1.0 / STATE_NOMINAL["u"]
        if comp in ("cholesky", "mean_square_def"):
            # the noise-covariance rows (L L^T = R_hat, n * mean square = sum of squares) stay unscaled: by
            # 1 / (L_aa L_bb) at the start (the residuals of the initial guess) Case 1's point A took 38
            # Ipopt iterations instead of 26; with factor 1, 26 (docs/performance.md, "Scaling")
            return 1.0
        return None

    @staticmethod
    def epsilon_row_factor(c) -> float:
        """Factor of an epsilon row J_k / J_k(theta_0) <= eps (pareto.epsilon): the largest factor of its variables.

        The row is no physics equation with a nominal residual: it depends on the variables only through
        J_k, so scaling them by s_x shrinks its derivatives by 1 / s_x (J_trim's by 1 / 20 for the trim
        inputs), while the model rows that hold the same variables keep theirs. With the largest factor of
        its variables the row keeps about the size of derivative it has unscaled. Measured on Case 1's
        anchor B, second stage (docs/performance.md, "Scaling"): factor 1 took 14 Ipopt iterations against
        11 unscaled; 20, and every factor from 10 to 1000, 10.
        """
        factors = [get_scaling_factor(v, default=1.0) for v in identify_variables(c.body, include_fixed=False)]
        return max(factors, default=1.0)

    def constraint_scaling_routine(self, model, overwrite: bool = False, submodel_scalers=None):
        # Rows without a physics factor: one nominal-value walk per equation family, a family being one
        # constraint component of all blocks of one kind (e.g. the flapping rows of every maneuver); its
        # first row's factor is given to all. Walking every row took 0.4 s per ODE row (the shared named
        # Expressions are expanded for each row): 10 min for a 5k-row problem.
        families, suffixes = {}, {}
        with PauseGC():
            for comp in model.component_objects(pyo.Constraint, active=True, descend_into=True):
                blk, name = comp.parent_block(), comp.local_name
                sfx = suffixes[id(blk)] = get_scaling_factor_suffix(blk)
                kind = blk.parent_component().local_name if blk is not model else ""
                for idx, c in comp.items():
                    if not c.active or not (overwrite or c not in sfx):
                        continue
                    factor = (self.epsilon_row_factor(c) if name == "eps_con"
                              else self.constraint_factor(name, blk, idx))
                    if factor is not None:
                        sfx[c] = factor
                    else:
                        families.setdefault((kind, name, _name(idx)), []).append(c)
        for rows in families.values():
            self.scale_constraint_by_nominal_value(rows[0], scheme=ConstraintScalingScheme.inverseMaximum,
                                                   overwrite=overwrite)
            sf = self.get_scaling_factor(rows[0])
            for c in rows[1:]:
                suffixes[id(c.parent_block())][c] = sf
        for o in model.component_data_objects(pyo.Objective, active=True, descend_into=True):
            # IDAES's setters take variables and constraints only; the objective's factor goes into the same
            # scaling_factor suffix of its block, where Pyomo's core.scale_model and the casadi adapter read it
            sfx = get_scaling_factor_suffix(o.parent_block())
            if overwrite or o not in sfx:
                sfx[o] = 1.0 / max(abs(pyo.value(o.expr)), 1.0)


def wants_scaling(solver: str, solver_options: dict) -> bool:
    """Whether a solve with these settings uses the scaled problem (casadi-ipopt's ``scaling`` switch)."""
    if solver != "casadi-ipopt":
        return False
    from ..solvers.casadi_ipopt import CasadiSettings

    return bool(solver_options.get("scaling", CasadiSettings.scaling))


def apply_scaling(m, solver: str, solver_options: dict) -> bool:
    """Write the Scaler's factors into ``m`` when the solver will use them; returns whether it did."""
    if not wants_scaling(solver, solver_options):
        return False
    IdentificationScaler(overwrite=True).scale_model(m)
    return True


def scaled_model(m, scaler: IdentificationScaler | None = None):
    """A scaled copy of ``m`` (Pyomo ``core.scale_model``) after ``scaler`` wrote its factors into ``m``."""
    (scaler or IdentificationScaler()).scale_model(m)
    return pyo.TransformationFactory("core.scale_model").create_using(m, rename=False)
