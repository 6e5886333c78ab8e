"""Figures and the readable report of a residual diagnosis.

Every figure is a function of plain data (a :class:`~pyomo_heli.diagnosis.residuals.Residuals`
and/or a :class:`~pyomo_heli.diagnosis.analysis.Diagnosis`) and returns a
matplotlib Figure (no pyplot, Agg-safe). :func:`write_diagnosis_report` writes
``diagnosis.md`` next to the figures.

- ``diagnosis_trim.png``       trim residual (model - data) vs airspeed per channel, with the fitted shape
- ``diagnosis_spectra.png``    residual PSD per output (after the nuisance), per role, dynamics band shaded
- ``diagnosis_coherence.png``  coherence of residual and input per output, identification maneuvers
- ``diagnosis_time.png``       residual time histories of the maneuvers least white
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from ..diagnosis.analysis import Diagnosis, summary_rows
from ..diagnosis.residuals import DISPLAY, Residuals
from ..diagnosis.timeseries import DYN_BAND, clean_time_residuals
from ..diagnosis.trim_forces import ImpliedForces
from ..diagnosis.trim_shape import ShapeTest, shape_curve
from ..units import DEG, KT
from . import plots
from .identification import markdown_table

FIGURES = ("diagnosis_trim.png", "diagnosis_spectra.png", "diagnosis_coherence.png", "diagnosis_time.png")
ROLE_STYLE = {"identification": {"color": "tab:blue"}, "validation": {"color": "tab:orange"}}


def _unit(name):
    return DISPLAY.get(name, ("SI", 1.0))


def plot_trim_residuals(res: Residuals, diag: Diagnosis) -> Figure:
    """Trim residual per channel against airspeed, the residual beyond the identified parameters and the
    fitted shape with its verdict."""
    ch = list(res.trim_channels)
    fig = Figure(figsize=(7.5, 2.6 * len(ch) + 0.8), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(ch), 1, sharex=True))
    tr = res.trim
    level = (tr["source"].astype(str) == "level").to_numpy() if "source" in tr else np.ones(len(tr), bool)
    vgrid = np.linspace(0.0, max(float(tr["V"].max()), 1.0), 200)
    for ax, c in zip(axes, ch):
        unit, fac = _unit(c)
        e = tr[f"res_{c}"].to_numpy(dtype=float) * fac
        v = tr["V"].to_numpy(dtype=float) / KT
        ax.axhline(0.0, color="grey", linewidth=0.8)
        ax.plot(v[level], e[level], "o", color="black", markersize=5, label="residual, level-flight trims")
        if (~level).any():
            ax.plot(v[~level], e[~level], "s", color="black", markerfacecolor="none", markersize=7,
                    label="residual, maneuver start trims")
        title = c
        if c in diag.trim_shapes:
            t = ShapeTest(**diag.trim_shapes[c])
            if t.nuisance and t.adjusted:
                ax.plot(np.asarray(t.V) / KT, np.asarray(t.adjusted) * fac, "^", color="tab:blue", markersize=5,
                        alpha=0.8, label=f"beyond a shift of {', '.join(t.nuisance)}")
            if t.shape != "noise":
                ax.plot(vgrid / KT, shape_curve(t, vgrid) * fac, "-", color="tab:red", linewidth=1.6,
                        label=f"fitted shape: {t.shape}")
            title = (f"{c}: {t.description}" + (" beyond a parameter shift" if t.nuisance else "")
                     + f" (smallest p = {min(t.p_values.values()):.2g})")
        ax.set_title(title, fontsize=10)
        ax.set_ylabel(f"{c} residual [{unit}]")
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=7, loc="best")
    axes[-1].set_xlabel("airspeed [kt]")
    fig.suptitle(f"Trim residual (model - data) vs airspeed: {diag.label}")
    return fig


def plot_residual_spectra(diag: Diagnosis) -> Figure:
    """Welch PSD of every output's residual (nuisance removed), averaged per role."""
    outs = sorted({o for sp in diag.spectra.values() for o in sp.get("psd", {})},
                  key=lambda o: list(DISPLAY).index(o) if o in DISPLAY else 99)
    ncol = 3
    nrow = max(1, math.ceil(len(outs) / ncol))
    fig = Figure(figsize=(12, 3.0 * nrow + 0.8), layout="constrained")
    axes = np.array(fig.subplots(nrow, ncol, squeeze=False)).ravel()
    for ax, o in zip(axes, outs):
        unit, fac = _unit(o)
        for role, sp in diag.spectra.items():
            if o not in sp.get("psd", {}):
                continue
            f = np.asarray(sp["f"])
            p = np.asarray(sp["psd"][o]) * fac**2
            ax.semilogy(f[1:], p[1:], label=f"{role} (band ratio {sp['band_ratio'][o]:.2g})",
                        **ROLE_STYLE.get(role, {}))
        ax.axvspan(*DYN_BAND, color="grey", alpha=0.15)
        ax.set_title(o, fontsize=10)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel(f"PSD [{unit}$^2$/Hz]")
        ax.grid(True, alpha=0.3, which="both")
        ax.legend(fontsize=7)
    for ax in axes[len(outs):]:
        ax.set_visible(False)
    fig.suptitle(f"Residual spectra (nuisance removed; shaded: dynamics band {DYN_BAND[0]:g}-{DYN_BAND[1]:g} Hz): "
                 f"{diag.label}")
    return fig


