"""The "Uncertainty and identifiability" section of the identification report (markdown lines).

Reads what pyomo_heli.uncertainty.front attached to the result: the
``uncertainty`` entries of the time-domain, chosen and direct points and
``identifiability.csv``. Values in display units (deg/m for the twist).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..uncertainty.cramer_rao import ParameterUncertainty
from ..uncertainty.identifiability import Identifiability


def _display(model, name):
    spec = model.parameters.spec(name)
    return spec.display if spec.display is not None else (spec.unit, 1.0)


def _cell(u: ParameterUncertainty, n: str, f: float) -> str:
    v, s = u.values[n] * f, u.se[n]
    if u.at_bound.get(n):
        return f"{v:.6g} (at {u.at_bound[n]} bound, projected out)"
    if s is None or not math.isfinite(s):
        return f"{v:.6g} +- n/a"
    rel = f" ({100 * s / abs(u.values[n]):.2g} %)" if u.values[n] else ""
    return f"{v:.6g} +- {s * f:.3g}{rel}"


def uncertainty_section(result, results_dir, model) -> list[str]:
    """Markdown lines, or [] when the result has no standard errors."""
    points = [("time-domain (A)", result.time_domain), ("multi-objective (C)", result.chosen),
              ("Eq. 11 direct", result.direct)]
    points = [(lab, ParameterUncertainty.from_dict(p["uncertainty"])) for lab, p in points
              if p and p.get("uncertainty")]
    if not points:
        return []
    names = list(result.parameters)
    L = ["## Uncertainty and identifiability", "",
         "Cramer-Rao standard errors (one sigma) at each estimate, from the output sensitivities with every "
         "residual covariance as estimated (see docs/uncertainty.md). A is the output-error ML estimate "
         "(F_time^-1); C and the direct solve use the sandwich covariance of the weighted sum "
         "a J_time + b J_trim they are stationary points of. A parameter at a bound is projected out.", ""]
    rows = []
    for lab, u in points:
        rows.append({"estimate": lab, **{f"{n} [{_display(model, n)[0]}]": _cell(u, n, _display(model, n)[1])
                                         for n in names},
                     "weights (a, b)": f"{u.weights[0]:.3g}, {u.weights[1]:.3g}"})
    df = pd.DataFrame(rows)
    L += ["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
    L += ["| " + " | ".join(str(x) for x in r) + " |" for r in df.itertuples(index=False)]
    chosen = dict(points).get("multi-objective (C)")
    if chosen is not None and len(names) > 1:
        corr = np.array(chosen.correlation, dtype=float)
        L += ["", "Correlation matrix of C:", "", "| | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
        L += [f"| {n} | " + " | ".join("-" if not math.isfinite(x) else f"{x:+.3f}" for x in corr[i]) + " |"
              for i, n in enumerate(names)]
    path = Path(results_dir) / "identifiability.csv"
    if path.is_file():
        ident = Identifiability.load(path)
        L += ["", "Identifiability at C: singular values of the noise-normalised sensitivity matrix "
              "(columns in units of each parameter's scale) per objective; 1/singular value is the "
              "Cramer-Rao bound along that direction. `identifiability.csv` has the full table.", "",
              "| objective | singular values | condition number | weakest direction | CRB along it [scale units] |",
              "|---|---|---|---|---|"]
        for obj in dict.fromkeys(ident.table.objective):
            sv = ident.table.loc[ident.table.objective == obj, "singular_value"]
            w = ident.weakest(obj)
            L.append(f"| {obj} | {', '.join(f'{x:.4g}' for x in sv)} | {ident.condition(obj):.3g} | "
                     f"{w.direction} | {w.se_scaled:.3g} |")
    L.append("")
    return L
