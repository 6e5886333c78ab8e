"""Standard errors of every front point and of the chosen points of an identification result.

Adds to an :class:`~pyomo_heli.pareto.result.IdentificationResult`:

- ``front.csv``: columns ``se_<parameter>`` (SI, empty when the parameter is at
  a bound) and ``at_bound`` (e.g. ``theta_twist:upper``) for every solved point;
- ``chosen.json``: an ``uncertainty`` entry (standard errors, correlation
  matrix, at-bound flags, the objective weights used) in ``chosen``,
  ``direct`` and in ``time_domain.json``; the direct Eq. 11 solve's weights are known in closed form
  (:func:`eq11_weights`), an epsilon point's from its solve's multiplier (``multiplier_trim``), the others'
  are found from the gradients;
- ``identifiability.csv``: singular values and directions of the scaled
  sensitivity matrices (time, trim, combined) at the chosen point.
"""
from __future__ import annotations

import math
from pathlib import Path

from ..log import format_parameters, info
from ..pareto.eq11 import utopia_distance_weights
from .cramer_rao import cramer_rao, point_information
from .identifiability import identifiability


def config_information(cfg, data, parameters):
    """:func:`~pyomo_heli.uncertainty.cramer_rao.point_information` at ``parameters`` with everything else as the
    identification config ``cfg`` sets it up (free parameters, records ``data``, outputs, input errors, noise)."""
    return point_information(cfg.model, cfg.free, parameters, data.maneuvers, data.trims, cfg.nlp.time_outputs,
                             cfg.nlp.trim_outputs, input_errors=cfg.nlp.input_errors, noise_sigma=cfg.nlp.noise_sigma,
                             input_error_ar=cfg.nlp.input_error_ar)


def approximations(cfg) -> list[str]:
    """What of the identification's noise model the Cramer-Rao information leaves out (it takes each output's noise
    white with its own variance, and the input errors of :func:`~.cramer_rao.point_information`): the standard errors
    are then approximate, and the results say so (``info.uncertainty_approximations``)."""
    nlp = cfg.nlp
    out = []
    if nlp.output_error_ar:
        out.append(f"the output noise's AR({nlp.output_error_ar}) model ([objectives] output_error_ar): outputs taken "
                   "as white, so coloured noise makes the standard errors too small")
    if nlp.input_reference_error:
        out.append("the records' input reference errors ([objectives] input_reference_error)")
    if nlp.covariance == "full":
        out.append("the outputs' full covariance ([objectives] covariance = \"full\"): taken diagonal")
    return out


def point_standard_errors(cfg, data, parameters: dict, kind: str = "eps", multiplier: float | None = None) -> dict:
    """name -> Cramer-Rao standard error (SI; nan at a bound) of a front point with these parameter values
    (``multiplier``: its solve's -dJ_time/dJ_trim, :func:`~.cramer_rao.objective_weights`)."""
    return dict(cramer_rao(config_information(cfg, data, parameters), cfg.free, kind=kind, multiplier=multiplier).se)


def eq11_weights(point: dict, utopia, nadir) -> tuple | None:
    """(a, b) with the direct Eq. 11 solve stationary for a J_time + b J_trim, in closed form
    (:func:`~pyomo_heli.pareto.eq11.utopia_distance_weights`). None (the weights are then found from the gradients)
    unless the front has exactly the two objectives and a spread in each."""
    if len(utopia) != 2 or len(nadir) != 2:
        return None
    w = utopia_distance_weights((point["J_time"], point["J_trim"]), utopia, nadir)
    return None if w is None else (float(w[0]), float(w[1]))


def _multiplier(row) -> float | None:
    """A front.csv row's multiplier_trim (None when the column is missing or empty)."""
    try:
        v = float(row.get("multiplier_trim"))
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def add_uncertainty(result, cfg, data, out=None, progress=info, points: str = "all"):
    """Compute and attach standard errors (every front point, A, chosen, direct); save to ``out``.

    points: "all" front points, or "chosen" (only A, the chosen point and the direct solve).
    """
    if points not in ("all", "chosen"):
        raise ValueError(f"points must be 'all' or 'chosen', got {points!r}")
    approx = approximations(cfg)
    result.info.pop("uncertainty_approximations", None)
    if approx:
        result.info["uncertainty_approximations"] = approx
        progress("standard errors are approximate: the information leaves out " + "; ".join(approx))
    names = list(result.parameters)
    front = result.front
    for c in [f"se_{n}" for n in names] + ["at_bound"]:
        front[c] = float("nan") if c != "at_bound" else ""
    front["at_bound"] = front["at_bound"].astype(object)
    wanted = {int(result.time_domain["index"]), int(result.chosen["index"])}
    by_index = {}
    for i, r in front.iterrows():
        if not bool(r["success"]) or (points == "chosen" and int(r["index"]) not in wanted):
            continue
        params = {n: float(r[n]) for n in names}
        info = config_information(cfg, data, params)
        u = cramer_rao(info, cfg.free, kind=str(r["kind"]), multiplier=_multiplier(r))
        for k, v in u.row().items():
            front.at[i, k] = v
        by_index[int(r["index"])] = (u, info)
        progress(f"  standard errors, point {int(r['index']):>2}: "  # display units, as every console line
                 + format_parameters({n: u.values[n] for n in names}, cfg.model.parameters, se=u.se,
                                     notes={n: f"at {u.at_bound[n]} bound" if u.at_bound[n] else "" for n in names}))
    for point in (result.time_domain, result.chosen):
        if point and int(point["index"]) in by_index:
            point["uncertainty"] = by_index[int(point["index"])][0].to_dict()
    if result.direct and result.direct.get("success"):
        u = cramer_rao(config_information(cfg, data, result.direct["parameters"]), cfg.free, kind="direct",
                       weights=eq11_weights(result.direct, result.utopia, result.nadir))
        result.direct["uncertainty"] = u.to_dict()
    ident = None
    if int(result.chosen["index"]) in by_index:
        ident = identifiability(by_index[int(result.chosen["index"])][1])
        progress("identifiability at the chosen point:\n" + ident.summary())
    if out is not None:
        result.save(out)
        if ident is not None:
            ident.save(Path(out) / "identifiability.csv")
    return result, ident
