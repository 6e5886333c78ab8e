"""Figures of an identification (paper Figs. 3, 5 and 6), each a function of result data.

Every function takes plain data (SI units, radians, m/s) and returns a
:class:`matplotlib.figure.Figure`; conversion to degrees, knots and g
happens here, at the edge, and every axis names its unit. The figures are
built without pyplot (no global state, no display needed): save them with
``fig.savefig(path)``.
"""
from __future__ import annotations

import math
from typing import Mapping, Sequence

import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from ..channels import DISPLAY_UNITS, OUTPUTS, TRIM_CHANNELS

#: display unit and SI -> display factor of every plotted quantity
UNITS = DISPLAY_UNITS
#: axis names (matplotlib mathtext)
SYMBOLS = {
    "q": "$q$",
    "theta": r"$\theta$",
    "n_x": "$n_x$",
    "n_z": "$n_z$",
    "TAS": "TAS",
    "beta_0": r"$\beta_0$",
    "col": r"$\theta_0$ (col)",
    "lon": r"$\theta_{1s}$ (lon)",
    "V": "airspeed",
}
DATA_STYLE = {"color": "black", "linewidth": 2.4, "alpha": 0.55, "label": "flight-test data", "zorder": 1}
#: default line styles of model curves, in the order the models are given
MODEL_STYLES = (
    {"color": "tab:red", "linestyle": "--", "linewidth": 1.4, "zorder": 4},
    {"color": "tab:blue", "linestyle": "-", "linewidth": 1.4, "zorder": 3},
    {"color": "tab:green", "linestyle": "-.", "linewidth": 1.3, "zorder": 5},
    {"color": "tab:purple", "linestyle": ":", "linewidth": 1.3, "zorder": 6},
)


def shown(name: str, values):
    """SI values of a quantity in its display unit."""
    return np.asarray(values, dtype=float) * UNITS[name][1]


def axis_label(name: str) -> str:
    return f"{SYMBOLS.get(name, name)} [{UNITS[name][0]}]"


def _styles(labels: Sequence[str], styles: Mapping[str, dict] | None) -> dict:
    styles = dict(styles or {})
    return {lab: {**MODEL_STYLES[i % len(MODEL_STYLES)], **styles.get(lab, {})} for i, lab in enumerate(labels)}


# ---------------------------------------------------------------- Fig. 3
def _label(ax, text, x, y, offset, arrow: bool = False, color="black") -> None:
    """A bold point label ``offset`` points away from (x, y), on a white box (and an arrow) so that it
    never hides a marker or the line."""
    ax.annotate(text, (float(x), float(y)), textcoords="offset points", xytext=offset, fontsize=13,
                fontweight="bold", color=color, ha="center", va="center", zorder=7,
                bbox=dict(boxstyle="round,pad=0.15", facecolor="white", edgecolor="none", alpha=0.85),
                arrowprops=dict(arrowstyle="-", color=color, lw=0.9, shrinkA=0, shrinkB=6) if arrow else None)


