"""The report of a closed loop: the error before and after each added effect.

:func:`write_loop_report` reads ``loop.json`` (see :mod:`pyomo_heli.workflows.close_loop`)
and writes next to it:

- ``loop_trim_vs_speed.png``  trim col, lon, theta vs speed: data and the model of every iteration
- ``loop_validation.png``     validation time histories: data and the model of every iteration
- ``loop_report.md``          before/after table (J_time, J_trim, RMS per trim channel and per output on
                              identification and validation data), parameters of every iteration, the
                              attribution tables and decisions; parameter errors against ``truth.json``
                              only when the dataset has one (nothing else reads it).

The models are replayed with the float simulator (as the identification report does).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import pandas as pd

from ..dataset import load_flight_test
from ..diagnosis.candidates import model_with_candidates
from ..nlp.identification import validation_maneuvers
from ..physics.discrepancy import REGRESSORS, is_force_term
from ..physics.model import HelicopterModel
from ..units import KT
from . import plots
from ..diagnosis.discovery import describe_fit
from ..diagnosis.trim_forces import implied_forces
from .diagnosis import implied_forces_section, record_bias_shapes
from .identification import (CURVE_SPEEDS, TRIM_CHANNELS, VALIDATION_OUTPUTS, _fmt, _save, markdown_table, predict,
                             read_truth, shown_path, truth_model_errors, truth_prediction, validation_rms)


#: the closed loop's record in its results folder (written by :mod:`pyomo_heli.workflows.close_loop`)
LOOP_FILE = "loop.json"


def load_loop(out) -> dict:
    """The closed loop's record ``loop.json`` in folder ``out``."""
    f = Path(out) / LOOP_FILE
    if not f.is_file():
        raise FileNotFoundError(f"{out}: no {LOOP_FILE}; is this a close-loop results folder?")
    return json.loads(f.read_text())


def iteration_model(base: HelicopterModel, it: dict) -> HelicopterModel:
    """The model of one loop iteration: the config's base model plus that iteration's extensions (with the
    shape parameters the loop's shape rule fixed for them)."""
    return model_with_candidates(base, it["extensions"], it.get("shape_parameters"))


def label(it: dict) -> str:
    return f"iter {it['iteration']}: M0" + "".join(f" + {n}" for n in it["extensions"])


def before_after_table(doc: dict) -> pd.DataFrame:
    """One row per iteration: J_time, J_trim, RMS trim per channel [deg] and RMS per output [display units]."""
    rows = []
    for it in doc["iterations"]:
        r = {"iteration": it["iteration"], "model": "M0" + "".join(f" + {n}" for n in it["extensions"])
             + (" (rejected)" if it.get("rejected") else ""),
             "J_time": it["J_time"], "J_trim": it["J_trim"]}
        for c in TRIM_CHANNELS:
            v = it["trim_rms"].get(c)
            r[f"trim {c} [deg]"] = None if v is None else float(plots.shown(c, v))
        for group, key in (("id", "identification_rms"), ("val", "validation_rms")):
            for o in VALIDATION_OUTPUTS:
                v = (it.get(key) or {}).get(o)
                if v is not None:
                    r[f"{group} {o} [{plots.UNITS[o][0]}]"] = float(plots.shown(o, v))
        rows.append(r)
    return pd.DataFrame(rows)


def final_index(doc: dict) -> int:
    """Position in ``doc['iterations']`` of the model the loop kept (a step rejected by the validation rule is not)."""
    its = doc["iterations"]
    k = doc.get("final_iteration")
    return next((j for j, it in enumerate(its) if it["iteration"] == k), len(its) - 1)


def change_table(doc: dict) -> pd.DataFrame:
    """Relative change of every RMS error from the first to the kept iteration [%] (negative = better)."""
    tab = before_after_table(doc)
    if len(tab) < 2 or final_index(doc) == 0:
        return pd.DataFrame()
    first, last = tab.iloc[0], tab.iloc[final_index(doc)]
    its = doc["iterations"]
    lost0, lost1 = (set(its[j].get("not_replayed", [])) for j in (0, final_index(doc)))
    note = "" if lost0 == lost1 else (  # the pooled RMS of the two are over different records: said, not hidden
        "over other records: not replayed by the first: " + (", ".join(sorted(lost0)) or "none")
        + "; by the kept: " + (", ".join(sorted(lost1)) or "none"))
    rows = []
    for c in tab.columns[4:]:
        if pd.notna(first[c]) and pd.notna(last[c]) and first[c]:
            rows.append({"error": c, "first": first[c], "last": last[c], "change %": 100 * (last[c] / first[c] - 1),
                         **({"note": note} if note and not c.startswith("trim") else {})})
    return pd.DataFrame(rows)


