"""Multistart and Monte Carlo on a two-worker Dask LocalCluster give the serial run's results, seed for seed."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.config import load_identification_config
from pyomo_heli.workflows.multistart import run_multistart
from pyomo_heli.parallel import dask_executor, run_tasks
from pyomo_heli.physics.parameters import bo105
from pyomo_heli.uncertainty.monte_carlo import ProblemSpec, run_monte_carlo

pytest.importorskip("distributed")

CONFIGS = Path(__file__).resolve().parent / "configs"
QUIET = dict(progress=lambda *_: None)


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of two worker processes (what `--workers 2` starts), shared by the tests here."""
    with dask_executor(workers=2) as ex:
        yield ex


def _square(x):
    return x * x


def test_run_tasks_keeps_the_order_of_the_tasks(cluster):
    seen = []
    assert run_tasks(_square, list(range(7)), cluster, lambda t, r: seen.append((t, r))) == [x * x for x in range(7)]
    assert sorted(seen) == [(x, x * x) for x in range(7)]


def test_multistart_on_dask_equals_serial(cluster, tmp_path):
    cfg = load_identification_config(CONFIGS / "tiny_case1_noisy.toml")
    serial = run_multistart(cfg, tmp_path / "serial", starts=3, seed=5)  # progress to the package logger
    dask = run_multistart(cfg, tmp_path / "dask", starts=3, seed=5, executor=cluster)
    cols = [c for c in serial.starts.columns if c != "wall_time"]
    pd.testing.assert_frame_equal(dask.starts[cols], serial.starts[cols], check_exact=True)
    assert dask.best == serial.best and serial.best is not None
    # the workers' solutions are stored as the serial run's are (a resumed run restores them)
    for k in range(3):
        a = np.load(tmp_path / "serial" / "points" / f"start{k:03d}.npz")
        b = np.load(tmp_path / "dask" / "points" / f"start{k:03d}.npz")
        np.testing.assert_array_equal(a["values"], b["values"])
    # both folders carry their log and provenance
    for run in ("serial", "dask"):
        log = (tmp_path / run / "pyomo_heli.log").read_text()
        assert "start   2: from theta_twist=" in log and "[3/3 starts" in log
        assert json.loads((tmp_path / run / "provenance.json").read_text())["pyomo_heli"]


def test_monte_carlo_on_dask_equals_serial(cluster, tmp_path):
    spec = ProblemSpec.make(CONFIGS / "mc_time_small.toml")
    sigma = {"q": 0.002, "theta": 0.002, "n_x": 0.01, "n_z": 0.01, "TAS": 0.3}
    kw = dict(truth=dict(bo105()), multi_objective=False, sigma=sigma, trim_sigma={}, crb=False,
              **QUIET)
    serial = run_monte_carlo(spec, 2, seed=11, out=tmp_path / "serial", workers=0, **kw)
    dask = run_monte_carlo(spec, 2, seed=11, out=tmp_path / "dask", executor=cluster, **kw)
    # the same realisations and estimates; Ipopt's iteration count may differ by one where the worker's BLAS threading
    # differs from this process's (seen in a fresh venv without OMP_NUM_THREADS), so estimates are compared to 1e-6
    cols = [c for c in serial.estimates.columns if c not in ("wall_time", "iterations")]
    pd.testing.assert_frame_equal(dask.estimates[cols], serial.estimates[cols], check_exact=False, rtol=1e-6)
    assert serial.estimates["success"].all()


def test_cli_multistart_sends_the_starts_to_a_scheduler(tmp_path):
    """`pyomo-heli multistart --scheduler ADDRESS`: the same starts on an existing cluster (here one of a
    thread worker in this process, reached through its scheduler's address) as `--workers 0` here."""
    from distributed import LocalCluster

    from pyomo_heli.cli import main
    from pyomo_heli.workflows.multistart import MultistartResult

    config = str(CONFIGS / "tiny_case1_noisy.toml")
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address=":0") as cluster:
        with dask_executor(scheduler=cluster.scheduler_address) as ex:
            assert run_tasks(_square, [3, 4], ex) == [9, 16]
        assert main(["multistart", config, "--starts", "2", "--seed", "7", "--out", str(tmp_path / "remote"),
                     "--scheduler", cluster.scheduler_address]) == 0
    assert main(["multistart", config, "--starts", "2", "--seed", "7", "--out", str(tmp_path / "here")]) == 0
    a, b = MultistartResult.load(tmp_path / "remote"), MultistartResult.load(tmp_path / "here")
    cols = [c for c in a.starts.columns if c != "wall_time"]
    pd.testing.assert_frame_equal(a.starts[cols], b.starts[cols], check_exact=True)


def test_a_worker_count_beside_a_scheduler_address_is_refused(tmp_path, capsys):
    """`--workers N --scheduler ADDRESS`: the cluster behind the address has its own workers, so N would be dropped
    without a word; every command and study taking both refuses it in one line naming both, before connecting."""
    import sys

    from pyomo_heli.cli import main
    from pyomo_heli.studies import close_loop_seeds, monte_carlo, score_test_level

    address = "tcp://127.0.0.1:9"  # nothing listens there: a refusal after connecting would hang or fail otherwise
    with pytest.raises(ValueError, match=r"--workers 2 and --scheduler tcp://127\.0\.0\.1:9"):
        with dask_executor(2, address):
            pass
    out = tmp_path / "ms"
    assert main(["multistart", str(CONFIGS / "tiny_case1_noisy.toml"), "--starts", "2", "--out", str(out),
                 "--workers", "2", "--scheduler", address]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--workers 2 and --scheduler" in err[0] and not out.exists()
    for run in (lambda: monte_carlo.main(["--workers", "2", "--scheduler", address, "--out", str(tmp_path / "mc")]),
                lambda: score_test_level.main(["--seeds", "1", "--workers", "2", "--scheduler", address,
                                               "--out", str(tmp_path / "st")])):
        with pytest.raises(SystemExit) as exc:
            run()
        assert exc.value.code == 2 and "--workers 2 and --scheduler" in capsys.readouterr().err
    argv = sys.argv
    sys.argv = ["close_loop_seeds", "--seeds", "1", "--workers", "2", "--scheduler", address,
                "--out", str(tmp_path / "cl")]
    try:
        with pytest.raises(SystemExit) as exc:
            close_loop_seeds.main()
    finally:
        sys.argv = argv
    assert exc.value.code == 2 and "--workers 2 and --scheduler" in capsys.readouterr().err
