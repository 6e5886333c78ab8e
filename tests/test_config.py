"""The identification config (pyomo_heli.config) and model parameter values: one error naming the file, table
and field.

Found by an adversarial audit (2026-11-25): before, these gave tracebacks, vague messages, or were
accepted silently (a misspelt key ignored, a negative mass reaching the trim solver, an empty output list
reaching the Pareto front's normalisation).
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from pyomo_heli.cli import main
from pyomo_heli.config import ConfigError, load_identification_config
from pyomo_heli.nlp.identification import identification_data
from pyomo_heli.physics.model import HelicopterModel

DATA = Path(__file__).resolve().parent.parent / "data" / "bo105_synthetic"
BASE = f'''[data]
dataset = "{DATA}"
maneuvers = ["lon3211_80kt_a"]
max_duration_s = 2.0
resample_hz = 25
{{data}}
[parameters.theta_twist]
unit = "deg/m"
initial = -2.1228
lower = -10.0
upper = 0.0
scale = 1.0
{{twist}}
[parameters.CL_alpha_HT]
initial = 4.3516
lower = 0.1
upper = 10.0
scale = 5.0

[pareto]
points = 4
{{pareto}}
{{extra}}
'''


def write(tmp_path, data="", twist="", pareto="", extra="", top="") -> Path:
    p = tmp_path / "cfg.toml"
    p.write_text(top + BASE.format(data=data, twist=twist, pareto=pareto, extra=extra))
    return p


def test_the_base_config_loads(tmp_path):
    cfg = load_identification_config(write(tmp_path))
    assert [f.name for f in cfg.free] == ["theta_twist", "CL_alpha_HT"]


@pytest.mark.parametrize("edit, message", [
    (dict(top="model = 3\n"), "'model' must be a table"),
    (dict(data="resample_hzz = 25"), r"\[data\]: unknown key\(s\) resample_hzz"),
    (dict(pareto="pointz = 3"), r"\[pareto\]: unknown key\(s\) pointz"),
    (dict(twist="initail = 1"), r"\[parameters.theta_twist\]: unknown key\(s\) initail"),
    (dict(extra="[discretization]\nnpc = 3"), r"\[discretization\]: unknown key\(s\) npc"),
    (dict(extra='[objectives]\ntime_output = ["q"]'), r"\[objectives\]: unknown key\(s\) time_output"),
    (dict(extra='[model]\nextension = ["rotor_wake_on_tail"]'), r"\[model\]: unknown key\(s\) extension"),
    (dict(extra='[objectives]\ntime_outputs = []'), "field 'time_outputs' is empty"),
    (dict(extra='[objectives]\ntrim_outputs = []'), "field 'trim_outputs' is empty"),
    (dict(extra='[objectives]\ntime_outputs = ["q", "q"]'), r"field 'time_outputs' names \['q'\] more than once"),
    (dict(extra='[objectives]\ninput_errors = ["col", "col"]\nnoise_sigma = { col_deg = 0.02 }'),
     "field 'input_errors' names"),
    (dict(extra='[objectives]\ninput_errors = ["col"]\nnoise_sigma = { col_deg = 0.02 }'),
     r"\[objectives.noise_sigma\]: no sigma for \['q', 'theta', 'n_x', 'n_z', 'TAS'\]"),
    (dict(data='validation = 5'), "field 'validation' must be"),
    (dict(twist="") | dict(extra="[parameters.Iyy]\ninitial = 4973\nlower = 2000\nupper = 8000\nscale = inf"),
     "field 'scale' must be a finite number"),
    (dict(extra="[parameters.Iyy]\ninitial = 4973\nlower = 2000\nupper = 8000\nscale = 0"),
     "field 'scale' must be a number > 0"),
    (dict(extra="[parameters.rho]\ninitial = 1.2\nlower = -1\nupper = 2\nscale = 1"),
     r"\[parameters.rho\]: parameter rho: value must be a finite number > 0"),
    (dict(pareto='cold_check = "yes"'), r"^\S+cfg.toml \[pareto\]: field 'cold_check' must be bool"),
    (dict(pareto='placement = "smart"'), r"\[pareto\]: pareto.placement must be one of uniform, adaptive"),
    (dict(pareto='placement = "adaptive"\nmax_solves = 3'), r"\[pareto\]: pareto.max_solves must be 4 to 1000"),
    # a value given that nothing reads (found by a review: each was accepted and dropped)
    (dict(pareto='max_solves = 50'), r"\[pareto\]: field 'max_solves' is not read here"),
    (dict(pareto='warm_start = "none"\npredictor = "none"'), r"\[pareto\]: field 'predictor' is not read here"),
    (dict(extra="[model]\nparameters = { CL_alpha_HT = 3.0 }"),
     r"\[parameters.CL_alpha_HT\]: 'initial' and \[model.parameters\] CL_alpha_HT = 3.0 \(SI\) give two values"),
])
def test_bad_config_is_one_clear_error(tmp_path, edit, message):
    with pytest.raises(ConfigError, match=message) as err:
        load_identification_config(write(tmp_path, **edit))
    text = str(err.value)
    assert "\n" not in text and str(tmp_path / "cfg.toml") in text
    assert text.count("[pareto]") <= 1  # the table is named once, not wrapped twice


def test_resample_inputs_without_a_resampled_grid_is_refused(tmp_path):
    """[data] resample_inputs says how the inputs reach the resample_hz grid: without resample_hz the records are
    fitted as recorded and the field would be dropped; one line naming it. With resample_hz it loads."""
    path = write(tmp_path, data='resample_inputs = "record"')
    assert load_identification_config(path).resample_inputs == "record"
    path.write_text(path.read_text().replace("resample_hz = 25\n", ""))
    with pytest.raises(ConfigError, match=r"\[data\]: field 'resample_inputs' is not read here") as err:
        load_identification_config(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_cold_check_on_a_front_that_makes_no_cold_solves_is_refused(tmp_path):
    """cold_check = true with the adaptive placement (which never reads it): one line naming the field."""
    path = write(tmp_path, pareto='placement = "adaptive"\ncold_check = true')
    path.write_text(path.read_text().replace("[pareto]\npoints = 4\n", "[pareto]\n"))
    with pytest.raises(ConfigError, match=r"\[pareto\]: field 'cold_check' is not read here"):
        load_identification_config(path)


@pytest.mark.parametrize("value, message", [
    ("[1, 2]", "must be a number"), ('"heavy"', "must be a number"), ("-2000", "must be a finite number > 0"),
    ("nan", "must be a finite number > 0"), ("true", "must be a number"),
])
def test_model_parameter_values_are_checked(tmp_path, value, message):
    path = write(tmp_path, extra=f"[model]\nparameters = {{ m = {value} }}")
    with pytest.raises(ConfigError, match=rf"\[model.parameters\]: parameter m: value {message}"):
        load_identification_config(path)


@pytest.mark.parametrize("data, message", [
    ('validation = ["nope"]', r"\[data\]: field 'validation': maneuver\(s\) \['nope'\] not in the dataset"),
    ("max_duration_s = 0.01", r"\[data\]: max_duration_s = 0.01 leaves fewer than 2 samples"),
    ("input_reference_s = 100", r"\[data\]: input_reference_s = 100 s is not shorter than maneuver"),
])
def test_data_selection_errors_name_the_config_before_any_solve(tmp_path, data, message):
    text = write(tmp_path, data=data).read_text()
    if "max_duration_s = 0.01" in data:  # the key replaces the base's 2.0
        text = text.replace("max_duration_s = 2.0\n", "")
    (tmp_path / "cfg.toml").write_text(text)
    cfg = load_identification_config(tmp_path / "cfg.toml")
    with pytest.raises(ValueError, match=message):
        identification_data(cfg)


def test_config_that_is_a_folder_or_not_text(tmp_path):
    with pytest.raises(ConfigError, match="is a directory, expected a file"):
        load_identification_config(tmp_path)
    bad = tmp_path / "bin.toml"
    bad.write_bytes(b"\xff\xfe\x00\x01")
    with pytest.raises(ConfigError, match=r"bin.toml: not a UTF-8 text file"):
        load_identification_config(bad)


def test_physics_refuses_values_it_cannot_take():
    """The parameter table's domains (docs/model_parameters.md section 12): the same check serves configs and
    --param."""
    m = HelicopterModel()
    for name, value in (("m", -1.0), ("rho", 0.0), ("Omega", math.inf), ("theta_twist", math.nan),
                        ("r_ref", 1.5), ("Iyy", -5.0)):
        with pytest.raises(ValueError, match=rf"parameter {name}: value must be"):
            m.with_parameters(**{name: value})
    assert m.with_parameters(K_beta=0.0, theta_twist=0.0).parameters["K_beta"] == 0.0


@pytest.mark.parametrize("param", ["rho=0", "R=0", "m=-2200", "Iyy=-5", "theta_twist=nan"])
def test_cli_param_outside_its_domain_is_exit_2(param, capsys):
    assert main(["trim", "--speeds-kt", "80", "--param", param]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and f"parameter {param.split('=')[0]}: value must be" in err


def test_close_loop_candidates_named_twice(tmp_path):
    with pytest.raises(ConfigError, match=r"\[loop\]: field 'candidates' names \['cg_offset'\] more than once"):
        load_identification_config(write(tmp_path, extra='[loop]\ncandidates = ["cg_offset", "cg_offset"]'))


@pytest.mark.parametrize("loop, message", [
    ('generic_family = "extended"', "field 'generic_family' is not read here: it is read with discovery = true only"),
    ('generic_rank = "p"', "field 'generic_rank' is not read here: it is read with discovery = true only"),
    ('discovery = true\ngeneric = ["dM_mu"]\ngeneric_family = "extended"',
     "field 'generic_family' is not read here: 'generic' names the terms"),
    ("validation_rule = false\nvalidation_joint = true", "field 'validation_joint' is not read here"),
    ('validation_rule = false\nafter_rejection = "stop"', "field 'after_rejection' is not read here"),
    ('score_inputs = "measured"', "field 'score_inputs' is not read here"),
    ("discovery = true\nratio = 3.0", "field 'ratio' is not read here: the score test's ratio and confounding rules"),
    ("discovery = true\nconfound_corr = 0.9", "field 'confound_corr' is not read here"),
])
def test_a_loop_field_nothing_reads_is_refused(tmp_path, loop, message):
    """Found by a review: each was accepted and dropped (the base config has no [objectives] input_errors). The
    config is refused when it is read, so by identify and diagnose too, not only when close-loop reads [loop]."""
    with pytest.raises(ConfigError, match=r"\[loop\]: " + message.replace("(", r"\(").replace(")", r"\)")):
        load_identification_config(write(tmp_path, extra=f"[loop]\n{loop}"))


def test_identify_refuses_a_bad_loop_table(tmp_path, capsys):
    """A [loop] typo (an unknown key, an unknown candidate) in a config given to identify (diagnose reads its config
    through the same loader): one line naming the table, exit 2, nothing written, instead of being accepted until
    close-loop reads the same file."""
    for loop, message in (("max_iteration = 3", r"\[loop\]: unknown f.*max_iteration"),
                          ('candidates = ["cg_ofset"]', r"\[loop\]: field 'candidates': unknown candidate 'cg_ofset'")):
        path = write(tmp_path, extra=f"[loop]\n{loop}")
        out = tmp_path / "out"
        assert main(["identify", str(path), "--out", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and re.search(message, err[0]) and str(path) in err[0], err
        assert not out.exists()


def test_model_mass_must_match_the_flight_tests(tmp_path):
    """The manifest's mass and air density are the aircraft and day the model must fly; a config whose model
    differs by more than 0.5 % is refused before any solve, unless the parameter is free."""
    cfg = load_identification_config(write(tmp_path, extra="[model]\nparameters = { m = 2400 }"))
    with pytest.raises(ValueError, match=r"manifest.json: field 'mass_kg' = 2200 kg but model parameter m = 2400 kg"
                                         r".*cfg.toml \[model\]\): set \[model\] parameters = \{ m = 2200 \}"):
        identification_data(cfg)
    ok = load_identification_config(write(tmp_path, extra="[model]\nparameters = { m = 2205 }"))
    assert len(identification_data(ok).maneuvers) == 1
    freed = load_identification_config(write(tmp_path, extra="[model]\nparameters = { m = 2400 }\n"
                                             "[parameters.m]\ninitial = 2400\nlower = 1500\nupper = 2600"))
    assert len(identification_data(freed).maneuvers) == 1


@pytest.mark.parametrize("edit, message", [
    (dict(extra='[objectives]\ninput_errors = ["col"]\nnoise_sigma = { q_deg_s = 0.2, theta_deg = 0.1, nx_g = 0.005, '
                'nz_g = 0.01, tas_m_s = 0.5, col_deg = inf }'), r"'col_deg' must be a positive number, got inf"),
    (dict(extra='[objectives]\ninput_errors = ["col"]\nnoise_sigma = { q_deg_s = 0.2, theta_deg = 0.1, nx_g = 0.005, '
                'nz_g = 0.01, tas_m_s = 0.5, col_deg = 1e300 }'), r"'col_deg' = 1e\+300 is not a sensor noise sigma"),
    (dict(extra='[objectives]\nuse = ["time", "trim", "linear", "linear"]'), r"field 'use' names \['linear'\]"),
    (dict(extra='[objectives]\ninput_errors = ["col"]\ncovariance = "full"\nnoise_sigma = { q_deg_s = 0.2, '
                'theta_deg = 0.1, nx_g = 0.005, nz_g = 0.01, tas_m_s = 0.5, col_deg = 0.05 }'),
     r"\[objectives\]: field 'covariance' = \"full\" is not used with input_errors"),
    (dict(extra='[objectives]\nuse = ["time", "trim", "linear"]\n[linear]\nwindow_s = inf'),
     r"\[linear\]: field 'window_s' must be a finite number"),
    (dict(extra='[objectives]\nuse = ["time", "trim", "linear"]\n[linear]\npairs = [["q", "lon"], ["q", "lon"]]'),
     r"\[linear\]: field 'pairs' names \[\['q', 'lon'\]\] more than once"),
    (dict(extra='[objectives]\nuse = ["time", "trim", "linear"]\n[linear]\nspeeds_kt = [true]'),
     r"\[linear\]: field 'speeds_kt' must be a non-empty list of speeds"),
    (dict(extra='[objectives]\nuse = ["time", "trim", "linear"]\n[linear]\npoints = 100000'),
     r"\[linear\]: field 'points' must be an integer in 2..50"),
    # a key the weighting does not read is refused, not ignored (the composite band came from the sweep_* keys)
    (dict(extra='[objectives]\nuse = ["time", "trim", "linear"]\n[linear]\nweighting = "tischler_remple"\n'
                'coherence_min = 0.99\nomega_min_rad_s = 5'),
     r"\[linear\]: field\(s\) coherence_min, omega_min_rad_s are not used with weighting = 'tischler_remple'"),
    (dict(extra='[objectives]\nuse = ["time", "trim", "linear"]\n[linear]\nsweep_points = 3'),
     r"\[linear\]: field\(s\) sweep_points are not used with weighting = 'bins'"),
])
def test_bad_config_second_audit(tmp_path, edit, message):
    with pytest.raises(ConfigError, match=message) as err:
        load_identification_config(write(tmp_path, **edit))
    assert "\n" not in str(err.value) and str(tmp_path / "cfg.toml") in str(err.value)


def test_dataset_folder_without_manifest(tmp_path):
    text = write(tmp_path).read_text().replace(str(DATA), str(tmp_path))
    (tmp_path / "cfg.toml").write_text(text)
    with pytest.raises(ConfigError, match=r"\[data\]: field 'dataset': .* is not a flight-test folder \(no manifest"):
        load_identification_config(tmp_path / "cfg.toml")


def test_a_relative_dataset_override_is_relative_to_the_working_directory(tmp_path, monkeypatch):
    """A relative [data] dataset in the config is relative to the config's folder; given as an override (a
    command line, a study's --out) it is relative to the working directory."""
    import re
    import shutil

    conf = tmp_path / "configs"
    conf.mkdir()
    shutil.copytree(DATA, tmp_path / "flight")
    (conf / "cfg.toml").write_text(write(tmp_path).read_text().replace(str(DATA), "../flight"))
    assert load_identification_config(conf / "cfg.toml").dataset == (tmp_path / "flight").resolve()
    monkeypatch.chdir(tmp_path)
    cfg = load_identification_config(conf / "cfg.toml", {"data": {"dataset": "flight"}})
    assert cfg.dataset == (tmp_path / "flight").resolve()
    with pytest.raises(ConfigError, match=re.escape(f"folder {tmp_path / 'configs' / 'elsewhere'} not found")):
        load_identification_config(conf / "cfg.toml", {"data": {"dataset": "configs/elsewhere"}})