def truth_errors(doc: dict, base: HelicopterModel, truth: dict) -> pd.DataFrame:
    """Identified parameters of every iteration vs truth (display units) and their errors [%]; with the loop's
    standard errors (``[loop] uncertainty``) also each SE and the error in units of it."""
    rows = []
    names = []
    for it in doc["iterations"]:
        names += [n for n in it["parameters"] if n not in names]
    for n in names:
        if n not in truth:
            continue
        spec = base.parameters.spec(n) if n in base.parameters else None
        unit, fac = (spec.display if spec is not None and spec.display else (spec.unit if spec else "", 1.0))
        r = {"parameter": n, "unit": unit, "truth": truth[n] * fac}
        for it in doc["iterations"]:
            v = it["parameters"].get(n)
            r[f"iter {it['iteration']}"] = None if v is None else v * fac
            r[f"iter {it['iteration']} error %"] = (None if v is None or not truth[n]
                                                   else 100 * (v - truth[n]) / abs(truth[n]))
            se = (it.get("standard_errors") or {}).get(n)
            if any(j.get("standard_errors") for j in doc["iterations"]):
                # the error in units of the estimate's own standard error: is a change of the error beyond noise?
                r[f"iter {it['iteration']} SE"] = None if se is None else se * fac
                r[f"iter {it['iteration']} error / SE"] = None if (v is None or not se) else (v - truth[n]) / se
        rows.append(r)
    return pd.DataFrame(rows)


#: the output name of the joint row of :func:`validation_change_table`
JOINT = "all outputs (joint)"


def validation_change_table(pred0, pred1, val_mans, segment_s: float | None = None,
                            alpha: float = 0.01) -> pd.DataFrame:
    """Per output: validation RMS of data minus model for two predictions and the paired test of the change
    (Diebold-Mariano with batch means, :mod:`pyomo_heli.diagnosis.validation_change`: whole records as batches by
    default, or ``segment_s`` segments). A last row, :data:`JOINT`, tests all these outputs at once (each output's
    squared error in units of model 0's mean square, summed: :func:`~pyomo_heli.diagnosis.validation_change.
    joint_mean_square_change`, over the outputs every record has); its RMS columns are empty and its change is that
    of the standardised RMS. An output some records lack is tested on the others (column ``records without it``)."""
    import numpy as np

    from ..diagnosis.validation_change import joint_mean_square_change, mean_square_change

    rows, r0s, r1s, seg_all = [], {}, {}, []
    for o in VALIDATION_OUTPUTS:
        # each output on the records that have it (beta_0 is optional per record): a record without it is named in
        # the row, not a reason to leave the output out of the test
        r0, r1, seg, without = [], [], [], []
        for mv in val_mans:
            a, b = pred0.maneuvers.get(mv.name), pred1.maneuvers.get(mv.name)
            if a is None or b is None or o not in mv.data or o not in a or o not in b:
                without.append(mv.name)
                continue
            y = mv.data[o].to_numpy(dtype=float)
            r0.append(y - a[o].to_numpy(dtype=float))
            r1.append(y - b[o].to_numpy(dtype=float))
            if segment_s is not None:
                seg.append(max(int(round(segment_s / float(np.median(np.diff(mv.t))))), 1))
        if not r0:
            continue
        c = mean_square_change(r0, r1, seg or None, alpha)
        if not without:  # the joint test needs the same records for every output
            r0s[o], r1s[o], seg_all = r0, r1, seg
        unit = plots.UNITS[o][0]
        rows.append({"output": o, "RMS before": float(plots.shown(o, c.ms0**0.5)),
                     "RMS after": float(plots.shown(o, c.ms1**0.5)), "unit": unit,
                     "change [%]": c.rms_change_pct, "z": c.z, "p (rise)": c.p_rise, "segments": c.segments,
                     "significant rise": c.rise_significant,
                     **({"records without it": ", ".join(without)} if without else {})})
    if len(r0s) > 1:
        c = joint_mean_square_change(r0s, r1s, seg_all or None, alpha)
        rows.append({"output": JOINT, "RMS before": None, "RMS after": None, "unit": "",
                     "change [%]": c.rms_change_pct, "z": c.z, "p (rise)": c.p_rise, "segments": c.segments,
                     "significant rise": c.rise_significant})
    return pd.DataFrame(rows)