def plot_pareto_front(front: pd.DataFrame, utopia: Sequence[float], nadir: Sequence[float], chosen: Mapping | None,
                      direct: Mapping | None = None) -> Figure:
    """The Pareto front (paper Fig. 3): J_trim on x, J_time on y.

    ``front`` has one row per front point with columns ``kind`` (A, eps, B),
    ``J_time``, ``J_trim`` and ``success``; ``utopia`` and ``nadir`` are
    (J_time, J_trim); ``chosen`` and ``direct`` are point dicts with
    ``J_time``, ``J_trim`` (and ``success``). Left: the objectives as
    solved; right: the normalised objectives of Eq. 11, where the utopia
    point is the origin and the chosen point is the one closest to it.
    """
    fig = Figure(figsize=(12, 5.2), layout="constrained")
    ax_raw, ax_n = fig.subplots(1, 2)
    ok = front["success"].astype(bool) & np.isfinite(front["J_time"]) & np.isfinite(front["J_trim"])
    good = front[ok].sort_values("J_trim")
    bad = front[~ok & np.isfinite(front["J_time"]) & np.isfinite(front["J_trim"])]
    u_time, u_trim = float(utopia[0]), float(utopia[1])
    n_time, n_trim = float(nadir[0]), float(nadir[1])
    span_time = (n_time - u_time) if n_time > u_time else 1.0
    span_trim = (n_trim - u_trim) if n_trim > u_trim else 1.0

    def norm(j_time, j_trim):
        return ((np.asarray(j_trim, dtype=float) - u_trim) / span_trim,
                (np.asarray(j_time, dtype=float) - u_time) / span_time)

    for ax, tf in ((ax_raw, lambda jt, jr: (np.asarray(jr, dtype=float), np.asarray(jt, dtype=float))), (ax_n, norm)):
        x, y = tf(good["J_time"], good["J_trim"])
        ax.plot(x, y, "-o", color="tab:blue", markersize=5, linewidth=1.3, label="Pareto front (epsilon-constraint)",
                zorder=3)
        if len(bad):
            xb, yb = tf(bad["J_time"], bad["J_trim"])
            ax.plot(xb, yb, "x", color="grey", markersize=8, label="solve failed (not on the front)", zorder=3)
        for kind in ("A", "B"):
            row = good[good["kind"] == kind]
            if len(row):
                xa, ya = tf(row["J_time"].iloc[0], row["J_trim"].iloc[0])
                _label(ax, kind, xa, ya, (14, 10))
        xu, yu = tf(u_time, u_trim)
        ax.plot(float(xu), float(yu), "*", color="black", markersize=14, label="utopia point U", zorder=4)
        knee = [(float(xu), float(yu))]
        if chosen is not None:
            xc, yc = tf(chosen["J_time"], chosen["J_trim"])
            ax.plot(float(xc), float(yc), "o", markersize=13, markerfacecolor="none", markeredgecolor="tab:orange",
                    markeredgewidth=2.2, label="chosen point C (Eq. 11 on the front)", zorder=5)
            knee.append((float(xc), float(yc)))
        if direct is not None and all(np.isfinite([direct.get("J_time", np.nan), direct.get("J_trim", np.nan)])):
            xd, yd = tf(direct["J_time"], direct["J_trim"])
            lab = "Eq. 11 solved directly" + ("" if direct.get("success", True) else " (solve failed)")
            ax.plot(float(xd), float(yd), "D", color="tab:green", markersize=7, label=lab, zorder=6)
            knee.append((float(xd), float(yd)))
        ax.grid(True, alpha=0.3)
        ax.margins(0.08)
        # U and C sit close together at the knee of the front: their labels go up and to the right, on
        # arrows, clear of the markers (U's to the upper left, C's to the upper right)
        _label(ax, "U", xu, yu, (-28, 16), arrow=True)
        if chosen is not None:
            _label(ax, "C", xc, yc, (30, 26), arrow=True, color="tab:orange")

    ax_raw.set_xlabel(r"$J_\mathrm{trim}$ [-]")
    ax_raw.set_ylabel(r"$J_\mathrm{time}$ [-]")
    ax_raw.set_title("Pareto front (objectives as solved)")
    ax_raw.legend(fontsize=8, loc="best")
    ax_n.set_xlabel(r"$(J_\mathrm{trim} - J_\mathrm{trim}^U)\,/\,(J_\mathrm{trim}^N - J_\mathrm{trim}^U)$ [-]")
    ax_n.set_ylabel(r"$(J_\mathrm{time} - J_\mathrm{time}^U)\,/\,(J_\mathrm{time}^N - J_\mathrm{time}^U)$ [-]")
    ax_n.set_title("Normalised objectives (Eq. 11: C is closest to U)")
    if chosen is not None:
        xc, yc = norm(chosen["J_time"], chosen["J_trim"])
        r = float(math.hypot(float(xc), float(yc)))
        if math.isfinite(r) and r > 0:
            a = np.linspace(0, np.pi / 2, 100)
            ax_n.plot(r * np.cos(a), r * np.sin(a), ":", color="tab:orange", linewidth=1.0)
            ax_n.text(0.97, 0.97, f"distance of C to U: {r:.3f}", transform=ax_n.transAxes, fontsize=9,
                      ha="right", va="top", bbox=dict(boxstyle="round", facecolor="white", edgecolor="0.7"))
    ax_n.set_aspect("equal", adjustable="datalim")
    return fig


