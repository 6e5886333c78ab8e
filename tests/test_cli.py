"""Command line: trim and simulate, and one-line errors with exit status 2 for bad input."""
import json
import subprocess
import sys

import pandas as pd
import pytest

from pyomo_heli.cli import main


def test_trim_table_and_json(tmp_path, capsys):
    out = tmp_path / "trims.json"
    assert main(["trim", "--speeds-kt", "0", "80", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "speed kt" in text and "col deg" in text and "beta_1c deg" in text
    recs = json.loads(out.read_text())
    assert [r["speed_kt"] for r in recs] == [0.0, 80.0]
    assert recs[0]["col_deg"] == pytest.approx(8.58, abs=0.02)   # model_spec 6.1, hover
    assert recs[0]["lambda_i"] == pytest.approx(0.0494, abs=1e-4)


def test_simulate_writes_csv(tmp_path, capsys):
    out = tmp_path / "sim.csv"
    assert main(["simulate", "--speed-kt", "80", "--input", "lon:3211:0.5:0.5", "--duration", "6",
                 "--out", str(out)]) == 0
    df = pd.read_csv(out)
    assert list(df.columns[:9]) == ["t_s", "col_deg", "lon_deg", "q_deg_s", "theta_deg", "nx_g", "nz_g", "tas_m_s",
                                    "beta0_deg"]
    assert len(df) == 301
    assert df["lon_deg"].max() - df["lon_deg"].min() == pytest.approx(1.0, abs=1e-9)
    assert df["q_deg_s"].abs().max() > 1.0  # the aircraft responds


BAD = [
    (["trim", "--speeds-kt", "-5"], "negative"),
    (["trim", "--speeds-kt", "200"], "outside the model's range"),
    (["trim", "--param", "Iyx=5000"], "Iyx"),
    (["trim", "--param", "Iyy=heavy"], "Iyy"),
    (["simulate", "--speed-kt", "80", "--input", "yaw:3211:0.5:0.5"], "yaw"),
    (["simulate", "--speed-kt", "80", "--input", "lon:sine:0.5:0.5"], "sine"),
    (["simulate", "--speed-kt", "80", "--input", "lon:3211:0.5"], "CHANNEL:SHAPE"),
    (["simulate", "--speed-kt", "-10"], "negative"),
    (["simulate", "--speed-kt", "500"], "outside the model's range"),
    (["simulate", "--speed-kt", "80", "--param", "CL_alpha=3"], "CL_alpha"),
    (["simulate", "--speed-kt", "80", "--duration", "-1"], "--duration"),
    (["simulate"], "--speed-kt"),
    (["fly"], "fly"),
]


@pytest.mark.parametrize("argv, culprit", BAD)
def test_bad_input_one_line_exit_2(argv, culprit, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert culprit in err and "Traceback" not in err


def test_console_entry_point_bad_input():
    proc = subprocess.run([sys.executable, "-m", "pyomo_heli.cli", "trim", "--speeds-kt", "-5"], capture_output=True,
                          text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("pyomo-heli trim: error:") and "Traceback" not in proc.stderr