def iterations_validation_change(cfg, first: dict, second: dict, val_mans) -> pd.DataFrame:
    """:func:`validation_change_table` of two iterations of a loop document (``loop.json`` records), each replayed
    on the validation records ``val_mans`` with its model and parameters (``cfg``: the loop's config)."""
    p0, p1 = (predict(label(it), iteration_model(cfg.model, it), it["parameters"], [], val_mans)
              for it in (first, second))
    return validation_change_table(p0, p1, val_mans)


def speed_groups(val_mans) -> list[tuple[float, list]]:
    """The validation records grouped by trim speed (rounded to whole knots): [(speed [kt], records), ...]."""
    speeds = sorted({round(mv.trim_speed / KT) for mv in val_mans})
    return [(float(kt), [mv for mv in val_mans if round(mv.trim_speed / KT) == kt]) for kt in speeds]


def validation_change_by_speed(pred0, pred1, val_mans, alpha: float = 0.01) -> pd.DataFrame:
    """Where a validation change sits: per trim speed, each output's RMS change [%] and the paired test of the
    joint row on that speed's records alone (:func:`validation_change_table`). One or two records per speed: the
    tests are weak and many (speeds x outputs), so a p here locates a change rather than proves it."""
    rows = []
    for kt, group in speed_groups(val_mans):
        tab = validation_change_table(pred0, pred1, group, alpha=alpha).set_index("output")
        row = {"speed [kt]": kt, "records": len(group)}
        row.update({f"{o} [%]": float(tab.loc[o, "change [%]"]) for o in tab.index if o != JOINT})
        if JOINT in tab.index:
            row["joint [%]"] = float(tab.loc[JOINT, "change [%]"])
            row["joint p (rise)"] = float(tab.loc[JOINT, "p (rise)"])
        rows.append(row)
    return pd.DataFrame(rows)


def truth_replay_errors(cfg, doc: dict, val_mans) -> tuple[list[dict], dict] | None:
    """Validation RMS of each iteration's model minus the truth simulator replayed the same way (same measured
    input increments, each model from its own trim): the model error without the sensor noise. Also the truth
    model's own data-minus-model RMS. None without ``truth.json``. Evaluation only."""
    import numpy as np

    if read_truth(cfg.dataset) is None or not val_mans:
        return None
    tpred = truth_prediction(cfg.dataset, [], val_mans)
    out = []
    for it in doc["iterations"]:
        pred = predict(label(it), iteration_model(cfg.model, it), it["parameters"], [], val_mans)
        row = {}
        for o in VALIDATION_OUTPUTS:
            runs = [(pred.maneuvers.get(mv.name), tpred.maneuvers.get(mv.name)) for mv in val_mans]
            if any(a is None or b is None or o not in a for a, b in runs):
                row[o] = None
                continue
            e = np.concatenate([(a[o] - b[o]).to_numpy(dtype=float) for a, b in runs])
            row[o] = float(np.sqrt(np.mean(e**2)))
        out.append(row)
    return out, validation_rms(tpred, val_mans)["all"]


#: validation records up to which the loop's validation figure has the identification report's size
WIDE = 4


#: ``figure_format`` of :func:`write_loop_report` that draws no figure (batch runs; ``report-loop`` draws them later)
NO_FIGURES = "none"


