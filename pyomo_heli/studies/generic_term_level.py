"""How far do generic terms' NLP estimates move when nothing is missing? Monte Carlo on the bundled records.

    python studies/generic_term_level.py --seeds 20261122-20261131 --out results/generic_term_level \
        [--terms col_scale lon_scale] [--config studies/held_out_discovery.toml] \
        [--data-config data/bo105_synthetic.toml] [--exact-inputs] [--identification eiv|oe] [--input-sigma-scale K] \
        [--resample-inputs sample|project|record] [--input-error-ar P]

Every seed generates the bundled flight test (``--data-config``: same maneuvers, trims and noise levels) from
**M0 with sensor noise only** (its truth effects removed, its seed replaced) into ``OUT/data/<seed>``, and estimates
each of ``--terms`` (names of the generic family, the extended one's included) alone in the identification NLP of
``--config`` with its free parameters, from their initial values, as a structure-determination step does
(:func:`pyomo_heli.diagnosis.discovery.nlp_screen`). Every true strength is zero, so each term's
``z = sign(c) sqrt(LR)`` should scatter as N(0, 1) and its estimate about 0: a term whose mean z over the seeds is
away from 0 has a bias in the estimator, not in the data. The held-out flight tests of one seed share these noise
draws (the truth effect changes the aircraft, not the noise), so a term that one seed's noise pushes is pushed on
every held-out row of that seed. Each seed's fits go to ``OUT/seed_<n>.json`` as it finishes (a rerun reuses them;
the generated data are deleted once the seed is done).

``--exact-inputs``: the same seeds with the recorded inputs' noise removed (outputs and trims drawn as before), into
``OUT/exact_inputs``; the fit's noise sigmas are then given (``[objectives] noise_sigma``: the outputs' from the
records' lead-in, the inputs' the generator's), since a lead-in without input noise has none to measure. The
difference to the plain run is what the input noise does to each estimate. ``--identification oe``: the config's
input errors dropped (the measured inputs taken as exact), into ``OUT/oe`` (``OUT/exact_inputs_oe``); with
``--exact-inputs`` that is the reference where nothing is mis-stated, and its difference to the errors-in-variables
run on the same data is what that formulation does to each estimate. ``--input-sigma-scale K``: the input errors'
sigmas the fit assumes times K (the lead-in's; with ``--exact-inputs`` the generator's), into
``OUT/input_sigma_x<K>`` (``OUT/exact_inputs_input_sigma_x<K>``): how the errors-in-variables estimates move with
the assumed input noise. ``--resample-inputs sample|project|record``: the fit's ``[data] resample_inputs`` instead
of the config's, into ``OUT/inputs_<choice>``: how the estimates move with the way the recorded inputs reach the
NLP's grid. ``--input-error-ar P``: the fit's ``[objectives] input_error_ar`` (the input errors an AR(P) process
fitted to the lead-in), into ``OUT/.../input_error_ar<P>``. ``--input-reference-error``: the fit's ``[objectives]
input_reference_error = true`` (each record's lead-in reference error estimated), into
``OUT/.../input_reference_error``. ``--output-error-ar P``: the fit's ``[objectives] output_error_ar`` (the output
noise an AR(P) process fitted to the lead-in), into ``OUT/.../output_error_ar<P>``.

Written: ``OUT/summary.csv`` and ``OUT/summary.md``: per term the seeds, the mean and standard deviation of the
estimate, the mean and standard deviation of z, the t statistic of the mean estimate (mean over its standard error
over the seeds) and the share of seeds with |z| above 2 and 3 (4.6 % and 0.3 % for N(0, 1)); the same for ``z_p``, the
p of the test a structure-determination step decides on (the LR corrected by the loop's robust score test, referred
to F(1, df); :func:`deciding_tests`) as a normal deviate; and the per-seed estimates.
"""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from pyomo_heli.config import ConfigError, load_identification_config
from pyomo_heli.flighttest.config import load_config
from pyomo_heli.nlp.identification import RESAMPLE_INPUTS
from pyomo_heli.physics.discrepancy import generic_names
from pyomo_heli.report.identification import markdown_table
from pyomo_heli.units import SENSOR_SIGMA_KEYS

from .args import claim_inputs, in_file, nonneg_int, out_folder
from .score_test_level import seeds_of
from .seeded import ROOT, m0_noise_data

TERMS = ("col_scale", "lon_scale")


