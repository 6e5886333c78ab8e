"""Tests of the equation-level NLP inspection (pyomo_heli.nlp.inspect, ``pyomo-heli inspect``).

The IDAES structural diagnostics take most of the time (~45 s on the full
small config). So the CLI runs on the full small config in a background
process, started first, while the in-process checks run on the same config
cut to 1 s of record (the degrees of freedom do not depend on the horizon).
"""
import re
import subprocess
import sys
from pathlib import Path

import pytest

from pyomo_heli.config import load_identification_config

ROOT = Path(__file__).resolve().parent.parent
SMALL = ROOT / "tests" / "configs" / "small_case1.toml"
CLI_TIMEOUT = 300  # hang guard only; the run takes ~60 s, more on a loaded machine


def _dof_line(text):
    mt = re.search(r"degrees of freedom: free variables - active equalities = (\d+) - (\d+) = (-?\d+); "
                   r"idaes degrees_of_freedom\(m\) = (-?\d+) \((\w+)\)", text)
    assert mt, "no degrees-of-freedom line in the report"
    free, eq, dof, dof_idaes, verdict = mt.groups()
    return int(free), int(eq), int(dof), int(dof_idaes), verdict


@pytest.fixture(scope="module")
def cli_run():
    """``python -m pyomo_heli.cli inspect small_case1.toml --no-diagnostics``, started in the background.

    The IDAES structural check is exercised in process on a shortened record
    (it takes ~45 s on the full small config).
    """
    proc = subprocess.Popen([sys.executable, "-m", "pyomo_heli.cli", "inspect", str(SMALL), "--no-diagnostics"],
                            cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    state = {}

    def result():
        if not state:
            try:
                out, err = proc.communicate(timeout=CLI_TIMEOUT)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()
                pytest.fail(f"pyomo-heli inspect did not finish in {CLI_TIMEOUT} s")
            state.update(rc=proc.returncode, out=out, err=err)
        return state

    yield result
    if proc.poll() is None:
        proc.kill()
        proc.communicate()


@pytest.fixture(scope="module")
def short_cfg():
    return load_identification_config(SMALL, overrides={"data": {"max_duration_s": 1.0}})


@pytest.fixture(scope="module")
def report(cli_run, short_cfg):  # cli_run first: the CLI works while this builds
    from pyomo_heli.nlp.inspect import inspect_problem

    return inspect_problem(short_cfg, diagnostics=True)


def test_dof_matches_idaes_and_free_parameters(report, short_cfg):
    from idaes.core.util.model_statistics import degrees_of_freedom

    from pyomo_heli.workflows.identify import build_problem

    free, eq, dof, dof_idaes_reported, verdict = _dof_line(report)
    m, _, _ = build_problem(short_cfg)
    assert dof == free - eq
    assert dof == dof_idaes_reported == degrees_of_freedom(m)
    assert verdict == "agree"
    # Cholesky factors are fixed by as many equalities, eps_con is an inequality:
    # the only decision freedom is the free parameters.
    assert dof == len(short_cfg.free) == len(m.theta_s)
    assert "decision freedom = the 2 free parameters theta_s" in report


def test_report_sections(report, short_cfg):
    # header: data and free parameters with SI and display units
    assert "dataset:" in report and "lon3211_80kt_a" in report
    assert "theta_twist" in report and "deg/m" in report and "rad/m" in report
    # per-block table: parameters, trim blocks with speed, maneuvers, objective part
    assert re.search(r"^params \(theta_s\)\s+2\s+2\s+0\s+0\s+0\s+2$", report, re.M)
    assert re.search(r"^trim\[10\]\s+80\.0 kt\s+8\s+8\s+0\s+8\s+0\s+0$", report, re.M)
    assert re.search(r"^man\[coldoublet_hover\]\s+\d+\s+\d+\s+5\s+\d+\s+0\s+0$", report, re.M)
    assert re.search(r"^objective \(L, cholesky, eps_con\)\s+5\s+5\s+0\s+5\s+1\s+0$", report, re.M)
    # IDAES structural diagnostics with the parameters fixed: square, no warnings
    diag = report.split("3. IDAES structural diagnostics")[1].split("4a.")[0]
    assert "Model Statistics" in diag and "0 WARNINGS" in diag, diag
    assert "structural diagnostics failed" not in diag
    assert "PyNumero" in diag


def test_report_scaling(report):
    """Section 3b: the IDAES Scaler's factors per family, nothing left unscaled, IDAES's own reports."""
    sec = report.split("3b. IDAES scaling")[1].split("4a.")[0]
    flat = " ".join(sec.split())  # the report wraps long lines
    assert "man[*].x[u] 0.025" in flat and "trim[*].V 0.025" in flat and "man[*].ode[q] 5" in flat
    assert "without a factor (kept at 1): 0 free variables, 0 constraints" in flat
    mt = re.search(r"badly_scaled_var_generator .*?: (\d+) variables unscaled, (\d+) scaled", flat)
    assert mt, sec
    assert int(mt.group(2)) < int(mt.group(1))  # the scaling brings the small angles and rates to order one
    assert "Scaling Factors for" in sec and "theta_s" in sec  # IDAES report_scaling_factors of the top level
    assert "scaling report failed" not in sec


def test_report_equations(report):
    point = report.split("4a. equations at one time point")[1].split("4b.")[0]
    assert "man[lon3211_80kt_a], t = 0.02 s" in point
    for s in ("u", "w", "q", "theta", "lambda_i"):
        assert f"  ode[{s},0.02]:" in point  # compact form
        assert f"  man[lon3211_80kt_a].ode[{s},0.02]:" in point  # full form
        assert f"man[lon3211_80kt_a].dx_disc_eq[{s},0.02]" in point
    assert "theta_dot  ==  q" in point  # compact ode[theta]
    # shared intermediates: defined once, before the equations, each after those it uses; named in the equations
    defs = point.split("named intermediates")[1].split("  dx_disc_eq[")[0]
    order = [defs.index(f"    {k} := ") for k in ("mu", "lam", "c_t", "T", "X", "Z", "M")]
    assert order == sorted(order)
    assert "q_dot  ==  M/" in point and "y_n_x  ==  X/" in point
    assert "M                        = man[lon3211_80kt_a].shared[M,0.02]" in point  # legend
    assert "man[lon3211_80kt_a].dx[theta,0.02]  ==  man[lon3211_80kt_a].x[q,0.02]" in point  # to_string()
    assert "flapping[2,0.02]" in point and "output_eq[n_z,0.02]" in point
    assert "col_trim                 = trim[10].col" in point  # legend
    trim = report.split("4b. equations of one trim block")[1].split("4c.")[0]
    assert "trim[10], V = 80.0 kt" in trim
    assert "V  ==  V_target" in trim and "trim[10].V  ==  trim[10].V_target" in trim
    for c in ("equilibrium[u]", "equilibrium[w]", "equilibrium[q]", "equilibrium[lambda_i]",
              "flapping[0]", "flapping[1]", "flapping[2]"):
        assert f"  {c}:" in trim and f"  trim[10].{c}:" in trim
    # every line wrapped at 120 characters, expressions included
    assert max(len(line) for line in report.splitlines()) <= 120
    params = report.split("4d. physical parameters")[1]
    assert "theta_twist    = 0.0174533 * theta_s[theta_twist]" in params
    assert "CL_alpha_HT    = 5 * theta_s[CL_alpha_HT]" in params


def test_toolbox_error_is_reported_not_raised(monkeypatch):
    from idaes.core.util.diagnostics_tools.diagnostics_toolbox import DiagnosticsToolbox

    from pyomo_heli.nlp.inspect import inspect_problem

    def boom(self, stream=None):
        raise RuntimeError("boom")

    monkeypatch.setattr(DiagnosticsToolbox, "report_structural_issues", boom)
    cfg = load_identification_config(SMALL, overrides={"data": {"max_duration_s": 0.1}})
    text = inspect_problem(cfg, diagnostics=True)
    assert "structural diagnostics failed: RuntimeError: boom" in text
    assert "4a. equations at one time point" in text  # the rest of the report is still there


def test_cli_inspect_small_config(cli_run):
    r = cli_run()
    assert r["rc"] == 0, r["err"][-2000:]
    out = r["out"]
    free, eq, dof, dof_idaes, verdict = _dof_line(out)
    assert dof == dof_idaes == 2 and verdict == "agree"
    assert "  man[lon3211_80kt_a].ode[q,0.02]:" in out and "  trim[10].equilibrium[q]:" in out


def test_cli_inspect_bad_config_path(tmp_path):
    missing = tmp_path / "nope.toml"
    r = subprocess.run([sys.executable, "-m", "pyomo_heli.cli", "inspect", str(missing)], cwd=ROOT,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2
    err = r.stderr.strip()
    assert "\n" not in err and "Traceback" not in err
    assert err.startswith("pyomo-heli inspect: error:") and "nope.toml" in err and "not found" in err
    assert r.stdout == ""


def test_inspect_of_a_three_objective_config_builds_j_linear_and_checks_linear(tmp_path, capsys):
    """Found by a review: inspect built the two-objective NLP of a three-objective config and never read [linear]. It
    now builds the J_linear blocks with the coherent bands identify fits (one response, q/lon at 80 kt, 11 bins on
    the tiny config), and a [linear] identify would refuse (a speed without a record) is one line, exit 2."""
    from pyomo_heli.cli import main

    tri = ROOT / "tests" / "configs" / "tiny_case1_tri.toml"
    assert main(["inspect", str(tri), "--no-diagnostics"]) == 0
    out = capsys.readouterr().out
    assert "frequency responses (J_linear, 11 coherent bins):" in out and "  q/lon at 80 kt " in out
    assert "lin[*]." in out  # the linear-model blocks are in the NLP
    bad = tmp_path / "tri.toml"
    bad.write_text(tri.read_text().replace("speeds_kt = [80]", "speeds_kt = [40]")
                   .replace('"../../data', f'"{ROOT / "data"}'))
    assert main(["inspect", str(bad), "--no-diagnostics"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[linear] speeds_kt: no response for q/lon at 40 kt" in err[0], err