def write_loop_report(out, cfg, figure_format: str = "png") -> Path:
    """Figures and ``loop_report.md`` of the loop in ``out`` (``cfg``: the loop's identification config).
    ``figure_format = "none"`` writes the report's text and tables only; ``pyomo-heli report-loop`` draws the
    figures later from loop.json."""
    out = Path(out)
    draw = figure_format != NO_FIGURES
    doc = load_loop(out)
    ft = load_flight_test(cfg.dataset)
    trims = ft.trims.reset_index(drop=True)
    val_mans = validation_maneuvers(cfg, ft)
    its = doc["iterations"]
    preds = {label(it): predict(label(it), iteration_model(cfg.model, it), it["parameters"],
                                list(CURVE_SPEEDS) + list(trims["V"]), val_mans) for it in its}
    if draw:
        fig = plots.plot_trim_vs_speed(trims, {lab: p.trim_table(CURVE_SPEEDS) for lab, p in preds.items()},
                                       title="Trim vs speed, before and after")
        _save(fig, out / f"loop_trim_vs_speed.{figure_format}")
    if val_mans and draw:
        fig = plots.plot_validation({mv.name: mv.data for mv in val_mans},
                                    {lab: p.shown_runs() for lab, p in preds.items()}, VALIDATION_OUTPUTS,
                                    inputs={mv.name: mv.inputs for mv in val_mans},
                                    titles={mv.name: f"{mv.name} ({mv.trim_speed / KT:.0f} kt)" for mv in val_mans},
                                    column_width=4.8 if len(val_mans) <= WIDE else 3.4)
        # noisy time histories hardly compress: many records (the bundled flight test has twelve) at a lower
        # resolution keep the figure near 1 MB
        if len(val_mans) <= WIDE:
            _save(fig, out / f"loop_validation.{figure_format}")
        else:
            fig.savefig(out / f"loop_validation.{figure_format}", dpi=72)

    L = ["# Closed-loop report", "", f"- config: `{doc['config']}`", f"- dataset: `{shown_path(doc['dataset'])}`",
         f"- settings: {doc['settings']}", f"- stopped: {doc['stopped']}"]
    if not draw:
        L += [f"- figures: not drawn (`--figure-format {NO_FIGURES}`); `pyomo-heli report-loop {out}` draws them"]
    L += [""]
    L += ["## Error before and after", "",
          "RMS of data minus model (float-model replay of each iteration's diagnosed point, `[loop] point`); "
          "trim over all trim points, `id` = identification maneuvers, `val` = validation maneuvers.", "",
          markdown_table(before_after_table(doc), digits=4), ""]
    ch = change_table(doc)
    kept = its[final_index(doc)]
    if len(ch):
        L += [f"Change from iteration 0 to iteration {kept['iteration']} (the model kept):", "",
              markdown_table(ch, digits=4), ""]
    if val_mans and len(its) > 1 and kept is not its[0]:
        first, last = preds[label(its[0])], preds[label(kept)]
        L += [f"Is a change of the validation error a real one? Paired test of iteration {kept['iteration']} "
              "against iteration 0 on the same records (Diebold-Mariano, squared error, batch means over whole "
              "records, `segments` of them; `pyomo_heli/diagnosis/validation_change.py`): a rise counts as "
              "significant when its one-sided p < 0.01. At the sensor-noise floor the same noise enters both "
              "models' residuals and does not cancel, so small changes of either sign are expected without any "
              "change of the model error.", "",
              markdown_table(validation_change_table(first, last, val_mans), digits=4), "",
              "Where it sits: the change of each output's validation RMS by trim speed, and the joint test on that "
              "speed's records alone (one or two records each, so a p here locates a change rather than proves it):",
              "", markdown_table(validation_change_by_speed(first, last, val_mans), digits=3), ""]
    if draw:
        L += [f"![Trim vs speed before and after](loop_trim_vs_speed.{figure_format})", ""]
    L += discovery_summary(doc, cfg, out, figures=draw)
    shown = [its[0]] + ([kept] if kept is not its[0] else [])
    forces = {label(it): implied_forces(iteration_model(cfg.model, it).with_parameters(**it["parameters"]), trims,
                                        ft.conventions, label=label(it), free=list(it["parameters"])) for it in shown}
    if all(len(f.table) for f in forces.values()):  # trim points with all three channels recorded
        if draw:
            _save(plots.plot_implied_forces({k: f.table for k, f in forces.items()}),
                  out / f"loop_trim_forces.{figure_format}")
        L += implied_forces_section(forces, f"loop_trim_forces.{figure_format}" if draw else None)
    if val_mans and draw:
        L += [f"![Validation before and after](loop_validation.{figure_format})", ""]
    truth = read_truth(cfg.dataset)
    if truth is not None:
        L += ["## Parameters vs truth", "", "From the dataset's `truth.json` (read only by this report).", "",
              markdown_table(truth_errors(doc, cfg.model, truth), digits=5), ""]
        tr = truth_replay_errors(cfg, doc, val_mans)
        if tr is not None:
            errs, truth_rms = tr
            rows = [{"model": label(it), **{f"{o} [{plots.UNITS[o][0]}]": (None if errs[k][o] is None
                                                                          else float(plots.shown(o, errs[k][o])))
                                          for o in VALIDATION_OUTPUTS}} for k, it in enumerate(its)]
            rows.append({"model": "truth model: data minus truth (noise floor)",
                         **{f"{o} [{plots.UNITS[o][0]}]": (None if truth_rms.get(o) is None
                                                           else float(plots.shown(o, truth_rms[o])))
                            for o in VALIDATION_OUTPUTS}})
            L += ["Validation RMS of each model minus the truth simulator replayed the same way (the model error "
                  "without the sensor noise; the last row is the truth model's own data-minus-model RMS, the "
                  "floor of the table above):", "", markdown_table(pd.DataFrame(rows), digits=4), ""]
        floor = truth_model_errors(cfg.dataset)["trim_rms"]["all"]
        L += ["Trim RMS of the truth model at the truth parameters (data minus truth: the trims' noise and offsets, "
              "the floor of the trim columns of \"Error before and after\") [deg]: "
              + ", ".join(f"{c} {_fmt(math.degrees(v), 4)}" for c, v in floor.items() if v is not None) + ".", ""]
    L += ["## Iterations", ""]
    for it in its:
        L += [f"### {label(it)}", "", f"Results: `{it['results_dir']}/` (front, report). "
              f"Parameters at the diagnosed point ({it.get('point', 'closest front point')}, SI, +- Cramer-Rao SE "
              "where computed): "
              + ", ".join(f"{k} = {_fmt(v, 6)}" + (f" +- {_fmt((it.get('standard_errors') or {})[k], 2)}"
                                                   if (it.get("standard_errors") or {}).get(k) else "")
                          for k, v in it["parameters"].items())
              + f"; J_time = {_fmt(it['J_time'], 8)}, J_trim = {_fmt(it['J_trim'], 5)}.", ""]
        sh = it.get("shape_selection")
        if sh:
            L += [f"Shape of {sh['candidate']} (shape rule: anchor A with the shape at its defaults "
                  f"{sh['defaults']}, J_time = {_fmt(sh['A_default']['J_time'], 8)}, and with it free, "
                  f"J_time = {_fmt(sh['A_free']['J_time'], 8)}): **{sh['decision']}**; held at "
                  + ", ".join(f"{n} = {_fmt(v, 5)}" for n, v in sh["values"].items()) + " for the whole front.", ""]
        L += iteration_checks(it)
        a = it.get("attribution")
        if a is None:
            L += ["No candidate left to score.", ""]
            continue
        L += discovery_section(it)
        sc = pd.DataFrame(a["scores"])
        # loops written before the df column referred every LM to chi-square(1)
        with_df = "df" in sc
        sc = sc[[c for c in ("name", "strength", "LM", "df", "LM_needed", "p_value", "significant", "kappa_hat", "kept",
                             "like", "like_corr", "trim_share") if c in sc]]
        need = ("LM > LM_needed, its own F(1, df) quantile" if with_df else f"LM > {a['threshold']:.3g}")
        # with discovery the structure determination decides; the score test only scores
        rule = ("its own ratio and confounding rule is not used with discovery" if it.get("discovery") else
                f"accepted when LM >= {a['ratio']:g} x runner-up's; confounded when projected |rho| >= "
                f"{a['confound_corr']:g}")
        L += [f"Score test (significant when p < {a['alpha']:g}/{len(sc)}, i.e. {need}; {rule}):", "",
              markdown_table(sc, digits=4), ""]
        if not it.get("discovery"):
            L += [f"**Decision: {a['decision']}** - {a['message']}", ""]
        if a.get("confounded_pairs"):
            L += ["Confounded pairs among the significant candidates (projected correlation): "
                  + "; ".join(f"{p[0]} / {p[1]} ({p[2]:+.2f})" for p in a["confounded_pairs"]), ""]
        rd = it.get("residual_diagnosis")
        if rd:
            L += [f"Residual analysis of what is left (pyomo_heli.diagnosis): **{rd['status']}**", ""]
            L += [f"- {f}" for f in rd.get("findings", [])] + [""] + record_bias_shapes(rd.get("record_biases") or {})
        if a.get("signature"):
            rows = [{"block": k, **v} for k, v in a["signature"].items()]
            L += ["Residual signature (SI):", "", markdown_table(pd.DataFrame(rows), digits=4), ""]
    problems = [f"{lab}: {p}" for lab, pr in preds.items() for p in pr.problems]
    L += ["## Simulation problems", ""] + ([f"- {p}" for p in problems] if problems else ["None."]) + [""]
    path = out / "loop_report.md"
    path.write_text("\n".join(L))
    return path


