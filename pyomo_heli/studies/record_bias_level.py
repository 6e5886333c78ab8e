"""How often do the records disagree on a bias when nothing is missing? Monte Carlo on the bundled records.

    python studies/record_bias_level.py --seeds 20261122-20261161 --out results/record_bias_level \
        [--config studies/held_out_discovery.toml] [--data-config data/bo105_synthetic.toml] \
        [--resample-inputs sample|project|record] [--replay fit|record]

Every seed generates the bundled flight test (``--data-config``: same maneuvers, trims and noise levels) from
**M0 with sensor noise only** (its truth effects removed, its seed replaced) into ``OUT/data/<seed>``. The
residual analysis's record-bias test (:mod:`pyomo_heli.diagnosis.record_bias`) runs on the residuals of the
exact model at the true parameters, every identification and validation record as the config prepares them
(its input-noise model: ``[objectives] input_errors`` or ``[diagnosis]``). Its p-value per output should be
uniform: below alpha at a rate alpha. Each seed's chi-squares and p-values go to ``OUT/seed_<n>.json`` as it
finishes (a rerun reuses them; the generated data are deleted once the seed is done).

Written: ``OUT/summary.csv`` and ``OUT/summary.md``: per output (and pooled) the number of tests, the mean
chi-square over its degrees of freedom, the fraction of p below 0.05 and 0.01, and the fraction of seeds the
residual analysis flags (some output below 0.01 / outputs, the diagnosis's level).
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from pyomo_heli.diagnosis.record_bias import record_bias_tests

from .seeded import cached_seed, needs_innovations, overrides_note, seeded_study_main, truth_residuals

LEVELS = (0.05, 0.01)
ALPHA = 0.01  # the residual analysis's default level


def one_seed(seed: int, config: Path, data_config: Path, out: Path, overrides: dict | None = None) -> dict:
    """The record-bias tests of one seed (read back from ``OUT/seed_<seed>.json`` when it is there)."""
    done = cached_seed(out, seed, overrides)
    if done is not None:
        return done
    f = out / f"seed_{seed}.json"
    res, data = truth_residuals(seed, config, data_config, out, overrides)
    inn = res.info["innovations"]["record_biases"]
    tests = record_bias_tests(inn, ALPHA)
    doc = {"seed": seed, "records": len(inn), "problems": res.problems,
           **({"overrides": overrides} if overrides else {}),
           "tests": {o: {"chi2": t.chi2, "df": t.df, "p": t.p, "consistent": t.consistent} for o, t in tests.items()}}
    f.write_text(json.dumps(doc, indent=1))
    shutil.rmtree(data, ignore_errors=True)
    return doc


def summary(docs: list[dict]) -> pd.DataFrame:
    rows = []
    outs = list(dict.fromkeys(o for d in docs for o in d["tests"]))
    for o in outs + ["all"]:
        ts = [t for d in docs for k, t in d["tests"].items() if o in ("all", k)]
        p = np.array([t["p"] for t in ts])
        rows.append({"output": o, "tests": len(ts),
                     "mean chi2 / df": float(np.mean([t["chi2"] / t["df"] for t in ts])),
                     **{f"p < {a:g} [%]": 100.0 * float(np.mean(p < a)) for a in LEVELS},
                     "seeds flagged [%]": 100.0 * float(np.mean([not d["tests"][o]["consistent"] for d in docs
                                                                 if o in d["tests"]]))
                     if o != "all" else
                     100.0 * float(np.mean([any(not t["consistent"] for t in d["tests"].values()) for d in docs]))})
    return pd.DataFrame(rows)


def summarise(docs: list) -> tuple[pd.DataFrame, str]:
    return summary(docs), (
        f"Record-bias test on the exact model's residuals, {len(docs)} seeds of M0 + noise ({docs[0]['records']} "
        f"records each, identification and validation{overrides_note(docs)}); expected: p < alpha in alpha of the "
        f"tests, and seeds flagged (some output below {ALPHA:g} / outputs) in about {100 * ALPHA:g} %.")


def main(argv=None) -> int:
    return seeded_study_main(__doc__.splitlines()[0], argv, one_seed, summarise, "20261122-20261161",
                             needs_innovations("the record-bias test"), data_overrides=True)


if __name__ == "__main__":
    sys.exit(main())
