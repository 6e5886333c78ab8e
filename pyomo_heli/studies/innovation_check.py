"""Does the residual analysis call the exact model "not white"? The plain whiteness test against the innovations.

    python studies/innovation_check.py [--config studies/close_loop_eiv.toml] [--dataset DIR [DIR ...]]
                                       [--loop DIR] [--out results/innovation_check]

The truth model of the dataset (``truth.json``: its parameters and effects; read only by this study) is
diagnosed at the true parameters twice: with the config's ``[objectives] input_errors`` (whiteness tested
on the residuals' innovations, :mod:`pyomo_heli.diagnosis.innovations`) and without them (the plain test on
the nuisance-cleaned residuals). Nothing is missing from that model, so a "not white" is a false alarm.
With ``--loop`` the diagnosed point of every iteration of a finished ``close-loop`` folder is diagnosed the
same two ways (the loop's own verdict uses the config as it is). Prints the verdicts, the tests that
fail and how the p-values spread (counts below 0.05 and 0.01, median); writes ``OUT/whiteness.csv``
(every test) and ``OUT/summary.csv``, a row per dataset, model and series. With several ``--dataset`` (noise
realisations of one flight test; no ``--loop``) also ``OUT/pooled.csv``: per series the share of all their
p-values below 0.05, 0.01 and 0.001 and how many datasets each verdict had.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import pandas as pd

from pyomo_heli.config import ConfigError, load_identification_config
from pyomo_heli.diagnosis.analysis import diagnose
from pyomo_heli.diagnosis.residuals import compute_residuals
from pyomo_heli.flighttest.generate import truth_model_of
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.report.identification import read_truth
from pyomo_heli.report.loop import iteration_model

from .args import flight_test_folder, in_file

ROOT = Path(__file__).resolve().parents[2]  # the checkout: studies/, data/


def cases(cfg, loop: Path | None) -> list[tuple[str, HelicopterModel, dict, bool]]:
    """(name, model, parameters, shift): the truth model at its parameters (no parameter shift in the trim
    shape test: nothing was identified), and each loop iteration at its diagnosed point (the shift of its
    free parameters allowed, as the loop's own verdict does)."""
    tm = truth_model_of(cfg.dataset)
    out = [("truth model", tm, tm.parameters.to_dict(), False)]
    if loop is not None:
        for it in json.loads((loop / "loop.json").read_text())["iterations"]:
            out.append((f"loop iteration {it['iteration']}", iteration_model(cfg.model, it), it["parameters"], True))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, default=ROOT / "studies" / "close_loop_eiv.toml")
    ap.add_argument("--dataset", type=Path, nargs="+",
                    help="other datasets than the config's (same maneuver names): each diagnosed, then pooled")
    ap.add_argument("--loop", type=Path, help="a finished close-loop folder: diagnose its iterations too")
    ap.add_argument("--out", type=Path, default=Path("results/innovation_check"))
    a = ap.parse_args(argv)
    try:
        cfg = load_identification_config(in_file(ap, a.config, "--config"))
    except ConfigError as exc:
        ap.error(str(exc))
    if not cfg.nlp.input_errors:
        ap.error(f"--config {a.config}: [objectives] input_errors is empty; the innovations need it")
    if a.dataset and len(a.dataset) > 1 and a.loop:
        ap.error("--loop: a loop belongs to one dataset; give one --dataset with it")
    datasets = [flight_test_folder(ap, d, "--dataset") for d in a.dataset] if a.dataset else [Path(cfg.dataset)]
    if a.loop and not (a.loop / "loop.json").is_file():
        ap.error(f"--loop {a.loop}: no loop.json there")
    no_truth = [d for d in datasets if read_truth(d) is None]
    if no_truth:
        where = f"--dataset {no_truth[0]}" if a.dataset else f"--config {a.config}: its dataset {no_truth[0]}"
        ap.error(f"{where}: no truth.json; this study needs the truth simulator's parameters")
    names = [d.name for d in datasets]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:  # the tables name a dataset by its folder
        ap.error(f"--dataset: two datasets in folders named {twice[0]!r}; give each its own folder name")
    a.out.mkdir(parents=True, exist_ok=True)
    rows, tests = [], []
    for dataset in datasets:
        r, t = diagnose_dataset(dataclasses.replace(cfg, dataset=dataset), a.loop)
        rows += [{"dataset": dataset.name, **x} for x in r]
        tests += [x.assign(dataset=dataset.name) for x in t]
    summary = pd.DataFrame(rows)
    summary.to_csv(a.out / "summary.csv", index=False)
    every = pd.concat(tests, ignore_index=True)
    every.to_csv(a.out / "whiteness.csv", index=False, float_format="%.6g")
    print(summary.drop(columns="failing").to_string(index=False))
    if len(datasets) > 1:
        pooled = pooled_table(summary, every)
        pooled.to_csv(a.out / "pooled.csv", index=False)
        print(pooled.to_string(index=False))
    return 0