def plot_coherence(diag: Diagnosis, role: str = "identification") -> Figure:
    """Coherence of each output's residual with the excited input, per maneuver of ``role``."""
    coh = pd.DataFrame(diag.coherence)
    outs = list(dict.fromkeys(coh["output"])) if len(coh) else []
    ncol = 3
    nrow = max(1, math.ceil(len(outs) / ncol))
    fig = Figure(figsize=(12, 3.0 * nrow + 1.0), layout="constrained")
    axes = np.array(fig.subplots(nrow, ncol, squeeze=False)).ravel()
    names = list(dict.fromkeys(coh.loc[coh["role"] == role, "maneuver"])) if len(coh) else []
    colors = {n: f"C{i % 10}" for i, n in enumerate(names)}
    for ax, o in zip(axes, outs):
        thr = []
        for n in names:
            cur = diag.coherence_curves.get(n, {})
            for key, C in cur.items():
                if key == "f" or not key.endswith(f":{o}"):
                    continue
                ax.plot(cur["f"], C, color=colors[n], linewidth=1.0, label=f"{n} ({key.split(':')[0]})")
            thr += list(coh.loc[(coh["maneuver"] == n) & (coh["output"] == o), "threshold"])
        if thr:
            ax.axhline(min(thr), color="black", linestyle=":", linewidth=1.0, label="zero-coherence threshold")
        ax.axvspan(*DYN_BAND, color="grey", alpha=0.12)
        ax.set_ylim(0, 1)
        ax.set_xlim(0, 5)
        ax.set_title(o, fontsize=10)
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("coherence [-]")
        ax.grid(True, alpha=0.3)
    for ax in axes[len(outs):]:
        ax.set_visible(False)
    if outs:
        h, lab = axes[0].get_legend_handles_labels()
        fig.legend(h, lab, loc="outside lower center", ncol=4, fontsize=7)
    fig.suptitle(f"Coherence of residual and input ({role} maneuvers): {diag.label}")
    return fig


def plot_time_residuals(res: Residuals, diag: Diagnosis, n_maneuvers: int = 3) -> Figure:
    """Residual time histories (raw and nuisance removed) of the ``n_maneuvers`` least white maneuvers."""
    w = pd.DataFrame(diag.whiteness)
    if len(w):
        worst = w.groupby("maneuver", sort=False)["p"].min().sort_values().index[:n_maneuvers]
    else:
        worst = res.maneuver_names()[:n_maneuvers]
    outs = list(res.outputs)
    names = list(worst)
    fig = Figure(figsize=(4.6 * max(len(names), 1) + 0.8, 1.6 * len(outs) + 1.2), layout="constrained")
    axes = np.array(fig.subplots(len(outs), max(len(names), 1), sharex="col", squeeze=False))
    if not names:
        return fig
    sub = res.time[res.time["maneuver"].isin(names)]
    clean, _ = clean_time_residuals(sub, outs)
    for j, n in enumerate(names):
        raw, cl = sub[sub["maneuver"] == n], clean[clean["maneuver"] == n]
        for i, o in enumerate(outs):
            unit, fac = _unit(o)
            ax = axes[i, j]
            ax.plot(raw["t"], raw[f"res_{o}"] * fac, color="grey", linewidth=0.9, label="raw residual")
            ax.plot(cl["t"], cl[f"res_{o}"] * fac, color="tab:red", linewidth=1.0, label="nuisance removed")
            ax.set_ylabel(f"{o} [{unit}]")
            ax.grid(True, alpha=0.3)
        axes[0, j].set_title(f"{n} ({raw['trim_speed'].iloc[0] / KT:.0f} kt, {raw['role'].iloc[0]})", fontsize=10)
        axes[-1, j].set_xlabel("time [s]")
    h, lab = axes[0, 0].get_legend_handles_labels()
    fig.legend(h, lab, loc="outside upper right", fontsize=8)
    fig.suptitle(f"Residual time histories (model - data) of the least white maneuvers: {diag.label}")
    return fig


