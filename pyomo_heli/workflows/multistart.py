"""Multi-start: the same identification NLP solved from seeded random initial guesses.

Why: the NLP is non-convex; a single solve from one initial guess says
nothing about other local optima. Here the NLP is built once, and for each
start the free parameters are drawn uniformly within their bounds (start k
uses its own generator seeded by (seed, k), so a start's guess does not
depend on how many starts are run), the states are re-initialised by float
trims and simulations at that guess (:func:`~pyomo_heli.nlp.identification.initialise_at`),
and the problem is solved cold. A start whose model cannot be trimmed or
whose solve fails is recorded with its status; the sweep goes on.

Problems: ``time`` (min J_time, anchor A: classic output error) or
``epsilon`` (min J_time subject to J_trim <= epsilon, one point of the front,
e.g. the chosen one).

Each finished start is written at once to ``DIR/starts.csv`` and to
``DIR/points/`` (exact record and full solution); running the same command
again on the same folder loads finished starts and solves only the rest.

A start *reaches the best optimum* when it converged and its objective is
within ``rtol`` (relative) of the best converged objective; the reported best
start is the first of those (the smallest objective among starts that agree to
rounding would change with it).
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..config import IdentificationConfig
from .identify import build_problem
from ..log import format_parameters, info
from ..nlp.identification import initialise_at
from ..pareto.front import FrontPoint, ParetoSolver
from ..pareto.result import write_csv, write_json
from ..pareto.snapshot import Snapshot
from ..pareto.store import fingerprint, variable_values
from .run_folder import RunFolder

PROBLEMS = ("time", "epsilon")


#: most starts one command runs: more is a typo (each start is a full NLP solve, seconds to minutes)
MAX_STARTS = 10_000


def draw_start(free, k: int, seed: int) -> dict:
    """Initial guess k (SI), uniform within each parameter's bounds, from its own generator seeded by (seed, k)."""
    u = np.random.default_rng([seed, k]).random(len(free))
    return {f.name: float(f.lower + uk * (f.upper - f.lower)) for f, uk in zip(free, u)}


def draw_starts(free, n: int, seed: int) -> list[dict]:
    """``n`` initial guesses (SI), uniform within each parameter's bounds; start k from rng (seed, k)."""
    return [draw_start(free, k, seed) for k in range(n)]


@dataclass
class MultistartResult:
    """One row per start (``starts``) and the summary: best objective, share reaching it."""

    starts: pd.DataFrame
    parameters: list
    problem: str
    epsilon: float | None
    seed: int
    rtol: float
    best: dict | None = None
    info: dict = field(default_factory=dict)

    @property
    def n_reached(self) -> int:
        return int(self.starts["reached_best"].sum())

    @property
    def share(self) -> float:
        return self.n_reached / len(self.starts) if len(self.starts) else float("nan")

    def save(self, out: str | Path) -> None:
        out = Path(out)
        write_csv(self.starts, out / "starts.csv")
        write_json(out / "multistart.json", {"parameters": self.parameters, "problem": self.problem,
                                             "epsilon": self.epsilon, "seed": self.seed, "rtol": self.rtol,
                                             "best": self.best, "n_starts": len(self.starts),
                                             "n_reached_best": self.n_reached, "share_reached_best": self.share,
                                             "info": self.info})

    @classmethod
    def load(cls, out: str | Path) -> "MultistartResult":
        out = Path(out)
        for name in ("starts.csv", "multistart.json"):
            if not (out / name).is_file():
                raise FileNotFoundError(f"{out}: no {name}; is this a multistart results folder?")
        d = json.loads((out / "multistart.json").read_text())
        return cls(starts=pd.read_csv(out / "starts.csv"), parameters=d["parameters"], problem=d["problem"],
                   epsilon=d["epsilon"], seed=d["seed"], rtol=d["rtol"], best=d["best"], info=d["info"])

    def __str__(self) -> str:
        from ..units import display_unit

        cols = (["start"] + [f"initial_{p}" for p in self.parameters] + self.parameters
                + ["objective", "status", "iterations", "reached_best"])
        units = self.info.get("units") or {}  # SI unit per parameter (older folders: none, shown in SI)
        shown = {p: display_unit(units[p]) if p in units else ("", 1.0) for p in self.parameters}
        table = self.starts[cols].copy()
        head = {}
        for p in self.parameters:
            for c in (f"initial_{p}", p):
                table[c] = pd.to_numeric(table[c], errors="coerce") * shown[p][1]
                head[c] = f"{c} [{shown[p][0]}]" if shown[p][0] not in ("", "-") else c
        lines = [f"multi-start ({self.problem}{'' if self.epsilon is None else f', J_trim <= {self.epsilon:.6g}'}), "
                 f"seed {self.seed}, parameters in " + ("the units of the configs:" if units else "SI units:"),
                 table.rename(columns=head).to_string(index=False, float_format=lambda x: f"{x:.6g}"), ""]
        if self.best is None:
            lines.append("no start converged")
        else:
            params = ", ".join(f"{p} = {self.best['parameters'][p] * shown[p][1]:.6g}"
                               + (f" {shown[p][0]}" if shown[p][0] not in ("", "-") else "") for p in self.parameters)
            lines.append(f"best objective {self.best['objective']:.10g} (start {self.best['start']}: {params})")
        lines.append(f"reached the best optimum (converged, objective within rtol {self.rtol:g}): "
                     f"{self.n_reached} of {len(self.starts)} starts = {100 * self.share:.0f} %")
        return "\n".join(lines)


