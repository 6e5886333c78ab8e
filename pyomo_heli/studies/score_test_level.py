"""How often does the loop's score test fire when no effect is missing? Monte Carlo on small M0 instances.

    python studies/score_test_level.py --seeds 101-140 --out results/score_test_level [--identification eiv|oe]
                                       [--truth m0|wake]

Every seed generates the small wake instance's flight test (:mod:`pyomo_heli.studies.small_instances`, the
close-loop tests' instance: a 20 kt lon doublet and an 80 kt lon 3-2-1-1 for identification, 6 s each with
a 2 s lead-in, 11 level trims; 80 kt validation doublet unused) from **M0 with sensor noise only**, so every
candidate's true strength is zero. It identifies twist and CL_alpha_HT (2 front points, the Eq. 11 point
solved directly, as the loop diagnoses),
with the measured col and lon errors estimated (``--identification eiv``, the default:
``[objectives] input_errors``, sigmas from the 1.9 s lead-in) or without (``oe``), and scores the whole
candidate library at that point (:func:`pyomo_heli.diagnosis.attribution.attribute`, robust) twice: with
the inputs taken as exact (``measured``) and, for ``eiv``, with the input errors eliminated
(``eliminated``). Each seed's scores go to ``OUT/<identification>/seed_<n>.json`` as it finishes (a rerun
reuses them).

Printed: per score mode, over all (seed, candidate) pairs, the fraction of p-values below 0.05, 0.01 and
0.001 (with a correct null distribution about 5, 1 and 0.1 %; a one-sided candidate's p is half the
two-sided one, or 1 for the wrong sign), the median degrees of freedom of the batch-means variance, the
number of seeds with a candidate significant at the loop's level (alpha = 0.01 over the 10 candidates)
and the number on which the loop would have accepted one (with the ratio rule); each twice: with the
loop's reference F(1, df) and with the same LM referred to chi-square(1), the reference before the df
correction (rows "chi2(1)"; the ratio rule is not re-evaluated there). The candidates'
scores within one seed are correlated, so the pairs are not independent draws.

``--trims``: the same question for the trim-only score test of ``pyomo-heli trim-loop``
(:mod:`pyomo_heli.studies.trim_score_level`, its own options).

``--truth wake`` measures the power instead: the same records from M0 + the wake-on-tail truth effect of
the small wake test (K_lamT 1.5), twist, CL_alpha_HT and Iyy identified on 3 front points as in that
test; the column ``decisions`` counts what the loop's first round would do (the candidate accepted, or
none / ambiguous / confounded).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats

from pyomo_heli.config import load_identification_config
from pyomo_heli.diagnosis.attribution import SEGMENT_S, Attribution, attribute
from pyomo_heli.diagnosis.candidates import make_candidate
from pyomo_heli.workflows.identify import run_identification
from pyomo_heli.nlp.identification import RESAMPLE_INPUTS, identification_data
from pyomo_heli.parallel import check_dask_flags

from . import small_instances as T
from .args import claim_inputs, nonneg_int, out_folder, positive_float

EIV = '\n[objectives]\ninput_errors = ["col", "lon"]\n'

WAKE = "[truth.effects.wake_on_tail]\nK_lamT = 1.5\nd_t = 1.8\ns_w = 0.5\n"


def variant(segment_s: float = SEGMENT_S, variance: str = "batch") -> str:
    """File-name suffix of a score-test variant ("" for the loop's own test)."""
    return (("" if segment_s == SEGMENT_S else f"_segment_{segment_s:g}")
            + ("" if variance == "batch" else f"_{variance}"))


def one_seed(seed: int, identification: str, out: Path, rescore: bool = False, segment_s: float = SEGMENT_S,
             truth: str = "m0", variance: str = "batch", resample_inputs: str = "sample") -> dict:
    f = out / f"seed_{seed}{variant(segment_s, variance)}.json"
    root = out / f"work_{seed}"
    if f.is_file() and not rescore:
        return json.loads(f.read_text())
    if (out / f"seed_{seed}.json").is_file():
        f0 = out / f"seed_{seed}.json"
        # score again at the saved identified point (the score test changed, the identification did not)
        # the resampling the point was identified with: work folders written before the key existed lack it
        cfg = load_identification_config(root / "ident.toml", {"data": {"resample_inputs": resample_inputs}})
        point = {"parameters": json.loads(f0.read_text())["parameters"]}
    else:
        # m0: the false-positive control's set-up; wake: the small wake test's (three parameters, three points)
        kw = (dict(free=("theta_twist", "CL_alpha_HT"), points=2) if truth == "m0"
              else dict(effect=WAKE, free=("theta_twist", "CL_alpha_HT", "Iyy"), points=3))
        cfg = T.make_case(root, seed=seed, loop=EIV if identification == "eiv" else "", maneuvers=T.WAKE_MANEUVERS,
                          input_reference_s=1.9, resample_inputs=resample_inputs, **kw)
        res = run_identification(cfg, root / "ident", progress=lambda s: None)
        point = res.direct if res.direct and res.direct.get("success") else res.chosen
    data = identification_data(cfg)
    model = cfg.model.with_parameters(**point["parameters"])
    doc = {"seed": seed, "identification": identification, "parameters": point["parameters"], "modes": {}}
    modes = {"measured": {}}
    if identification == "eiv":
        modes["eliminated"] = dict(input_errors=cfg.nlp.input_errors, noise_sigma=cfg.nlp.noise_sigma)
    for mode, kw in modes.items():
        att = attribute(model, [f.name for f in cfg.free], data, cfg.nlp.time_outputs, cfg.nlp.trim_outputs,
                        segment_s=segment_s, robust=variance != "white",
                        variance="white" if variance == "white_offsets" else "batch", **kw)
        doc["modes"][mode] = att.to_dict()
    f.write_text(json.dumps(doc, indent=1))
    return doc


def seed_task(task: tuple) -> dict:
    """``one_seed(*task)`` as a task of a Dask worker."""
    return one_seed(*task)


def seeds_of(text: str) -> list[int]:
    """'101-140' or '101,105,110-115' as a list of seeds (integers >= 0); ValueError naming the part."""
    out = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        try:
            seeds = list(range(int(a), int(b) + 1)) if b else [int(a)]
        except ValueError:
            raise ValueError(f"cannot read {part!r}; give integers >= 0 and ranges, e.g. 101-140 or "
                             f"101,105,110-115") from None
        if not seeds:
            raise ValueError(f"{part!r} is an empty range (write the lower seed first)")
        out += seeds
    return out


def summary(docs: list[dict]) -> pd.DataFrame:
    rows = []
    for mode in docs[0]["modes"]:
        scores = pd.concat([pd.DataFrame(d["modes"][mode]["scores"]).assign(seed=d["seed"]) for d in docs])
        atts = [Attribution.from_dict(d["modes"][mode]) for d in docs]
        # the same LM against chi-square(1), the reference before the df correction (one-sided: half, or 1)
        one = scores["p_value"] < 1.0
        half = np.where(scores["name"].map(lambda n: make_candidate(n).one_sided), 0.5, 1.0)
        p_chi2 = np.where(one, stats.chi2.sf(scores["LM"], 1) * half, 1.0)
        level = atts[0].alpha / len(atts[0].scores)
        sig_chi2 = pd.Series(p_chi2 < level).groupby(scores["seed"].to_numpy()).any()
        rows.append({"scores": mode, "reference": "chi2(1)", "seeds": len(docs), "pairs": len(scores),
                     "p < 0.05": float(np.mean(p_chi2 < 0.05)), "p < 0.01": float(np.mean(p_chi2 < 0.01)),
                     "p < 0.001": float(np.mean(p_chi2 < 0.001)), "median df": float("inf"),
                     "seeds with a significant candidate": int(sig_chi2.sum()), "seeds accepting": None})
        rows.append({"scores": mode, "reference": "F(1, df)", "seeds": len(docs), "pairs": len(scores),
                     "p < 0.05": float(np.mean(scores["p_value"] < 0.05)),
                     "p < 0.01": float(np.mean(scores["p_value"] < 0.01)),
                     "p < 0.001": float(np.mean(scores["p_value"] < 0.001)),
                     "median df": float(scores["df"].median()) if "df" in scores else float("inf"),
                     "seeds with a significant candidate": int(sum(bool(a.scores["significant"].any()) for a in atts)),
                     "seeds accepting": int(sum(a.decision == "accepted" for a in atts)),
                     "decisions": ", ".join(f"{k} {v}" for k, v in pd.Series(
                         [a.accepted if a.decision == "accepted" else a.decision for a in atts]
                     ).value_counts().items())})
    return pd.DataFrame(rows)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    if "--trims" in argv:  # the trim-only score test: its own study and options
        from .trim_score_level import main as trim_main

        argv.remove("--trims")
        return trim_main(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trims", action="store_true",
                    help="the trim-only score test on synthetic trim sets instead "
                         "(pyomo_heli.studies.trim_score_level; --trims --help lists its options)")
    ap.add_argument("--seeds", required=True, help="e.g. 101-140 or 101,105,110-115")
    ap.add_argument("--identification", choices=("eiv", "oe"), default="eiv")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--truth", choices=("m0", "wake"), default="m0",
                    help="m0: noise only (the level); wake: M0 + the wake-on-tail truth effect of the small wake "
                         "test, identified like that test (the power), into OUT/<identification>_wake")
    ap.add_argument("--segment-s", type=positive_float, default=SEGMENT_S,
                    help="batch-means segment length [s] of the score test (default: the loop's); other values "
                         "score the finished seeds' identified points into seed_<n>_segment_<s>.json")
    ap.add_argument("--variance", choices=("batch", "white", "white_offsets"), default="batch",
                    help="batch: the loop's robust test; white: the plain test (variance F, no input-offset "
                         "nuisance; in the eliminated mode the input-noise colour is in the whitening), scored at "
                         "the finished seeds' identified points into seed_<n>_white.json; white_offsets: the "
                         "input-offset nuisance projected off as in the loop's test, variance F, into "
                         "seed_<n>_white_offsets.json")
    ap.add_argument("--resample-inputs", choices=RESAMPLE_INPUTS, default="sample",
                    help="[data] resample_inputs of the instances (default sample: the committed numbers were "
                         "made so, before project became the config default)")
    ap.add_argument("--workers", type=nonneg_int, default=0,
                    help="run the seeds on a Dask LocalCluster of this many processes (default 0: one after the "
                         "other in this process)")
    ap.add_argument("--scheduler", metavar="ADDRESS", help="run the seeds on the Dask cluster of this scheduler "
                                                          "(its workers must see --out)")
    ap.add_argument("--rescore", action="store_true",
                    help="score the finished seeds again at their saved identified points (no identification)")
    a = ap.parse_args(argv)
    try:
        check_dask_flags(a.workers, a.scheduler)
    except ValueError as exc:
        ap.error(str(exc))
    try:
        seeds = seeds_of(a.seeds)
    except ValueError as exc:
        ap.error(f"--seeds: {exc}")
    out = out_folder(ap, a.out) / (a.identification if a.truth == "m0" else f"{a.identification}_wake")
    # finished seeds are kept for a rerun (--rescore scores them again): refused when made with other inputs
    claim_inputs(ap, out, resample_inputs=a.resample_inputs)
    docs = []
    from pyomo_heli.log import configure_console
    from pyomo_heli.parallel import dask_executor, run_tasks

    configure_console()

    def report(task, doc):
        tops = {m: d["scores"][0] for m, d in doc["modes"].items()}
        print(f"seed {task[0]}: " + "; ".join(f"{m} top {r['name']} LM {r['LM']:.3g} (df {r['df']:.3g}, "
                                               f"p {r['p_value']:.2g})" for m, r in tops.items()), flush=True)

    tasks = [(s, a.identification, out.resolve(), a.rescore, a.segment_s, a.truth, a.variance, a.resample_inputs)
             for s in seeds]
    # one seed per task: here one after the other (--workers 0), on a LocalCluster or on --scheduler's cluster;
    # a seed's scores depend only on its seed, so they are the same wherever it ran
    with dask_executor(a.workers, a.scheduler) as ex:
        docs = run_tasks(seed_task, tasks, ex, report)
    table = summary(docs)
    table.to_csv(out / f"summary{variant(a.segment_s, a.variance)}.csv",
                 index=False)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3g}"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
