"""Logging, progress with ETA, display units and provenance (issue 30, points 5 and 8)."""
from __future__ import annotations

import io
import json
import logging
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pyomo_heli import __version__
from pyomo_heli.cli import main
from pyomo_heli.log import (Progress, configure_console, format_parameters, get_logger, provenance,
                            results_folder, write_provenance)
from pyomo_heli.physics.parameters import bo105
from pyomo_heli.units import DEG

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(autouse=True)
def _reset_logger():
    """Each test starts with no handler on the package logger (an earlier test may have run the command line)
    and leaves it as it found it."""
    import pyomo_heli.log as L

    log = logging.getLogger("pyomo_heli")
    level, propagate, handlers, cli = log.level, log.propagate, list(log.handlers), list(L._cli_handlers)
    for h in handlers:
        log.removeHandler(h)
    L._cli_handlers.clear()
    yield
    configure_console(0)
    for h in list(log.handlers):
        log.removeHandler(h)
    for h in handlers:
        log.addHandler(h)
    L._cli_handlers[:] = cli
    log.setLevel(level)
    log.propagate = propagate


def test_progress_counts_and_estimates_time_left():
    now = [0.0]
    bar = Progress(4, "starts", clock=lambda: now[0])
    now[0] = 10.0
    assert bar.tick() == " [1/4 starts, 10s, ETA 30s]"  # 10 s per start, 3 left
    now[0] = 10.5
    assert bar.tick(from_disk=True) == " [2/4 starts, 10s, ETA 21s]"  # read back: done, not in the rate (2 x 10.5 s)
    now[0] = 130.5
    assert bar.tick() == " [3/4 starts, 2m10s, ETA 1m05s]"
    now[0] = 200.0
    assert bar.tick() == " [4/4 starts, 3m20s]"
    loop = Progress(3, "loop iterations", at_most=True, clock=lambda: 0.0)
    assert loop.suffix() == " [0/<=3 loop iterations, 0s, ETA ?]"


def test_parameters_are_shown_in_the_units_of_the_configs():
    p = bo105()
    text = format_parameters({"theta_twist": -8.0 * DEG, "CL_alpha_HT": 4.5, "unknown_x": 2.0}, p)
    assert text == "theta_twist=-8 deg/m CL_alpha_HT=4.5 1/rad unknown_x=2"


def test_console_levels_and_log_file(tmp_path, capsys):
    log = get_logger("test")
    f = tmp_path / "run.log"
    configure_console(0, f)
    log.info("info line")
    log.debug("debug line")
    log.warning("warning line")
    cap = capsys.readouterr()
    assert cap.out == "info line\n" and cap.err == "warning line\n"
    configure_console(-1)  # -q
    log.info("quiet info")
    log.warning("quiet warning")
    cap = capsys.readouterr()
    assert cap.out == "" and cap.err == "quiet warning\n"
    configure_console(1)  # -v
    log.debug("verbose debug")
    assert "verbose debug" in capsys.readouterr().out
    text = f.read_text()
    assert "INFO    pyomo_heli.test: info line" in text and "warning line" in text and "debug line" not in text
    assert text.split()[0].endswith("Z")  # UTC time stamps


def test_flags_are_accepted_before_and_after_the_command(tmp_path, capsys):
    f = tmp_path / "cli.log"
    assert main(["-q", "linearize", "--speeds-kt", "0", "--log-file", str(f)]) == 0
    assert "modes (eigenvalues of A)" in capsys.readouterr().out  # results are printed even with -q
    assert f.exists()
    assert main(["linearize", "-v", "--speeds-kt", "0"]) == 0
    assert main(["--log-file", str(tmp_path / "no" / "x.log"), "linearize"]) == 2
    assert "--log-file" in capsys.readouterr().err


def test_console_survives_a_closed_pipe(capsys):
    """stdout whose reader went away (`pyomo-heli ... | head -1`): the first failed write silences the console
    handler, the run goes on, warnings still reach stderr."""
    r, w = os.pipe()
    os.close(r)
    broken = io.TextIOWrapper(io.FileIO(w, "w"), line_buffering=True)
    configure_console(0)
    log = get_logger("pipe")
    old = sys.stdout
    sys.stdout = broken
    try:
        for i in range(3):
            log.info(f"progress {i}")  # must not raise
        log.warning("still here")
    finally:
        sys.stdout = old
        try:
            broken.close()
        except OSError:
            pass
    assert "still here" in capsys.readouterr().err


