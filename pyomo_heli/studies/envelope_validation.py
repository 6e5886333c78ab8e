"""Validation of a closed loop's first and last models on an independent flight test across the speed range.

    python studies/envelope_validation.py --loops docs/results/close_loop_eiv docs/results/close_loop \
        --out results/envelope_validation [--data-config studies/validation_envelope.toml] [--data DIR]

Why: the bundled flight test validates at 80 kt only (two doublets, as the paper's Fig. 6), where the
rotor wake on the tail that M0 lacks does not act. Its validation RMS can then only compare two models
that are both close to the truth there, against the sensor noise: issue 5's "validation RMS does not rise
on any output" is decided by the noise draw of two records. This study replays the loop's first
(M0) and last models on another flight test of the same truth, made by ``--data-config`` (default
``studies/validation_envelope.toml``: lon and col doublets at hover, 20, 40, 60, 80 and 100 kt, another
noise seed; generated into ``OUT/data`` unless ``--data`` names a folder), and reports per output:

- the RMS of data minus model before and after, pooled over every maneuver, with the loop report's paired
  test of the change (Diebold-Mariano, batch means over whole records, one-sided p of a rise);
- the same per speed;
- evaluation only (reads the data's ``truth.json``): the RMS of model minus the truth simulator replayed
  the same way (the model error without the sensor noise), and the truth model's own data-minus-model RMS.

Nothing is fitted: the models are the loop's, replayed with the float simulator from their own trims and
driven by the measured input increments (as the loop report does). Written: ``OUT/envelope_validation.md``
and ``OUT/envelope_validation.csv`` (one row per loop, speed group and output); each loop's rows go to
``OUT/loops/`` as soon as they are done, and a rerun reuses them while the loop and the data are unchanged.
"""
from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd

from pyomo_heli.studies.commands import run_command
from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.nlp.identification import prepare_data
from pyomo_heli.report import plots
from pyomo_heli.report.identification import VALIDATION_OUTPUTS, predict
from pyomo_heli.report.loop import (iteration_model, label, speed_groups, truth_replay_errors,
                                    validation_change_table)

ROOT = Path(__file__).resolve().parents[2]  # the checkout: studies/, data/


def loop_config(loop: Path, doc: dict, data: Path):
    """The loop's config (as named in its loop.json), its dataset replaced by ``data``."""
    path = Path(doc["config"])
    for p in (path, ROOT / path, loop / path):
        if p.is_file():
            return load_identification_config(p, {"data": {"dataset": str(data.resolve()), "validation": "validation"}})
    raise SystemExit(f"{loop / 'loop.json'}: its config {doc['config']} was not found")


def evaluate(loop: Path, data: Path) -> pd.DataFrame:
    """Rows (speed group, output) for the first and last iteration of the loop in ``loop``."""
    doc = json.loads((loop / "loop.json").read_text())
    cfg = loop_config(loop, doc, data)
    mans = list(prepare_data(load_flight_test(data), "validation", input_reference_s=cfg.input_reference_s).maneuvers)
    first, last = doc["iterations"][0], doc["iterations"][-1]
    preds = [predict(label(it), iteration_model(cfg.model, it), it["parameters"], [], mans) for it in (first, last)]
    failed = [p for pr in preds for p in pr.problems]
    if failed:
        raise SystemExit(f"{loop}: replay problems on {data}: {failed}")
    groups = [("all", mans)] + [(f"{kt:.0f} kt", group) for kt, group in speed_groups(mans)]
    doc_fl = {**doc, "iterations": [first, last]}  # model minus truth for the two models compared
    rows = []
    for name, group in groups:
        change = validation_change_table(preds[0], preds[1], group).set_index("output")
        truth = truth_replay_errors(cfg, doc_fl, group)
        for o in VALIDATION_OUTPUTS:
            c = change.loc[o]
            row = {"loop": str(loop), "speeds": name, "maneuvers": len(group), "output": o, "unit": c["unit"],
                   "RMS before": c["RMS before"], "RMS after": c["RMS after"], "change %": c["change [%]"],
                   "p (rise)": c["p (rise)"], "significant rise": bool(c["significant rise"])}
            if truth is not None:
                errs, floor = truth
                mt0, mt1 = errs[0][o], errs[1][o]
                row.update({"truth model RMS": float(plots.shown(o, floor[o])),
                            "model-truth before": float(plots.shown(o, mt0)),
                            "model-truth after": float(plots.shown(o, mt1)),
                            "model-truth change %": 100.0 * (mt1 / mt0 - 1.0)})
            rows.append(row)
    return pd.DataFrame(rows)


