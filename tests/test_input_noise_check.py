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


def test_study_writes_every_row_of_a_seed_and_resumes(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["--seeds", "5", "--config", str(CONFIG), "--data-config", str(GEN), "--out", str(out)]
    assert main(args) == 0
    doc = json.loads((out / "seed_5.json").read_text())
    assert {doc[v]["status"] for v in ("bundled", "no_input_noise", "input_errors")} == {"Solve_Succeeded"}
    assert doc["bundled"]["truth"]["K_lamT"] == 1.5
    assert [doc[v]["input_errors"] for v in ("bundled", "input_errors")] == [[], ["col", "lon"]]
    # output error: Cramer-Rao bounds; input errors estimated: the reduced Hessian, larger (they take information)
    assert [list(doc[v]["se_percent"]) for v in ("bundled", "no_input_noise", "input_errors")] == \
        [["cramer_rao"], ["cramer_rao"], ["reduced_hessian"]]
    assert doc["input_errors"]["se_percent"]["reduced_hessian"]["theta_twist"] > \
        doc["bundled"]["se_percent"]["cramer_rao"]["theta_twist"]
    assert not (out / "data").exists()  # the generated flight tests are deleted once the seed is done
    head = (out / "summary.md").read_text().splitlines()[0]
    tw = {v: doc[v]["error_percent"]["theta_twist"] for v in ("bundled", "no_input_noise", "input_errors")}
    assert f"{tw['bundled']:+.1f} to {tw['bundled']:+.1f} % with the inputs' noise" in head
    assert f"with the input errors estimated {tw['input_errors']:+.1f} to {tw['input_errors']:+.1f} %" in head
    # the noise-free row: the config projects its inputs already (the default), so one solve; the truth, as above
    free = json.loads((out / "no_noise.json").read_text())
    assert list(free) == ["config"] and free["config"]["resample_inputs"] == "project"
    assert max(abs(e) for e in free["config"]["error_percent"].values()) < 0.25
    assert f"{free['config']['error_percent']['theta_twist']:+.2f} % with the inputs by 'project'" in head
    (out / "seed_5.json").write_text(json.dumps({**doc, "marker": 1}))
    (out / "no_noise.json").write_text('{"config": {')  # cut short by a kill: solved again, not a crash
    assert main(args) == 0  # the finished seed is read back, not solved again
    assert json.loads((out / "seed_5.json").read_text())["marker"] == 1
    assert json.loads((out / "no_noise.json").read_text())["config"]["status"] == "Solve_Succeeded"


def test_both_standard_errors_agree_in_output_error(tmp_path):
    """Second method: on output-error data the reduced Hessian's standard errors (observed information, exact second
    derivatives) are the Cramer-Rao bounds' (expected information from simulated sensitivities) within 10 %."""
    from pyomo_heli.studies.input_noise_check import STANDARD_ERRORS, flight_test

    res = anchor_a(CONFIG, flight_test(5, GEN, tmp_path, input_noise=True), standard_errors=STANDARD_ERRORS)
    se = res["se_percent"]
    for n, x in se["cramer_rao"].items():
        assert se["reduced_hessian"][n] == pytest.approx(x, rel=0.1), n


def test_a_dataset_without_an_effect_strength_is_refused_by_name(tmp_path):
    g = load_config(GEN)
    data = tmp_path / "m0"
    generate(dataclasses.replace(g, effects={}), data, force=True)
    with pytest.raises(ValueError, match="truth.json: no effect strength"):
        anchor_a(CONFIG, data)


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace("[truth.effects.wake_on_tail]\nK_lamT = 1.5\nd_t = 1.8\ns_w = 0.5",
                         "[truth.effects.drag_rise]\nk_dr = 0.1"), "no truth effect with a strength this study frees"),
    (lambda t: t.replace("noise = true", "noise=true"), "expected one 'noise = true' line"),
])
def test_a_data_config_the_study_cannot_use_is_one_line_before_any_work(tmp_path, capsys, edit, message):
    gen = tmp_path / "gen.toml"
    gen.write_text(edit(GEN.read_text()))
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as exc:
        main(["--seeds", "5", "--config", str(CONFIG), "--data-config", str(gen), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and f"--data-config {gen}: {message}" in err[-1]
    assert not out.exists()
