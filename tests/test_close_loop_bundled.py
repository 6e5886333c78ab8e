"""Issue 5's first acceptance point at full size: the closed loop on data/bo105_synthetic with the input errors
estimated (studies/close_loop_eiv.toml), run afresh and checked as the issue words it, and against the committed
run in docs/results/close_loop_eiv (slow: about 4 minutes on one core; `pytest --runslow -k bundled_close_loop`).

The default suite checks the same criteria on a small instance (tests/test_close_loop.py); there the validation
criterion is checked as the model error against the truth replay and the paired test, because on 6 s records the
sign of a change at the sensor-noise floor is set by the noise draw (docs/close_loop.md, "Where it stands").
"""
import json
from pathlib import Path

import pytest

from pyomo_heli.cli import main
from test_close_loop import _pooled_trim

ROOT = Path(__file__).resolve().parents[1]
COMMITTED = ROOT / "docs" / "results" / "close_loop_eiv" / "loop.json"
TIME_OUTPUTS = ("q", "theta", "n_x", "n_z", "TAS", "beta_0")


@pytest.mark.slow
def test_bundled_close_loop_meets_the_first_acceptance_point(tmp_path):
    assert main(["close-loop", str(ROOT / "studies" / "close_loop_eiv.toml"), "--out", str(tmp_path / "loop")]) == 0
    doc = json.loads((tmp_path / "loop" / "loop.json").read_text())
    its = doc["iterations"]
    first, last = its[0], its[-1]
    # the wake-on-tail candidate is picked first
    assert first["attribution"]["accepted"] == "rotor_wake_on_tail"
    # the RMS trim error (col, lon, theta pooled) falls by at least 50 %
    assert _pooled_trim(last["trim_rms"]) <= 0.5 * _pooled_trim(first["trim_rms"])
    # the validation RMS error (data minus model, all validation maneuvers of the bundled flight test: hover to
    # 100 kt) does not rise on any output
    v0, v1 = first["validation_rms"], last["validation_rms"]
    assert set(v0) == set(TIME_OUTPUTS)
    assert {o: (v0[o], v1[o]) for o in TIME_OUTPUTS if v1[o] > v0[o]} == {}
    # the errors of twist, tail lift slope and Iyy against truth fall (truth read here, never by the loop)
    truth = json.loads((ROOT / "data" / "bo105_synthetic" / "truth.json").read_text())["parameters"]
    for n in ("theta_twist", "CL_alpha_HT", "Iyy"):
        assert abs(last["parameters"][n] - truth[n]) < abs(first["parameters"][n] - truth[n]), n
    report = (tmp_path / "loop" / "loop_report.md").read_text()
    assert "## Error before and after" in report and "## Parameters vs truth" in report
    # ... and the run is the committed one: same iterations, parameters and errors
    committed = json.loads(COMMITTED.read_text())["iterations"]
    assert len(committed) == len(its)
    for new, old in zip(its, committed):
        assert new["extensions"] == old["extensions"]
        assert new["parameters"] == pytest.approx(old["parameters"], rel=1e-6)
        for key in ("trim_rms", "validation_rms", "identification_rms"):
            assert new[key] == pytest.approx(old[key], rel=1e-6), key
