"""How often does the validation rule's paired test fire when no output got worse? Monte Carlo on the bundled records.

    python studies/validation_test_level.py --seeds 20261122-20261147 --out results/validation_test_level \
        [--config studies/held_out_discovery.toml] [--data-config data/bo105_synthetic.toml]

Every seed generates the bundled flight test (``--data-config``: same maneuvers, trims and noise levels) from
**M0 with sensor noise only** (its truth effects removed, its seed replaced) into ``OUT/data/<seed>``. On the
config's validation records, as the loop replays them, the noise of each output is n = data - truth replay
(:func:`~pyomo_heli.report.identification.truth_prediction`), and e0 = truth replay - M0 at the config's
initial parameters (a model error of realistic shape). Two models with residuals r0 = n + e0 and r1 = n - e0
have errors of equal energy, so a rise of the validation error from one to the other is pure noise:
the one-sided p of the rule's test (:func:`~pyomo_heli.diagnosis.validation_change.mean_square_change`, in
both directions) should fall below alpha at a rate alpha. It is computed with the rule's batches (whole
records) and, for comparison, with 1 s batches, which ignore the colour of the noise beyond a second. Each
seed's p-values go to ``OUT/seed_<n>.json`` as it finishes (a rerun reuses them).

The same for the validation rule's joint test of all outputs at once
(:func:`~pyomo_heli.diagnosis.validation_change.joint_mean_square_change` on every output's r0 and r1); it
standardises each output by the first model's mean square, so its two directions are not p and 1 - p.

Written: ``OUT/summary.csv`` and ``OUT/summary.md``: per batch choice and output (all outputs' tests pooled, and
the joint test), the number of tests (seeds x 2 directions) and the fraction with p < 0.05 and p < 0.01. The two
directions of one seed are not independent draws (p and 1 - p).
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.diagnosis.validation_change import joint_mean_square_change, mean_square_change
from pyomo_heli.nlp.identification import validation_maneuvers
from pyomo_heli.report.identification import VALIDATION_OUTPUTS, predict, truth_prediction

from .seeded import cached_seed, m0_noise_data, seeded_study_main

#: batch choices: name -> batch length [s] (None: whole records, the rule's)
BATCHES = {"whole records": None, "1 s": 1.0}
LEVELS = (0.05, 0.01)


def one_seed(seed: int, config: Path, data_config: Path, out: Path) -> dict:
    """The p-values of one seed (read back from ``OUT/seed_<seed>.json`` when it is there)."""
    done = cached_seed(out, seed)
    if done is not None:
        return done
    f = out / f"seed_{seed}.json"
    data = m0_noise_data(seed, data_config, out)
    cfg = load_identification_config(config, overrides={"data": {"dataset": str(data)}})
    val = validation_maneuvers(cfg, load_flight_test(data))
    if not val:
        raise ValueError(f"{config}: [data] validation selects no records")
    truth = truth_prediction(data, [], val)
    m0 = predict("initial", cfg.model, {f.name: f.initial for f in cfg.free}, [], val)
    dt = float(np.median(np.diff(val[0].t)))
    doc = {"seed": seed, "records": len(val), "p": {}, "joint": {}}
    R0, R1 = {}, {}
    for o in VALIDATION_OUTPUTS:
        n = [mv.data[o].to_numpy(float) - truth.maneuvers[mv.name][o].to_numpy(float) for mv in val]
        e0 = [truth.maneuvers[mv.name][o].to_numpy(float) - m0.maneuvers[mv.name][o].to_numpy(float) for mv in val]
        r0, r1 = [a + b for a, b in zip(n, e0)], [a - b for a, b in zip(n, e0)]
        R0[o], R1[o] = r0, r1
        for name, seg_s in BATCHES.items():
            seg = None if seg_s is None else max(int(round(seg_s / dt)), 1)
            doc["p"][f"{name}|{o}"] = [mean_square_change(r0, r1, seg).p_rise, mean_square_change(r1, r0, seg).p_rise]
    for name, seg_s in BATCHES.items():  # all outputs at once, as the validation rule's joint row
        seg = None if seg_s is None else max(int(round(seg_s / dt)), 1)
        doc["joint"][name] = [joint_mean_square_change(a, b, seg).p_rise for a, b in ((R0, R1), (R1, R0))]
    f.write_text(json.dumps(doc, indent=1))
    return doc


def summary(docs: list[dict]) -> pd.DataFrame:
    rows = []
    for name in BATCHES:
        for o in list(VALIDATION_OUTPUTS) + ["all"]:
            ps = np.array([p for d in docs for k, v in d["p"].items() for p in v
                           if k.split("|")[0] == name and (o == "all" or k.split("|")[1] == o)])
            if ps.size:
                rows.append({"batches": name, "output": o, "tests": int(ps.size),
                             **{f"p < {a:g} [%]": 100.0 * float(np.mean(ps < a)) for a in LEVELS}})
        ps = np.array([p for d in docs for p in d.get("joint", {}).get(name, [])])
        if ps.size:
            rows.append({"batches": name, "output": "joint (all outputs at once)", "tests": int(ps.size),
                         **{f"p < {a:g} [%]": 100.0 * float(np.mean(ps < a)) for a in LEVELS}})
    return pd.DataFrame(rows)


def summarise(docs: list) -> tuple[pd.DataFrame, str]:
    return summary(docs), (
        f"Paired validation test under equal error energy, {len(docs)} seeds of M0 + noise "
        f"({docs[0]['records']} validation records each); expected: p < alpha in alpha of the tests.")


def main(argv=None) -> int:
    return seeded_study_main(__doc__.splitlines()[0], argv, one_seed, summarise, "20261122-20261147")


if __name__ == "__main__":
    sys.exit(main())