# --- structure determination ([loop] discovery, pyomo_heli.diagnosis.discovery) --------------------------------------
def iteration_checks(it: dict) -> list[str]:
    """The validation rule's paired test against the previous iteration, the rejection and the backward check."""
    L = []
    named = it.get("name_check")
    if it.get("validation_check"):
        verdict = "rejected: " + it["rejected"] if it.get("rejected") and not named else "passed"
        L += ["Validation rule (paired test against the model kept so far; a significant rise on any output rejects "
              f"the step, and of all outputs at once with `[loop] validation_joint`): **{verdict}**", "",
              markdown_table(pd.DataFrame(it["validation_check"]), digits=4), ""]
    if it.get("validation_note"):  # records the test could not take (it passed on the others, or on none)
        L += [f"Validation rule: {it['validation_note']}", ""]
    if named:
        G = named.get("most_significant_generic_fit") or named["best_generic_fit"]  # older loop.json: the best
        L += [f"Name check (a physical candidate the loop added must leave the generic family nothing significant "
              f"at the next step): **rejected: {it['rejected']}**; with it fitted the step found "
              f"{describe_fit(G)} (its decision: {named['decision']})", ""]
    if it.get("backward_check"):
        L += ["Backward check (Wald test of the strengths added before the last one, Cramer-Rao SE):", "",
              markdown_table(pd.DataFrame(it["backward_check"]), digits=4), ""]
    if it.get("decision"):
        L += [f"**{it['decision']['decision']}**: {it['decision']['message']}", ""]
    return L