def _row(k: int, guess: dict, p: FrontPoint, objective: float) -> dict:
    row = {"start": k, **{f"initial_{n}": v for n, v in guess.items()}, **p.parameters,
           "J_time": p.J_time, "J_trim": p.J_trim, "objective": objective, "success": p.success,
           "status": p.status, "iterations": p.iterations, "wall_time": p.wall_time}
    return row


@dataclass(frozen=True)
class StartTask:
    """One start: everything its result depends on (picklable, for a Dask worker)."""

    cfg: IdentificationConfig
    key: str  # the run's fingerprint: a worker builds the NLP of a key once
    k: int
    guess: dict
    epsilon: float


_CACHE: dict = {}


def _built(cfg: IdentificationConfig, key: str):
    """(nlp, data, solver, initial snapshot) of a config, built once per worker process."""
    if key not in _CACHE:
        _CACHE.clear()
        m, data, _ = build_problem(cfg)
        ps = ParetoSolver(m, cfg.pareto)
        _CACHE[key] = (m, data, ps, Snapshot(m))
    return _CACHE[key]


def _solve_start(m, data, ps, initial, cfg, k: int, guess: dict, eps: float) -> FrontPoint:
    """Start ``k`` from ``guess``: the model back to its initial state, initialised at the guess, solved cold."""
    initial.restore()  # every start from the same model state: independent of the others
    try:
        initialise_at(m, data, cfg.model, cfg.free, guess)
    except (RuntimeError, ValueError, ArithmeticError) as exc:
        return FrontPoint(index=k, kind="start", epsilon=eps, J_time=math.nan, J_trim=math.nan,
                          parameters={n: math.nan for n in guess}, success=False,
                          status=f"initialisation failed: {exc}", iterations=0, wall_time=0.0)
    return ps.solve_objective("time", epsilon=eps, index=k, kind="start")


def run_start(task: StartTask) -> tuple[dict, list | None]:
    """A start on a worker: its row and the solution's variable values (None if nothing was solved)."""
    m, data, ps, initial = _built(task.cfg, task.key)
    p = _solve_start(m, data, ps, initial, task.cfg, task.k, task.guess, task.epsilon)
    values = variable_values(m) if p.iterations > 0 else None
    return _row(task.k, task.guess, p, p.J_time), values


def run_multistart(cfg: IdentificationConfig, out: str | Path, starts: int = 20, seed: int = 0,
                   problem: str = "time", epsilon: float | None = None, rtol: float = 1e-6,
                   restart: bool = False, progress=info, executor=None) -> MultistartResult:
    """Solve ``problem`` from ``starts`` random initial guesses; every start on disk as it finishes.

    executor: None solves the starts here one after the other; a ``concurrent.futures.Executor`` (e.g. from
    :func:`pyomo_heli.parallel.dask_executor`) solves them on its workers, each building the NLP once. The
    results are the same either way (each start restores the same initial state).
    """
    if problem not in PROBLEMS:
        raise ValueError(f"problem must be one of {', '.join(PROBLEMS)}, got {problem!r}")
    if (problem == "epsilon") != (epsilon is not None):
        raise ValueError("an epsilon (J_trim bound) is needed for problem 'epsilon', and only there")
    if not 1 <= starts <= MAX_STARTS:
        raise ValueError(f"--starts must be between 1 and {MAX_STARTS:,}, got {starts}")
    if int(seed) != seed or seed < 0:
        raise ValueError(f"--seed must be an integer >= 0, got {seed}")
    if not (math.isfinite(rtol) and rtol > 0):
        raise ValueError(f"--rtol must be a finite number > 0, got {rtol}")
    if epsilon is not None and not (math.isfinite(epsilon) and epsilon >= 0):
        raise ValueError(f"--epsilon must be a finite number >= 0 (J_trim >= 0), got {epsilon}")
    with RunFolder(out, "multi-start", cfg, restart) as run, run.locked():
        return _run_multistart(cfg, run, starts, seed, problem, epsilon, rtol, progress, executor)


