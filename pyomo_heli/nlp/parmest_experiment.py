"""The identification NLP as a parmest ``Experiment`` (Pyomo's parameter-estimation tool).

parmest's contract: ``get_labeled_model()`` returns a Pyomo model with the Suffixes

- ``experiment_outputs``: model output -> measured value (here ``m.y_hat[k, o]``, output ``o`` at the
  ``k``-th sample of all records, an Expression of ``m.man[name].y[o, t]``, -> the record's sample, SI),
- ``unknown_parameters``: the parameters to estimate (here the scaled free parameters ``m.theta_s[name]``,
  physical value = ``m.theta_scale[name] * m.theta_s[name]``),
- ``measurement_error``: output -> noise standard deviation [SI]: ``[objectives.noise_sigma]`` where the config
  gives it, else the records' quiet lead-in (``[data] input_reference_s > 0``, the pooled variance about each
  lead-in's mean, as the errors-in-variables fit takes it); None when neither is there (parmest's unknown error).

The model is the one pyomo_heli itself solves (:func:`~pyomo_heli.nlp.identification.build_identification_nlp`),
so parmest with ``obj_function=time_domain_objective`` minimises the same J_time (paper Eqs. 5-6) as point A
of the front, scaled as :class:`~pyomo_heli.pareto.front.ParetoSolver` scales it. parmest's own
``"SSE_weighted"`` fits the same outputs by least squares weighted by ``measurement_error`` instead (the ML
estimate with known noise when it holds the true sigmas, for an output-error config). Its ``"SSE"`` sums the
squared residuals of outputs in different units (rad/s, rad, g, m/s) unweighted, so the airspeed decides: not an
estimate of this model's parameters. With ``[objectives] input_errors`` neither parmest objective has the input
errors' prior (J_input): use ``time_domain_objective``.

    from pyomo.contrib.parmest.parmest import Estimator
    from pyomo_heli.solvers.pyomo_plugin import as_ipopt

    est = Estimator([IdentificationExperiment(cfg)], obj_function=time_domain_objective)
    with as_ipopt():                      # parmest asks SolverFactory("ipopt") for its solver
        obj, theta = est.theta_est()      # theta: "theta_s[name]" -> scaled value
"""
from __future__ import annotations

import pyomo.environ as pyo
from pyomo.contrib.parmest.experiment import Experiment

from .identification import build_identification_nlp, identification_data
from .objectives import noise_sigmas


def time_domain_objective(m):
    """J_time of the labelled model over the scale point A is solved with (parmest ``obj_function``)."""
    return m.J_time / m.J_time_scale


class IdentificationExperiment(Experiment):
    """One identification config's data and model as a parmest Experiment (all its maneuvers together).

    ``data``: the :class:`~pyomo_heli.nlp.identification.IdentificationData` (default: read as the config
    says). Each ``get_labeled_model()`` builds a new model (parmest builds and modifies its own copies).
    """

    def __init__(self, cfg, data=None):
        self.cfg = cfg
        self.data = identification_data(cfg) if data is None else data

    def get_labeled_model(self):
        cfg, data = self.cfg, self.data
        m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
        # the optimizer-level scale of point A (ParetoSolver.s_time): J_time at the initial guess
        m.J_time_scale = pyo.Param(initialize=max(abs(pyo.value(m.J_time)), 1.0), mutable=False)
        outputs = list(cfg.nlp.time_outputs)
        sigma = {k: float(v) for k, v in (cfg.nlp.noise_sigma or {}).items()}  # channel -> SI
        if not sigma:
            try:  # the records' quiet lead-in, where the config sets one
                sigma = noise_sigmas(data.maneuvers, outputs)
            except ValueError:
                sigma = {}
        # parmest wants the outputs indexed data point first, one family per output: m.y_hat[k, o] is the
        # model output o at the k-th sample of all records (an Expression: the NLP itself is unchanged)
        where, measured = [], []
        for mv in data.maneuvers:
            blk = m.man[mv.name]
            for i, tt in enumerate(blk.samples):
                where.append((blk, tt))
                measured.append({o: float(mv.data[o].iloc[i]) for o in cfg.nlp.time_outputs})
        m.data_points = pyo.Set(initialize=range(len(where)), ordered=True)
        m.y_hat = pyo.Expression(m.data_points, outputs, rule=lambda _, k, o: where[k][0].y[o, where[k][1]])
        m.experiment_outputs = pyo.Suffix(direction=pyo.Suffix.LOCAL)
        m.measurement_error = pyo.Suffix(direction=pyo.Suffix.LOCAL)
        for k in m.data_points:
            for o in outputs:
                m.experiment_outputs[m.y_hat[k, o]] = measured[k][o]
                m.measurement_error[m.y_hat[k, o]] = sigma.get(o)
        m.unknown_parameters = pyo.Suffix(direction=pyo.Suffix.LOCAL)
        m.unknown_parameters.update((m.theta_s[n], pyo.ComponentUID(m.theta_s[n])) for n in m.free_parameters)
        return m
