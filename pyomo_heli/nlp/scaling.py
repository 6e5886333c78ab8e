"""Scaling of the identification NLP through IDAES's scaling API: a Scaler beside the model.

:class:`IdentificationScaler` is an IDAES ``CustomScalerBase`` as IDAES unit models have one: it writes
scaling factors into the model's ``scaling_factor`` suffixes (IDAES's convention, read back with
``idaes.core.scaling.get_scaling_factor``):

- variables: 1 / nominal, nominal = max(|value at the initial guess|, ``variable_floor``), so variables of
  order one and smaller keep factor 1 and large ones (airspeed components in m/s, rotor thrust
  coefficients' products, ...) come to order one;
- constraints: 1 / the largest nominal term of the row (IDAES's ``inverseMaximum`` scheme over those
  variable nominals), computed for the first row of each equation family and given to the family;
- objective: 1 / max(|J_time|, 1) at the initial guess, the optimizer-level objective scale of the paper
  (Fig. 4) that :class:`~pyomo_heli.pareto.front.ParetoSolver` applies through ``m.objective``.

:func:`scaled_model` applies the factors with Pyomo's ``core.scale_model`` transformation; the casadi
adapter then solves the scaled copy through the NL file (``point_rows=False``: the compiled point rows
are written for the unscaled variables). The one-off check of commit 921fc42
(``git show 921fc42:studies/scaling_check.py``) compares the iterations of point A:
on its default instance (small_case1_noisy.toml, lon3211_80kt_a cut to 3 s, 4946 variables) both reach the
same estimate (to 2e-13), unscaled in 31 Ipopt iterations, scaled in 33; with the constraint factors alone
(variables unscaled) Ipopt's restoration failed. Ipopt's own gradient-based scaling, the scaled free
parameters ``theta_s`` and the objective scale already do what this adds, so the solves do not use it.
"""
from __future__ import annotations

import pyomo.environ as pyo
from idaes.core.scaling import CustomScalerBase
from idaes.core.scaling.util import get_scaling_factor_suffix
from idaes.core.scaling.custom_scaler_base import ConstraintScalingScheme


class IdentificationScaler(CustomScalerBase):
    """Scaling factors of an identification NLP (:func:`~pyomo_heli.nlp.identification.build_identification_nlp`)."""

    #: variables with |value| below this keep scaling factor 1 (nothing small is blown up)
    variable_floor = 1.0

    def variable_scaling_routine(self, model, overwrite: bool = False, submodel_scalers=None):
        for v in model.component_data_objects(pyo.Var, descend_into=True):
            if v.fixed or v.value is None:
                continue
            self.set_variable_scaling_factor(v, 1.0 / max(abs(v.value), self.variable_floor), overwrite=overwrite)

    def constraint_scaling_routine(self, model, overwrite: bool = False, submodel_scalers=None):
        # One nominal-value walk per equation family: a family is an indexed constraint of one block with
        # the same names in its index (e.g. the 'q' rows of a maneuver's ODE at every collocation point);
        # its first row's factor is given to all. Walking every row took 0.4 s per ODE row (the shared
        # named Expressions are expanded for each row): 10 min for a 5k-row problem.
        families = {}
        for c in model.component_data_objects(pyo.Constraint, active=True, descend_into=True):
            idx = c.index()
            names = tuple(i for i in (idx if isinstance(idx, tuple) else (idx,)) if isinstance(i, str))
            families.setdefault((id(c.parent_component()), names), []).append(c)
        for rows in families.values():
            self.scale_constraint_by_nominal_value(rows[0], scheme=ConstraintScalingScheme.inverseMaximum,
                                                   overwrite=overwrite)
            sf = self.get_scaling_factor(rows[0])
            for c in rows[1:]:
                self.set_constraint_scaling_factor(c, sf, overwrite=overwrite)
        for o in model.component_data_objects(pyo.Objective, active=True, descend_into=True):
            # IDAES's setters take variables and constraints only; the objective's factor goes into the same
            # scaling_factor suffix of its block, where Pyomo's core.scale_model reads it
            sfx = get_scaling_factor_suffix(o.parent_block())
            if overwrite or o not in sfx:
                sfx[o] = 1.0 / max(abs(pyo.value(o.expr)), 1.0)


def scaled_model(m, scaler: IdentificationScaler | None = None):
    """A scaled copy of ``m`` (Pyomo ``core.scale_model``) after ``scaler`` wrote its factors into ``m``."""
    (scaler or IdentificationScaler()).scale_model(m)
    return pyo.TransformationFactory("core.scale_model").create_using(m, rename=False)
