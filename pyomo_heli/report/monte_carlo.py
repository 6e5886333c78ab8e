"""Table and figure of a Monte Carlo result (pyomo_heli.uncertainty.monte_carlo.MonteCarloResult).

Values are shown in each parameter's display unit (deg/m for the twist),
converted here at the edge.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from ..physics.parameters import bo105

ESTIMATOR_LABELS = {"time": "time domain (A)", "multi": "multi-objective (Eq. 11 choice)"}
ESTIMATOR_COLORS = {"time": "tab:red", "multi": "tab:blue"}


def display(name: str) -> tuple[str, float]:
    """(unit, SI -> display factor) of a parameter."""
    spec = bo105().spec(name)
    return spec.display if spec.display is not None else (spec.unit, 1.0)


def summary_markdown(res) -> str:
    """The summary as a markdown table (display units)."""
    s = res.summary()
    lines = ["| estimator | parameter | unit | truth | mean | bias | bias % | spread (std) | CRB (median) | "
             "spread/CRB | n | at bound |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for _, r in s.iterrows():
        unit, f = display(r["parameter"])

        def g(x, scale=f):
            return "-" if not math.isfinite(x) else f"{x * scale:.5g}"

        lines.append(f"| {ESTIMATOR_LABELS.get(r['estimator'], r['estimator'])} | {r['parameter']} | {unit} | "
                     f"{g(r['truth'])} | {g(r['mean'])} | {g(r['bias'])} | {g(r['bias %'], 1.0)} | {g(r['std'])} | "
                     f"{g(r['crb'])} | {g(r['std/crb'], 1.0)} | {int(r['n'])} | {int(r['at bound'])} |")
    return "\n".join(lines)


def plot_monte_carlo(res, path: str | Path | None = None) -> Figure:
    """Per parameter: the estimates of every realization per estimator, the truth, and mean +- CRB."""
    params = list(res.parameters)
    est = res.estimates[res.estimates.success.astype(bool)]
    estimators = sorted(dict.fromkeys(est.estimator), key=lambda e: (e not in ESTIMATOR_LABELS,
                                                                     list(ESTIMATOR_LABELS).index(e)
                                                                     if e in ESTIMATOR_LABELS else 0, e))
    fig = Figure(figsize=(5.0 * len(params), 3.9), layout="constrained")
    axes = fig.subplots(1, len(params), squeeze=False)[0]
    for ax, p in zip(axes, params):
        unit, f = display(p)
        for j, e in enumerate(estimators):
            x = est.loc[est.estimator == e, p].to_numpy(float) * f
            y = j + np.linspace(-0.25, 0.25, len(x)) if len(x) > 1 else np.full(len(x), float(j))
            ax.plot(x, y, "o", ms=4, alpha=0.7, color=ESTIMATOR_COLORS.get(e, "k"),
                    label=f"{ESTIMATOR_LABELS.get(e, e)} (n={len(x)})")
            se = est.loc[est.estimator == e, f"se_{p}"].to_numpy(float) * f if f"se_{p}" in est else np.array([])
            if np.isfinite(se).any():
                m, s = float(np.mean(x)), float(np.nanmedian(se))
                ax.errorbar([m], [j + 0.4], xerr=[[s], [s]], fmt="s", color=ESTIMATOR_COLORS.get(e, "k"), capsize=4,
                            ms=5)
        ax.axvline(res.truth[p] * f, color="black", linewidth=1.2, linestyle="--", label="truth")
        ax.set_yticks(range(len(estimators)))
        ax.set_yticklabels([ESTIMATOR_LABELS.get(e, e).split(" (")[0] for e in estimators])
        ax.set_xlabel(f"{p} [{unit}]")
        ax.set_title(f"{p}: estimates, mean $\\pm$ median CRB", fontsize=9)
        ax.set_ylim(-0.6, len(estimators) - 0.3)
    fig.legend(*axes[0].get_legend_handles_labels(), fontsize=7, loc="outside lower center",
               ncol=len(estimators) + 1)
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
