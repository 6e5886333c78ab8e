"""Figures and tables of a tri-objective run: front projections, Bode plots, estimates vs truth.

Plots are functions of saved results (``front.csv``, ``chosen.json``,
``frequency_responses.csv``); the model curves of the Bode plots come from the
float model's finite-difference linearisation (``simulation.linearize``) at
each estimate, a route independent of the NLP.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from ..dataset.frequency_response import load_responses
from ..pareto.result import IdentificationResult
from ..simulation.linearize import linearize_float
from .identification import _display, markdown_table, read_truth

ESTIMATES = (("time-domain (A)", "C0", "--"), ("bi-objective", "C2", "-."), ("tri-objective", "C3", "-"))


def estimates(result: IdentificationResult) -> dict[str, dict]:
    """Label -> free parameter values (SI) of the time-domain, bi- and tri-objective choices."""
    return {"time-domain (A)": result.time_domain["parameters"],
            "bi-objective": result.info["bi_objective"]["chosen"]["parameters"],
            "tri-objective": result.chosen["parameters"]}


def plot_front_projections(front: pd.DataFrame, result: IdentificationResult) -> Figure:
    """The three 2-D projections of the (J_time, J_trim, J_linear) front."""
    fig = Figure(figsize=(13, 4.2))
    ok = front[front["success"].astype(bool) & front["kind"].isin(["A", "B", "C", "eps"])]
    bad = front[~front["success"].astype(bool)]
    pairs = (("J_time", "J_trim"), ("J_time", "J_linear"), ("J_trim", "J_linear"))
    tri, bi = result.chosen, result.info["bi_objective"]["chosen"]
    for k, (x, y) in enumerate(pairs):
        ax = fig.add_subplot(1, 3, k + 1)
        sc = ax.scatter(ok[x], ok[y], c=ok["J_linear" if y != "J_linear" else "J_trim"], cmap="viridis", s=30)
        for _, r in ok[ok["kind"].isin(["A", "B", "C"])].iterrows():
            ax.annotate(r["kind"], (r[x], r[y]), textcoords="offset points", xytext=(5, 5))
        if len(bad):
            ax.scatter(bad[x], bad[y], marker="x", color="grey", label="not converged")
        ax.scatter([tri[x]], [tri[y]], s=160, facecolors="none", edgecolors="C3", linewidths=2,
                   label="tri-objective choice (Eq. 11)")
        ax.scatter([bi[x]], [bi[y]], s=110, marker="s", facecolors="none", edgecolors="C2", linewidths=2,
                   label="bi-objective choice")
        ax.set_xlabel(x)
        ax.set_ylabel(y)
        fig.colorbar(sc, ax=ax, label="J_linear" if y != "J_linear" else "J_trim")
        if k == 0:
            ax.legend(fontsize=7)
    fig.suptitle("Tri-objective front: projections (colour = the third objective)")
    fig.tight_layout()
    return fig


def model_curves(model, params: dict, responses, omega: np.ndarray) -> list[np.ndarray]:
    """G(j omega) of the float model at ``params`` for each response's speed and pair."""
    mdl = model.with_parameters(**params)
    lins = {}
    out = []
    for r in responses:
        key = round(r.speed, 6)
        if key not in lins:
            lins[key] = linearize_float(mdl, r.speed)
        out.append(lins[key].frequency_response(r.output, r.input, omega))
    return out


def plot_bode(responses, curves: dict, omega: np.ndarray) -> Figure:
    """Gain, phase and coherence per response: data (coherent band highlighted) and model curves."""
    n = len(responses)
    fig = Figure(figsize=(4.2 * n, 8.5))
    for j, r in enumerate(responses):
        axg, axp, axc = (fig.add_subplot(3, n, j + 1 + n * i) for i in range(3))
        k = r.coherent
        sel = (r.omega > 0) & (r.omega <= omega.max())
        axg.semilogx(r.omega[sel], r.gain_db[sel], ".", color="0.7", label="data (all bins)")
        axg.semilogx(r.omega[k], r.gain_db[k], "ko", ms=4, label="data, coherent band")
        axp.semilogx(r.omega[sel], r.phase_deg[sel], ".", color="0.7")
        axp.semilogx(r.omega[k], r.phase_deg[k], "ko", ms=4)
        for (label, color, ls) in ESTIMATES + (("truth", "k", ":"),):
            if label in curves:
                G = curves[label][j]
                axg.semilogx(omega, 20 * np.log10(np.abs(G)), color=color, ls=ls, label=label)
                ph = np.degrees(np.angle(G))
                # keep the model phase on the data's branch near the band for readability
                if k.any():
                    ref = np.degrees(np.angle(np.interp(r.omega[k][0], omega, G.real)
                                              + 1j * np.interp(r.omega[k][0], omega, G.imag)))
                    ph = ph + 360 * np.round((r.phase_deg[k][0] - ref) / 360)
                axp.semilogx(omega, ph, color=color, ls=ls)
        axc.semilogx(r.omega[sel], r.coherence[sel], "k.")
        axc.axhline(0.9, color="grey", lw=0.8)
        axg.set_title(r.label)
        axg.set_ylabel("gain [dB]")
        axp.set_ylabel("phase [deg]")
        axc.set_ylabel("coherence")
        axc.set_xlabel("omega [rad/s]")
        axc.set_ylim(0, 1.05)
        if j == 0:
            axg.legend(fontsize=7)
    fig.tight_layout()
    return fig