def given_sigmas(cfg, data_config: Path | None, input_scale: float = 1.0) -> dict:
    """``[objectives] noise_sigma`` (display units, as the config table takes them): the time outputs' sigmas from the
    records' lead-in; those of ``cfg``'s input errors the generator's (``data_config``: a flight test without input
    noise, whose lead-in has none to measure) or, with ``data_config`` None, the lead-in's; the inputs' times
    ``input_scale``."""
    from pyomo_heli.nlp.identification import identification_data
    from pyomo_heli.nlp.objectives import lead_in_sigma

    mans = identification_data(cfg).maneuvers
    si = dict(lead_in_sigma(mans, list(cfg.nlp.time_outputs)))
    inputs = (lead_in_sigma(mans, list(cfg.nlp.input_errors)) if data_config is None
              else {c: v for c, v in load_config(data_config).sensors.sigma.items() if c in cfg.nlp.input_errors})
    si.update({c: input_scale * v for c, v in inputs.items()})
    return {key: si[ch] / unit for key, (ch, unit) in SENSOR_SIGMA_KEYS.items() if ch in si}


def one_seed(seed: int, terms: list[str], config: Path, data_config: Path, out: Path,
             exact_inputs: bool = False, identification: str = "eiv", input_sigma_scale: float = 1.0,
             resample_inputs: str | None = None, input_error_ar: int | None = None,
             input_reference_error: bool = False, output_error_ar: int | None = None) -> dict:
    """The NLP estimates of ``terms`` on one seed (read back from ``OUT/seed_<seed>.json`` when it holds them);
    ``resample_inputs``, ``input_error_ar``, ``input_reference_error`` (if true) and ``output_error_ar`` override the
    config's ``[data] resample_inputs`` and ``[objectives] input_error_ar``, ``input_reference_error`` and
    ``output_error_ar``."""
    from pyomo_heli.diagnosis.discovery import nlp_screen
    from pyomo_heli.nlp.identification import identification_data

    f = out / f"seed_{seed}.json"
    if f.is_file():
        try:
            doc = json.loads(f.read_text())
        except ValueError:
            doc = None
        if (doc and doc.get("config") == str(config) and set(terms) <= set(doc["fits"])
                and all("z_LR" in doc["fits"][n] for n in terms)
                and doc.get("input_sigma_scale", 1.0) == input_sigma_scale
                and doc.get("resample_inputs") == resample_inputs and doc.get("input_error_ar") == input_error_ar
                and doc.get("input_reference_error", False) == input_reference_error
                and doc.get("output_error_ar") == output_error_ar):
            return doc
    data = m0_noise_data(seed, data_config, out, input_noise=not exact_inputs)
    over = {"data": {"dataset": str(data), **({"resample_inputs": resample_inputs} if resample_inputs else {})}}
    if identification == "oe":
        over["objectives"] = {"input_errors": []}
    else:
        over["objectives"] = {**({"input_error_ar": input_error_ar} if input_error_ar is not None else {}),
                              **({"input_reference_error": True} if input_reference_error else {}),
                              **({"output_error_ar": output_error_ar} if output_error_ar is not None else {})}
    cfg = load_identification_config(config, overrides=over)
    if cfg.nlp.input_errors and (exact_inputs or input_sigma_scale != 1.0):
        cfg = load_identification_config(config, overrides={**over, "objectives": {**over["objectives"],
            "noise_sigma": given_sigmas(cfg, data_config if exact_inputs else None, input_sigma_scale)}})
    start = {p.name: p.initial for p in cfg.free}
    s = nlp_screen(cfg, start, list(terms), progress=lambda _: None)
    deciding = deciding_tests(cfg, s, list(terms), identification_data(cfg))
    fits = {}
    for n, r in s["fits"].items():
        lr = float(r["LR"]) if r["success"] else float("nan")
        fits[n] = {"estimate": float(r["estimate"]), "LR": lr,
                   "z": math.copysign(math.sqrt(max(lr, 0.0)), r["estimate"]) if r["success"] else float("nan"),
                   "LR_time": float(r.get("LR_time", float("nan"))), "LR_trim": float(r.get("LR_trim", float("nan"))),
                   "success": bool(r["success"]), **deciding[n]}
    doc = {"seed": seed, "config": str(config), "exact_inputs": exact_inputs, "identification": identification,
           "input_sigma_scale": input_sigma_scale, "resample_inputs": resample_inputs, "input_error_ar": input_error_ar,
           "input_reference_error": input_reference_error, "output_error_ar": output_error_ar, "J0": float(s["J0"]),
           "fits": fits}
    f.write_text(json.dumps(doc, indent=1))
    shutil.rmtree(data, ignore_errors=True)
    return doc