def discovery_section(it: dict) -> list[str]:
    """The structure-determination step of one iteration: NLP estimates, encompassing, decision."""
    d = it.get("discovery")
    if not d:
        return []
    back = it.get("step_from")
    L = ([f"Step rejected: back to the model of iteration {back['iteration']}; its structure determination again "
          f"without {', '.join(back['without'])} (`[loop] after_rejection`).", ""] if back else [])
    L += [f"Structure determination over a library of {d['library_size']} terms (physical candidates and generic "
          f"discrepancy terms; the score test below ranks them, "
          + ("the likelihood ratio of the NLP" if d.get("criterion", "likelihood ratio") == "likelihood ratio"
             else f"the {d['criterion']}") + f" decides at p < {d['level']:.3g}, Bonferroni over the library):", ""]
    sc = d.get("screen") or {}
    fits = sc.get("fits", {})
    if fits:
        rows = [{"term": f["name"], "form": f["formula"], "estimate": f["estimate"], "SE": f["se"], "LR": f["LR"],
                 "p": f["p"], "significant": bool(f["p"] < d["level"]), "solve": f["status"],
                 **({"detectable |c|": f["detectable"]} if "detectable" in f else {})} for f in fits.values()]
        L += [f"Each term alone in the full NLP (joint likelihood of time series and trims, base J = {sc['J0']:.8g}):",
              "", markdown_table(pd.DataFrame(rows), digits=4), ""]
    if d.get("encompassing"):
        L += ["Encompassing (does the generic term add anything once the physical candidate is fitted?):", "",
              markdown_table(pd.DataFrame([{k: v for k, v in r.items() if k != "shape"} for r in d["encompassing"]]),
                             digits=5), ""]
    L += [f"**Discovery: {d['decision']}** - {d['message']}", ""]
    if d.get("shape_by_channel") and d["decision"] in ("none", "ambiguous"):
        L += ["Shape of what is left per force/moment channel (score test over the generic family: the best speed "
              "shape and the best state or control dependence, sign from the one-step estimate kappa_hat):", "",
              markdown_table(pd.DataFrame([{k: v for k, v in r.items() if not k.endswith("term")}
                                           for r in d["shape_by_channel"]]), digits=3), ""]
    return L


def discovered_terms(doc: dict) -> list[tuple[dict, dict]]:
    """(iteration record, fit) of every generic term the loop added and kept."""
    its = doc["iterations"]
    kept = its[final_index(doc)]
    out = []
    for it in its[:final_index(doc)]:
        d = it.get("discovery") or {}
        if d.get("decision") == "discovered" and d.get("added") in kept["extensions"]:
            out.append((it, d["discovered"]))
    return out


def _trim_contexts(model: HelicopterModel, params: dict, speeds_kt):
    """(speed [kt], trim point, evaluated context) of the model's level trims at ``speeds_kt``."""
    from ..simulation.trim import trim_float

    m = model.with_parameters(**params)
    for v in speeds_kt:
        tp = trim_float(m, v * KT)
        x = {"u": tp.u, "w": tp.w, "q": 0.0, "theta": tp.theta, "lambda_i": tp.lambda_i, **tp.extra_states}
        yield v, tp, m.evaluate(x, {"col": tp.col, "lon": tp.lon})


def _extensions(model: HelicopterModel, names) -> list:
    return [e for e in model.extensions if e.name in set(names)]


def discovered_curve(model: HelicopterModel, params: dict, term, speeds_kt) -> pd.DataFrame:
    """The discovered force or moment along the model's level trims: speed [kt], the regressor's state and the value."""
    ext = _extensions(model, [term])[0]
    return pd.DataFrame([{"V [kt]": v, "mu": float(ctx.flow.mu),
                          "alpha [deg]": float(math.degrees(math.atan2(tp.w, tp.u))), "lambda_i": tp.lambda_i,
                          "col [deg]": math.degrees(tp.col), "lon [deg]": math.degrees(tp.lon), "w [m/s]": tp.w,
                          "value": float(ext.value(ctx))}
                         for v, tp, ctx in _trim_contexts(model, params, speeds_kt)])