def plot_input_path(diag: Diagnosis) -> Figure:
    """The input errors of the records the input-path terms move most (``Diagnosis.input_path["histories"]``): what
    the residual asks of each input channel alone (a piecewise-constant error, no dictionary:
    :func:`~pyomo_heli.diagnosis.input_path.asked_errors`) and what the selected terms give, in deg, each record's
    mean removed."""
    hist = (diag.input_path or {}).get("histories") or []
    chans = [c for c in ("col", "lon") if hist and f"fitted_{c}" in hist[0]]
    fig = Figure(figsize=(4.6 * max(len(hist), 1) + 0.8, 2.0 * max(len(chans), 1) + 1.2), layout="constrained")
    axes = np.array(fig.subplots(max(len(chans), 1), max(len(hist), 1), sharex="col", squeeze=False))
    terms = "; ".join(f"{t['channel']} += {t['estimate']:+.3g} x {t['signal']}" for t in diag.input_path["terms"]) \
        if diag.input_path else ""
    for j, h in enumerate(hist):
        for i, c in enumerate(chans):
            ax = axes[i, j]
            ax.plot(h["t"], np.degrees(h[f"asked_{c}"]), color="grey", linewidth=0.9,
                    label="asked by the residual (0.5 s steps, this channel alone)")
            ax.plot(h["t"], np.degrees(h[f"fitted_{c}"]), color="tab:red", linewidth=1.2, label="selected terms")
            ax.set_ylabel(f"{c} error [deg]")
            ax.grid(True, alpha=0.3)
        axes[0, j].set_title(h["maneuver"], fontsize=10)
        axes[-1, j].set_xlabel("time [s]")
    if hist:
        hd, lab = axes[0, 0].get_legend_handles_labels()
        fig.legend(hd, lab, loc="outside upper right", fontsize=8)
    fig.suptitle(f"Input errors the rotor would have to see (what it saw minus the record): {terms}", fontsize=10)
    return fig


# ---------------------------------------------------------------- the report
def _fmt(x, d=3):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{d}g}" if isinstance(x, (float, np.floating)) else str(x)


def record_bias_shapes(record_biases: dict) -> list[str]:
    """Markdown lines: for each output whose records disagree on its bias (``Diagnosis.record_biases``), the
    residual bias of the records at each trim speed against their mean, in display units."""
    L = []
    for o, t in record_biases.items():
        if not t["consistent"]:
            unit, fac = _unit(o)
            by = pd.DataFrame([{"trim speed [kt]": r["V"] / KT, f"bias - mean [{unit}]": r["shift"] * fac,
                                f"SE [{unit}]": r["se"] * fac, "records": r["records"]} for r in t["by_speed"]])
            L += [f"{o}: residual bias (model - data) of the records at each trim speed against their mean:", "",
                  markdown_table(by, digits=3), ""]
    return L


def record_bias_table(diag: Diagnosis) -> pd.DataFrame:
    """The record-bias tests with each output's common bias in its display unit (deg, deg/s, g, kt), the unit in a
    column beside it."""
    tab = diag.table("record_biases")
    if tab.empty:
        return tab
    units = [DISPLAY[o] for o in tab["output"]]
    tab["common"] = [c * fac for c, (_, fac) in zip(tab["common"], units)]
    tab.insert(list(tab.columns).index("common") + 1, "unit", [u for u, _ in units])
    return tab


def implied_forces_section(forces: ImpliedForces | dict, figure: str | None) -> list[str]:
    """The report section of the steady force and moment the trims ask for (one model, or label -> model); the
    figure's file name, or None where no figure was drawn."""
    many = forces if isinstance(forces, dict) else {forces.label: forces}

    def sigmas(f):
        return f"{f.sigma_source}: " + ", ".join(f"{c} {math.degrees(v):.3g} deg" for c, v in f.sigma.items())

    # each model's standard errors use its own noise estimate: one line for one model, else per model below
    L = ["## Steady force and moment the trims ask for", "",
         "At each recorded trim point, the force and moment the model would need to balance at the recorded "
         "controls and attitude (equation error at the trims; no library of effects): zero where the model "
         "trims as recorded. Standard errors from the trim channels' noise "
         + (f"({sigmas(next(iter(many.values())))})" if len(many) == 1 else "(each model's, below)")
         + "; `pyomo_heli/diagnosis/trim_forces.py`, docs/diagnosis.md. chi2 = sum (value / SE)^2 over the "
         "points; `beyond parameters`: after the least-squares fit of a shift of the identified parameters (what "
         "the trade-off of the Pareto choice leaves without any missing physics). The parameters were fitted to "
         "the same trims, so these p are pointers.", ""]
    if figure is not None:
        L += [f"![steady force and moment the trims ask for]({figure})", ""]
    for lab, f in many.items():
        L += [f"{lab}" + (f" (noise {sigmas(f)})" if len(many) > 1 else "") + ":", "",
              markdown_table(f.summary(), digits=4), ""]
    return L