def deciding_tests(cfg, screen: dict, terms: list[str], data) -> dict:
    """Per term, the test a structure-determination step decides on (:func:`pyomo_heli.diagnosis.discovery.judge`),
    at the screen's base: the robust score test of the loop's settings (``[loop]``, the config's) over ``terms`` at
    the base estimate, the LR corrected by it (``LR_robust``, ``df``) and its p (``p``); with input errors that is
    the corrected LR's p, in output error the score test's own. ``z_p``: that p as a normal deviate with the
    estimate's sign, sign(c) Phi^-1(1 - p / 2) (a one-sided term's p: Phi^-1(1 - p)), N(0, 1) when the deciding
    test keeps its level. ``z_LR``: the corrected LR's p as a normal deviate the same way, whichever test decides
    (z_p itself when the LR does; in output error what the LR would have decided)."""
    from scipy import stats

    from pyomo_heli.diagnosis.attribution import attribute
    from pyomo_heli.diagnosis.candidates import as_candidate
    from pyomo_heli.diagnosis.discovery import deciding_criterion, judge
    from pyomo_heli.workflows.close_loop import loop_settings, score_test_inputs

    settings = loop_settings(cfg)
    model = cfg.model.with_parameters(**{f.name: float(screen["base"][f.name]) for f in cfg.free})
    att = attribute(model, [f.name for f in cfg.free], data, cfg.nlp.time_outputs, cfg.nlp.trim_outputs,
                    candidates=terms, alpha=settings.alpha, ratio=settings.ratio, confound_corr=settings.confound_corr,
                    robust=settings.robust, **score_test_inputs(cfg, settings))
    rows = att.scores.set_index("name")
    criterion = deciding_criterion(cfg, screen)
    out = {}
    for n in terms:
        f = dict(screen["fits"][n])
        one_sided = bool(getattr(as_candidate(n), "one_sided", False))
        judge(f, rows.loc[n], one_sided, criterion)
        p, p_lr = float(f["p"]), float(f.get("p_robust_LR", f["p"]))

        def deviate(q: float) -> float:
            return (math.copysign(float(stats.norm.isf(q if one_sided else q / 2)), f["estimate"])
                    if math.isfinite(q) else float("nan"))

        out[n] = {"LR_robust": float(f["LR_robust"]), "df": float(f["df"]), "p": p, "z_p": deviate(p),
                  "p_LR": p_lr, "z_LR": deviate(p_lr), "criterion": criterion}
    return out


def summary(docs: list[dict], terms: list[str]) -> pd.DataFrame:
    """Per term: the estimate's and z's mean and standard deviation over the seeds, the mean's t statistic, the
    share of seeds with |z| above 2 and 3, and z_p's mean, standard deviation and share above 2 (failed fits left
    out; z_p NaN for seeds stored without it); where the score test decides (output error), the same of z_LR, what
    the corrected LR would have decided."""
    rows = []
    both = parted(docs, terms)
    for n in terms:
        ok = [d["fits"][n] for d in docs if d["fits"][n]["success"]]
        c = np.array([r["estimate"] for r in ok])
        z = np.array([r["z"] for r in ok])
        zp = np.array([r.get("z_p", float("nan")) for r in ok])
        sd_c = float(np.std(c, ddof=1)) if len(c) > 1 else float("nan")
        rows.append({"term": n, "seeds": len(ok), "mean c": float(np.mean(c)), "sd c": sd_c,
                     "t of mean c": float(np.mean(c) / (sd_c / np.sqrt(len(c)))) if len(c) > 1 else float("nan"),
                     "mean z": float(np.mean(z)), "sd z": float(np.std(z, ddof=1)) if len(z) > 1 else float("nan"),
                     "z beyond +-2 [%]": 100.0 * float(np.mean(np.abs(z) > 2)),
                     "z beyond +-3 [%]": 100.0 * float(np.mean(np.abs(z) > 3)),
                     "mean z_p": float(np.mean(zp)),
                     "sd z_p": float(np.std(zp, ddof=1)) if len(zp) > 1 else float("nan"),
                     "z_p beyond +-2 [%]": 100.0 * float(np.mean(np.abs(zp) > 2))})
        if both:
            zl = np.array([r["z_LR"] for r in ok])
            rows[-1].update({"mean z_LR": float(np.mean(zl)),
                             "sd z_LR": float(np.std(zl, ddof=1)) if len(zl) > 1 else float("nan"),
                             "z_LR beyond +-2 [%]": 100.0 * float(np.mean(np.abs(zl) > 2))})
    return pd.DataFrame(rows)


