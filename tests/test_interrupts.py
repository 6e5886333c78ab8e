"""Run safety (issue 32): interrupts, two runs on one folder, output failures, on real processes.

Every test runs the real command (``python -m pyomo_heli``) on the tiny Case 1 config and compares with
an uninterrupted run of the same command. The config asks Ipopt for a log file (``output_file``, flushed
line by line): the test sends its signal once that log shows iterations of a solve that has not ended,
so the signal really arrives inside Ipopt (which swallows it: the log then ends with Ipopt's "Unknown
Exception caught" instead of an EXIT line).
"""
import json
import os
import re
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

HERE = Path(__file__).parent
ROOT = HERE.parent
TINY = HERE / "configs" / "tiny_case1_noisy.toml"
TIMING = ["wall_time", "setup_time", "cold_wall_time"]
IPOPT_SWALLOWED = "Unknown Exception caught in Ipopt"


def _env(**extra):
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]), **extra}


def _default_sigint():
    """In the child: SIGINT to its default, even when the test runs as a background job (which ignores it,
    and a process keeps an ignored SIGINT ignored: see pyomo_heli.interrupts)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _cli(*args, env=None, **kw):
    kw.setdefault("preexec_fn", _default_sigint)
    kw.setdefault("stdout", subprocess.PIPE)
    kw.setdefault("stderr", subprocess.PIPE)
    return subprocess.Popen([sys.executable, "-m", "pyomo_heli", *map(str, args)], env=env or _env(), text=True,
                            **kw)


@pytest.fixture(scope="module")
def logged(tmp_path_factory):
    """The tiny config with an Ipopt log file (the solution does not depend on it); returns (config, log)."""
    d = tmp_path_factory.mktemp("config")
    log = d / "ipopt.log"
    cfg = d / "tiny_logged.toml"
    cfg.write_text(TINY.read_text().replace("../../data", str(ROOT / "data")).replace(
        'name = "casadi-ipopt"', f'name = "casadi-ipopt"\noptions = {{ output_file = "{log}", file_print_level = 5 }}'))
    return cfg, log


@pytest.fixture(scope="module")
def reference(logged, tmp_path_factory):
    """An uninterrupted run of the command."""
    out = tmp_path_factory.mktemp("uninterrupted")
    proc = _cli("identify", logged[0], "--out", out, "--no-report", "--uncertainty", "none")
    _, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr
    return out


def _in_solve(log: Path) -> bool:
    """The Ipopt log shows iteration 1 of a solve that has not ended (a solver re-used for several solves
    appends to its log: only what follows the last EXIT line counts)."""
    try:
        text = log.read_text()
    except (FileNotFoundError, UnicodeDecodeError):
        return False
    current = text.rsplit("EXIT:", 1)[-1]
    return bool(re.search(r"^\s+1 ", current, re.M)) and IPOPT_SWALLOWED not in current


def _wait(proc, condition, what):
    deadline = time.monotonic() + 300
    while not condition():
        assert proc.poll() is None, f"the run ended before {what}"
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.002)


def _same_results(out: Path, ref: Path):
    """front.csv (every column but times, exact), chosen.json's numbers, every stored point bitwise."""
    f_out = pd.read_csv(out / "front.csv").drop(columns=TIMING, errors="ignore")
    f_ref = pd.read_csv(ref / "front.csv").drop(columns=TIMING, errors="ignore")
    pd.testing.assert_frame_equal(f_out, f_ref, check_exact=True)
    c_out, c_ref = json.loads((out / "chosen.json").read_text()), json.loads((ref / "chosen.json").read_text())
    for key in ("chosen", "direct"):
        assert {k: v for k, v in c_out[key].items() if k not in TIMING} == \
               {k: v for k, v in c_ref[key].items() if k not in TIMING}, key
    assert c_out["utopia"] == c_ref["utopia"] and c_out["nadir"] == c_ref["nadir"]
    keys = sorted(p.name for p in (ref / "points").glob("*.npz"))
    assert sorted(p.name for p in (out / "points").glob("*.npz")) == keys
    for name in keys:
        with np.load(out / "points" / name) as a, np.load(ref / "points" / name) as b:
            ra, rb = json.loads(str(a["record"])), json.loads(str(b["record"]))
            assert ra["parameters"] == rb["parameters"], name  # bitwise: JSON floats round-trip exactly
            assert np.array_equal(a["values"], b["values"], equal_nan=True), name  # every NLP variable


def _one_line(stderr: str) -> str:
    lines = [ln for ln in stderr.strip().splitlines() if not ln.startswith("CasADi -")]
    assert len(lines) == 1, stderr
    return lines[0]