# ---------------------------------------------------------------- Fig. 5
def plot_trim_vs_speed(trims: pd.DataFrame, curves: Mapping[str, pd.DataFrame],
                       channels: Sequence[str] = TRIM_CHANNELS,
                       styles: Mapping[str, dict] | None = None, title: str | None = None) -> Figure:
    """Trim inputs and attitude against airspeed (paper Fig. 5).

    ``trims``: measured trim points, columns ``V`` [m/s] and the channels
    [rad], optional ``source`` (``"level"`` or the maneuver whose start
    trim the point is). ``curves``: model label -> DataFrame with ``V`` and
    the channels (NaN where the model could not be trimmed).
    """
    fig = Figure(figsize=(7.5, 2.6 * len(channels) + 0.8), layout="constrained")
    axes = np.atleast_1d(fig.subplots(len(channels), 1, sharex=True))
    st = _styles(list(curves), styles)
    if "source" in trims:
        level = trims["source"].astype(str) == "level"
    else:
        level = pd.Series(True, index=trims.index)
    for ax, ch in zip(axes, channels):
        for lab, df in curves.items():
            ax.plot(shown("V", df["V"]), shown(ch, df[ch]), label=lab, **st[lab])
        if level.any():
            ax.plot(shown("V", trims.loc[level, "V"]), shown(ch, trims.loc[level, ch]), "o", color="black",
                    markersize=5, label="data: level-flight trims", zorder=7)
        if (~level).any():
            ax.plot(shown("V", trims.loc[~level, "V"]), shown(ch, trims.loc[~level, ch]), "s", color="black",
                    markerfacecolor="none", markersize=7, label="data: maneuver start trims", zorder=7)
        ax.set_ylabel(axis_label(ch))
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel(axis_label("V"))
    axes[0].legend(fontsize=8, loc="best")
    if title:
        fig.suptitle(title)
    return fig


