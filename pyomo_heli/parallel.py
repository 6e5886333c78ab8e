"""Independent tasks of the studies on Dask (``dask.distributed``), or serially in this process.

Multistart (one task per start), Monte Carlo (per realisation), the loop over seeds
(``studies/close_loop_seeds.py``, per seed) and the score-test level study (``studies/score_test_level.py``,
per seed) hand their tasks to :func:`run_tasks`. Each task is a picklable object holding everything its
result depends on (config, seed, index), and a worker process builds what it needs once and restores the
same start for every task, so a result does not depend on which worker ran it or what it ran before:
the results equal the serial run's, seed for seed (tests/test_parallel.py).

Where the tasks run (:func:`dask_executor`):

- ``workers=0`` and no scheduler: serially in this process (no Dask);
- ``workers=N``: a ``distributed.LocalCluster`` of N single-threaded worker processes on this machine;
- ``scheduler="tcp://host:8786"``: the Dask cluster behind that scheduler (the workers need this package
  installed and, for the studies that write into ``--out``, the same file system).
"""
from __future__ import annotations

import concurrent.futures as cf
import contextlib
import logging
import sys
from typing import Callable, Iterable


def _add_paths(paths) -> None:
    for p in reversed(list(paths)):
        if p not in sys.path:
            sys.path.insert(0, p)


def check_dask_flags(workers: int | None, scheduler: str | None) -> None:
    """Refuse a worker count beside a scheduler address: the scheduler's cluster has its own workers, so the
    count would be dropped without a word. ValueError naming both options."""
    if scheduler is not None and workers:
        raise ValueError(f"--workers {workers} and --scheduler {scheduler}: the scheduler's cluster brings its own "
                         f"workers; give one of the two")


@contextlib.contextmanager
def dask_executor(workers: int = 0, scheduler: str | None = None, paths: Iterable[str] = (),
                  processes: bool = True):
    """A ``concurrent.futures.Executor`` on Dask, or None (run serially here) when ``workers == 0`` and no
    ``scheduler`` is given.

    paths: folders put at the front of each worker's ``sys.path`` (the study scripts' own folders, so that
    their task functions unpickle there). processes: False runs the LocalCluster's workers as threads of
    this process (quick to start; only for tasks that share nothing).
    """
    check_dask_flags(workers, scheduler)
    if scheduler is None and not workers:
        yield None
        return
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - a dependency
        raise RuntimeError("running on Dask needs dask.distributed: pip install 'dask[distributed]'") from exc
    cluster = None
    if scheduler is not None:
        client = Client(scheduler)
    else:
        cluster = LocalCluster(n_workers=int(workers), threads_per_worker=1, processes=processes,
                               dashboard_address=":0")  # any free port: runs side by side
        client = Client(cluster)
    try:
        paths = [str(p) for p in paths]
        if paths:
            client.run(_add_paths, paths)
        yield client.get_executor(pure=False)
    finally:
        # a worker busy in a solver may need killing at the end: that is expected here, not worth a warning
        nanny = logging.getLogger("distributed.nanny")
        level = nanny.level
        nanny.setLevel(logging.ERROR)
        try:
            client.close()
            if cluster is not None:
                cluster.close()
        finally:
            nanny.setLevel(level)


def run_tasks(fn: Callable, tasks: list, executor: cf.Executor | None = None,
              on_result: Callable | None = None) -> list:
    """``fn(task)`` for every task; results in the order of ``tasks``.

    executor: None runs them here one after the other; else any ``concurrent.futures.Executor`` (a Dask
    ``Client.get_executor()``, a process pool). ``on_result(task, result)`` is called as each one finishes
    (in finishing order), e.g. to write it to disk and report progress.
    """
    results: list = [None] * len(tasks)
    if executor is None:
        for i, t in enumerate(tasks):
            results[i] = fn(t)
            if on_result is not None:
                on_result(t, results[i])
        return results
    futures = {executor.submit(fn, t): i for i, t in enumerate(tasks)}
    try:
        for f in cf.as_completed(futures):
            i = futures[f]
            results[i] = f.result()
            if on_result is not None:
                on_result(tasks[i], results[i])
    except BaseException:
        for f in futures:
            f.cancel()
        raise
    return results
