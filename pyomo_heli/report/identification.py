"""The report of an identification run: figures, tables and error metrics.

:func:`write_report` reads a results folder (``front.csv``, ``chosen.json``,
``time_domain.json``, see :class:`~pyomo_heli.pareto.result.IdentificationResult`)
and writes next to them:

- ``pareto_front.png``  the front, anchors A and B, utopia U, chosen C, direct Eq. 11 point (paper Fig. 3)
- ``trim_vs_speed.png`` trim col, lon, theta vs speed: data and both models (paper Fig. 5)
- ``validation.png``    validation maneuvers: data and both models (paper Fig. 6)
- ``parameters.md``, ``parameters.csv``  the parameter table (paper Tables 2-3)
- ``metrics.json``      the RMS errors (SI) and every simulation problem, machine-readable
- ``report.md``         all of the above, linked, with the front table

Model predictions come from :func:`pyomo_heli.simulation.replay.predict`, independently of the
NLP, with the float model: trims by continuation from hover, maneuvers from the model's own trim at
the maneuver's trim speed with inputs = model trim + measured increments, as the identification
does. A trim or simulation that fails is recorded and reported, never raised; this module only
formats.
``truth.json`` of the dataset is read only here, for the truth column.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd

from ..channels import OUTPUTS, TRIM_CHANNELS
from ..dataset import load_flight_test
from ..nlp.identification import validation_maneuvers
from ..pareto.epsilon import utopia_distance_n
from ..pareto.result import IdentificationResult, write_json
from ..physics.model import HelicopterModel
from ..simulation.replay import Prediction, predict
from ..units import KT
from . import plots

#: outputs compared on the validation maneuvers (all recorded time outputs)
VALIDATION_OUTPUTS = OUTPUTS
#: speeds of the model trim curves [m/s]: 0 .. 120 kt every 2.5 kt
CURVE_SPEEDS = tuple(np.arange(0.0, 120.0 + 1e-9, 2.5) * KT)
TIME_DOMAIN = "time-domain (A)"
MULTI_OBJECTIVE = "multi-objective (C)"


def shown_path(path) -> str:
    """A path as a report shows it: relative to the working directory when it lies inside it (a checkout's
    ``data/...``, so a committed report names no machine's folders), else as given."""
    try:
        return str(Path(path).resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(path)


def _rms(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


def validation_rms(pred: Prediction, maneuvers, outputs=VALIDATION_OUTPUTS) -> dict:
    """RMS of data minus model per maneuver and output (SI), plus ``"all"`` pooling every maneuver.

    A failed simulation gives None for that maneuver (and is left out of ``"all"``).
    """
    out, pooled = {}, {o: [] for o in outputs}
    for mv in maneuvers:
        sim = pred.maneuvers.get(mv.name)
        if sim is None:
            out[mv.name] = None
            continue
        row = {}
        for o in outputs:
            if o in mv.data and o in sim:
                e = mv.data[o].to_numpy(dtype=float) - sim[o].to_numpy(dtype=float)
                row[o] = _rms(e)
                pooled[o].append(e)
            else:
                row[o] = None
        out[mv.name] = row
    out["all"] = {o: (_rms(np.concatenate(v)) if v else None) for o, v in pooled.items()}
    return out


def trim_rms(pred: Prediction, trims: pd.DataFrame, channels=TRIM_CHANNELS) -> dict:
    """RMS of data minus model trim per channel (SI) over all trim points, the level ones and the
    maneuver start ones; points the model could not trim are counted in ``n_failed`` and left out."""
    model = pred.trim_table(trims["V"])
    level = (trims["source"].astype(str) == "level").to_numpy() if "source" in trims else np.ones(len(trims), bool)
    ok = np.isfinite(model[list(channels)].to_numpy(dtype=float)).all(axis=1)
    out = {"n_points": int(len(trims)), "n_failed": int((~ok).sum())}
    for group, mask in (("all", np.ones(len(trims), bool)), ("level", level), ("maneuver_start", ~level)):
        m = mask & ok
        out[group] = {c: (_rms(trims[c].to_numpy(dtype=float)[m] - model[c].to_numpy(dtype=float)[m])
                          if m.any() else None) for c in channels}
    return out


def truth_prediction(dataset: str | Path, trim_speeds=(), maneuvers=()) -> Prediction:
    """:func:`predict` with the truth model of a generated flight test (M0 + the effects of its ``truth.json`` at
    the truth parameters, :func:`~pyomo_heli.flighttest.generate.truth_model_of`). FileNotFoundError without
    ``truth.json``. Evaluation only."""
    from ..flighttest.generate import truth_model_of

    return predict("truth", truth_model_of(dataset), {}, list(trim_speeds), list(maneuvers))


def truth_model_errors(dataset: str | Path, maneuvers=(), trims: pd.DataFrame | None = None) -> dict:
    """The truth model's errors (SI): ``trim_rms`` (:func:`trim_rms`) against ``trims`` (the dataset's own by
    default) and ``maneuver_rms`` (:func:`validation_rms`) on ``maneuvers`` (prepared records of the dataset, e.g.
    the validation ones), with the ``problems`` of its replay.

    The truth model at the truth parameters leaves only the sensor noise and the trims' offsets: the floor below
    which no identified model's errors can be expected to fall. FileNotFoundError without ``truth.json``.
    """
    if trims is None:
        trims = load_flight_test(dataset).trims.reset_index(drop=True)
    pred = truth_prediction(dataset, trims["V"], maneuvers)
    return {"trim_rms": trim_rms(pred, trims), "maneuver_rms": validation_rms(pred, maneuvers),
            "problems": pred.problems}


# ---------------------------------------------------------------- tables
def _display(model: HelicopterModel, name: str) -> tuple[str, float]:
    spec = model.parameters.spec(name)
    return (spec.display[0], spec.display[1]) if spec.display else (spec.unit, 1.0)


def read_truth(dataset: Path) -> dict | None:
    """Truth parameters (SI) of a synthetic dataset, or None if it has no ``truth.json``."""
    f = Path(dataset) / "truth.json"
    if not f.is_file():
        return None
    with open(f) as fh:
        return json.load(fh)["parameters"]


def read_truth_effects(dataset: Path) -> dict | None:
    """Truth effects of a synthetic dataset (name -> their parameters, SI), or None without ``truth.json``."""
    f = Path(dataset) / "truth.json"
    if not f.is_file():
        return None
    with open(f) as fh:
        return json.load(fh).get("effects", {})


def parameter_table(result: IdentificationResult, cfg, truth: dict | None = None) -> pd.DataFrame:
    """Parameters in display units: initial, time-domain, multi-objective, Eq. 11 direct (+ truth and errors). A
    point whose solve did not converge (a failed direct solve, a failed anchor A) is NaN ("n/a"): its last iterate is
    not an estimate."""
    initial = {f.name: f.initial for f in cfg.free}

    def value(point, name):
        return point["parameters"][name] if point and point.get("success", True) else np.nan

    rows = []
    for name in result.parameters:
        unit, fac = _display(cfg.model, name)
        row = {"parameter": name, "unit": unit,
               "initial": initial.get(name, cfg.model.parameters[name]) * fac,
               "time-domain": value(result.time_domain, name) * fac,
               "multi-objective": value(result.chosen, name) * fac,
               "Eq. 11 direct": value(result.direct, name) * fac}
        if truth is not None:
            tv = truth.get(name)
            row["truth"] = tv * fac if tv is not None else np.nan
            for col in ("time-domain", "multi-objective", "Eq. 11 direct"):
                ok = tv is not None and tv != 0 and math.isfinite(row[col])
                row[f"{col} error %"] = 100.0 * (row[col] - row["truth"]) / abs(row["truth"]) if ok else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def _fmt(x, digits=6) -> str:
    if x is None:
        return "n/a"
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        if math.isnan(x):
            return "n/a"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        return f"{x:.{digits}g}"
    return str(x)


def markdown_table(df: pd.DataFrame, digits: int = 6, formats: dict | None = None) -> str:
    formats = formats or {}
    head = "| " + " | ".join(str(c) for c in df.columns) + " |"
    sep = "|" + "|".join("---" for _ in df.columns) + "|"
    lines = [head, sep]
    for _, r in df.iterrows():
        cells = []
        for c in df.columns:
            v = r[c]
            cells.append(formats[c](v) if c in formats else _fmt(v, digits))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def parameters_in_display_units(frame: pd.DataFrame, model: HelicopterModel, names,
                                keep: pd.Series | None = None) -> tuple[pd.DataFrame, list[str]]:
    """A copy of ``frame`` (a front's rows) with each parameter column of ``names`` in its display unit and the
    unit in its header (``name [unit]``), and those headers; rows where ``keep`` is False get no value (a point
    that did not converge has no estimate)."""
    out, headers = frame.copy(), []
    for name in names:
        if name in out:
            unit, fac = _display(model, name)
            col = out[name].astype(float) * fac
            out[name] = col if keep is None else col.where(keep)
            headers.append(f"{name} [{unit}]")
            out = out.rename(columns={name: headers[-1]})
    return out, headers


def front_table(result: IdentificationResult, model: HelicopterModel) -> pd.DataFrame:
    """front.csv with parameters in display units."""
    f, params = parameters_in_display_units(result.front, model, result.parameters)
    cols = ([c for c in ("index", "kind", "epsilon", "J_time", "J_trim") if c in f] + params
            + [c for c in ("success", "status", "iterations", "wall_time", "utopia_distance") if c in f])
    return f[cols].rename(columns={"wall_time": "wall time [s]"})


def utopia_distance_of(result: IdentificationResult, point: dict) -> float | None:
    """Eq. 11: distance of a point to the utopia point, objectives normalised by nadir - utopia."""
    try:
        d = float(utopia_distance_n([[point[k] for k in ("J_time", "J_trim")]], result.utopia[:2], result.nadir[:2])[0])
    except (KeyError, TypeError, ValueError):
        return None
    return d if math.isfinite(d) else None


def nadir_rule_line(choices) -> str | None:
    """The Eq. 11 choice under each nadir rule (chosen.json ``info.eq11_by_nadir``), None if not recorded."""
    if not choices:
        return None
    return "Eq. 11 choice by nadir rule: " + "; ".join(
        f"{rule}: point {c['index']} ({c['kind']}), nadir {tuple(float(f'{v:.6g}') for v in c['nadir'])}, "
        f"distance {_fmt(c['distance'], 4)}" for rule, c in choices.items())


def mean_interior_iterations(front: pd.DataFrame, column: str = "iterations") -> float | None:
    """Mean Ipopt iterations (``column``) of the interior front points, None without any; a solve that raised
    records -1 (no count), which is left out."""
    if column not in front:
        return None
    its = pd.to_numeric(front.loc[front["kind"] == "eps", column], errors="coerce").dropna()
    its = its[its >= 0]
    return float(its.mean()) if len(its) else None


def mean_cold_iterations(front: pd.DataFrame) -> float | None:
    """Mean iterations of the cold re-solves of the interior points ([pareto] cold_check), None without them."""
    return mean_interior_iterations(front, "cold_iterations")


def _mean_col(front: pd.DataFrame, col: str) -> float | None:
    if col not in front:
        return None
    v = pd.to_numeric(front.loc[front["kind"] == "eps", col], errors="coerce").dropna()
    return float(v.mean()) if len(v) else None


def _shown_rms(name: str, v) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{float(plots.shown(name, v)):.4g}"


# ---------------------------------------------------------------- orchestration
def _save(fig, path: Path) -> None:
    fig.savefig(path, dpi=120)


def placement_line(pl: dict, first: str = "by normalised arc length") -> str:
    """One sentence on an adaptive epsilon placement (``chosen.json`` ``info.placement``): solves, convergence,
    and the direct Eq. 11 solve's distance from C. ``first``: what placed the points before the refinement."""
    last = (pl.get("rounds") or [{}])[-1]
    return (f"Adaptive epsilon placement: {pl['solves']} front solves, anchors included "
            f"({pl['arc_length_solves']} "
            f"{first}, {pl['refinement_solves']} refining around C; cap {pl['max_solves']}); "
            f"{'converged' if pl['converged'] else 'NOT converged'}: {pl['stop']}"
            + (f" (C's neighbours within {_fmt(last['bracket_se'], 3)} of its standard errors)"
               if 'bracket_se' in last else "")
            + (f"; the direct Eq. 11 solve lies {_fmt(pl['direct_se'], 3)} of C's standard errors from C"
               if pl.get("direct_se") is not None else "") + ".")


def write_report(out_dir, cfg, results_dir=None, figure_format: str = "png") -> Path:
    """Write figures, tables, metrics and ``report.md`` of the identification in ``results_dir``
    (default: ``out_dir``) into ``out_dir``; return the path of ``report.md``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    result = IdentificationResult.load(results_dir if results_dir is not None else out)
    ft = load_flight_test(cfg.dataset)
    truth = read_truth(cfg.dataset)
    # full records at the recorded rate
    val_mans = validation_maneuvers(cfg, ft)
    trims = ft.trims.reset_index(drop=True)

    speeds = list(CURVE_SPEEDS) + list(trims["V"])
    models = {TIME_DOMAIN: result.time_domain["parameters"], MULTI_OBJECTIVE: result.chosen["parameters"]}
    preds = {lab: predict(lab, cfg.model, p, speeds, val_mans) for lab, p in models.items()}

    # --- figures
    fig = plots.plot_pareto_front(result.front, result.utopia, result.nadir, result.chosen, result.direct)
    _save(fig, out / f"pareto_front.{figure_format}")
    curves = {lab: pr.trim_table(CURVE_SPEEDS) for lab, pr in preds.items()}
    fig = plots.plot_trim_vs_speed(trims, curves)
    _save(fig, out / f"trim_vs_speed.{figure_format}")
    fig = plots.plot_validation({mv.name: mv.data for mv in val_mans},
                                {lab: pr.shown_runs() for lab, pr in preds.items()}, VALIDATION_OUTPUTS,
                                inputs={mv.name: mv.inputs for mv in val_mans},
                                titles={mv.name: f"{mv.name} ({mv.trim_speed / KT:.0f} kt)" for mv in val_mans},
                                notes={mv.name: [f"{lab}: diverged" for lab, pr in preds.items()
                                                 if mv.name in pr.partial] for mv in val_mans})
    _save(fig, out / f"validation.{figure_format}")

    # --- tables and metrics
    ptab = parameter_table(result, cfg, truth)
    ptab.to_csv(out / "parameters.csv", index=False, float_format="%.10g")
    err_fmt = {c: (lambda v: _fmt(v, 3)) for c in ptab.columns if c.endswith("error %")}
    ptab_md = markdown_table(ptab, formats=err_fmt)
    (out / "parameters.md").write_text(
        "# Identified parameters\n\nDisplay units; initial = the config's initial guess"
        + ("; truth from the dataset's truth.json, errors relative to it." if truth is not None else ".")
        + "\n\n" + ptab_md + "\n")
    vrms = {lab: validation_rms(pr, val_mans) for lab, pr in preds.items()}
    trms = {lab: trim_rms(pr, trims) for lab, pr in preds.items()}
    problems = {lab: pr.problems for lab, pr in preds.items()}
    mean_it = mean_interior_iterations(result.front)
    write_json(out / "metrics.json", {
        "units": "SI (rad, rad/s, m/s, g)", "validation_maneuvers": [mv.name for mv in val_mans],
        "validation_rms": vrms, "trim_rms": trms, "problems": problems, "models": models,
        "mean_iterations_interior_front": mean_it})

    # --- report.md
    info = result.info
    L = ["# Identification report", ""]
    L += [f"- config: `{info.get('config', cfg.path)}`", f"- dataset: `{shown_path(cfg.dataset)}`",
          f"- free parameters: {', '.join(result.parameters)}",
          f"- identification maneuvers: {', '.join(info.get('maneuvers', [])) or str(cfg.maneuvers)}",
          f"- model extensions: {', '.join(info.get('extensions', [])) or 'none (M0)'}",
          f"- solver: {info.get('solver', 'n/a')}; total time {_fmt(info.get('total_time'), 4)} s "
          f"(NLP build {_fmt(info.get('build_time'), 3)} s, solver setup {_fmt(info.get('solver_setup_time'), 3)} s)",
          "- models compared below: **time-domain (A)** = the J_time anchor (classic output error), "
          "**multi-objective (C)** = the front point closest to the utopia point (Eq. 11)", ""]
    if info.get("unreliable"):  # an anchor did not converge (pyomo_heli.workflows.identify): say so before any number
        u = info["unreliable"]
        L += [f"> **UNRELIABLE**: {u.get('reason')}. The {', '.join(u.get('quantities', []))} depend on the "
              "anchors and are not to be trusted (chosen.json `info.unreliable`).", ""]
    if info.get("uncertainty_approximations"):  # the noise model the Cramer-Rao information leaves out
        L += ["> **Standard errors approximate**: the information leaves out "
              + "; ".join(info["uncertainty_approximations"]) + " (chosen.json `info.uncertainty_approximations`).",
              ""]
    all_problems = [f"{lab}: {p}" for lab, ps in problems.items() for p in ps]
    if all_problems:
        L += ["> **Simulation problems** (the affected curves are missing or cut short in the figures, "
              "and left out of the RMS tables):", ">"] + [f"> - {p}" for p in all_problems] + [""]

    L += ["## Pareto front", "", f"![Pareto front](pareto_front.{figure_format})", "",
          f"Utopia U (J_time, J_trim) = ({_fmt(result.utopia[0], 10)}, {_fmt(result.utopia[1], 6)}); "
          f"nadir = ({_fmt(result.nadir[0], 10)}, {_fmt(result.nadir[1], 6)}).  ",
          f"Chosen point C: front point {result.chosen.get('index')} "
          f"(J_time = {_fmt(result.chosen['J_time'], 10)}, J_trim = {_fmt(result.chosen['J_trim'], 6)}).  "]
    if result.direct:
        d = result.direct
        L.append(f"Eq. 11 solved directly: J_time = {_fmt(d['J_time'], 10)}, J_trim = {_fmt(d['J_trim'], 6)} "
                 f"({d.get('status')}, {d.get('iterations')} iterations, {_fmt(d.get('wall_time'), 3)} s).  ")
        dc, dd = utopia_distance_of(result, result.chosen), utopia_distance_of(result, d)
        L.append(f"Normalised distance to U (Eq. 11): C {_fmt(dc, 4)}, direct solve {_fmt(dd, 4)}"
                 + (" (the direct solve lies closer to U than every sampled front point: the front is sampled "
                       "coarsely near C, or its solves stopped short of the optimum)."
                    if dd is not None and dc is not None and dd < dc - 1e-3 else ".") + "  ")
    if nadir_rule_line(info.get("eq11_by_nadir")):
        L.append(nadir_rule_line(info["eq11_by_nadir"]) + ".  ")
    pl = info.get("placement")
    if pl:  # adaptive epsilon placement (pareto/placement.py)
        L.append(placement_line(pl) + "  ")
    n_eps = int((result.front["kind"] == "eps").sum())
    L.append(f"Mean iterations per interior front point: {_fmt(mean_it, 4)} "
             f"(over {n_eps} epsilon-constraint solve{'s' if n_eps != 1 else ''}, failed ones included).")
    cold_it = mean_cold_iterations(result.front)
    if cold_it is not None:
        L[-1] += "  "
        L.append(f"Warm starts vs cold starts on the same interior points: mean iterations warm {_fmt(mean_it, 4)}, "
                 f"cold {_fmt(cold_it, 4)} (ratio warm/cold {_fmt(mean_it / cold_it, 3)}; "
                 f"mean wall time warm {_fmt(_mean_col(result.front, 'wall_time'), 3)} s, "
                 f"cold {_fmt(_mean_col(result.front, 'cold_wall_time'), 3)} s).")
    L += ["", "Front (parameters in display units):", "",
          markdown_table(front_table(result, cfg.model),
                         formats={"wall time [s]": lambda v: _fmt(v, 3), "J_time": lambda v: _fmt(v, 12)}), ""]

    L += ["## Parameters", "", "Table: [parameters.md](parameters.md) (also `parameters.csv`).", "", ptab_md, ""]

    from .uncertainty import uncertainty_section

    L += uncertainty_section(result, results_dir if results_dir is not None else out, cfg.model)

    L += ["## Trim predictions", "", f"![Trim vs speed](trim_vs_speed.{figure_format})", "",
          f"RMS of data minus model over the {len(trims)} trim points "
          f"({int(trims['source'].eq('level').sum()) if 'source' in trims else len(trims)} level-flight, the rest "
          f"maneuver start trims) [deg]:", ""]
    rows = []
    for lab, r in trms.items():
        for group in ("all", "level", "maneuver_start"):
            if group != "all" and "source" not in trims:
                continue
            rows.append({"model": lab, "points": group.replace("_", " "),
                         **{f"{c} [deg]": _shown_rms(c, r[group][c]) for c in TRIM_CHANNELS},
                         "not trimmed": r["n_failed"]})
    L += [markdown_table(pd.DataFrame(rows)), ""]

    L += ["## Validation maneuvers", ""]
    if not val_mans:
        L += ["The dataset has no validation maneuvers.", ""]
    else:
        L += [f"![Validation maneuvers](validation.{figure_format})", "",
              "Each model is trimmed at the maneuver's speed and driven by its own trim inputs plus the measured "
              "input increments (as in the identification). RMS of data minus model:", ""]
        rows = []
        for lab, r in vrms.items():
            for name in [mv.name for mv in val_mans] + ["all"]:
                v = r[name]
                rows.append({"model": lab, "maneuver": name if name != "all" else "**all pooled**",
                             **{f"{o} [{plots.UNITS[o][0]}]": ("failed" if v is None else _shown_rms(o, v[o]))
                                for o in VALIDATION_OUTPUTS}})
        L += [markdown_table(pd.DataFrame(rows)), ""]

    L += ["## Simulation problems", ""]
    L += [f"- {p}" for p in all_problems] if all_problems else ["None: every trim and simulation succeeded."]
    L += ["", "Machine-readable numbers (SI): `metrics.json`.", ""]
    path = out / "report.md"
    path.write_text("\n".join(L))
    return path
