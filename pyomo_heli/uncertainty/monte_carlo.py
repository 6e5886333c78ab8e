"""Monte Carlo over seeded noise realizations: time-domain and multi-objective estimates.

Each realization adds known white noise (:mod:`.realizations`) to a
noise-free data set, re-solves point A (time domain) and, optionally, the
Pareto front and its Eq. 11 choice (multi-objective), and computes the
Cramer-Rao standard errors at each estimate. The spread of the estimates over
realizations is an independent check of those standard errors.

Speed: a worker process builds the NLP once, with the measured data held in
variables pinned by bounds (``NLPOptions.mutable_data``); every realization
restores the same initial point, pins the new data and re-solves, so no NL
file is rewritten and the result of a realization does not depend on which
worker ran it or what it ran before.

Parallelism: the realizations are independent tasks
(:func:`run_realization` on a picklable :class:`RealizationTask`). By default
they run on a Dask ``LocalCluster`` of ``workers`` processes; ``scheduler``
sends them to an existing Dask cluster, and any object with the
``concurrent.futures.Executor`` interface can be passed instead.
``workers=0`` runs them in this process. Each finished
realization is appended to ``realizations.csv`` at once, and a rerun into the
same folder skips realizations already there.
"""
from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..config import load_identification_config
from ..provenance import ResultsMismatchError, config_sha256, dataset_sha256
from ..dataset import load_flight_test
from ..nlp.identification import build_identification_nlp, identification_data, set_measurements
from ..pareto.front import ParetoSolver
from ..log import Progress, format_parameters, info, results_folder
from ..parallel import dask_executor, run_tasks
from .cramer_rao import cramer_rao, point_information
from .realizations import noisy_copy


@dataclass(frozen=True)
class ProblemSpec:
    """An identification config plus overrides of its tables (e.g. a shorter horizon)."""

    config: str
    overrides: str = "{}"  # JSON text, so the spec is hashable and picklable

    @classmethod
    def make(cls, config, overrides: dict | None = None) -> "ProblemSpec":
        return cls(str(Path(config).resolve()), json.dumps(overrides or {}, sort_keys=True))


@dataclass(frozen=True)
class RealizationTask:
    problem: ProblemSpec
    k: int
    seed: int
    sigma: tuple  # ((output, sigma SI), ...)
    trim_sigma: tuple
    multi_objective: bool = True
    crb: bool = True
    low_speed: tuple | None = None  # (speed SI, ((output, sigma SI), ...)): the sigmas of maneuvers trimmed below it


_CACHE: dict = {}


def _problem(spec: ProblemSpec):
    """(cfg, data, nlp, pareto solver) of a spec, built once per process."""
    if spec not in _CACHE:
        _CACHE.clear()
        cfg = load_identification_config(spec.config, json.loads(spec.overrides))
        cfg.nlp = dataclasses.replace(cfg.nlp, mutable_data=True)
        ft = load_flight_test(cfg.dataset)
        data = identification_data(cfg, ft)
        m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp)
        ps = ParetoSolver(m, cfg.pareto)
        _CACHE[spec] = (cfg, data, m, ps)
    return _CACHE[spec]


def _row(task, estimator, p, cfg, noisy, t0) -> dict:
    row = {"realization": task.k, "estimator": estimator, "front_index": p.index, "kind": p.kind,
           "success": bool(p.success), "status": p.status, "iterations": p.iterations, "J_time": p.J_time,
           "J_trim": p.J_trim, **{n: float(v) for n, v in p.parameters.items()}}
    if task.crb and p.success:
        info = point_information(cfg.model, cfg.free, p.parameters, noisy.maneuvers, noisy.trims,
                                 cfg.nlp.time_outputs, cfg.nlp.trim_outputs, input_errors=cfg.nlp.input_errors,
                                 noise_sigma=cfg.nlp.noise_sigma, input_error_ar=cfg.nlp.input_error_ar)
        row.update(cramer_rao(info, cfg.free, kind=p.kind, multiplier=getattr(p, "multiplier_trim", None)).row())
    row["wall_time"] = time.perf_counter() - t0
    return row


def _bound_names(cell) -> set:
    """The parameter names of an ``at_bound`` cell ("theta_twist:upper;Iyy:lower"; empty or NaN: none)."""
    if not isinstance(cell, str):
        return set()
    return {part.split(":")[0].strip() for part in cell.split(";") if part.strip()}


