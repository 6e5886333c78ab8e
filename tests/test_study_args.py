"""The studies (pyomo_heli.studies, run by studies/*.py) refuse bad arguments with one argparse error line (exit 2)
before any work (docs/robustness.md, "Bad input"); found by the second bad-input audit (2026-11-25)."""
from __future__ import annotations

import importlib
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("argv, message", [
    (["score_test_level.py", "--seeds", "5-1"], "--seeds: '5-1' is an empty range"),
    (["score_test_level.py", "--seeds", "a"], "--seeds: cannot read 'a'"),
    (["score_test_level.py", "--seeds", "1", "--segment-s", "nan"], "argument --segment-s: 'nan' is not a finite"),
    (["score_test_level.py", "--seeds", "1", "--out", "README.md"], "README.md is a file, expected a folder"),
    (["monte_carlo.py", "--seed", "-1"], "argument --seed: must be an integer >= 0"),
    (["monte_carlo.py", "--workers", "-1"], "argument --workers: must be an integer >= 0"),
    (["monte_carlo.py", "--config", "studies/case1_tri.toml"],
     "[objectives] use = ['time', 'trim', 'linear'] (the study fits J_time and J_trim)"),
    (["monte_carlo.py", "--config", "tests/configs/tiny_case1_tri_adaptive.toml"],
     "[pareto] placement = 'adaptive' (the study solves the uniform grid)"),
    (["close_loop_seeds.py", "--out", "OUT"], "nothing to do: give --seeds and/or --existing"),
    (["close_loop_seeds.py", "--seeds", "1", "--config", "nope.toml", "--out", "OUT"],
     "--config nope.toml: file not found"),
    (["envelope_validation.py", "--loops", "tests/results/close_loop", "--data-config", "nope.toml", "--out", "OUT"],
     "--data-config nope.toml: file not found"),
    (["validation_test_level.py", "--seeds", "x", "--out", "OUT"], "--seeds: cannot read 'x'"),
    (["validation_test_level.py", "--seeds", "1", "--config", "nope.toml", "--out", "OUT"],
     "--config nope.toml: file not found"),
    (["validation_test_level.py", "--seeds", "1", "--data-config", "studies/held_out_small.toml", "--out", "OUT"],
     "held_out_small.toml: unknown key 'loop'"),
    (["record_bias_level.py", "--seeds", "x", "--out", "OUT"], "--seeds: cannot read 'x'"),
    (["record_bias_level.py", "--seeds", "1", "--config", "nope.toml", "--out", "OUT"],
     "--config nope.toml: file not found"),
    (["record_bias_level.py", "--seeds", "1", "--config", "studies/multistart_case1.toml", "--out", "OUT"],
     "the record-bias test needs the residuals' innovations"),
    (["input_path_level.py", "--seeds", "1", "--config", "studies/multistart_case1.toml", "--out", "OUT"],
     "the input path needs the residuals' innovations"),
    (["input_path_level.py", "--seeds", "1", "--resample-inputs", "nearest", "--out", "OUT"],
     "argument --resample-inputs: invalid choice: 'nearest'"),
    (["generic_term_level.py", "--seeds", "1", "--terms", "col_scale", "dM_nope", "--out", "OUT"],
     "--terms: dM_nope not in the generic family"),
    (["generic_term_level.py", "--seeds", "1", "--identification", "ls", "--out", "OUT"],
     "argument --identification: invalid choice: 'ls'"),
    (["generic_term_level.py", "--seeds", "1", "--config", "nope.toml", "--out", "OUT"],
     "--config nope.toml: file not found"),
    (["generic_term_level.py", "--seeds", "1", "--input-sigma-scale", "0", "--out", "OUT"],
     "--input-sigma-scale: must be a positive number, got 0"),
    (["generic_term_level.py", "--seeds", "1", "--input-sigma-scale", "2", "--identification", "oe", "--out", "OUT"],
     "--input-sigma-scale: scales the input errors' sigmas, which --identification oe has none of"),
    (["generic_term_level.py", "--seeds", "1", "--resample-inputs", "nearest", "--out", "OUT"],
     "argument --resample-inputs: invalid choice: 'nearest'"),
    (["generic_term_level.py", "--seeds", "1", "--input-error-ar", "9", "--out", "OUT"],
     "[objectives]: field 'input_error_ar' must be an integer 0..8"),
    (["generic_term_level.py", "--seeds", "1", "--input-error-ar", "2", "--identification", "oe", "--out", "OUT"],
     "--input-error-ar: models the input errors, which --identification oe has none of"),
    (["generic_term_level.py", "--seeds", "1", "--input-reference-error", "--identification", "oe", "--out", "OUT"],
     "--input-reference-error: models the input errors, which --identification oe has none of"),
    (["generic_term_level.py", "--seeds", "1", "--output-error-ar", "9", "--out", "OUT"],
     "[objectives]: field 'output_error_ar' must be an integer 0..8"),
    (["benchmark.py", "--quick", "--out", "tests"], "--out tests: is a folder, expected a file name"),
    (["innovation_check.py", "--config", "nope.toml"], "--config nope.toml: file not found"),
    (["innovation_check.py", "--config", "studies/case1.toml"], "input_errors is empty; the innovations need it"),
    (["innovation_check.py", "--dataset", "tests"], "--dataset tests: no manifest.json there"),
    (["innovation_check.py", "--dataset", "data/bo105_synthetic", "data/bo105_synthetic", "--loop", "tests"],
     "--loop: a loop belongs to one dataset"),
    (["innovation_check.py", "--loop", "tests"], "--loop tests: no loop.json there"),
    (["innovation_check.py", "--dataset", "data/bo105_flight_trims_padfield1996"],
     "--dataset data/bo105_flight_trims_padfield1996: no truth.json"),
    (["innovation_check.py", "--dataset", "data/bo105_synthetic", "data/bo105_synthetic"],
     "--dataset: two datasets in folders named 'bo105_synthetic'"),
])
def test_study_script_bad_argument_is_one_line_exit_2(argv, message, tmp_path, monkeypatch, capsys):
    """In-process through the study's ``main(argv)`` (a subprocess per case cost 5 s of imports each), as a
    subprocess for a study whose ``main`` reads ``sys.argv`` itself; ``test_a_study_runs_as_a_module`` keeps the
    ``python -m`` route."""
    argv = [str(tmp_path / "out") if a == "OUT" else a for a in argv]
    if "--out" not in argv:
        argv += ["--out", str(tmp_path / "out")]
    module = "pyomo_heli.studies." + argv[0].removesuffix(".py")  # what studies/<name>.py runs
    main = importlib.import_module(module).main
    if inspect.signature(main).parameters:
        monkeypatch.chdir(ROOT)
        try:
            code = main(argv[1:])
        except SystemExit as exc:
            code = exc.code
        err = capsys.readouterr().err
    else:
        r = subprocess.run([sys.executable, "-m", module, *argv[1:]], cwd=ROOT, capture_output=True,
                           text=True, timeout=120)
        code, err = r.returncode, r.stderr
    assert code == 2, err
    assert message in err.strip().splitlines()[-1], err
    assert not (tmp_path / "out").exists()  # refused before anything was written