def evaluate_saved(loop: Path, data: Path, folder: Path) -> pd.DataFrame:
    """:func:`evaluate`, each loop's rows written to ``folder`` as soon as they are done and read back by a rerun
    while the loop's ``loop.json`` and the flight test's files are the same (a SHA-256 of both in the file name;
    the manifest alone is the same for every seed), so that an interrupted study resumes."""
    from pyomo_heli.provenance import dataset_sha256

    key = hashlib.sha256((loop / "loop.json").read_bytes() + dataset_sha256(data).encode()).hexdigest()[:16]
    name = "_".join(p for p in Path(loop).parts if p not in ("/", ".", ".."))
    f = folder / f"{name}_{key}.csv"
    if f.is_file():
        return pd.read_csv(f)
    tab = evaluate(loop, data)
    folder.mkdir(parents=True, exist_ok=True)
    tab.to_csv(f.with_suffix(".tmp"), index=False)
    f.with_suffix(".tmp").replace(f)
    return pd.read_csv(f)  # the same types whether just computed or read back


def markdown(tab: pd.DataFrame, data: Path) -> str:
    lines = ["# Validation across the speed range (`studies/envelope_validation.py`)", "",
             f"Flight test: `{data}`. Before = the loop's iteration 0 (M0), after = its last iteration. RMS of data "
             "minus model in display units; p (rise) = one-sided paired test of a rise (significant below 0.01); "
             "model-truth = RMS of model minus the truth simulator replayed the same way (evaluation only).", ""]
    for loop, t in tab.groupby("loop", sort=False):
        lines += [f"## {loop}", "", "All maneuvers pooled:", ""]
        a = t[t["speeds"] == "all"]
        cols = [c for c in ("output", "unit", "RMS before", "RMS after", "change %", "p (rise)", "truth model RMS",
                            "model-truth before", "model-truth after", "model-truth change %") if c in a]
        lines += _table(a[cols])
        per = t[t["speeds"] != "all"]
        lines += ["", "Change of data minus model [%] per speed (model minus truth [%] in brackets):", ""]
        wide = []
        for sp, g in per.groupby("speeds", sort=False):
            r = {"speeds": sp}
            for _, x in g.iterrows():
                mt = f" ({x['model-truth change %']:+.0f})" if "model-truth change %" in x else ""
                r[x["output"]] = f"{x['change %']:+.1f}{mt}"
            wide.append(r)
        lines += _table(pd.DataFrame(wide)) + [""]
        rises = [f"{r['speeds']} {r['output']} {r['change %']:+.2f} % (p = {r['p (rise)']:.3g})"
                 for _, r in t.iterrows() if r["change %"] > 0]
        lines += ["Rises of data minus model: " + ("; ".join(rises) or "none"), ""]
    return "\n".join(lines)


def _table(df: pd.DataFrame) -> list[str]:
    def fmt(col, v):
        if not isinstance(v, (float, np.floating)):
            return str(v)
        if "change" in col:
            return f"{v:+.2f}"
        return f"{v:.3g}" if col.startswith("p ") else f"{v:.4g}"

    return (["| " + " | ".join(df.columns) + " |", "|" + "---|" * len(df.columns)]
            + ["| " + " | ".join(fmt(c, v) for c, v in zip(df.columns, r)) + " |" for r in df.itertuples(index=False)])


def main(argv=None) -> int:
    from .args import claim_inputs, flight_test_folder, in_file, out_folder
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loops", type=Path, nargs="+", required=True, help="close-loop results folders")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--data-config", type=Path, default=ROOT / "studies" / "validation_envelope.toml")
    ap.add_argument("--data", type=Path, help="an existing flight-test folder (default: generate OUT/data)")
    a = ap.parse_args(argv)
    for p in a.loops:
        if not (p / "loop.json").is_file():
            ap.error(f"--loops {p}: no loop.json there (a close-loop results folder is needed)")
    data = a.data or a.out / "data"
    if a.data is None and not (data / "manifest.json").is_file():
        in_file(ap, a.data_config, "--data-config")
    out_folder(ap, a.out).mkdir(parents=True, exist_ok=True)
    if a.data is None:  # OUT/data is generated once: refused when --data-config has changed since
        claim_inputs(ap, a.out, data_config=in_file(ap, a.data_config, "--data-config"))
    if a.data is None and not (data / "manifest.json").is_file():
        run_command(["generate-data", "--config", str(a.data_config), "--out", str(data)])
    flight_test_folder(ap, data, "--data")
    tab = pd.concat([evaluate_saved(p, data, a.out / "loops") for p in a.loops], ignore_index=True)
    tab.to_csv(a.out / "envelope_validation.csv", index=False)
    text = markdown(tab, data)
    (a.out / "envelope_validation.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
