"""pyomo_heli.studies.envelope_validation: the loop's first and last models on an independent flight test.

The envelope flight test must be the bundled one's truth, sensors and trims with another seed (its header
says so); the study's numbers are checked against the truth simulator on a two-maneuver instance: at 20 kt,
where the truth's wake on the tail acts and M0 lacks it, the committed bundled loop's last model is closer to
the truth replay than its first.
"""
from __future__ import annotations

import tomllib
from pathlib import Path

import pytest

from pyomo_heli.flighttest.generate import generate_from_file
from pyomo_heli.studies.envelope_validation import evaluate

ROOT = Path(__file__).resolve().parent.parent
ENVELOPE = ROOT / "tests" / "configs" / "validation_envelope.toml"  # a copy of studies/validation_envelope.toml


def test_envelope_flight_test_shares_the_bundled_truth_sensors_and_trims():
    env = tomllib.loads(ENVELOPE.read_text())
    bundled = tomllib.loads((ROOT / "data" / "bo105_synthetic.toml").read_text())
    for table in ("truth", "sensors", "trims"):
        assert env[table] == bundled[table], table
    assert env["dataset"]["seed"] != bundled["dataset"]["seed"]
    val = [m for m in env["maneuvers"] if m["role"] == "validation"]
    assert sorted({m["speed_kt"] for m in val}) == [0, 20, 40, 60, 80, 100]
    assert {m["name"] for m in env["maneuvers"]}.isdisjoint({m["name"] for m in bundled["maneuvers"]})


def test_study_on_two_maneuvers_sees_the_wake_model_closer_to_truth(tmp_path):
    text = ENVELOPE.read_text()
    head, *blocks = text.split("[[maneuvers]]")
    keep = ("lon3211_80kt_env", "londoublet_20kt_env", "londoublet_80kt_env")
    small = head + "".join("[[maneuvers]]" + b for b in blocks if any(f'"{k}"' in b for k in keep))
    (tmp_path / "gen.toml").write_text(small)
    generate_from_file(tmp_path / "gen.toml", tmp_path / "data")
    tab = evaluate(ROOT / "tests" / "results" / "close_loop", tmp_path / "data")
    assert set(tab["speeds"]) == {"all", "20 kt", "80 kt"}
    at20 = tab[tab["speeds"] == "20 kt"].set_index("output")
    # evaluation against the truth simulator: the wake-on-tail model's error falls where the wake acts
    for o in ("q", "theta"):
        assert at20.loc[o, "model-truth after"] < 0.2 * at20.loc[o, "model-truth before"], o
        assert at20.loc[o, "change %"] < -20.0, o
    # the paired test's p and the RMS columns are consistent with the change
    row = at20.loc["theta"]
    assert row["change %"] == pytest.approx(100 * (row["RMS after"] / row["RMS before"] - 1), rel=1e-9)
    assert row["p (rise)"] > 0.5  # a fall: the one-sided p of a rise lies above one half