def test_a_study_runs_as_a_module(tmp_path):
    """``python -m pyomo_heli.studies.<name>`` (what studies/<name>.py runs): a bad argument, one line, exit 2."""
    r = subprocess.run([sys.executable, "-m", "pyomo_heli.studies.monte_carlo", "--seed", "-1", "--out",
                        str(tmp_path / "out")], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "argument --seed: must be an integer >= 0" in r.stderr.strip().splitlines()[-1]


def test_monte_carlo_with_no_successful_realization_says_so_and_exits_1(tmp_path, monkeypatch, capsys):
    """Every realization failed (the stand-in: run_monte_carlo returns two failed rows): the summary is empty, so
    the study says why on its last line (the first row's status) and exits 1, not 0."""
    import pandas as pd

    import pyomo_heli.uncertainty.monte_carlo as mc
    from pyomo_heli.studies.monte_carlo import main

    rows = pd.DataFrame({"realization": [0, 1], "estimator": ["time", "time"], "success": [False, False],
                         "status": ["error: ValueError: a bug", "error: ValueError: a bug"]})
    monkeypatch.setattr(mc, "run_monte_carlo", lambda *a, **k: mc.MonteCarloResult(rows, ["Iyy"], {"Iyy": 1.0}))
    monkeypatch.chdir(ROOT)
    out = tmp_path / "mc"
    out.mkdir()
    assert main(["--realizations", "2", "--time-only", "--workers", "0", "--out", str(out)]) == 1
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("monte_carlo: no realization succeeded (2 rows in") and "a bug" in last
