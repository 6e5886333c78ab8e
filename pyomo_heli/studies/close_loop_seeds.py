"""The full-size closed loop on several noise realisations of the synthetic flight test, and how often each
acceptance criterion of issue 5 holds.

    python studies/close_loop_seeds.py --seeds 20261124 20261125 --out results/close_loop_seeds \
        [--config studies/close_loop.toml] [--data-config data/bo105_synthetic.toml] \
        [--existing docs/results/close_loop docs/results/close_loop_seed2]

For every seed: ``pyomo-heli generate-data --config DATA_CONFIG --seed SEED`` (the bundled flight test with
only the noise seed changed) into ``OUT/data_SEED``, then ``pyomo-heli close-loop CONFIG --dataset ...`` into
``OUT/loop_SEED``. A realisation whose ``loop.json`` exists is not rerun, so an interrupted study resumes
where it stopped. ``--existing`` adds loops run before (their ``loop.json`` names the dataset; it must still
be there).

Written: ``OUT/seeds.csv`` (one row per realisation) and ``OUT/seeds.md`` (the same table and the count of
realisations meeting each criterion). Evaluation only: the table reads each dataset's ``truth.json``; the
loop itself never does.

Criteria (issue 5, first acceptance point), first vs last iteration of each loop:

- the first accepted candidate is ``rotor_wake_on_tail``;
- the pooled RMS trim error (root mean square over col, lon, theta) falls by at least 50 %;
- the validation RMS of data minus model does not rise on any output (and, separately, no rise that the
  paired test of the loop report calls significant, one-sided p < 0.01; and, evaluation only, the validation
  RMS of model minus the truth simulator replayed the same way falls on every output: the model error
  without the sensor noise, as in the loop report);
- the errors of theta_twist, CL_alpha_HT and Iyy against truth fall (absolute relative error).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from pyomo_heli.studies.commands import run_command
from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.nlp.identification import validation_maneuvers
from pyomo_heli.parallel import check_dask_flags
from pyomo_heli.provenance import ResultsMismatchError
from pyomo_heli.report.identification import VALIDATION_OUTPUTS, read_truth
from pyomo_heli.report.loop import JOINT, iterations_validation_change, truth_replay_errors
from pyomo_heli.workflows.check_effect import loop_dataset
from pyomo_heli.workflows.close_loop import LoopMismatchError, finished_loop

ROOT = Path(__file__).resolve().parents[2]  # the checkout: studies/, data/
WAKE = "rotor_wake_on_tail"
PARAMETERS = ("theta_twist", "CL_alpha_HT", "Iyy")
TRIM = ("col", "lon", "theta")


def run_seed(seed: int, out: Path, config: Path, data_config: Path) -> Path:
    """Generate the realisation and run the loop on it unless already done; the loop folder."""
    data, loop = out / f"data_{seed}", out / f"loop_{seed}"
    if not (data / "truth.json").is_file():
        t0 = time.perf_counter()
        run_command(["generate-data", "--config", str(data_config), "--seed", str(seed), "--out", str(data)])
        print(f"seed {seed}: data generated in {time.perf_counter() - t0:.0f} s", flush=True)
    if not finished_loop(loop, config, data):  # a loop not stopped resumes; one of another config is refused
        t0 = time.perf_counter()
        run_command(["close-loop", str(config), "--dataset", str(data), "--out", str(loop)])
        print(f"seed {seed}: loop done in {time.perf_counter() - t0:.0f} s", flush=True)
    return loop


def seed_task(task: tuple):
    """``run_seed(*task)`` as a task of a Dask worker: (loop folder, 0), or (None, exit status) where the
    command failed (it has printed why)."""
    try:
        return run_seed(*task), 0
    except SystemExit as exc:
        return None, int(exc.code) if isinstance(exc.code, int) else 1
    except LoopMismatchError as exc:  # --out holds another config's loop: one line, the other seeds go on
        print(f"close_loop_seeds: error: {exc}", file=sys.stderr, flush=True)
        return None, 2


def evaluate(name: str, loop: Path, config: Path) -> dict:
    """One row of the table: the criteria of issue 5 for the loop in ``loop``."""
    doc = json.loads((loop / "loop.json").read_text())
    try:
        dataset = loop_dataset(loop, doc, config)
    except ResultsMismatchError as exc:
        raise SystemExit(str(exc)) from None
    cfg = load_identification_config(config, {"data": {"dataset": str(dataset.resolve())}})
    truth = read_truth(dataset)
    if truth is None:
        raise SystemExit(f"{dataset}: no truth.json, cannot score the loop in {loop}")
    its = doc["iterations"]
    i0, i1 = its[0], its[-1]
    first = next((it["attribution"]["accepted"] for it in its
                  if it.get("attribution") and it["attribution"].get("accepted")), None)
    row = {"realisation": name, "iterations": len(its), "first accepted": first,
           "added": "+".join(i1["extensions"]) or "-"}
    pooled = [float(np.sqrt(np.mean([it["trim_rms"][c] ** 2 for c in TRIM]))) for it in (i0, i1)]
    row["pooled trim change %"] = 100 * (pooled[1] / pooled[0] - 1)
    val_mans = validation_maneuvers(cfg, load_flight_test(dataset))
    change = iterations_validation_change(cfg, i0, i1, val_mans).set_index("output")
    for o in VALIDATION_OUTPUTS:
        row[f"val {o} change %"] = float(change.loc[o, "change [%]"])
        row[f"val {o} p(rise)"] = float(change.loc[o, "p (rise)"])
    errs, _ = truth_replay_errors(cfg, doc, val_mans)
    for o in VALIDATION_OUTPUTS:
        row[f"model-truth {o} change %"] = 100 * (errs[-1][o] / errs[0][o] - 1)
    for n in PARAMETERS:
        e0, e1 = (100 * (it["parameters"][n] - truth[n]) / abs(truth[n]) for it in (i0, i1))
        row[f"{n} err0 %"], row[f"{n} err1 %"] = e0, e1
        # the loop's own standard error at the last iteration (None: not computed or at a bound)
        se = (i1.get("standard_errors") or {}).get(n)
        row[f"{n} SE1 %"] = 100 * se / abs(truth[n]) if se else float("nan")
        row[f"{n} err1/SE"] = (i1["parameters"][n] - truth[n]) / se if se else float("nan")
    # the residual analysis of the last iteration (when nothing more was accepted): noise only or not
    row["final residual"] = (i1.get("residual_diagnosis") or {}).get("status", "-")
    row["wake first"] = first == WAKE
    row["trim -50 %"] = row["pooled trim change %"] <= -50.0
    row["no val rise"] = all(row[f"val {o} change %"] <= 0.0 for o in VALIDATION_OUTPUTS)
    row["no significant val rise"] = not bool(change.drop(index=JOINT, errors="ignore")["significant rise"].any())
    row["model-truth falls on every output"] = all(row[f"model-truth {o} change %"] < 0.0 for o in VALIDATION_OUTPUTS)
    for n in PARAMETERS:
        row[f"{n} error falls"] = abs(row[f"{n} err1 %"]) < abs(row[f"{n} err0 %"])
    row["all criteria"] = (row["wake first"] and row["trim -50 %"] and row["no val rise"]
                           and all(row[f"{n} error falls"] for n in PARAMETERS))
    return row


CRITERIA = ["wake first", "trim -50 %", "no val rise", "no significant val rise",
            "model-truth falls on every output"] + \
    [f"{n} error falls" for n in PARAMETERS] + ["all criteria"]


def markdown(tab: pd.DataFrame) -> str:
    short = tab[["realisation", "first accepted", "pooled trim change %"]
                + [f"val {o} change %" for o in VALIDATION_OUTPUTS]
                + [c for n in PARAMETERS for c in (f"{n} err0 %", f"{n} err1 %")]].copy()

    def fmt(v):
        return f"{v:+.2f}" if isinstance(v, float) else str(v)

    lines = ["| " + " | ".join(short.columns) + " |", "|" + "---|" * len(short.columns)]
    lines += ["| " + " | ".join(fmt(v) for v in r) + " |" for r in short.itertuples(index=False)]
    lines += ["", "| criterion | realisations meeting it |", "|---|---|"]
    lines += [f"| {c} | {int(tab[c].sum())} of {len(tab)} |" for c in CRITERIA]
    lines += ["", "Last iteration against truth in the loop's own standard errors (`standard_errors` of loop.json):",
              "", "| realisation | " + " | ".join(f"{n} err % / SE % / err/SE" for n in PARAMETERS) + " |",
              "|---|" + "---|" * len(PARAMETERS)]
    lines += ["| " + str(r["realisation"]) + " | "
              + " | ".join(f"{r[f'{n} err1 %']:+.2f} / {r[f'{n} SE1 %']:.2f} / {r[f'{n} err1/SE']:+.2f}"
                           for n in PARAMETERS)
              + " |" for _, r in tab.iterrows()]
    rises = [f"{r['realisation']}: {o} {r[f'val {o} change %']:+.2f} % (p = {r[f'val {o} p(rise)']:.3g})"
             for _, r in tab.iterrows() for o in VALIDATION_OUTPUTS if r[f"val {o} change %"] > 0]
    lines += ["", "Validation rises (data minus model, paired test p of the rise): " + ("; ".join(rises) or "none")]
    if "final residual" in tab:
        lines += ["", "Residual analysis of the last iteration (docs/diagnosis.md): "
                  + "; ".join(f"{r['realisation']}: {r['final residual']}" for _, r in tab.iterrows())]
    return "\n".join(lines) + "\n"


def main() -> None:
    from .args import claim_inputs, in_file, nonneg_int, out_folder
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=nonneg_int, nargs="*", default=[])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--config", type=Path, default=ROOT / "studies" / "close_loop.toml")
    ap.add_argument("--data-config", type=Path, default=ROOT / "data" / "bo105_synthetic.toml")
    ap.add_argument("--existing", type=Path, nargs="*", default=[], help="loop folders run before (tabulated only)")
    ap.add_argument("--workers", type=nonneg_int, default=0,
                    help="run the seeds on a Dask LocalCluster of this many processes (default 0: one after the "
                         "other in this process)")
    ap.add_argument("--scheduler", metavar="ADDRESS", help="run the seeds on the Dask cluster of this scheduler "
                                                          "(its workers must see --out)")
    a = ap.parse_args()
    try:
        check_dask_flags(a.workers, a.scheduler)
    except ValueError as exc:
        ap.error(str(exc))
    for p in a.existing:
        if not (p / "loop.json").is_file():
            ap.error(f"--existing {p}: no loop.json there (a close-loop results folder is needed)")
    if not a.seeds and not a.existing:
        ap.error("nothing to do: give --seeds and/or --existing")
    if a.seeds:
        in_file(ap, a.config, "--config")
        in_file(ap, a.data_config, "--data-config")
    out_folder(ap, a.out).mkdir(parents=True, exist_ok=True)
    if a.seeds:  # OUT/data_<seed> are generated once: refused when --data-config has changed since
        claim_inputs(ap, a.out, data_config=a.data_config)
    loops = [(str(p), p) for p in a.existing]
    from pyomo_heli.log import configure_console
    from pyomo_heli.parallel import dask_executor, run_tasks

    configure_console()
    tasks = [(seed, a.out.resolve(), a.config.resolve(), a.data_config.resolve()) for seed in a.seeds]
    # one seed per task: here one after the other (--workers 0), on a LocalCluster of --workers processes, or
    # on the cluster of --scheduler (whose workers must see --out); a seed's result is the same wherever it ran
    with dask_executor(a.workers, a.scheduler) as ex:
        done = run_tasks(seed_task, tasks, ex)
    for (seed, *_), (loop, code) in zip(tasks, done):
        if code != 0:
            raise SystemExit(code)
        loops.append((f"seed {seed}", loop))
    tab = pd.DataFrame([evaluate(name, loop, a.config) for name, loop in loops])
    tab.to_csv(a.out / "seeds.csv", index=False)
    text = markdown(tab)
    (a.out / "seeds.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
