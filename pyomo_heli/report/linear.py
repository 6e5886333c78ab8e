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
from ..pareto.result import IdentificationResult, ResultFileError, check_point_record, is_number
from ..physics.model import INPUTS, OUTPUTS
from ..simulation.linearize import linearize_float
from .identification import (_display, markdown_table, nadir_rule_line, parameters_in_display_units,
                             placement_line, read_truth, read_truth_effects)
from .linearization import gain_unit

ESTIMATES = (("time-domain (A)", "C0", "--"), ("bi-objective", "C2", "-."), ("tri-objective", "C3", "-"))


# ---------------------------------------------------------------- checks of the results folder and config
#: columns of frequency_responses.csv (written by dataset.frequency_response.save_responses); 'maneuvers' optional
RESPONSE_COLUMNS = ("speed", "output", "input", "omega", "T_re", "T_im", "coherence", "input_power", "coherent")
#: columns of front.csv the report plots
FRONT_COLUMNS = ("kind", "success", "J_time", "J_trim", "J_linear")
_OBJECTIVE_KEYS = ("index", "kind", "J_time", "J_trim", "J_linear")
_TRUE, _FALSE = {"true", "1"}, {"false", "0"}
MAX_LISTED = 5


def _rows_values(idx, values) -> str:
    """'row 3 ('x')' / 'rows 3 ('x'), 9 ('y'), ...' from 0-based data-row indices (reported 1-based)."""
    shown = ", ".join(f"{i + 1} ({values[i]!r})" for i in idx[:MAX_LISTED])
    return f"row{'s' if len(idx) > 1 else ''} {shown}{', ...' if len(idx) > MAX_LISTED else ''}"


def _read_table(path: Path, what: str) -> pd.DataFrame:
    """A CSV table of the results folder as text cells; ResultFileError naming the file if unreadable or empty."""
    if path.is_dir():
        raise ResultFileError(f"{path} is a directory, expected a CSV file ({what})")
    if not path.is_file():
        raise ResultFileError(f"{path}: file not found ({what}); is this a tri-objective results folder?")
    try:
        df = pd.read_csv(path, dtype=str, keep_default_na=False)
    except pd.errors.EmptyDataError:
        raise ResultFileError(f"{path}: empty file, expected a CSV table of {what}") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise ResultFileError(f"{path}: not a readable CSV table: {str(exc).strip().splitlines()[0]}") from None
    if df.empty:
        raise ResultFileError(f"{path}: no data rows (header only), expected {what}")
    return df


def _missing_columns(df: pd.DataFrame, path: Path, required) -> None:
    missing = [c for c in required if c not in df.columns]
    if missing:
        raise ResultFileError(f"{path}: column{'s' if len(missing) > 1 else ''} "
                              f"{', '.join(repr(c) for c in missing)} missing "
                              f"(columns: {', '.join(map(str, df.columns))})")


def _numbers(df: pd.DataFrame, path: Path, col: str, finite=None) -> np.ndarray:
    """Column ``col`` as floats; ResultFileError naming file, column and rows for text or (where ``finite``,
    a row mask, or everywhere when None) empty/non-finite cells."""
    raw = df[col].astype(str).str.strip().to_numpy()
    values = pd.to_numeric(pd.Series(raw), errors="coerce").to_numpy(dtype=float)
    text = [i for i, (r, v) in enumerate(zip(raw, values)) if np.isnan(v) and r.lower() not in ("", "nan")]
    if text:
        raise ResultFileError(f"{path}: column '{col}': non-numeric value{'s' if len(text) > 1 else ''} "
                              f"({_rows_values(text, raw)})")
    need = np.ones(len(raw), bool) if finite is None else np.asarray(finite, bool)
    bad = [int(i) for i in np.flatnonzero(need & ~np.isfinite(values))]
    if bad:
        raise ResultFileError(f"{path}: column '{col}': empty or non-finite value{'s' if len(bad) > 1 else ''} "
                              f"({_rows_values(bad, raw)})")
    return values


def _booleans(df: pd.DataFrame, path: Path, col: str) -> np.ndarray:
    raw = df[col].astype(str).str.strip().to_numpy()
    low = [r.lower() for r in raw]
    bad = [i for i, r in enumerate(low) if r not in _TRUE | _FALSE]
    if bad:
        raise ResultFileError(f"{path}: column '{col}': value{'s' if len(bad) > 1 else ''} neither True nor False "
                              f"({_rows_values(bad, raw)})")
    return np.array([r in _TRUE for r in low])


