"""The input-noise study (studies/input_noise_check.py, docs/uncertainty.md) on the small wake flight test."""
import dataclasses
import json
from pathlib import Path

import pytest

from pyomo_heli.flighttest.config import load_config
from pyomo_heli.flighttest.generate import generate
from pyomo_heli.studies.input_noise_check import anchor_a, main

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "tests" / "configs" / "input_noise_small.toml"
GEN = ROOT / "studies" / "held_out_small_gen.toml"


def test_the_truth_form_recovers_the_truth_without_noise(tmp_path):
    """Known truth: on a noise-free flight test the model of the truth's form (its strength K_lamT freed from 1.0,
    truth 1.5) gives back every parameter at anchor A, so the study's scatter is the noise's."""
    text = GEN.read_text()
    assert text.count("noise = true") == 1
    gen = tmp_path / "clean.toml"
    gen.write_text(text.replace("noise = true", "noise = false"))
    data = tmp_path / "clean"
    generate(load_config(gen), data, force=True)
    res = anchor_a(CONFIG, data)
    assert res["status"] == "Solve_Succeeded"
    assert set(res["error_percent"]) == {"theta_twist", "CL_alpha_HT", "Iyy", "K_lamT"}
    assert max(abs(e) for e in res["error_percent"].values()) < 0.25, res["error_percent"]


def test_study_writes_both_versions_of_a_seed_and_resumes(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["--seeds", "5", "--config", str(CONFIG), "--data-config", str(GEN), "--out", str(out)]
    assert main(args) == 0
    doc = json.loads((out / "seed_5.json").read_text())
    assert {doc[v]["status"] for v in ("bundled", "no_input_noise")} == {"Solve_Succeeded"}
    assert doc["bundled"]["truth"]["K_lamT"] == 1.5
    assert not (out / "data").exists()  # the generated flight tests are deleted once the seed is done
    head = (out / "summary.md").read_text().splitlines()[0]
    tw = {v: doc[v]["error_percent"]["theta_twist"] for v in ("bundled", "no_input_noise")}
    assert f"{tw['bundled']:+.1f} to {tw['bundled']:+.1f} % with the inputs' noise" in head
    # the noise-free rows (the config's inputs are projected, the default): the truth, as in the test above
    free = json.loads((out / "no_noise.json").read_text())
    assert [free[k]["resample_inputs"] for k in ("config", "project")] == ["project", "project"]
    assert max(abs(e) for e in free["project"]["error_percent"].values()) < 0.25
    assert f"{free['project']['error_percent']['theta_twist']:+.2f} % with the inputs by 'project'" in head
    (out / "seed_5.json").write_text(json.dumps({**doc, "marker": 1}))
    assert main(args) == 0  # the finished seed is read back, not solved again
    assert json.loads((out / "seed_5.json").read_text())["marker"] == 1


def test_a_dataset_without_an_effect_strength_is_refused_by_name(tmp_path):
    g = load_config(GEN)
    data = tmp_path / "m0"
    generate(dataclasses.replace(g, effects={}), data, force=True)
    with pytest.raises(ValueError, match="truth.json: no effect strength"):
        anchor_a(CONFIG, data)


def test_a_data_config_whose_noise_cannot_be_switched_off_is_refused_by_name(tmp_path):
    from pyomo_heli.studies.input_noise_check import noise_free_flight_test

    gen = tmp_path / "gen.toml"
    gen.write_text(GEN.read_text().replace("noise = true", "noise = true  # on"))
    noise_free_flight_test(gen, tmp_path / "a")  # a comment after the value is fine
    gen.write_text(GEN.read_text().replace("noise = true", "noise=true"))
    with pytest.raises(ValueError, match=f"--data-config {gen}: expected one 'noise = true' line"):
        noise_free_flight_test(gen, tmp_path / "b")
