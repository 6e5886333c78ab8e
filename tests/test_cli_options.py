"""The command line's checks of its options and results folders (pyomo_heli.cli.options, pyomo_heli.cli.folders):
one line naming the option, file or key at fault, exit status 2, never a traceback.

Every case fails before any solve or simulation (each test well under a second, except the infeasible
multi-start, about 3 s); nothing is written into the repository (tmp_path only).
"""
import json
import shutil
from pathlib import Path

import pytest

from pyomo_heli.cli import main

ROOT = Path(__file__).resolve().parent.parent
CONFIGS = ROOT / "tests" / "configs"
M0_RESULTS = ROOT / "tests" / "results" / "m0_noise_small"
M0_CONFIG = CONFIGS / "m0_noise_small.toml"
README = ROOT / "README.md"


def _one_line_error(capsys, *culprits):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert "Traceback" not in err and "error:" in err, err
    for c in culprits:
        assert c in err, (c, err)
    return err


@pytest.fixture
def tiny_config(tmp_path):
    """tests/configs/tiny_case1_noisy.toml with its dataset path made absolute (cwd-independent)."""
    text = (CONFIGS / "tiny_case1_noisy.toml").read_text().replace('"../../data/', f'"{ROOT / "data"}/')
    path = tmp_path / "tiny.toml"
    path.write_text(text)
    return path


@pytest.fixture
def results(tmp_path):
    """A copy of a committed identification results folder, free to corrupt."""
    d = tmp_path / "results"
    shutil.copytree(M0_RESULTS, d)
    return d


# ---------------------------------------------------------------- simulate (1-4)
SIM = ["simulate", "--speed-kt", "80", "--duration", "2"]
LON = ["--input", "lon:3211:0.5:0.5"]

SIMULATE_BAD = [
    (SIM + ["--rate", "inf"], ["--rate"]),
    (SIM + ["--rate", "nan"], ["--rate"]),
    (SIM + ["--rate", "0"], ["--rate"]),
    (SIM + ["--rate", "1e-9"], ["--rate", "--duration", "2 samples"]),
    (SIM + ["--rate", "1e9"], ["--rate", "samples"]),
    (["simulate", "--speed-kt", "80", "--duration", "inf"], ["--duration"]),
    (["simulate", "--speed-kt", "80", "--duration", "nan"], ["--duration"]),
    (["simulate", "--speed-kt", "80", "--duration", "0"], ["--duration"]),
    (["simulate", "--speed-kt", "nan"], ["--speed-kt"]),
    (SIM + ["--t-start", "nan"] + LON, ["--t-start"]),
    (SIM + ["--t-start", "inf"] + LON, ["--t-start"]),
    (SIM + ["--t-start", "-5"] + LON, ["--t-start"]),
    (SIM + ["--t-start", "2"] + LON, ["--t-start", "--duration", "never be applied"]),
    (SIM + ["--t-start", "7"] + LON, ["--t-start", "--duration"]),
    (SIM + ["--input", "lon:3211:90:0.5"], ["--input", "90 deg", "20 deg"]),
    (SIM + ["--input", "col:step:-25:1"], ["--input", "-25 deg"]),
    (SIM + ["--input", "lon:3211:nan:0.5"], ["--input", "amplitude"]),
    (SIM + ["--input", "lon:3211:inf:0.5"], ["--input", "amplitude"]),
    (SIM + ["--input", "lon:3211:0.5:0"], ["--input", "step"]),
    (SIM + ["--input", "lon:3211:0.5:-1"], ["--input", "step"]),
    (SIM + ["--input", "lon:3211:0.5:nan"], ["--input", "step"]),
    (SIM + ["--input", "lon:3211:0.5:inf"], ["--input", "step"]),
]


@pytest.mark.parametrize("argv, culprits", SIMULATE_BAD)
def test_simulate_bad_numbers(argv, culprits, capsys):
    assert main(argv) == 2
    _one_line_error(capsys, *culprits)


def test_simulate_out_in_missing_folder(tmp_path, capsys):
    assert main(SIM + ["--out", str(tmp_path / "nowhere" / "x.csv")]) == 2
    _one_line_error(capsys, "--out", "nowhere")


def test_simulate_out_is_a_folder(tmp_path, capsys):
    assert main(SIM + ["--out", str(tmp_path)]) == 2
    _one_line_error(capsys, "--out", "folder")


def test_trim_json_in_missing_folder(tmp_path, capsys):
    assert main(["trim", "--speeds-kt", "80", "--json", str(tmp_path / "nowhere" / "t.json")]) == 2
    _one_line_error(capsys, "--json")