def read_front(out: Path) -> pd.DataFrame:
    """front.csv of a tri-objective folder with the plotted columns checked (success as bool, J_* as floats)."""
    path = out / "front.csv"
    df = _read_table(path, "front points")
    _missing_columns(df, path, FRONT_COLUMNS)
    front = pd.read_csv(path)
    front["success"] = _booleans(df, path, "success")
    for col in ("J_time", "J_trim", "J_linear"):
        front[col] = _numbers(df, path, col, finite=front["success"].to_numpy())
    return front


def read_responses(out: Path) -> list:
    """frequency_responses.csv checked cell by cell, then loaded (``load_responses``)."""
    path = out / "frequency_responses.csv"
    df = _read_table(path, "frequency responses")
    _missing_columns(df, path, RESPONSE_COLUMNS)
    coherent = _booleans(df, path, "coherent")
    for col in ("speed", "omega", "coherence", "input_power"):
        _numbers(df, path, col)
    for col in ("T_re", "T_im"):  # outside the coherent band an estimate may be undefined
        _numbers(df, path, col, finite=coherent)
    for col, names in (("output", OUTPUTS), ("input", INPUTS)):
        raw = df[col].astype(str).str.strip().to_numpy()
        bad = [i for i, v in enumerate(raw) if v not in names]
        if bad:
            raise ResultFileError(f"{path}: column '{col}': not a model {col} ({_rows_values(bad, raw)}); "
                                  f"use one of {', '.join(names)}")
    speed = _numbers(df, path, "speed")
    neg = [int(i) for i in np.flatnonzero(speed < 0)]
    if neg:
        raise ResultFileError(f"{path}: column 'speed': negative trim speed [m/s] "
                              f"({_rows_values(neg, df['speed'].to_numpy())})")
    return load_responses(path)


def check_tri_objective(out: Path, cfg, result: IdentificationResult) -> None:
    """The folder is a complete tri-objective run and ``cfg`` is a tri-objective config freeing its parameters.

    ResultFileError (a ValueError) naming chosen.json and the key; ValueError naming the config and the folder
    when they do not belong together.
    """
    ch = out / "chosen.json"
    objectives = result.info.get("objectives")
    if not (isinstance(objectives, list) and "linear" in objectives):
        got = "missing" if objectives is None else f"{objectives!r}"
        raise ResultFileError(f"{out}: not a tri-objective results folder ({ch} key 'info.objectives' is "
                              f"{got}, expected ['time', 'trim', 'linear']); report-linear needs the "
                              "output of identify with [objectives] use = ['time', 'trim', 'linear'] (identify "
                              "writes the report of a bi-objective run itself)")
    if "linear" not in cfg.objectives:
        raise ValueError(f"config {cfg.path} is not tri-objective ([objectives] use = "
                              f"{list(cfg.objectives)}) but results folder {out} is ({objectives}): give the "
                              "config the results came from")
    have, want = list(result.parameters), [f.name for f in cfg.free]
    if sorted(have) != sorted(want):
        raise ValueError(f"config {cfg.path} frees {', '.join(want) or 'nothing'} but results folder {out} "
                              f"holds {', '.join(have) or 'nothing'}: give the config the results came from")
    bi = result.info.get("bi_objective")
    if not isinstance(bi, dict) or "chosen" not in bi:
        raise ResultFileError(f"{ch}: key 'info.bi_objective.chosen' is missing (the bi-objective choice of a "
                              "tri-objective run)")
    check_point_record(bi["chosen"], have, ch, "info.bi_objective.chosen", finite=True)
    if result.chosen is None:
        raise ResultFileError(f"{ch}: key 'chosen' is null (no front point converged): nothing to report")
    points = (("chosen", ch, result.chosen), ("info.bi_objective.chosen", ch, bi["chosen"]),
              (None, out / "time_domain.json", result.time_domain), ("direct", ch, result.direct))
    for key, file, point in points:
        if point is None:
            continue
        for k in _OBJECTIVE_KEYS:
            v = point.get(k)
            if v is None or (k != "kind" and not is_number(v)):
                where = f"{key}.{k}" if key else k
                raise ResultFileError(f"{file}: key '{where}' must be {'a string' if k == 'kind' else 'a number'}, "
                                      f"got {v!r}")
    for key, ok in (("grid", lambda v: isinstance(v, list) and len(v) == 2 and all(is_number(x) for x in v)),
                    ("total_time", is_number), ("failed_points", is_number)):
        if not ok(result.info.get(key)):
            raise ResultFileError(f"{ch}: key 'info.{key}' is missing or malformed, got {result.info.get(key)!r}")
    for key in ("utopia", "nadir"):
        if len(getattr(result, key)) != 3:
            raise ResultFileError(f"{ch}: key '{key}' must hold the 3 objectives (J_time, J_trim, J_linear), "
                                  f"got {list(getattr(result, key))}")