def test_spectral_window_of_too_few_samples_is_named():
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.dataset.frequency_response import SpectralSettings, estimate

    mv = load_flight_test(DATA).maneuvers["lon3211_80kt_a"]
    with pytest.raises(ValueError, match=r"lon3211_80kt_a: linear.window_s = 1e-09 s is 0 samples at 50 Hz"):
        estimate([mv], "q", "lon", SpectralSettings(window_s=1e-9))


def test_pareto_points_have_an_upper_limit(tmp_path):
    path = write(tmp_path)
    path.write_text(path.read_text().replace("points = 4", "points = 100000"))
    with pytest.raises(ConfigError, match=r"field 'points': the epsilon grid needs 2 \(the anchors\) to 1000 points"):
        load_identification_config(path)


@pytest.mark.parametrize("options, message", [
    ("{ tol = nan }", "option 'tol' must be a finite number"),
    ('{ linear_solver = "ma97" }', "option 'linear_solver' = 'ma97' is not available"),
    ("{ bogus_option = 3 }", "unknown Ipopt option 'bogus_option'"),
    ("{ max_iter = 2.5 }", "option 'max_iter' must be an integer"),
])
def test_solver_options_are_checked_at_load(tmp_path, options, message):
    path = write(tmp_path, extra=f'[solver]\nname = "casadi-ipopt"\noptions = {options}')
    with pytest.raises(ConfigError, match=rf"cfg.toml \[solver\] options: {message}"):
        load_identification_config(path)