def run_realization(task: RealizationTask) -> list[dict]:
    """Solve one realization; rows for the time-domain estimate and (optionally) the multi-objective one.

    A solve that raises (e.g. a failed anchor) gives a row with success False
    and the error as its status, so one bad realization never stops the study.
    """
    try:
        return _run_realization(task)
    except Exception as exc:  # noqa: BLE001 - recorded, not swallowed: the row carries the error
        est = ("time", "multi") if task.multi_objective else ("time",)
        return [{"realization": task.k, "estimator": e, "success": False,
                 "status": f"error: {type(exc).__name__}: {exc}"[:300]} for e in est]


def _run_realization(task: RealizationTask) -> list[dict]:
    t0 = time.perf_counter()
    cfg, data, m, ps = _problem(task.problem)
    ps._snap_initial.restore()  # the same start for every realization, whatever ran before
    low = None if task.low_speed is None else (task.low_speed[0], dict(task.low_speed[1]))
    noisy = noisy_copy(data, dict(task.sigma), dict(task.trim_sigma), task.seed, task.k, low_speed=low)
    set_measurements(m, noisy)
    if task.multi_objective:
        points = ps.front()
        a = points[0]
        rows = [_row(task, "time", a, cfg, noisy, t0)]
        chosen, _ = ps.choose()
        if chosen is None:  # no front point converged: the multi-objective row fails, point A's row stands
            rows.append({"realization": task.k, "estimator": "multi", "success": False,
                         "status": "no front point converged: nothing to choose"})
            return rows
        multi = _row(task, "multi", chosen, cfg, noisy, t0)
        failed = ps.anchor_failures()  # utopia and nadir of an unconverged anchor: the choice is not to be trusted
        if failed:
            multi.update(success=False, status="; ".join(failed))
        rows.append(multi)
    else:
        # point A alone: J_time from the initial guess, as the front's first anchor
        a = ps._solve("time", 0, "A", math.inf, "none")
        rows = [_row(task, "time", a, cfg, noisy, t0)]
    return rows


@dataclass
class MonteCarloResult:
    """Estimates per realization and estimator, the truth, and the summary statistics."""

    estimates: pd.DataFrame
    parameters: list
    truth: dict
    info: dict = field(default_factory=dict)

    def summary(self) -> pd.DataFrame:
        """Per estimator and parameter: mean, bias, spread (std), median CRB and spread/CRB."""
        rows = []
        est = self.estimates[self.estimates.success.astype(bool)]
        for e in sorted(dict.fromkeys(est.estimator), key=lambda e: (e != "time", e)):
            d = est[est.estimator == e]
            for p in self.parameters:
                x = d[p].to_numpy(dtype=float)
                tr = self.truth.get(p, float("nan"))
                se_col = f"se_{p}"
                se = d[se_col].to_numpy(dtype=float) if se_col in d else np.array([np.nan])
                crb = float(np.nanmedian(se)) if np.isfinite(se).any() else float("nan")
                std = float(np.std(x, ddof=1)) if len(x) > 1 else float("nan")
                at_bound = (sum(p in _bound_names(v) for v in d["at_bound"]) if "at_bound" in d else 0)
                rows.append({"estimator": e, "parameter": p, "n": len(x), "truth": tr, "mean": float(np.mean(x)),
                             "bias": float(np.mean(x)) - tr, "bias %": 100 * (float(np.mean(x)) - tr) / abs(tr)
                             if tr else float("nan"), "std": std, "crb": crb,
                             "std/crb": std / crb if crb and math.isfinite(crb) else float("nan"),
                             "at bound": at_bound})
        return pd.DataFrame(rows)

    def save(self, out) -> None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        self.estimates.to_csv(out / "realizations.csv", index=False, float_format="%.12g")
        self.summary().to_csv(out / "summary.csv", index=False, float_format="%.8g")
        (out / "monte_carlo.json").write_text(json.dumps({"parameters": self.parameters, "truth": self.truth,
                                                          "info": self.info}, indent=2, sort_keys=True) + "\n")

    @classmethod
    def load(cls, out) -> "MonteCarloResult":
        out = Path(out)
        meta = json.loads((out / "monte_carlo.json").read_text())
        return cls(estimates=pd.read_csv(out / "realizations.csv"), parameters=meta["parameters"],
                   truth=meta["truth"], info=meta.get("info", {}))

    def __str__(self) -> str:
        return self.summary().to_string(index=False, float_format=lambda x: f"{x:.5g}")


