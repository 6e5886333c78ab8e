"""The results folder's lock, per-process temporary names, no store write after an interrupt, --starts bound.

Fast checks of the pieces; the end-to-end runs (real signals, two real runs on one folder) are in
tests/test_interrupts.py.
"""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pyomo_heli import interrupts
from pyomo_heli.cli import main
from pyomo_heli.pareto import store as store_module
from pyomo_heli.pareto.store import LOCK_FILE, FolderBusyError, FolderLock, PointStore

ROOT = Path(__file__).parent.parent
TINY = ROOT / "tests" / "configs" / "tiny_case1_noisy.toml"


def _holder(folder: Path, imports: str = "from pyomo_heli.pareto.store import FolderLock",
            holding: str = "FolderLock({folder!r}, 'identification')"):
    """Another process holding the folder (by default its lock, ``holding`` a with-item) until killed."""
    code = (f"import sys, time; {imports}\n"
            f"with {holding.format(folder=str(folder))}:\n"
            "    print('locked', flush=True); time.sleep(600)\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-c", code, "identify", "cfg.toml"], env=env, stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "locked"
    return proc


def test_a_locked_folder_is_refused_naming_the_holder_and_freed_when_it_dies(tmp_path):
    proc = _holder(tmp_path)
    try:
        with pytest.raises(FolderBusyError) as err:
            with FolderLock(tmp_path):
                pass
        msg = str(err.value)
        assert "\n" not in msg and f"pid {proc.pid}:" in msg and str(tmp_path) in msg and "--out" in msg
        # the command line refuses the same way, in one line, before touching the folder (exit 2)
        assert main(["identify", str(TINY), "--out", str(tmp_path), "--no-report"]) == 2
        assert sorted(p.name for p in tmp_path.iterdir()) == [LOCK_FILE]
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    with FolderLock(tmp_path):  # the kernel released the lock with its holder: the stale file does not block
        with FolderLock(tmp_path):  # re-entrant within one process
            pass


def test_temporary_names_are_unique_to_the_process_and_never_left_behind(tmp_path, monkeypatch):
    s = PointStore(tmp_path, "fp")
    seen = []
    real_replace = os.replace
    monkeypatch.setattr(store_module.os, "replace", lambda a, b: (seen.append(Path(a).name), real_replace(a, b)))
    s.save("B", {"x": 1.0})
    assert seen == [f"B.npz.{os.getpid()}.tmp"] and s.record("B") == {"x": 1.0}

    def broken(fh, **arrays):
        fh.write(b"PK\x03")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(store_module.np, "savez", broken)
    with pytest.raises(OSError, match="A.npz"):
        s.save("A", {"x": 2.0})
    assert sorted(p.name for p in s.dir.iterdir()) == ["B.npz"]


def test_no_point_is_stored_once_an_interrupt_arrived(tmp_path):
    """An interrupt that a solver swallowed still stops the store: nothing computed after it is saved."""
    s = PointStore(tmp_path, "fp")
    before = signal.getsignal(signal.SIGTERM)
    with interrupts.guard():
        with pytest.raises(interrupts.Interrupted):
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)  # the handler raises at once
        assert interrupts.requested() == signal.SIGTERM
        with pytest.raises(interrupts.Interrupted):
            s.save("A", {"x": 1.0})
    assert s.keys() == [] and interrupts.requested() is None  # the guard's end forgets it
    assert signal.getsignal(signal.SIGTERM) is before  # and puts the old handler back


def test_starts_bounded_and_drawn_one_at_a_time(tmp_path, monkeypatch, capsys):
    from pyomo_heli.workflows import multistart
    from pyomo_heli.config import load_identification_config

    assert main(["multistart", str(TINY), "--starts", "10000000", "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "--starts" in err and "10,000" in err and not (tmp_path / "m").exists()

    drawn = []
    real = multistart.draw_start

    def draw(free, k, seed):
        drawn.append(k)
        return real(free, k, seed)

    class Stop(Exception):
        pass

    def stop(*a, **k):
        raise Stop

    monkeypatch.setattr(multistart, "draw_start", draw)
    monkeypatch.setattr(multistart, "initialise_at", stop)
    with pytest.raises(Stop):  # the first start: only its guess was drawn, not 10,000 up front
        multistart.run_multistart(load_identification_config(TINY), tmp_path / "n", starts=multistart.MAX_STARTS,
                                  progress=lambda *_: None)
    assert drawn == [0]


@pytest.mark.parametrize("error", [ZeroDivisionError("float division by zero"), RuntimeError("casadi crashed")])
def test_internal_error_is_exit_1_with_the_traceback_hint(monkeypatch, capsys, error):
    """An internal error never passes for bad input (before: a RuntimeError gave exit 2, others a traceback)."""
    import pyomo_heli.dataset.cli as dataset_cli

    def broken(directory):
        raise error

    monkeypatch.setattr(dataset_cli, "check_data", broken)
    data = str(ROOT / "data" / "bo105_synthetic")
    assert main(["check-data", data]) == 1
    err = capsys.readouterr().err.strip()
    assert err == (f"pyomo-heli check-data: internal error: {type(error).__name__}: {error}; rerun with --traceback "
                   f"(or PYOMO_HELI_TRACEBACK=1) to see where")
    assert main(["check-data", data, "--traceback"]) == 1
    err = capsys.readouterr().err
    assert "Traceback (most recent call last)" in err and "in broken" in err
    monkeypatch.setenv("PYOMO_HELI_TRACEBACK", "1")
    assert main(["check-data", data]) == 1 and "in broken" in capsys.readouterr().err


def test_a_lookup_that_fails_inside_the_package_is_an_internal_error_not_bad_input(monkeypatch, capsys):
    """A KeyError or ValueError counts as bad input only when a ``raise`` of the package names the input at fault.
    One from an operation of the package's own code (a dict lookup, a library call; before, a candidate's missing lag
    state in the sensitivities ended as "error: b1c_lag", exit 2) is an internal error, exit 1."""
    import numpy as np

    import pyomo_heli.dataset.cli as dataset_cli
    from pyomo_heli.physics.discrepancy import generic_term

    data = str(ROOT / "data" / "bo105_synthetic")
    monkeypatch.setattr(dataset_cli, "check_data", {}.__getitem__)
    assert main(["check-data", data]) == 1
    assert capsys.readouterr().err.startswith(f"pyomo-heli check-data: internal error: KeyError: {data!r}; rerun")
    # a library's ValueError on the package's call (a singular linear solve) is internal too
    monkeypatch.setattr(dataset_cli, "check_data", lambda d: np.linalg.solve(np.zeros((2, 2)), np.ones(2)))
    assert main(["check-data", data]) == 1
    assert capsys.readouterr().err.startswith("pyomo-heli check-data: internal error: LinAlgError: Singular matrix")
    monkeypatch.setattr(dataset_cli, "check_data", generic_term)  # raises KeyError naming the unknown term
    assert main(["check-data", data]) == 2
    assert capsys.readouterr().err.startswith(f"pyomo-heli check-data: error: unknown discrepancy term {data!r}")