def test_sigint_during_anchor_a_stores_nothing_and_rerun_is_identical(logged, reference, tmp_path):
    cfg, log = logged
    out = tmp_path / "run"
    log.unlink(missing_ok=True)
    proc = _cli("identify", cfg, "--out", out, "--no-report", "--uncertainty", "none")
    _wait(proc, lambda: _in_solve(log), "anchor A's solve started")  # A is the first solve of the run
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert IPOPT_SWALLOWED in log.read_text()  # the signal reached Ipopt, which swallowed it
    assert proc.returncode == 130
    line = _one_line(stderr)
    assert "interrupted by SIGINT while solving point A (not stored)" in line and str(out) in line
    assert list((out / "points").glob("*")) == [] and not (out / "chosen.json").exists()

    again = _cli("identify", cfg, "--out", out, "--no-report", "--uncertainty", "none")
    _, stderr = again.communicate(timeout=600)
    assert again.returncode == 0, stderr
    _same_results(out, reference)


def test_sigterm_during_anchor_b_keeps_a_and_resumes_identically(logged, reference, tmp_path):
    cfg, log = logged
    out = tmp_path / "run"
    log.unlink(missing_ok=True)
    proc = _cli("identify", cfg, "--out", out, "--no-report", "--uncertainty", "none")
    a_done = out / "points" / "A.npz"
    _wait(proc, lambda: a_done.exists() and _in_solve(log), "anchor B's solve started")
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=120)
    assert IPOPT_SWALLOWED in log.read_text()
    assert proc.returncode == 130
    assert "interrupted by SIGTERM while solving point B (not stored)" in _one_line(stderr)
    assert sorted(p.name for p in (out / "points").iterdir()) == ["A.npz"]  # no B, no temporary file

    again = _cli("identify", cfg, "--out", out, "--no-report", "--uncertainty", "none")
    stdout, stderr = again.communicate(timeout=600)
    assert again.returncode == 0, stderr
    assert stdout.count("(from disk)") == 1
    _same_results(out, reference)


# slow (41 s; CI time): three multistart runs. The default run has SIGINT and SIGTERM in the anchors and in the
# loop, and the multistart share and its resume (tests/test_pareto_resume.py)
@pytest.mark.slow
def test_sigint_in_multistart_keeps_the_counts(logged, tmp_path):
    """An interrupted start is not a failed start: not stored, not counted; the rerun's share is the whole run's."""
    cfg, log = logged
    whole = tmp_path / "whole"
    proc = _cli("multistart", cfg, "--starts", 2, "--seed", 1, "--out", whole)
    stdout, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 0, stderr
    out = tmp_path / "run"
    log.unlink(missing_ok=True)
    proc = _cli("multistart", cfg, "--starts", 2, "--seed", 1, "--out", out)
    first = out / "points" / "start000.npz"
    _wait(proc, lambda: first.exists() and _in_solve(log), "start 1's solve started")
    proc.send_signal(signal.SIGINT)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130 and "interrupted by SIGINT" in _one_line(stderr)
    assert IPOPT_SWALLOWED in log.read_text()
    stored = sorted(p.name for p in (out / "points").iterdir())
    assert stored == ["start000.npz"] and len(pd.read_csv(out / "starts.csv")) == 1
    assert not (out / "multistart.json").exists()

    again = _cli("multistart", cfg, "--starts", 2, "--seed", 1, "--out", out)
    _, stderr = again.communicate(timeout=600)
    assert again.returncode == 0, stderr
    t_out = pd.read_csv(out / "starts.csv").drop(columns=["wall_time"])
    t_ref = pd.read_csv(whole / "starts.csv").drop(columns=["wall_time"])
    pd.testing.assert_frame_equal(t_out, t_ref, check_exact=True)
    j_out, j_ref = (json.loads((d / "multistart.json").read_text()) for d in (out, whole))
    assert (j_out["n_reached_best"], j_out["n_starts"]) == (j_ref["n_reached_best"], j_ref["n_starts"]) == (2, 2)


def test_two_runs_started_together_one_is_refused(logged, reference, tmp_path):
    """Two identical commands on one empty folder: one runs, the other is refused naming it; the folder equals
    an uninterrupted run (before, both ran on the folder at once, sharing one temporary file name)."""
    cfg, _ = logged
    out = tmp_path / "shared"
    command = ("identify", cfg, "--out", out, "--no-report", "--uncertainty", "none")
    first = _cli(*command)
    # the second starts once the first holds the folder, and the first is paused (SIGSTOP) meanwhile: the
    # tiny run takes seconds, so on a loaded machine it could otherwise end before the second even starts
    # looking, and the test would prove nothing
    lock = out / ".pyomo-heli.lock"
    _wait(first, lambda: lock.is_file() and f'"pid": {first.pid},' in lock.read_text(), "the first run took the lock")
    first.send_signal(signal.SIGSTOP)
    try:
        second = _cli(*command)
        _, err_second = second.communicate(timeout=600)
    finally:
        first.send_signal(signal.SIGCONT)
    _, err_first = first.communicate(timeout=600)
    assert (first.returncode, second.returncode) == (0, 2), (err_first, err_second)
    line = _one_line(err_second)
    assert "in use by another run" in line and f"pid {first.pid}:" in line and "pyomo-heli identify" in line
    files = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    assert files == sorted(str(p.relative_to(reference)) for p in reference.rglob("*"))
    _same_results(out, reference)