def truth_lines(params: pd.DataFrame, cfg, label: str = "tri-objective", limit: float = 2.0) -> list[str]:
    """Which parameters of the ``label`` estimate lie within ``limit`` standard errors of the truth, and, for those
    beyond, the effects of the data's truth model (``truth.json``) that the identification model lacks: a model
    error, which the standard errors (noise only) do not count. Empty without truth or standard errors."""
    col = f"{label} error/SE"
    if col not in params:
        return []
    rated = [(r.parameter, float(r[col])) for _, r in params.iterrows() if np.isfinite(r[col])]
    ok = [f"{n} ({z:+.2g})" for n, z in rated if abs(z) <= limit]
    off = [f"{n} ({z:+.2g})" for n, z in rated if abs(z) > limit]
    lines = [f"Against the truth, the {label} estimate in standard errors: within {limit:g}: "
             f"{', '.join(ok) or 'none'}; beyond: {', '.join(off) or 'none'}."]
    if off:
        have = {e.name for e in getattr(cfg.model, "extensions", ())}
        lacking = [n for n in (read_truth_effects(cfg.dataset) or {}) if n not in have]
        lines[0] += (f" The data's truth model has {', '.join(lacking)} (truth.json), which the identification model "
                     f"lacks: a model error, not counted in the standard errors (measurement noise only), that the "
                     f"noise alone would not explain." if lacking else
                     " The identification model has every effect of the data's truth model: no model error of that "
                     "kind explains it.")
    return [*lines, ""]


def estimates(result: IdentificationResult) -> dict[str, dict]:
    """Label -> free parameter values (SI) of the time-domain, bi- and tri-objective choices."""
    return {"time-domain (A)": result.time_domain["parameters"],
            "bi-objective": result.info["bi_objective"]["chosen"]["parameters"],
            "tri-objective": result.chosen["parameters"]}


def standard_errors(cfg, est: dict[str, dict], data=None) -> dict[str, dict]:
    """Label -> parameter -> Cramer-Rao standard error (SI; nan at a bound) of each estimate.

    The information is that of the time series and the trims at the estimate
    (:mod:`pyomo_heli.uncertainty.cramer_rao`): the time-domain estimate A from the time series alone, the
    bi-objective choice from the sandwich of the weighted sum it is stationary for (as ``pyomo-heli
    identify`` gives it), the tri-objective choice with the bi-objective choice's weights at its own
    estimate. The frequency responses' information is not counted (a tri-objective point is stationary
    for a sum with J_linear, whose curvature this does not hold), so every SE is that of the data the
    two-objective fit also has.
    """
    from ..nlp.identification import identification_data
    from ..uncertainty.cramer_rao import cramer_rao
    from ..uncertainty.front import config_information

    data = data if data is not None else identification_data(cfg)
    out, weights = {}, None
    for label, p in est.items():
        info = config_information(cfg, data, p)
        if label == "time-domain (A)":
            u = cramer_rao(info, cfg.free, kind="A")
        elif label == "bi-objective":
            u = cramer_rao(info, cfg.free, kind="eps")
            weights = u.weights
        else:
            u = cramer_rao(info, cfg.free, kind="eps", weights=weights)
        out[label] = dict(u.se)
    return out


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


# ---------------------------------------------------------------- linear model: labelled matrices and modes
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


def plot_bode(responses, curves: dict, omega: np.ndarray, coherence_min: float = 0.9) -> Figure:
    """Gain, phase and coherence per response: data (coherent band highlighted) and model curves;
    ``coherence_min``: the band's coherence threshold, drawn on the coherence panel."""
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
        axc.axhline(coherence_min, color="grey", lw=0.8)
        axg.set_title(r.label)
        axg.set_ylabel(f"gain [dB re 1 {gain_unit(r.output, r.input)}]")
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