def _run_multistart(cfg, run: RunFolder, starts, seed, problem, epsilon, rtol, progress,
                    executor=None) -> MultistartResult:
    out = run.root
    key = fingerprint(cfg.raw, cfg.dataset, command="multistart", seed=seed, problem=problem, epsilon=epsilon)
    store = run.store(key, progress, items="start")
    t0 = time.perf_counter()
    eps = math.inf if epsilon is None else float(epsilon)
    resumed = 0
    starts_csv = run.front("starts.csv", fresh=False, order="start")  # rewritten as each start finishes
    bar = run.progress_bar(starts, "starts")
    params_of = cfg.model.parameters

    def finished(k, guess, row, from_disk):
        starts_csv.add(row)
        shown = format_parameters({n: row[n] for n in guess}, params_of)
        start = format_parameters(guess, params_of)
        progress(f"  start {k:>3}: from {start} -> {shown} objective={row['objective']:.10g} "
                 f"[{row['status']}, {row['iterations']} it, {row['wall_time']:.1f} s]"
                 f"{' (from disk)' if from_disk else ''}" + bar.tick(from_disk))

    def pending():
        """The starts still to solve, each guess drawn when it is reached (memory does not grow with --starts);
        finished ones are read back on the way."""
        nonlocal resumed
        for k in range(starts):
            guess = draw_start(cfg.free, k, seed)
            if store.has(f"start{k:03d}"):
                resumed += 1
                finished(k, guess, store.record(f"start{k:03d}"), True)
            else:
                yield StartTask(cfg, key, k, guess, eps)

    if executor is None:
        m, data, _ = build_problem(cfg)
        ps = ParetoSolver(m, cfg.pareto)  # its one solver and the switchable objective; no front is traced
        progress(f"built NLP and solver in {time.perf_counter() - t0:.1f} s")
        initial = Snapshot(m)
        for t in pending():
            p = _solve_start(m, data, ps, initial, cfg, t.k, t.guess, eps)
            row = _row(t.k, t.guess, p, p.J_time)
            store.save(f"start{t.k:03d}", row, m if p.iterations > 0 else None)
            finished(t.k, t.guess, row, False)
    elif todo := list(pending()):
        from ..parallel import run_tasks

        progress(f"solving {len(todo)} start(s) on {type(executor).__name__} workers (each builds the NLP once)")

        def done(t, result):
            row, values = result
            store.save(f"start{t.k:03d}", row, values=values)
            finished(t.k, t.guess, row, False)

        run_tasks(run_start, todo, executor, done)
    table = starts_csv.table()
    ok = table["success"].astype(bool) & np.isfinite(table["objective"])
    best = None
    table["reached_best"] = False
    if ok.any():
        fb = float(table.loc[ok, "objective"].min())
        table["reached_best"] = ok & (np.abs(table["objective"] - fb) <= rtol * max(abs(fb), 1.0))
        # the first start that reached it: among starts equal to rounding, the smallest objective is noise
        kb = int(table.index[table["reached_best"]][0])
        fb = float(table.loc[kb, "objective"])
        best = {"start": int(table.loc[kb, "start"]), "objective": fb,
                "parameters": {f.name: float(table.loc[kb, f.name]) for f in cfg.free},
                "J_time": float(table.loc[kb, "J_time"]), "J_trim": float(table.loc[kb, "J_trim"])}
        # how far the starts that reached it are from the best parameters, in scaled units
        scaled = np.column_stack([(table[f.name] - best["parameters"][f.name]) / f.scale for f in cfg.free])
        table["distance_to_best_scaled"] = np.linalg.norm(scaled, axis=1)
    result = MultistartResult(starts=table, parameters=[f.name for f in cfg.free], problem=problem,
                              epsilon=epsilon, seed=seed, rtol=rtol, best=best,
                              info={"config": str(cfg.path), "dataset": str(cfg.dataset),
                                    "total_time": time.perf_counter() - t0,
                                    "bounds": {f.name: [f.lower, f.upper] for f in cfg.free},
                                    "units": {f.name: cfg.model.parameters.spec(f.name).unit for f in cfg.free},
                                    "resumed_starts": resumed})
    result.save(out)
    return result