def discovered_total(model: HelicopterModel, params: dict, terms, speeds_kt) -> pd.DataFrame:
    """The force and moment the discovered force/moment ``terms`` add together along the model's level trims: speed
    [kt] and one column per channel they touch, ``dX [N]``, ``dZ [N]``, ``dM [N m]`` (the sum of their values)."""
    exts = _extensions(model, terms)
    chans = [ch for ch in "XZM" if any(e.channel == ch for e in exts)]
    return pd.DataFrame([{"V [kt]": v, **{f"d{ch} [{'N m' if ch == 'M' else 'N'}]":
                                          sum(float(e.value(ctx)) for e in exts if e.channel == ch) for ch in chans}}
                         for v, _, ctx in _trim_contexts(model, params, speeds_kt)])


def rejected_discoveries(doc: dict) -> list[tuple[dict, dict]]:
    """(rejected iteration record, fit) of every generic term the loop discovered at the kept model and did not keep.

    When the validation rule rejects the step that added a discovered term, the loop goes back to the model before
    it and tries the next significant term (``[loop] after_rejection``); the terms rejected there, in the order they
    were tried, are what the missing effect looks like (shape, estimate in the rejected iteration) when nothing is
    kept after them. Rejections at models the loop went on from are not listed (a later step explained more)."""
    its = doc["iterations"]
    k = final_index(doc)
    out = []
    for j in range(k + 1, len(its)):
        if not its[j].get("rejected"):
            continue
        d = its[j - 1].get("discovery") or {}  # the step that proposed it: the kept model's, or a retry's there
        if d.get("decision") == "discovered" and d.get("discovered") and d.get("added") in its[j]["extensions"]:
            out.append((its[j], d["discovered"]))
    return out


def rejected_discovery(doc: dict) -> tuple[dict, dict] | None:
    """The first of :func:`rejected_discoveries` (the best-ranked term rejected at the kept model), or None."""
    found = rejected_discoveries(doc)
    return found[0] if found else None


def term_estimate(it: dict, fit: dict) -> tuple[float, float, bool]:
    """(estimate, standard error, whether the standard error is iteration ``it``'s own) of a discovered term in
    ``it``; the structure step's fit's standard error where ``it`` has none (``[loop] uncertainty = "none"``, or at a
    bound), which the report then says."""
    c = it["parameters"].get(fit["strength"], fit["estimate"])
    se = (it.get("standard_errors") or {}).get(fit["strength"])
    own = se is not None and math.isfinite(se)
    return c, se if own else fit["se"], own


#: what a report line adds when a term's standard error is not its iteration's own (:func:`term_estimate`)
SCREEN_SE = "standard error of the structure step's fit: the iteration's own was not computed"


def unexplained_statement(rejected: dict, fit: dict) -> str:
    """One line: the residual stays unexplained, with the shape of the discovered term that was not kept."""
    c, se, own = term_estimate(rejected, fit)
    return (f"the residual stays unexplained: not explained by any library effect; discovered {fit['formula']}, "
            f"c = {c:.4g} +- {se:.2g} (estimate of the rejected iteration {rejected['iteration']}"
            f"{'' if own else '; ' + SCREEN_SE}), not kept")


def limit_statement(record: dict) -> str:
    """At the iteration limit, what the residual left looks like when the step of ``record`` discovered a generic
    term that is not added (the loop stops there): that term's shape, reported as unexplained; "" otherwise."""
    d = record.get("discovery") or {}
    if d.get("decision") != "discovered" or not d.get("discovered"):
        return ""
    A = d["discovered"]
    return (f"; the residual stays unexplained: not explained by any library effect; discovered {describe_fit(A)}, "
            f"p = {A['p']:.2g} < {d['level']:.2g} at the kept model, not added")


STATE_OF = {"alpha": "alpha [deg]", "w": "w [m/s]", "lam": "lambda_i", "col": "col [deg]", "lon": "lon [deg]"}
STATE_OF.update({f"{r}mu": c for r, c in STATE_OF.items() if f"{r}mu" in REGRESSORS})  # speed products