def plot_implied_forces(tables: Mapping[str, pd.DataFrame], title: str | None = None) -> Figure:
    """The steady force and moment each model lacks at the recorded trims, against airspeed, +- 2 standard errors
    (:func:`pyomo_heli.diagnosis.trim_forces.implied_forces`).

    ``tables``: model label -> its table (columns ``V [kt]``, ``dX [N]``, ``dZ [N]``, ``dM [N m]``, ``se ...``;
    optional ``source``: ``"level"`` or the maneuver whose start trim the point is, drawn hollow). Zero: the
    model balances at the recorded controls and attitude.
    """
    forces = (("dX [N]", "$\\Delta X$ [N] (forward)"), ("dZ [N]", "$\\Delta Z$ [N] (down)"),
              ("dM [N m]", "$\\Delta M$ [N m] (nose-up)"))
    fig = Figure(figsize=(7.5, 8.6), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    st = _styles(list(tables), None)
    n = max(len(tables), 1)
    for j, (lab, t) in enumerate(tables.items()):
        level = (t["source"].astype(str) == "level") if "source" in t else pd.Series(True, index=t.index)
        dv = (j - (n - 1) / 2) * 0.8  # side by side at one speed
        for ax, (col, _) in zip(axes, forces):
            for mask, face in ((level, st[lab]["color"]), (~level, "none")):
                if mask.any():
                    ax.errorbar(t.loc[mask, "V [kt]"] + dv, t.loc[mask, col], yerr=2 * t.loc[mask, f"se {col}"],
                                fmt="o" if face != "none" else "s", color=st[lab]["color"], markerfacecolor=face,
                                markersize=4, capsize=2, linewidth=0.9,
                                label=lab + ("" if face != "none" else " (maneuver start trims)"))
    for ax, (_, name) in zip(axes, forces):
        ax.axhline(0.0, color="black", linewidth=0.6)
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("airspeed [kt]")
    axes[0].legend(fontsize=8, loc="best")
    fig.suptitle(title or "Steady force and moment the trims ask for (+- 2 SE)")
    return fig


# ---------------------------------------------------------------- Fig. 6
def _ylim(data_vals: list, model_vals: list):
    """Y limits showing the data and the models, but not letting a diverging model flatten the data."""
    d = np.concatenate([np.asarray(v, dtype=float) for v in data_vals]) if data_vals else np.array([])
    m = np.concatenate([np.asarray(v, dtype=float) for v in model_vals]) if model_vals else np.array([])
    d, m = d[np.isfinite(d)], m[np.isfinite(m)]
    allv = np.concatenate([d, m])
    if not allv.size:
        return None
    lo, hi = float(allv.min()), float(allv.max())
    if d.size:
        dlo, dhi = float(d.min()), float(d.max())
        span = max(dhi - dlo, 1e-6 * max(abs(dlo), abs(dhi), 1.0))
        lo, hi = max(lo, dlo - 2 * span), min(hi, dhi + 2 * span)
    pad = 0.05 * (hi - lo) if hi > lo else 0.5 * max(abs(hi), 1e-3)
    return lo - pad, hi + pad


def theil_inequality(measured, predicted) -> float:
    """Theil's inequality coefficient of a prediction (0: perfect, 1: worst)::

        TIC = sqrt(mean((y_p - y_m)^2)) / (sqrt(mean(y_p^2)) + sqrt(mean(y_m^2)))

    over the samples where both are finite (the flight-test measure of fit; a TIC below about 0.25-0.3 is
    usually taken as a good match). Unit-free: the same in SI and display units."""
    m, p = np.asarray(measured, dtype=float), np.asarray(predicted, dtype=float)
    ok = np.isfinite(m) & np.isfinite(p)
    if not ok.any():
        return float("nan")
    m, p = m[ok], p[ok]
    den = math.sqrt(np.mean(p ** 2)) + math.sqrt(np.mean(m ** 2))
    return float(math.sqrt(np.mean((p - m) ** 2)) / den) if den > 0 else 0.0


def fit_metrics(t_data, y_data, t_model, y_model) -> tuple[float, float]:
    """(RMS of model minus data, TIC) of a simulated output against the measured one, the model taken at the
    data's sample times within its own time span (a diverged simulation is scored where it exists)."""
    t_data, y_data = np.asarray(t_data, dtype=float), np.asarray(y_data, dtype=float)
    t_model, y_model = np.asarray(t_model, dtype=float), np.asarray(y_model, dtype=float)
    keep = np.isfinite(t_model) & np.isfinite(y_model)
    if keep.sum() < 2:
        return float("nan"), float("nan")
    t_model, y_model = t_model[keep], y_model[keep]
    inside = (t_data >= t_model[0]) & (t_data <= t_model[-1]) & np.isfinite(y_data)
    if not inside.any():
        return float("nan"), float("nan")
    ym = np.interp(t_data[inside], t_model, y_model)
    yd = y_data[inside]
    return float(np.sqrt(np.mean((ym - yd) ** 2))), theil_inequality(yd, ym)


def plot_validation(maneuvers: Mapping[str, pd.DataFrame], predictions: Mapping[str, Mapping[str, pd.DataFrame | None]],
                    outputs: Sequence[str] = OUTPUTS,
                    inputs: Mapping[str, Sequence[str]] | None = None, styles: Mapping[str, dict] | None = None,
                    titles: Mapping[str, str] | None = None,
                    notes: Mapping[str, Sequence[str]] | None = None, column_width: float = 4.8,
                    metrics: bool = True) -> Figure:
    """Measured and predicted time histories of validation maneuvers (paper Fig. 6).

    ``metrics``: annotate every output panel with each model's RMS error (display unit) and Theil
    inequality coefficient (:func:`fit_metrics`), in the model's colour.

    ``maneuvers``: name -> measured DataFrame (SI, column ``t`` and the
    outputs). ``predictions``: model label -> {name -> simulated DataFrame,
    or None when the simulation failed}. ``inputs``: name -> input channels
    to show in a top row (the measured inputs, which every model replays).
    ``notes``: name -> remarks added to the column title (e.g. a model that
    diverged). One column per maneuver (``column_width`` inches wide), one row per output.
    """
    names = list(maneuvers)
    show_inputs = bool(inputs) and any(inputs.get(n) for n in names)
    rows = (["input"] if show_inputs else []) + list(outputs)
    ncol = max(len(names), 1)
    fig = Figure(figsize=(column_width * ncol + 0.8, 1.75 * len(rows) + 1.2), layout="constrained")
    axes = np.array(fig.subplots(len(rows), ncol, sharex="col", squeeze=False))
    st = _styles(list(predictions), styles)
    if not names:
        axes[0, 0].text(0.5, 0.5, "no validation maneuvers", ha="center", va="center", transform=axes[0, 0].transAxes)
        return fig
    for j, name in enumerate(names):
        data = maneuvers[name]
        t = data["t"].to_numpy(dtype=float)
        for i, row in enumerate(rows):
            ax = axes[i, j]
            if row == "input":
                for k, ch in enumerate(inputs.get(name, [])):
                    ax.plot(t, shown(ch, data[ch]), color=("black", "dimgray")[k % 2], linewidth=1.2,
                            label=f"{ch} (measured)")
                ax.set_ylabel("input [deg]")
                ax.legend(fontsize=7, loc="upper right")
                ax.grid(True, alpha=0.3)
                continue
            dvals, mvals = [], []
            if row in data:
                ax.plot(t, shown(row, data[row]), **DATA_STYLE)
                dvals.append(shown(row, data[row]))
            k_note = 0
            for lab, runs in predictions.items():
                sim = runs.get(name)
                if sim is None or row not in sim:
                    continue
                y = shown(row, sim[row])
                ax.plot(sim["t"].to_numpy(dtype=float), y, label=lab, **st[lab])
                mvals.append(y)
                if metrics and row in data:
                    rms, tic = fit_metrics(t, shown(row, data[row]), sim["t"].to_numpy(dtype=float), y)
                    ax.text(0.01, 0.97 - 0.13 * k_note, f"RMS {rms:.3g} {UNITS[row][0]}, TIC {tic:.3f}",
                            transform=ax.transAxes, ha="left", va="top", fontsize=6.5, color=st[lab].get("color"),
                            zorder=8, bbox=dict(boxstyle="square,pad=0.1", facecolor="white", edgecolor="none",
                                                alpha=0.7))
                    k_note += 1
            lim = _ylim(dvals, mvals)
            if lim is not None:
                ax.set_ylim(*lim)
            ax.set_ylabel(axis_label(row))
            ax.grid(True, alpha=0.3)
        failed = [lab for lab, runs in predictions.items() if runs.get(name) is None]
        remarks = ([("simulation failed: " + ", ".join(failed))] if failed else []) + list((notes or {}).get(name, []))
        head = (titles or {}).get(name, name)
        if remarks:
            head += "\n(" + "; ".join(remarks) + ")"
        axes[0, j].set_title(head, fontsize=10, color="firebrick" if remarks else "black")
        axes[-1, j].set_xlabel("time [s]")
    handles = [Line2D([], [], **DATA_STYLE)] + [Line2D([], [], label=lab, **st[lab]) for lab in predictions]
    title = "panels: RMS of model - data, TIC = Theil inequality coefficient" if metrics else None
    fig.legend(handles=handles, loc="outside upper center", ncol=min(len(handles), 2 * ncol), fontsize=9,
               title=title, title_fontsize=8)
    return fig