def test_climbing_trim_points_are_refused_by_the_identification(tmp_path):
    """The NLP's trim blocks are level: a trim row with gamma_fp != 0 is named, not compared with a level trim."""
    import shutil

    ds = tmp_path / "ds"
    shutil.copytree(DATA, ds)
    trims = (ds / "trims.csv").read_text().splitlines()
    col = trims[0].split(",").index(next(c for c in trims[0].split(",") if c.startswith("gamma_fp")))
    cells = trims[3].split(",")
    cells[col] = "5"
    trims[3] = ",".join(cells)
    (ds / "trims.csv").write_text("\n".join(trims) + "\n")
    cfg = load_identification_config(write(tmp_path).rename(tmp_path / "c.toml"), {"data": {"dataset": str(ds)}})
    with pytest.raises(ValueError, match=r"trims.csv: rows \[3\] have a flight-path angle gamma_fp != 0"):
        identification_data(cfg)


def test_third_audit_tau_lambda_too_small_for_the_simulator(capsys):
    """A 1e-12 s inflow time constant made simulate run for hours; the domain asks >= 1 ms."""
    assert main(["simulate", "--speed-kt", "80", "--duration", "2", "--param", "tau_lambda=1e-12"]) == 2
    assert "parameter tau_lambda: value must be a finite number >= 0.001 (1 ms)" in capsys.readouterr().err