def test_progress_to_a_closed_pipe_in_a_real_process(tmp_path):
    """A real process printing progress into a pipe closed by its reader ends normally, its traceback-free."""
    code = ("import sys; from pyomo_heli.log import configure_console, info; configure_console(0)\n"
            "import time\n"
            "for i in range(2000): info(f'progress line {i} ' + 'x' * 100)\n"
            "sys.stderr.write('finished\\n')\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
    p.stdout.readline()
    p.stdout.close()  # the reader goes away after one line, as `| head -1` does
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 0, err
    assert "finished" in err and "Traceback" not in err and "Exception ignored" not in err


def test_results_folder_gets_log_and_provenance(tmp_path):
    cfg_dir = tmp_path / "configs"
    cfg_dir.mkdir()
    config = cfg_dir / "run.toml"
    config.write_text("")
    dataset = tmp_path / "data" / "flight"
    dataset.mkdir(parents=True)

    @results_folder("out", lambda a: (config, [dataset]))
    def run(out, fail=False):
        get_logger("x").info("solving point 1")
        if fail:
            raise RuntimeError("solver crashed")
        return 3

    out = tmp_path / "results"
    assert run(out) == 3
    assert "INFO    pyomo_heli.x: solving point 1" in (out / "pyomo_heli.log").read_text()
    doc = json.loads((out / "provenance.json").read_text())
    assert doc["pyomo_heli"] == __version__
    for key in ("pyomo", "casadi", "ipopt", "utc_time", "command"):
        assert doc[key], key
    assert doc["utc_time"].endswith("Z")
    assert doc["datasets_relative_to_config"] == ["../data/flight"]
    assert doc["config"] == "../configs/run.toml"
    from importlib.metadata import version

    assert doc["pyomo"] == version("pyomo") and doc["casadi"] == version("casadi")
    assert "finished in" in (out / "pyomo_heli.log").read_text().splitlines()[-1]
    # a second run into the same folder keeps the first one's record
    first = doc
    assert run(out) == 3
    again = json.loads((out / "provenance.json").read_text())
    assert again["previous"] == [first] and "previous" not in first
    # a run that fails after it began writing the folder still records what made it
    with pytest.raises(RuntimeError):
        run(tmp_path / "failed", fail=True)
    assert (tmp_path / "failed" / "provenance.json").is_file()


def test_git_commit_is_recorded_in_a_checkout(tmp_path):
    doc = provenance()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True)
    if head.returncode != 0:
        assert doc["git"] is None
    else:
        assert doc["git"]["commit"] == head.stdout.strip()


def test_ipopt_version_is_the_one_casadi_runs(tmp_path):
    """The recorded Ipopt version is the banner version of a real casadi Ipopt solve."""
    doc = json.loads(write_provenance(tmp_path).read_text())
    script = ("import casadi; x = casadi.SX.sym('x');"
              "s = casadi.nlpsol('s', 'ipopt', {'x': x, 'f': (x - 1) ** 2}, {'ipopt.print_level': 5});"
              "s(x0=0)")
    banner = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True).stdout
    assert f"Ipopt version {doc['ipopt']}" in banner, banner[:500]


def test_display_units_agree_with_the_parameter_table():
    """The units-based display rule (used where only a parameter's SI unit is known: result tables) gives
    every parameter of the model and of the candidate library the display unit of its own table entry."""
    from pyomo_heli.diagnosis.candidates import CANDIDATES, make_candidate
    from pyomo_heli.units import display_unit

    from pyomo_heli.physics.discrepancy import FAMILIES, generic_names, generic_term

    generic = sorted({n for f in FAMILIES for n in generic_names(f)})
    specs = (list(bo105().specs()) + [s for n in CANDIDATES for s in make_candidate(n).parameters()]
             + [s for n in generic for s in generic_term(n).parameters()])  # beta0_bias [rad] was shown in rad
    assert any(s.display for s in specs)
    for s in specs:
        unit, factor = display_unit(s.unit)
        want = s.display if s.display is not None else (s.unit, 1.0)
        assert unit == want[0] and factor == pytest.approx(want[1], rel=1e-15), s.name


def test_result_tables_are_printed_in_display_units():
    from pyomo_heli.pareto.result import IdentificationResult

    r = IdentificationResult.load(ROOT / "tests" / "results" / "case1")
    text = str(r)
    assert "theta_twist [deg/m]" in text and "CL_alpha_HT [1/rad]" in text
    twist = r.chosen["parameters"]["theta_twist"] / DEG
    line = next(ln for ln in text.splitlines() if ln.startswith("multi-objective (chosen)"))
    assert f"{twist:.6g}" in line