def write_linear_report(out_dir, cfg, warn=None, figure_format: str = "png", standard_error: bool = True) -> Path:
    """Figures and ``report_linear.md`` of a tri-objective results folder; the folder must agree with ``cfg``
    (:func:`pyomo_heli.provenance.check_results_match`; ``warn`` gets its notes on records the folder lacks).
    ``standard_error``: the estimates' Cramer-Rao standard errors (:func:`standard_errors`) in the table."""
    from ..provenance import check_results_match

    out = Path(out_dir)
    result = IdentificationResult.load(out)
    check_tri_objective(out, cfg, result)
    check_results_match(cfg, result, out, **({"warn": warn} if warn else {}))
    front = read_front(out)
    responses = read_responses(out)
    truth = read_truth(cfg.dataset)
    est = estimates(result)
    # each estimate in the config's model; "truth" is the model the data were generated with (its effects and every
    # parameter of truth.json), as the identification report's truth prediction
    sets = {label: (cfg.model, p) for label, p in est.items()}
    if truth is not None:
        from ..flighttest.generate import truth_model_of

        sets["truth"] = (truth_model_of(cfg.dataset), {})
    omega = np.geomspace(0.3, 30, 200)
    curves = {label: model_curves(model, p, responses, omega) for label, (model, p) in sets.items()}
    fig = plot_front_projections(front, result)
    fig.savefig(out / f"front_projections.{figure_format}", dpi=110)
    lin = cfg.linear
    fig = plot_bode(responses, curves, omega, coherence_min=(lin.composite.coherence_min
                                                             if lin.weighting == "tischler_remple"
                                                             else lin.spectral.coherence_min))
    fig.savefig(out / f"bode.{figure_format}", dpi=110)
    band_curves = {label: [model_curves(model, p, [r], r.band().omega)[0] for r in responses]
                   for label, (model, p) in sets.items()}
    errs = band_errors(responses, band_curves)
    errs.to_csv(out / "band_errors.csv", index=False, float_format="%.6g")

    se = standard_errors(cfg, est) if standard_error else {}
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
            if label in se:
                row[f"{label} SE"] = se[label][name] * fac
                if "truth" in row:
                    row[f"{label} error/SE"] = (p[name] * fac - row["truth"]) / row[f"{label} SE"] \
                        if se[label][name] > 0 else float("nan")
        rows.append(row)
    params = pd.DataFrame(rows)
    params.to_csv(out / "parameters_tri.csv", index=False, float_format="%.6g")
    objs = pd.DataFrame([{"point": label, **{k: d[k] for k in ("index", "kind", "J_time", "J_trim", "J_linear")}}
                         for label, d in (("time-domain (A)", result.time_domain),
                                          ("bi-objective", result.info["bi_objective"]["chosen"]),
                                          ("tri-objective", result.chosen), ("Eq. 11 direct (3 obj.)", result.direct))
                         if d is not None])
    shown = front.drop(columns=[c for c in front.columns if c.startswith("cold_") or c in ("warm_start",)],
                       errors="ignore")
    # the parameters in display units with their unit in the header, as every table of the report; a point that
    # did not converge has no estimate (its last iterate is no value to read)
    shown, _ = parameters_in_display_units(shown, cfg.model, result.parameters,
                                           keep=shown["success"].astype(bool) if "success" in shown else None)
    text = [f"# Tri-objective identification: {cfg.path.name}", "",
            f"Objectives {', '.join(result.info['objectives'])}; grid {result.info['grid'][0]} (J_trim) x "
            f"{result.info['grid'][1]} (J_linear); total time {result.info['total_time']:.0f} s; "
            f"{result.info['failed_points']} point(s) not converged"
            + (f", {result.info['infeasible_points']} of them infeasible (status `infeasible`)"
               if result.info.get("infeasible_points") else "") + ".", "",
            *([placement_line(pl, "on the anchors and a coarse grid"), ""] if (pl := result.info.get("placement"))
              else []),
            "## Estimates (display units)", "", markdown_table(params, 5), "",
            *(["SE: Cramer-Rao standard error from the time series and trims at the estimate (A: time series; "
               "bi: the weighted sum it is stationary for; tri: the bi choice's weights; the frequency responses' "
               "information not counted); error/SE = (estimate - truth) / SE.", ""] if se else []),
            *truth_lines(params, cfg),
            "## Objective values of the choices", "", markdown_table(objs, 6), "",
            f"utopia (J_time, J_trim, J_linear) = {tuple(round(v, 6) for v in result.utopia)}, "
            f"nadir = {tuple(round(v, 6) for v in result.nadir)}", "",
            *([line, ""] if (line := nadir_rule_line(result.info.get("eq11_by_nadir"))) else []),
            "## Frequency-response errors in the coherent band", "", markdown_table(errs, 4), "",
            f"![front](front_projections.{figure_format})", "", f"![bode](bode.{figure_format})", "",
            "## Front", "", markdown_table(shown, 6), ""]
    path = out / "report_linear.md"
    path.write_text("\n".join(text))
    return path