def _check_same_run(out: Path, run: dict) -> None:
    """Realizations stored in ``out`` are resumed only by the run that made them: the same config (path and content),
    overrides, flight test (by content), seed, noise sigmas, estimators and standard errors (``monte_carlo.json``'s
    ``info``; a key it lacks is not compared). ResultsMismatchError, one line naming what differs, otherwise."""
    f = out / "monte_carlo.json"
    if not f.is_file():
        raise ResultsMismatchError(f"{out / 'realizations.csv'} has no monte_carlo.json beside it, so it cannot be "
                                   f"told to belong to this run; use another --out or remove the folder")
    try:
        stored = json.loads(f.read_text()).get("info", {})
    except ValueError as exc:
        raise ResultsMismatchError(f"{f}: not readable ({exc}); use another --out or remove the folder") from None
    differ = [k for k, v in run.items()
              if k != "config" and k in stored and json.loads(json.dumps(v)) != stored[k]]  # the path may differ
    if differ:
        raise ResultsMismatchError(f"{out} holds the realizations of another run (it differs in: {', '.join(differ)});"
                                   " use another --out or remove the folder")


def _config_and_dataset(arguments):
    spec = arguments["problem"]
    return spec.config, [load_identification_config(spec.config, json.loads(spec.overrides)).dataset]


@results_folder("out", _config_and_dataset)
def run_monte_carlo(problem: ProblemSpec, realizations: int, seed: int, sigma: dict, trim_sigma: dict,
                    truth: dict, out=None, multi_objective: bool = True, crb: bool = True, workers: int = 2,
                    executor: cf.Executor | None = None, progress=info, scheduler: str | None = None,
                    low_speed: tuple[float, dict] | None = None) -> MonteCarloResult:
    """Run (or finish) ``realizations`` noise realizations; write each one to ``out`` as it finishes.

    Where they run (:func:`pyomo_heli.parallel.dask_executor`): ``executor`` if given (any
    concurrent.futures Executor); else the Dask cluster of ``scheduler`` (an address); else a Dask
    LocalCluster of ``workers`` processes; ``workers == 0``: serially in this process. The estimates are
    the same wherever they run. ``low_speed``: (speed [m/s], {output: sigma}), the sigmas of the maneuvers trimmed
    below that speed (:func:`~pyomo_heli.uncertainty.realizations.noisy_copy`).
    """
    cfg = load_identification_config(problem.config, json.loads(problem.overrides))
    params = [f.name for f in cfg.free]
    csv = Path(out) / "realizations.csv" if out is not None else None
    run = {"config": problem.config, "config_sha256": config_sha256(problem.config),
           "dataset_sha256": dataset_sha256(cfg.dataset),  # the noise-free records the realizations perturb
           "overrides": json.loads(problem.overrides), "seed": seed, "sigma": dict(sigma),
           "trim_sigma": dict(trim_sigma), "multi_objective": multi_objective, "crb": crb}
    low = None if low_speed is None else (float(low_speed[0]), tuple(sorted(low_speed[1].items())))
    if low is not None:
        run["low_speed"] = [low[0], dict(low[1])]
    rows: list[dict] = []
    if csv is not None:
        csv.parent.mkdir(parents=True, exist_ok=True)
        if csv.exists():
            _check_same_run(Path(out), run)
            # a rerun asking for fewer realizations than are stored summarises those it asks for
            rows = [r for r in pd.read_csv(csv).to_dict("records") if int(r["realization"]) < realizations]
        (Path(out) / "monte_carlo.json").write_text(json.dumps({"parameters": params, "info": run}, indent=2,
                                                               sort_keys=True) + "\n")
    done = {int(r["realization"]) for r in rows}
    tasks = [RealizationTask(problem, k, seed, tuple(sorted(sigma.items())), tuple(sorted(trim_sigma.items())),
                             multi_objective, crb, low) for k in range(realizations) if k not in done]
    if done:
        progress(f"{len(done)} realizations already in {csv}; running {len(tasks)}")
    t0 = time.perf_counter()
    bar = Progress(len(tasks), "realisations")
    shown = cfg.model.parameters

    def finished(task, new):
        rows.extend(new)
        rows.sort(key=lambda r: (int(r["realization"]), str(r["estimator"])))
        if csv is not None:
            pd.DataFrame(rows).to_csv(csv, index=False, float_format="%.12g")
        r = new[0]
        progress(f"  realization {r['realization']:>3}: " + "; ".join(
            f"{x['estimator']} " + format_parameters({p: x.get(p, float("nan")) for p in params}, shown)
            + f" [{x['status']}]" for x in new) + bar.tick())

    if executor is not None:
        run_tasks(run_realization, tasks, executor, finished)
    else:
        with dask_executor(workers, scheduler) as ex:
            run_tasks(run_realization, tasks, ex, finished)
    est = pd.DataFrame(rows)
    result = MonteCarloResult(estimates=est, parameters=params, truth={p: float(truth[p]) for p in params},
                              info={**run, "realizations": realizations,
                                    "wall_time_this_run": time.perf_counter() - t0})
    if out is not None:
        result.save(out)
    return result