def test_simulate_short_valid_record_still_works(tmp_path):
    out = tmp_path / "sim.csv"
    assert main(SIM + ["--rate", "10", "--t-start", "0.5"] + LON + ["--out", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 1 + 21


# ---------------------------------------------------------------- --out under a file (2)
def test_identify_out_under_a_file(tiny_config, capsys):
    assert main(["identify", str(tiny_config), "--out", str(README / "x"), "--no-report"]) == 2
    _one_line_error(capsys, "--out", "README.md")


def test_identify_out_is_a_file(tiny_config, capsys):
    assert main(["identify", str(tiny_config), "--out", str(README), "--no-report"]) == 2
    _one_line_error(capsys, "--out", "README.md")


def test_generate_data_out_under_a_file(capsys):
    assert main(["generate-data", "--config", str(CONFIGS / "gen_m0_noise_small.toml"),
                 "--out", str(README / "x")]) == 2
    _one_line_error(capsys, "--out", "README.md")


def test_multistart_out_under_a_file(tiny_config, capsys):
    assert main(["multistart", str(tiny_config), "--starts", "1", "--out", str(README / "x")]) == 2
    _one_line_error(capsys, "--out", "README.md")


# ---------------------------------------------------------------- multistart (5)
@pytest.mark.parametrize("extra, culprit", [
    (["--seed", "-1"], "--seed"),
    (["--seed", "1.5"], "--seed"),
    (["--starts", "0"], "--starts"),
    (["--starts", "-3"], "--starts"),
    (["--rtol", "-1"], "--rtol"),
    (["--rtol", "0"], "--rtol"),
    (["--rtol", "nan"], "--rtol"),
    (["--rtol", "inf"], "--rtol"),
    (["--epsilon", "nan"], "--epsilon"),
    (["--epsilon", "inf"], "--epsilon"),
    (["--epsilon", "-1"], "--epsilon"),
])
def test_multistart_bad_options(tiny_config, tmp_path, extra, culprit, capsys):
    assert main(["multistart", str(tiny_config), "--starts", "2", "--out", str(tmp_path / "ms")] + extra) == 2
    err = _one_line_error(capsys, culprit)
    if extra[0] == "--epsilon" and extra[1] == "-1":
        assert "J_trim" in err
    assert not (tmp_path / "ms").exists()  # refused before anything is built or written


def test_multistart_infeasible_epsilon_says_so(tiny_config, tmp_path, capsys):
    assert main(["multistart", str(tiny_config), "--starts", "1", "--epsilon", "0", "--out", str(tmp_path / "ms")]) == 1
    err = capsys.readouterr().err
    assert "--epsilon" in err and "infeasible" in err


# ---------------------------------------------------------------- diagnose options (6)
@pytest.mark.parametrize("extra, culprits", [
    (["--seed", "-1"], ["--seed"]),
    (["--test-rate-hz", "inf"], ["--test-rate-hz"]),
    (["--test-rate-hz", "nan"], ["--test-rate-hz"]),
    (["--test-rate-hz", "0"], ["--test-rate-hz"]),
    (["--test-rate-hz", "-5"], ["--test-rate-hz"]),
    (["--test-rate-hz", "1000"], ["--test-rate-hz", "sample rate", "25 Hz"]),
    (["--alpha", "nan"], ["--alpha"]),
])
def test_diagnose_bad_options(results, tmp_path, extra, culprits, capsys):
    assert main(["diagnose", str(results), "--config", str(M0_CONFIG), "--out", str(tmp_path / "d")] + extra) == 2
    _one_line_error(capsys, *culprits)
    assert not (tmp_path / "d" / "diagnosis.json").exists()


def test_diagnose_out_under_a_file(results, capsys):
    assert main(["diagnose", str(results), "--config", str(M0_CONFIG), "--out", str(README / "x")]) == 2
    _one_line_error(capsys, "--out", "README.md")


# ---------------------------------------------------------------- results folder files (7)
def _set_chosen_parameter(results, name, value_text):
    path = results / "chosen.json"
    d = json.loads(path.read_text())
    d["chosen"]["parameters"][name] = "@@"
    path.write_text(json.dumps(d).replace('"@@"', value_text))


CORRUPT = [
    ("chosen.json", "[]", ["chosen.json", "JSON object"]),
    ("chosen.json", "{bad", ["chosen.json", "invalid JSON", "line 1"]),
    ("chosen.json", "", ["chosen.json", "invalid JSON"]),
    ("chosen.json", '{"parameters": ["theta_twist"]}', ["chosen.json", "'units'"]),
    ("chosen.json", '{"parameters": 3, "units": {}, "utopia": [0, 0], "nadir": [1, 1], "chosen": null, "direct": null}',
     ["chosen.json", "'parameters'"]),
    ("time_domain.json", "[1, 2]", ["time_domain.json", "JSON object"]),
    ("time_domain.json", "{bad", ["time_domain.json", "invalid JSON"]),
    ("time_domain.json", '{"parameters": {}}', ["time_domain.json", "theta_twist"]),
    ("front.csv", "", ["front.csv", "empty"]),
    ("front.csv", "a,b\n1,2\n", ["front.csv", "index"]),
]


@pytest.mark.parametrize("name, text, culprits", CORRUPT)
@pytest.mark.parametrize("command", ["diagnose", "uncertainty"])
def test_corrupt_results_file_is_named(results, tmp_path, command, name, text, culprits, capsys):
    (results / name).write_text(text)
    argv = (["diagnose", str(results), "--config", str(M0_CONFIG), "--out", str(tmp_path / "d")]
            if command == "diagnose" else
            ["uncertainty", str(M0_CONFIG), "--results", str(results), "--out", str(tmp_path / "u"), "--points",
             "chosen"])
    assert main(argv) == 2
    _one_line_error(capsys, *culprits)


@pytest.mark.parametrize("value", ["NaN", "Infinity", '"x"', "null", "true"])
def test_non_finite_parameter_in_chosen_json_is_refused(results, tmp_path, value, capsys):
    _set_chosen_parameter(results, "CL_alpha_HT", value)
    assert main(["diagnose", str(results), "--config", str(M0_CONFIG), "--out", str(tmp_path / "d")]) == 2
    _one_line_error(capsys, "chosen.json", "CL_alpha_HT")


def test_results_file_that_is_a_directory(results, tmp_path, capsys):
    (results / "chosen.json").unlink()
    (results / "chosen.json").mkdir()
    assert main(["diagnose", str(results), "--config", str(M0_CONFIG), "--out", str(tmp_path / "d")]) == 2
    _one_line_error(capsys, "chosen.json", "is a directory")


def test_results_folder_that_is_a_file(tmp_path, capsys):
    assert main(["diagnose", str(M0_CONFIG)]) == 2
    _one_line_error(capsys, str(M0_CONFIG), "is a file")


# ---------------------------------------------------------------- config vs results (8)
@pytest.fixture
def config_with_iyy(tmp_path):
    text = M0_CONFIG.read_text().replace('"../data/', f'"{ROOT / "tests" / "data"}/')
    text += "\n[parameters.Iyy]\ninitial = 4973\nlower = 2000\nupper = 8000\n"
    path = tmp_path / "iyy.toml"
    path.write_text(text)
    return path


def test_uncertainty_config_frees_a_parameter_the_results_lack(results, config_with_iyy, tmp_path, capsys):
    assert main(["uncertainty", str(config_with_iyy), "--results", str(results), "--out", str(tmp_path / "u"),
                 "--points", "chosen"]) == 2
    _one_line_error(capsys, "Iyy", str(config_with_iyy), str(results))
    assert not (tmp_path / "u").exists()


def test_diagnose_config_frees_a_parameter_the_results_lack(results, config_with_iyy, tmp_path, capsys):
    assert main(["diagnose", str(results), "--config", str(config_with_iyy), "--out", str(tmp_path / "d")]) == 2
    _one_line_error(capsys, "Iyy", str(config_with_iyy), str(results))


def test_diagnose_results_hold_a_parameter_the_config_does_not_free(results, tmp_path, capsys):
    text = M0_CONFIG.read_text().replace('"../data/', f'"{ROOT / "tests" / "data"}/')
    start = text.index("[parameters.CL_alpha_HT]")
    end = text.index("\n[", start + 1)
    cfg = tmp_path / "one.toml"
    cfg.write_text(text[:start] + text[end + 1:])
    assert main(["diagnose", str(results), "--config", str(cfg), "--out", str(tmp_path / "d")]) == 2
    _one_line_error(capsys, "CL_alpha_HT", str(cfg), str(results))


# ---------------------------------------------------------------- a directory where a file belongs (9)
def test_check_data_manifest_is_a_directory(tmp_path, capsys):
    (tmp_path / "ds" / "manifest.json").mkdir(parents=True)
    assert main(["check-data", str(tmp_path / "ds")]) == 2
    _one_line_error(capsys, "manifest.json", "is a directory")


def test_inspect_config_is_a_directory(tmp_path, capsys):
    assert main(["inspect", str(tmp_path)]) == 2
    _one_line_error(capsys, str(tmp_path), "is a directory")


def test_identify_config_is_a_directory(tmp_path, capsys):
    assert main(["identify", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    _one_line_error(capsys, str(tmp_path), "is a directory")