def test_closed_pipe_never_aborts_the_solve(logged, reference, tmp_path):
    """``pyomo-heli identify ... | head -1`` (unbuffered output, so every line is written at once)."""
    cfg, _ = logged
    out = tmp_path / "run"
    proc = _cli("identify", cfg, "--out", out, "--no-report", "--uncertainty", "none",
                env=_env(PYTHONUNBUFFERED="1"))
    proc.stdout.readline()
    proc.stdout.close()  # as head does after its line
    stderr = proc.stderr.read()
    proc.wait(timeout=600)
    assert proc.returncode == 0, stderr
    assert "Broken pipe" not in stderr and "Exception ignored" not in stderr
    _same_results(out, reference)


def test_output_failures_are_io_errors_with_their_path(logged, tmp_path):
    """A full standard output (> /dev/full) and a results file that cannot be written (a file size limit
    stands in for a full disk): exit status 1, one line with the path and the --traceback hint, not 'bad
    input' (exit 2). With --traceback, the stack is shown."""
    with open("/dev/full", "w") as full:
        proc = _cli("check-data", ROOT / "data" / "bo105_synthetic", stdout=full)
        _, stderr = proc.communicate(timeout=300)
    assert proc.returncode == 1
    line = _one_line(stderr)
    assert "I/O error: <standard output>: No space left on device" in line and "--traceback" in line

    def small_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # writes past the limit then fail with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (20_000, 20_000))  # the tiny NLP's NL file is larger

    cfg, _ = logged
    proc = _cli("identify", cfg, "--out", tmp_path / "run", "--no-report", preexec_fn=small_files)
    _, stderr = proc.communicate(timeout=600)
    assert proc.returncode == 1
    line = _one_line(stderr)
    assert re.search(r"I/O error: \S*/pyomo_heli_nl_\w+/model\.nl: File too large; rerun with --traceback", line), line

    for extra, env in ((["--traceback"], None), ([], _env(PYOMO_HELI_TRACEBACK="1"))):
        with open("/dev/full", "w") as full:
            proc = _cli("check-data", ROOT / "data" / "bo105_synthetic", *extra, stdout=full, env=env)
            _, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 1
        assert "Traceback (most recent call last)" in stderr and "OutputError" in stderr
        assert stderr.strip().splitlines()[-1].startswith("pyomo-heli check-data: I/O error: <standard output>")


def test_full_disk_while_storing_a_point_names_the_file(tmp_path, monkeypatch, capsys):
    """No space left while a finished point is written: exit 1 naming the file, no temporary file left."""
    import errno

    from pyomo_heli import cli
    from pyomo_heli.pareto import store

    def full(fh, **arrays):
        fh.write(b"PK")
        raise OSError(errno.ENOSPC, "No space left on device")  # as a write() reports it: no file name

    monkeypatch.setattr(store.np, "savez", full)
    out = tmp_path / "run"
    assert cli.main(["identify", str(TINY), "--out", str(out), "--no-report", "--uncertainty", "none"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert re.search(rf"I/O error: {re.escape(str(out))}/points/A\.npz\.{os.getpid()}\.tmp: No space left on "
                     rf"device; rerun with --traceback", line), line
    assert list((out / "points").iterdir()) == []


def test_sigterm_stops_close_loop_inside_an_iteration(logged, tmp_path):
    """close-loop identifies iteration 0 in iter_0/: SIGTERM during its anchor B stops the loop (exit 130),
    A stays on disk, B is not stored, no loop.json claims a finished iteration. (The rerun resumes
    iter_0 through identify's store, whose equality with an uninterrupted run is tested above.)"""
    cfg, log = logged
    out = tmp_path / "loop"
    log.unlink(missing_ok=True)
    proc = _cli("close-loop", cfg, "--out", out, "--max-iterations", 0)
    a_done = out / "iter_0" / "points" / "A.npz"
    _wait(proc, lambda: a_done.exists() and _in_solve(log), "iteration 0's anchor B started")
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130
    line = _one_line(stderr)
    assert "interrupted by SIGTERM while solving point B (not stored)" in line and str(out) in line
    assert sorted(p.name for p in (out / "iter_0" / "points").iterdir()) == ["A.npz"]
    assert not (out / "loop.json").exists() and not (out / "iter_0" / "chosen.json").exists()
