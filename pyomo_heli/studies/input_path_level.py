"""How often does the input path find a signal when nothing is missing? Monte Carlo on the bundled records.

    python studies/input_path_level.py --seeds 20261122-20261161 --out results/input_path_level \
        [--config studies/held_out_discovery.toml] [--data-config data/bo105_synthetic.toml] \
        [--resample-inputs sample|project|record] [--replay fit|record] [--input-path-family standard|extended]

Every seed generates the bundled flight test (``--data-config``: same maneuvers, trims and noise levels) from
**M0 with sensor noise only** (its truth effects removed, its seed replaced) into ``OUT/data/<seed>``. The
residual analysis's input-path regression (:mod:`pyomo_heli.diagnosis.input_path`) runs on the residuals of the
exact model at the true parameters, every identification and validation record as the config prepares them (a
shift of its free parameters allowed, its input-noise model: ``[objectives] input_errors``). Nothing acts on the
control path, so a selected term is a false alarm (Bonferroni over the dictionary bounds their rate by alpha) or a
mismatch of the replay and the records, which a term's mean z over the seeds shows (docs/diagnosis.md).
Each seed's selected terms and the first step's regression (every term alone) go to ``OUT/seed_<n>.json`` as it
finishes (a rerun reuses them; the generated data are deleted once the seed is done).

Written: ``OUT/summary.csv`` and ``OUT/summary.md``: per dictionary term its first-step z over the seeds (mean
and standard deviation; a term the data hold systematically has a mean away from 0) and the share of p below 0.01,
0.05 and 0.1; and for any term the share of seeds whose smallest p times the dictionary size is below each level
(at 0.01, the residual analysis's alpha: a term selected), expected at most the level.
"""
from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from .seeded import cached_seed, needs_innovations, overrides_note, seeded_study_main, truth_residuals

LEVELS = (0.01, 0.05, 0.1)


def one_seed(seed: int, config: Path, data_config: Path, out: Path, overrides: dict | None = None) -> dict:
    """The input path of one seed (read back from ``OUT/seed_<seed>.json`` when it is there)."""
    done = cached_seed(out, seed, overrides)
    if done is not None:
        return done
    res, data = truth_residuals(seed, config, data_config, out, overrides)
    ip = res.info["innovations"]["input_path"]
    size = round(ip["alpha"] / ip["level"])  # the dictionary's size (a term a record set cannot fit is in it too)
    doc = {"seed": seed, "records": ip["records"], "problems": res.problems, "alpha": ip["alpha"], "terms": size,
           **({"overrides": overrides} if overrides else {}),
           "selected": [f"{t['channel']} += {t['estimate']:+.3g} x {t['signal']} (p = {t['p']:.2g})"
                        for t in ip["terms"]],
           "first step smallest p": min((r["p"] for r in ip["first"]), default=1.0),
           "first step": {f"{r['channel']} x {r['signal']}": {k: r[k] for k in ("estimate", "se", "z", "p")}
                          for r in ip["first"]}}
    (out / f"seed_{seed}.json").write_text(json.dumps(doc, indent=1))
    shutil.rmtree(data, ignore_errors=True)
    return doc


def below(doc: dict, level: float) -> bool:
    """Does the seed's first step have a term below ``level`` / dictionary size (the Bonferroni-adjusted smallest p
    below ``level``)? At alpha it is a term selected."""
    return doc["first step smallest p"] * doc["terms"] < level


def summary(docs: list[dict]) -> pd.DataFrame:
    """Per dictionary term, its first-step z over the seeds (mean, standard deviation: 0 and 1 when nothing is
    missing) and how often its p falls below 0.01 and 0.05; last, any term: the Bonferroni-adjusted smallest p
    below each level (:func:`below`; at 0.01 a term selected)."""
    rows = []
    for term in docs[0]["first step"]:
        z = np.array([d["first step"][term]["z"] for d in docs if term in d["first step"]])
        p = np.array([d["first step"][term]["p"] for d in docs if term in d["first step"]])
        rows.append({"term": term, "seeds": len(z), "mean z": float(np.mean(z)), "sd z": float(np.std(z, ddof=1))
                     if len(z) > 1 else float("nan"), **{f"p < {a:g} [%]": 100.0 * float(np.mean(p < a))
                                                        for a in LEVELS}})
    rows.append({"term": "any (smallest p x terms)", "seeds": len(docs), "mean z": float("nan"), "sd z": float("nan"),
                 **{f"p < {a:g} [%]": 100.0 * float(np.mean([below(d, a) for d in docs])) for a in LEVELS}})
    return pd.DataFrame(rows)


def summarise(docs: list) -> tuple[pd.DataFrame, str]:
    hits = [f"seed {d['seed']}: {'; '.join(d['selected'])}" for d in docs if d["selected"]]
    return summary(docs), (
        f"Input-path regression on the exact model's residuals, {len(docs)} seeds of M0 + noise "
        f"({docs[0]['records']} records each, identification and validation{overrides_note(docs)}; "
        f"{docs[0]['terms']} terms, alpha "
        f"{docs[0]['alpha']:g}); expected: mean z about 0 (+- {2 / np.sqrt(len(docs)):.2g}), sd z about 1, p below "
        f"each level in that share of the seeds, and any term below it at most so often. Terms selected (false "
        f"alarms): {len(hits)} of {len(docs)} seeds" + (" (" + ", ".join(hits) + ")" if hits else "") + ".")


def main(argv=None) -> int:
    return seeded_study_main(__doc__.splitlines()[0], argv, one_seed, summarise, "20261122-20261161",
                             needs_innovations("the input path"), data_overrides=True,
                             input_path_family=True)


if __name__ == "__main__":
    sys.exit(main())