def test_third_audit_close_loop_with_no_converged_point_is_exit_1(tmp_path, capsys):
    """The first identification converges nowhere (max_iter = 1): the loop stops with the statuses' file named
    (exit 1, as identify: a failed solve, not bad input) instead of a traceback."""
    path = write(tmp_path, extra='[solver]\nname = "casadi-ipopt"\noptions = { max_iter = 1 }')
    path.write_text(path.read_text().replace("points = 4", "points = 2"))
    assert main(["close-loop", str(path), "--out", str(tmp_path / "loop")]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "iteration 0: no front point converged" in err and "iter_0/front.csv" in err


@pytest.mark.parametrize("key, value", [("extensions", 5), ("extensions", [1]), ("shape_parameters", "x"),
                                        ("config", 5)])
def test_third_audit_close_loop_info_of_the_wrong_type_is_named(tmp_path, key, value, capsys):
    import json
    import shutil

    res = tmp_path / "res"
    shutil.copytree(Path(__file__).resolve().parent / "results" / "close_loop_iter_1", res)
    doc = json.loads((res / "chosen.json").read_text())
    doc["info"][key] = value
    (res / "chosen.json").write_text(json.dumps(doc))
    assert main(["diagnose", str(res), "--out", str(tmp_path / "d"), "--no-residuals"]) == 2
    assert f"chosen.json: key 'info.{key}' must be" in capsys.readouterr().err


def test_diagnosis_input_noise_takes_the_objectives_sigmas(tmp_path):
    """[diagnosis] input_noise without its own noise_sigma takes [objectives.noise_sigma] (docs/diagnosis.md), not
    the records' lead-in (a review: the identification's sigmas were dropped); a channel that table lacks is refused
    in one line."""
    from pyomo_heli.units import DEG

    sig = "noise_sigma = { q_deg_s = 0.2, theta_deg = 0.1, nx_g = 0.005, nz_g = 0.01, tas_m_s = 0.5, col_deg = 0.03 }"
    obj = f'[objectives]\ninput_errors = ["col"]\n{sig}\n'
    cfg = load_identification_config(write(tmp_path, extra=obj + '[diagnosis]\ninput_noise = ["col"]\nreplay = "fit"'))
    got = cfg.diagnosis_settings.noise_sigma
    assert got is not None and got["col"] == pytest.approx(0.03 * DEG) and got["q"] == pytest.approx(0.2 * DEG)
    assert got == cfg.nlp.noise_sigma
    with pytest.raises(ConfigError, match=r"\[diagnosis\]: input_noise \['lon'\] takes its sigmas from "
                                          r"\[objectives.noise_sigma\], which has none for \['lon'\]") as err:
        load_identification_config(write(tmp_path, extra=obj + '[diagnosis]\ninput_noise = ["lon"]'))
    assert "\n" not in str(err.value)
