"""The score test of a finished loop's iterations again, with the inputs taken as exact and with the
input errors eliminated (errors in variables), side by side.

    python studies/attribution_eiv_check.py --config studies/close_loop_eiv.toml \
        --loops docs/results/close_loop_eiv docs/results/close_loop_seeds_eiv/loop_20261127 \
        --datasets data/bo105_synthetic results/data_20261127 --out results/attribution_eiv_check
    # results/data_20261127: pyomo-heli generate-data --config data/bo105_synthetic.toml --seed 20261127 \
    #     --out results/data_20261127   (the seeds study's flight test of that seed)

For every iteration of every loop folder (its ``loop.json``: the model variant, the shape parameters
and the diagnosed parameters), rebuilds the model, prepares the loop's identification data (the
dataset named in ``loop.json``, the config's maneuvers and input reference) and runs
:func:`pyomo_heli.diagnosis.attribution.attribute` twice: ``measured`` (the inputs as exact, the test the
loops ran so far) and ``eliminated`` (``input_errors`` and ``noise_sigma`` of the config: the time
residuals weighted by the covariance the input noise gives them; only with input errors in the config, an
output-error loop's config gives the ``measured`` rows only). No identification is run. Writes
``attribution_<loop>_<iteration>_<mode>.json`` as each finishes (a rerun reuses them) and prints one
table: decision, top candidate (LM, df, p), runner-up (LM), threshold.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

from pyomo_heli.close_loop import load_loop, model_with_candidates
from pyomo_heli.config import load_identification_config as load_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.diagnosis.attribution import Attribution, attribute
from pyomo_heli.nlp.identification import identification_data


def run(config: Path, loops: list[Path], out: Path, datasets: list[Path] | None = None) -> pd.DataFrame:
    cfg = load_config(config)
    # without [objectives] input_errors (output-error loops) only the "measured" test applies
    modes = ("measured", "eliminated") if cfg.nlp.input_errors else ("measured",)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if datasets and len(datasets) != len(loops):
        raise SystemExit(f"--datasets: {len(datasets)} given for {len(loops)} loops; give one per loop or none")
    for k, loop in enumerate(loops):
        doc = load_loop(loop)
        ft = load_flight_test(datasets[k] if datasets else doc["dataset"])
        data = identification_data(cfg, ft)
        for it in doc["iterations"]:
            model = model_with_candidates(cfg.model, it["extensions"], it.get("shape_parameters"))
            model = model.with_parameters(**it["parameters"])
            for mode in modes:
                f = out / f"attribution_{loop.name}_{it['iteration']}_{mode}.json"
                if f.is_file():
                    att = Attribution.from_dict(json.loads(f.read_text()))
                else:
                    kw = (dict(input_errors=cfg.nlp.input_errors, noise_sigma=cfg.nlp.noise_sigma)
                          if mode == "eliminated" else {})
                    att = attribute(model, it["free"], data, cfg.nlp.time_outputs, cfg.nlp.trim_outputs, **kw)
                    f.write_text(json.dumps(att.to_dict(), indent=1))
                s = att.scores  # sorted by LM, wrong-sign one-sided scores last
                rows.append({"loop": loop.name, "iteration": it["iteration"],
                             "model": "M0" + "".join(" + " + n for n in it["extensions"]), "inputs": mode,
                             "decision": att.decision, "accepted": att.accepted or "",
                             "top": s.loc[0, "name"], "LM top": s.loc[0, "LM"], "df top": s.loc[0, "df"],
                             "p top": s.loc[0, "p_value"], "second": s.loc[1, "name"], "LM second": s.loc[1, "LM"],
                             "threshold": att.threshold})
                print(f"{loop.name} iteration {it['iteration']} {mode}: {att.decision} "
                      f"(top {rows[-1]['top']} LM {rows[-1]['LM top']:.3g} df {rows[-1]['df top']:.3g}, second "
                      f"{rows[-1]['second']} LM {rows[-1]['LM second']:.3g})", flush=True)
    table = pd.DataFrame(rows)
    table.to_csv(out / "attribution_eiv_check.csv", index=False)
    return table


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", type=Path, required=True, help="the loops' config (with [objectives] input_errors)")
    ap.add_argument("--loops", type=Path, nargs="+", required=True, help="close-loop results folders")
    ap.add_argument("--datasets", type=Path, nargs="+",
                    help="the loops' flight tests, one per loop (default: the dataset named in each loop.json)")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    try:
        table = run(a.config, a.loops, a.out, a.datasets)
    except FileNotFoundError as e:  # a folder without loop.json, or a loop's dataset that is gone
        raise SystemExit(f"{e} (give the flight tests with --datasets if the loops' own are gone)")
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