def parted(docs: list[dict], terms: list[str]) -> bool:
    """Whether the deciding test is not the corrected LR (output error: the score test's own p) on these seeds, so
    that z_p and z_LR part."""
    return any(d["fits"][n].get("criterion") == "score test" and "z_LR" in d["fits"][n] for d in docs for n in terms)


def per_seed(docs: list[dict], terms: list[str]) -> pd.DataFrame:
    """One row per seed: each term's estimate, z and z_p; where z_p and z_LR part (:func:`parted`) also each term's
    z_LR and, over the terms, the largest |z_p| and |z_LR| with their term (a family-wise test at level a compares
    them with Phi^-1(1 - a / 2); a one-sided term's, the lags', with Phi^-1(1 - a))."""
    both = parted(docs, terms)
    keys = ("estimate", "z", "z_p") + (("z_LR",) if both else ())
    rows = []
    for d in docs:
        row = {"seed": str(d["seed"]), **{f"{n} {k}": d["fits"][n].get(k, float("nan")) for n in terms for k in keys}}
        if both:
            for k in ("z_p", "z_LR"):
                z = {n: abs(d["fits"][n][k]) for n in terms if d["fits"][n]["success"]
                     and math.isfinite(d["fits"][n][k])}
                top = max(z, key=z.get) if z else None
                row[f"largest |{k}|"] = z[top] if top else float("nan")
                row[f"largest |{k}| term"] = top or "-"
        rows.append(row)
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", required=True, help="e.g. 20261122-20261131")
    ap.add_argument("--terms", nargs="+", default=list(TERMS),
                    help=f"generic terms to estimate (default: {' '.join(TERMS)})")
    ap.add_argument("--config", default=str(ROOT / "studies" / "held_out_discovery.toml"))
    ap.add_argument("--data-config", default=str(ROOT / "data" / "bo105_synthetic.toml"))
    ap.add_argument("--out", required=True)
    ap.add_argument("--exact-inputs", action="store_true",
                    help="the recorded inputs without noise, the fit's sigmas given, into OUT/exact_inputs")
    ap.add_argument("--input-sigma-scale", type=float, default=1.0, metavar="K",
                    help="errors in variables: the input errors' sigmas times K (the lead-in's, or with "
                         "--exact-inputs the generator's), into OUT/.../input_sigma_x<K>")
    ap.add_argument("--identification", choices=("eiv", "oe"), default="eiv",
                    help="eiv: the config's input errors (default); oe: none, the measured inputs taken as exact "
                         "(into OUT/oe or OUT/exact_inputs_oe)")
    ap.add_argument("--resample-inputs", choices=RESAMPLE_INPUTS, default=None,
                    help="[data] resample_inputs for the fit (default: the config's), into OUT/.../inputs_<choice>")
    ap.add_argument("--input-error-ar", type=nonneg_int, default=None, metavar="P",
                    help="[objectives] input_error_ar for the fit: the input errors an AR(P) process fitted to the "
                         "lead-in (default: the config's), into OUT/.../input_error_ar<P>")
    ap.add_argument("--input-reference-error", action="store_true",
                    help="[objectives] input_reference_error = true for the fit: each record's lead-in reference "
                         "error estimated too, into OUT/.../input_reference_error")
    ap.add_argument("--output-error-ar", type=nonneg_int, default=None, metavar="P",
                    help="[objectives] output_error_ar for the fit: the output noise an AR(P) process fitted to the "
                         "lead-in (default: the config's), into OUT/.../output_error_ar<P>")
    a = ap.parse_args(argv)
    try:
        seeds = seeds_of(a.seeds)
    except ValueError as exc:
        ap.error(f"--seeds: {exc}")
    known = generic_names("control")
    bad = [n for n in a.terms if n not in known]
    if bad:
        ap.error(f"--terms: {', '.join(bad)} not in the generic family (e.g. {', '.join(known[-6:])})")
    config, data_config = in_file(ap, a.config, "--config"), in_file(ap, a.data_config, "--data-config")
    try:
        load_config(data_config)
        load_identification_config(config)
    except ConfigError as exc:
        ap.error(str(exc))
    if not (math.isfinite(a.input_sigma_scale) and a.input_sigma_scale > 0):
        ap.error(f"--input-sigma-scale: must be a positive number, got {a.input_sigma_scale:g}")
    for flag, key, value, what in (
            ("--input-error-ar", "input_error_ar", a.input_error_ar, "models the input errors"),
            ("--input-reference-error", "input_reference_error", a.input_reference_error or None,
             "models the input errors"),
            ("--output-error-ar", "output_error_ar", a.output_error_ar, "weighs the errors-in-variables J_time")):
        if value is not None and a.identification == "oe":
            ap.error(f"{flag}: {what}, which --identification oe has none of")
        if value is not None:
            try:
                load_identification_config(config, {"objectives": {key: value}})
            except ConfigError as exc:
                ap.error(f"{flag}: {exc}")
    if a.input_sigma_scale != 1.0 and a.identification == "oe":
        ap.error("--input-sigma-scale: scales the input errors' sigmas, which --identification oe has none of")
    sub = "_".join((["exact_inputs"] if a.exact_inputs else []) + (["oe"] if a.identification == "oe" else [])
                   + ([f"input_sigma_x{a.input_sigma_scale:g}"] if a.input_sigma_scale != 1.0 else [])
                   + ([f"inputs_{a.resample_inputs}"] if a.resample_inputs else [])
                   + ([f"input_error_ar{a.input_error_ar}"] if a.input_error_ar is not None else [])
                   + (["input_reference_error"] if a.input_reference_error else [])
                   + ([f"output_error_ar{a.output_error_ar}"] if a.output_error_ar is not None else []))
    out = out_folder(ap, a.out) / sub
    claim_inputs(ap, out, config=config, data_config=data_config)  # finished seeds are kept for a rerun
    docs = []
    for s in seeds:
        docs.append(one_seed(s, a.terms, config.resolve(), data_config.resolve(), out, a.exact_inputs,
                             a.identification, a.input_sigma_scale, a.resample_inputs, a.input_error_ar,
                             a.input_reference_error, a.output_error_ar))
        fits = docs[-1]["fits"]
        print(f"seed {s}: " + ", ".join(f"{n} c = {fits[n]['estimate']:+.4g} (z {fits[n]['z']:+.2f}, z_p "
                                        f"{fits[n]['z_p']:+.2f})" for n in a.terms),
              flush=True)
    try:
        (out / "data").rmdir()
    except OSError:
        pass
    tab, seeds_tab = summary(docs, a.terms), per_seed(docs, a.terms)
    tab.to_csv(out / "summary.csv", index=False)
    header = (f"Generic terms estimated alone in the identification NLP ({Path(a.config).name}, its free parameters "
              f"from their initial values), {len(docs)} seeds of M0 + noise"
              + (" without the recorded inputs' noise" if a.exact_inputs else "")
              + (", the measured inputs taken as exact (no input errors)" if a.identification == "oe"
                 else ", input errors estimated" + (" (sigmas given)" if a.exact_inputs else "")
                 + (f", their sigmas times {a.input_sigma_scale:g}" if a.input_sigma_scale != 1.0 else ""))
              + (f"; inputs resampled by {a.resample_inputs!r}" if a.resample_inputs else "")
              + (f"; input errors an AR({a.input_error_ar}) process" if a.input_error_ar is not None else "")
              + ("; each record's input reference error estimated" if a.input_reference_error else "")
              + (f"; output noise an AR({a.output_error_ar}) process" if a.output_error_ar is not None else "")
              + "; expected: mean c and mean z about 0 "
              f"(mean z +- {2 / np.sqrt(len(docs)):.2g}), sd z about 1, z beyond +-2 in about 4.6 % of the seeds. "
              "z = sign(c) sqrt(LR); z_p = sign(c) Phi^-1(1 - p / 2) with p the deciding test's (the LR corrected "
              "by the robust score test with input errors, the score test's own in output error), the same "
              "expectations"
              + ("; z_LR the same of the corrected LR's p, which does not decide here (per seed: the largest |z_p| "
                 "and |z_LR| over the terms)." if parted(docs, a.terms) else "."))
    (out / "summary.md").write_text(header + "\n\n" + markdown_table(tab, digits=3) + "\n\nPer seed:\n\n"
                                    + markdown_table(seeds_tab, digits=3) + "\n")
    print(tab.to_string(index=False))
    return 0


if __name__ == "__main__":
    sys.exit(main())