def discovery_summary(doc: dict, cfg, out, figures: bool = True) -> list[str]:
    """What the loop discovered: the statement, and a figure of the force or moment vs airspeed and vs the state it
    depends on (``loop_discovered_<term>.png``; not drawn with ``figures = False``, the table is written either way),
    for every term it kept and for a term whose step was rejected."""
    found = discovered_terms(doc)
    rejected = rejected_discoveries(doc)
    L = []
    if found:
        kept = doc["iterations"][final_index(doc)]
        model = iteration_model(cfg.model, kept)
        L += ["## Discovered, not explained by any library effect", ""]
        for it, fit in found:
            c, se, own = term_estimate(kept, fit)
            whose = "the kept model's estimate and standard error" if own else f"the kept model's estimate; {SCREEN_SE}"
            L += [f"- iteration {it['iteration']}: not explained by any library effect; discovered {fit['formula']}, "
                  f"c = {c:.4g} +- {se:.2g} ({whose})", ""]
            L += _discovered_figure(model, kept["parameters"], fit, c, se, out, figures)
        L += _total_figure(model, kept["parameters"], [fit for _, fit in found], out, figures)
    if rejected:
        L += ["## Discovered, not kept (validation rule): the residual stays unexplained", ""]
        for it, fit in rejected:
            c, se, _ = term_estimate(it, fit)
            L += [f"- {unexplained_statement(it, fit)}; rejected because adding it {it['rejected']}", ""]
            L += _discovered_figure(iteration_model(cfg.model, it), it["parameters"], fit, c, se, out, figures)
    if found or rejected:
        L += ["To test an effect you suspect behind it (an extension whose strength has bounds): "
              f"`pyomo-heli check-effect {out} --effect FILE.py:CLASS --iteration K` (docs/discovery.md).", ""]
    return L


def _total_figure(model: HelicopterModel, params: dict, fits: list, out, figures: bool = True) -> list[str]:
    """``loop_discovered_total.png`` and its table: what the kept discovered force and moment terms add together
    along the level trims, one panel per channel; only where two or more of them are kept."""
    names = [f["name"] for f in fits if is_force_term(f["name"])]
    if len(names) < 2:
        return []
    tab = discovered_total(model, params, names, list(range(0, 121, 10)))
    text = ["The kept discovered terms together (" + ", ".join(names) + "), per channel: the discrepancy the kept "
            "model adds along its level trims. Their estimates are correlated, so a band from the standard errors "
            "alone would mislead; none is drawn.", ""]
    if not figures:
        return [*text, markdown_table(tab, digits=4), ""]
    from matplotlib.figure import Figure

    cols = [c for c in tab.columns if c != "V [kt]"]
    fig = Figure(figsize=(3.6 * len(cols) + 1, 3.4))
    for ax, col in zip(fig.subplots(1, len(cols), squeeze=False)[0], cols):
        ax.plot(tab["V [kt]"], tab[col], "o-")
        ax.set_xlabel("V [kt]")
        ax.set_ylabel(col)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.grid(alpha=0.3)
    fig.suptitle("The kept discovered terms together along the level trims (" + " + ".join(names) + ")")
    fig.tight_layout()
    fig.savefig(Path(out) / "loop_discovered_total.png", dpi=90)
    return [*text, "![the kept discovered terms together vs airspeed](loop_discovered_total.png)", "",
            markdown_table(tab, digits=4), ""]


def _discovered_figure(model: HelicopterModel, params: dict, fit: dict, c: float, se: float, out,
                       figures: bool = True) -> list[str]:
    """``loop_discovered_<term>.png`` and its table: the term's force or moment along the level trims."""
    if not is_force_term(fit["name"]):
        return []
    tab = discovered_curve(model, params, fit["name"], list(range(0, 121, 10)))
    if not figures:
        return [markdown_table(tab, digits=4), ""]
    from matplotlib.figure import Figure

    unit = "N m" if fit["name"].startswith("dM") else "N"
    reg = fit["name"][3:]
    xcol = STATE_OF.get(reg, "mu")
    fig = Figure(figsize=(9, 3.6))
    ax1, ax2 = fig.subplots(1, 2)
    for ax, xc in ((ax1, "V [kt]"), (ax2, xcol)):
        ax.plot(tab[xc], tab["value"], "o-", label=f"c = {c:.3g}")
        ax.fill_between(tab[xc], tab["value"] * (1 - 2 * se / abs(c)) if c else tab["value"],
                        tab["value"] * (1 + 2 * se / abs(c)) if c else tab["value"], alpha=0.25, label="+- 2 SE")
        ax.set_xlabel(xc)
        ax.set_ylabel(f"{fit['name'][:2]} [{unit}]")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.grid(alpha=0.3)
    ax1.legend()
    fig.suptitle(f"Discovered {fit['formula']} along the level trims")
    fig.tight_layout()
    name = f"loop_discovered_{fit['name']}.png"
    fig.savefig(Path(out) / name, dpi=90)
    return [f"![{fit['name']} vs airspeed]({name})", "", markdown_table(tab, digits=4), ""]