def pooled_table(summary: pd.DataFrame, tests: pd.DataFrame) -> pd.DataFrame:
    """Per model and series over the datasets: how many, the tests, the share of their p-values below 0.05, 0.01
    and 0.001 [%] (about 5, 1 and 0.1 when the null distribution is right), and the datasets whose verdict was
    noise only."""
    out = []
    for (model, series), w in tests.groupby(["model", "whiteness_of"], sort=False):
        s = summary[(summary["model"] == model) & (summary["whiteness of"] == series)]
        out.append({"model": model, "whiteness of": series, "datasets": int(s["dataset"].nunique()),
                    "tests": len(w), **{f"p < {q:g} [%]": 100.0 * float((w["p"] < q).mean())
                                        for q in (0.05, 0.01, 0.001)},
                    "noise only (datasets)": int(s["noise only"].astype(bool).sum())})
    return pd.DataFrame(out)


def diagnose_dataset(cfg, loop: Path | None) -> tuple[list[dict], list[pd.DataFrame]]:
    """The summary rows and the whiteness tests of the truth model (and ``loop``'s iterations) on ``cfg``'s
    dataset, each with the config's input errors (innovations) and without (plain)."""
    rows, tests = [], []
    for name, model, params, shift in cases(cfg, loop):
        # the plain test: no input noise in the residual analysis (its [diagnosis] settings too, which a config's
        # [diagnosis] table fixes at load: replacing the NLP's input errors alone left the innovations in)
        plain = dataclasses.replace(cfg.diagnosis_settings, input_noise=())
        for series, nlp, diag in (("innovations", cfg.nlp, cfg.diagnosis),
                                  ("plain", dataclasses.replace(cfg.nlp, input_errors=()), plain)):
            c = dataclasses.replace(cfg, model=model, nlp=nlp, diagnosis=diag)
            d = diagnose(compute_residuals(c, params, label=name, trim_sensitivities=shift))
            w = pd.DataFrame(d.whiteness)
            w = w[w["p"].notna()]  # the tests that ran (a NaN p: too few samples)
            bad = w[~w["white"].astype(bool)]
            rows.append({"model": name, "whiteness of": series, "noise only": d.verdict["noise_only"],
                         "trim shapes": ", ".join(f"{k} {v}" for k, v in d.verdict["trim_shape"].items()),
                         "not white (id)": int((bad["role"] == "identification").sum()),
                         "not white (val)": int((bad["role"] == "validation").sum()), "tests": len(w),
                         # the p-values' spread: about 5 %, 1 % and 0.5 when the null distribution is right
                         "p < 0.05": int((w["p"] < 0.05).sum()), "p < 0.01": int((w["p"] < 0.01).sum()),
                         "median p": float(w["p"].median()),
                         "failing": "; ".join(f"{r.output} in {r.maneuver} (p = {r.p:.1e})" for r in bad.itertuples())})
            tests.append(w.assign(model=name, whiteness_of=series))
            print(f"{Path(cfg.dataset).name}: {name}, {series}: noise only = {d.verdict['noise_only']}; "
                  f"not white: {rows[-1]['failing'] or 'none'}", flush=True)
    return rows, tests


if __name__ == "__main__":
    sys.exit(main())