def write_diagnosis_report(out_dir, res: Residuals, diag: Diagnosis, results_dir=None, command: str | None = None,
                           figure_format: str = "png", forces: ImpliedForces | None = None) -> Path:
    """Write the figures and ``diagnosis.md`` into ``out_dir``; return the path of ``diagnosis.md``. ``forces``: the
    steady force and moment the trims ask for (:func:`~pyomo_heli.diagnosis.trim_forces.implied_forces`), shown
    when given."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figs = {f"diagnosis_trim.{figure_format}": plot_trim_residuals(res, diag),
            f"diagnosis_spectra.{figure_format}": plot_residual_spectra(diag),
            f"diagnosis_coherence.{figure_format}": plot_coherence(diag),
            f"diagnosis_time.{figure_format}": plot_time_residuals(res, diag)}
    for name, fig in figs.items():
        fig.savefig(out / name, dpi=90)
    s = diag.settings
    L = ["# Residual diagnosis", ""]
    if command:
        L += [f"Produced by `{command}`.", ""]
    L += [f"- model: **{diag.label}**" + (f" from `{results_dir}`" if results_dir else ""),
          "- parameters (SI): " + ", ".join(f"{k} = {v:.6g}" for k, v in diag.parameters.items()),
          f"- config: `{diag.info.get('config', 'n/a')}`; dataset: `{diag.info.get('dataset', 'n/a')}`; "
          f"model extensions: {', '.join(diag.info.get('extensions', [])) or 'none (M0)'}",
          f"- residual = model - data; alpha = {s['alpha']:g}; whiteness tested at {s['test_rate_hz']:g} Hz; "
          f"trim-shape p-values from {s['n_mc']} seeded Monte Carlo draws (seed {s['seed']}). "
          f"Method: `docs/diagnosis.md`.", ""]
    L += ["## Findings", ""] + [f"- {f}" for f in diag.findings] + [""]
    rows = pd.DataFrame(summary_rows(diag))
    if len(rows):
        L += ["## Summary per channel", "", "RMS in display units; p = smallest p-value of the channel's tests.", "",
              markdown_table(rows, digits=4), ""]

    L += ["## Trim residuals against airspeed", "", f"![trim residuals](diagnosis_trim.{figure_format})", ""]
    trows = []
    for c, t in diag.trim_shapes.items():
        unit, fac = _unit(c)
        f = t["fit"]
        trows.append({"channel": c, "shape": t["shape"], **{f"p {k}": v for k, v in t["p_values"].items()},
                      "RMS": t["rms"] * fac, "RMS after shape": t["rms_after"] * fac, "unit": unit,
                      "bump centre [kt]": f["centre"] / KT if "centre" in f else np.nan,
                      "bump amplitude": f["amplitude"] * fac if "amplitude" in f else np.nan,
                      "runs z": t["runs"].get("z")})
    if trows:
        L += ["Shapes fitted by least squares; p-values of F against noise only (Monte Carlo); shape chosen by BIC "
              "when any p < alpha / shapes tested; n/a: shape not tested (absorbed by the parameter shift, "
              "see docs/diagnosis.md).", "", markdown_table(pd.DataFrame(trows), digits=3), ""]

    if forces is not None and len(forces.table):
        fig = plots.plot_implied_forces({forces.label: forces.table})
        fig.savefig(out / f"diagnosis_trim_forces.{figure_format}", dpi=90)
        L += implied_forces_section(forces, f"diagnosis_trim_forces.{figure_format}")

    w = pd.DataFrame(diag.whiteness)
    L += ["## Time-series residuals", ""]
    if len(w):
        piv = w.pivot_table(index=["role", "maneuver"], columns="output", values="p", sort=False).reset_index()
        inn = s.get("innovations")
        what = (f"innovations of {', '.join(inn['outputs'])} (the measured inputs' noise taken out, nuisance "
                "projected off; docs/diagnosis.md), residuals with the per-maneuver nuisance removed for any "
                "other output"
                if inn else "residuals with the per-maneuver nuisance removed")
        ib = w.loc[w["role"] == "identification", "bound"]
        ident_bound = _fmt(float(ib.iloc[0]), 2) if len(ib) else "none"
        L += [f"Ljung-Box p-values ({what}, at {s['test_rate_hz']:g} Hz; "
              f"white when p > alpha / number of tests of the role, bound {ident_bound} for identification):", "",
              markdown_table(piv, digits=2), "",
              f"![time residuals](diagnosis_time.{figure_format})", ""]
    if diag.record_biases:
        L += ["### Record biases", "", "Do the records agree on each output's bias (generalised least-squares bias per "
              "record under the innovations' covariance; chi-square of their spread, Bonferroni over the outputs; "
              "docs/diagnosis.md)?", "", markdown_table(record_bias_table(diag), digits=3), ""]
        L += record_bias_shapes(diag.record_biases)
    if diag.input_path:
        ip = diag.input_path
        rows = pd.DataFrame([{"": "selected", **t} for t in ip["terms"]]
                            + [{"": "not selected", **t} for t in sorted(ip["screen"], key=lambda r: -abs(r["z"]))[:4]])
        L += ["### Input path", "", "Do the input errors follow a signal of the flight (stepwise regression of each "
              "input channel's error on the measured inputs, the model's q, theta, TAS and the inputs' rates, "
              f"corrected for the input noise; level {ip['level']:.2g} per term; docs/diagnosis.md)? The error is what "
              "the rotor sees minus the recorded input, estimate in rad per signal unit (SI):", "",
              markdown_table(rows, digits=3), ""]
        if ip.get("histories"):
            fig = plot_input_path(diag)
            fig.savefig(out / f"diagnosis_input_path.{figure_format}", dpi=90)
            L += [f"![input errors]({'diagnosis_input_path.' + figure_format})", ""]
    if diag.spectra:
        L += ["### Spectra", "", f"![spectra](diagnosis_spectra.{figure_format})", "",
              "Band ratio = mean PSD in 0.1-2 Hz / mean PSD in 2-5 Hz (about 1 for white noise):", ""]
        br = pd.DataFrame({role: sp["band_ratio"] for role, sp in diag.spectra.items()}).T.reset_index(names="role")
        L += [markdown_table(br, digits=3), ""]
    coh = pd.DataFrame(diag.coherence)
    if len(coh):
        L += ["### Coherence with the inputs", "", f"![coherence](diagnosis_coherence.{figure_format})", ""]
        top = coh.sort_values("peak", ascending=False).head(8)
        L += ["Highest peak coherences (dynamics band):", "",
              markdown_table(top[["maneuver", "role", "output", "input", "peak", "f_peak", "threshold", "significant"]],
                             digits=3), ""]
    corr = pd.DataFrame(diag.correlations)
    if len(corr):
        corr = corr.dropna(subset=["r"])
        corr["|r|"] = corr["r"].abs()
        top = corr.sort_values("|r|", ascending=False).groupby(["kind", "role", "channel"], sort=False).head(2)
        top = top.sort_values(["kind", "role", "|r|"], ascending=[True, True, False])
        L += ["### Correlation with physical regressors", "",
              "Pearson r, two largest per channel (time: pooled per role at the test rate; descriptive, see "
              "docs/diagnosis.md). Regressors: V airspeed, mu advance ratio, chi wake skew angle, lambda_i inflow, "
              "q, theta, dq/dt, input increments dcol, dlon and their rates.", "",
              markdown_table(top[["kind", "role", "channel", "regressor", "r", "p", "n"]], digits=3), ""]
    nu = pd.DataFrame(diag.nuisance)
    if len(nu):
        cols = [c for c in nu.columns if c.startswith("offset_")]
        show = nu[["maneuver", "role"] + cols].copy()
        for c in cols:
            show[c.replace("offset_", "input offset ") + " [deg]"] = show.pop(c) / DEG
        L += ["### Nuisance removed per maneuver", "",
              "Constant input offsets estimated per maneuver (the replay starts from the first recorded input "
              "sample, whose noise acts as a constant input error); output biases are removed too.", "",
              markdown_table(show, digits=3), ""]
    if diag.problems:
        L += ["## Problems", ""] + [f"- {p}" for p in diag.problems] + [""]
    L += ["Machine-readable: `diagnosis.json`; residuals (unless `--no-residuals`): the `residuals_*` folder "
          "(time.csv.gz, trim.csv, meta.json; `Residuals.load`).", ""]
    path = out / "diagnosis.md"
    path.write_text("\n".join(L))
    return path