def band_errors(responses, curves: dict) -> pd.DataFrame:
    """Max |gain| [dB] and |phase| [deg] error of each model over each response's coherent band."""
    rows = []
    for j, r in enumerate(responses):
        b = r.band()
        for label, G in curves.items():
            Gb = G[j] if len(G[j]) == len(b.omega) else None
            if Gb is None:
                continue
            rows.append({"response": r.label, "model": label,
                         "max gain error [dB]": float(np.max(np.abs(20 * np.log10(np.abs(b.T / Gb))))),
                         "max phase error [deg]": float(np.max(np.abs(np.degrees(np.angle(b.T / Gb))))),
                         "bins": len(b.omega)})
    return pd.DataFrame(rows)


def write_linear_report(out_dir, cfg) -> Path:
    """Figures and ``report_linear.md`` of a tri-objective results folder."""
    out = Path(out_dir)
    result = IdentificationResult.load(out)
    front = pd.read_csv(out / "front.csv")
    responses = load_responses(out / "frequency_responses.csv")
    truth = read_truth(cfg.dataset)
    est = estimates(result)
    sets = dict(est)
    if truth is not None:
        sets["truth"] = {n: truth[n] for n in result.parameters if n in truth}
    omega = np.geomspace(0.3, 30, 200)
    curves = {label: model_curves(cfg.model, p, responses, omega) for label, p in sets.items()}
    fig = plot_front_projections(front, result)
    fig.savefig(out / "front_projections.png", dpi=110)
    fig = plot_bode(responses, curves, omega)
    fig.savefig(out / "bode.png", dpi=110)
    band_curves = {label: [model_curves(cfg.model, p, [r], r.band().omega)[0] for r in responses]
                   for label, p in sets.items()}
    errs = band_errors(responses, band_curves)
    errs.to_csv(out / "band_errors.csv", index=False, float_format="%.6g")

    rows = []
    for name in result.parameters:
        unit, fac = _display(cfg.model, name)
        row = {"parameter": name, "unit": unit, "initial": next(f.initial for f in cfg.free if f.name == name) * fac}
        if truth is not None and name in truth:
            row["truth"] = truth[name] * fac
        for label, p in est.items():
            row[label] = p[name] * fac
            if "truth" in row and row["truth"]:
                row[f"{label} error %"] = 100 * (p[name] * fac - row["truth"]) / abs(row["truth"])
        rows.append(row)
    params = pd.DataFrame(rows)
    params.to_csv(out / "parameters_tri.csv", index=False, float_format="%.6g")
    objs = pd.DataFrame([{"point": label, **{k: d[k] for k in ("index", "kind", "J_time", "J_trim", "J_linear")}}
                         for label, d in (("time-domain (A)", result.time_domain),
                                          ("bi-objective", result.info["bi_objective"]["chosen"]),
                                          ("tri-objective", result.chosen), ("Eq. 11 direct (3 obj.)", result.direct))])
    shown = front.drop(columns=[c for c in front.columns if c.startswith("cold_") or c in ("warm_start",)], errors="ignore")
    text = [f"# Tri-objective identification: {cfg.path.name}", "",
            f"Objectives {', '.join(result.info['objectives'])}; grid {result.info['grid'][0]} (J_trim) x "
            f"{result.info['grid'][1]} (J_linear); total time {result.info['total_time']:.0f} s; "
            f"{result.info['failed_points']} point(s) not converged.", "",
            "## Estimates (display units)", "", markdown_table(params, 5), "",
            "## Objective values of the choices", "", markdown_table(objs, 6), "",
            f"utopia (J_time, J_trim, J_linear) = {tuple(round(v, 6) for v in result.utopia)}, "
            f"nadir = {tuple(round(v, 6) for v in result.nadir)}", "",
            "## Frequency-response errors in the coherent band", "", markdown_table(errs, 4), "",
            "![front](front_projections.png)", "", "![bode](bode.png)", "",
            "## Front", "", markdown_table(shown, 6), ""]
    path = out / "report_linear.md"
    path.write_text("\n".join(text))
    return path
