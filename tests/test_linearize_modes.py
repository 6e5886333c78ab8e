"""`pyomo-heli linearize`: labelled A, B, C, D and a mode table, checked against eigenvalues computed here."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pyomo_heli.cli import main
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.report.linearization import gain_unit, labelled_matrices, mode_table
from pyomo_heli.simulation.linearize import LinearModel, linearize_float
from pyomo_heli.units import KT


def _eigen_checks(A: np.ndarray, modes: list[dict]) -> None:
    """Every row is an eigenvalue of A (one per conjugate pair) with frequency, damping, period and time to
    half/double as their definitions give them, and the rows cover all eigenvalues."""
    ev = np.linalg.eigvals(A)  # computed here, independently of the package
    covered = 0
    for r in modes:
        lam = complex(r["real [1/s]"], r["imag [rad/s]"])
        assert np.min(np.abs(ev - lam)) < 1e-9 * max(1.0, abs(lam)), (lam, ev)
        wn = abs(lam)
        assert r["frequency [rad/s]"] == pytest.approx(wn, rel=1e-12)
        assert r["damping [-]"] == pytest.approx(-lam.real / wn, rel=1e-12)
        if lam.imag > 0:
            covered += 2
            assert r["period [s]"] == pytest.approx(2 * math.pi / lam.imag, rel=1e-12)
        else:
            covered += 1
            assert r["period [s]"] is None or not math.isfinite(r["period [s]"])
        if lam.real > 0:
            assert r["time to double [s]"] == pytest.approx(math.log(2) / lam.real, rel=1e-12)
        else:
            assert r["time to half [s]"] == pytest.approx(math.log(2) / -lam.real, rel=1e-12)
    assert covered == len(ev)


def test_linearize_prints_labelled_matrices_and_writes_modes_json(tmp_path, capsys):
    out = tmp_path / "lin.json"
    assert main(["linearize", "--speeds-kt", "0", "80", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    for label in ("A (dx/dt = A x + B u)", "B (dx/dt = A x + B u)", "C (y = C x + D u)", "D (y = C x + D u)",
                  "du/dt [m/s^2]", "dq/dt [rad/s^2]", "theta [rad]", "lambda_i [-]", "n_z [g]", "col [rad]",
                  "modes (eigenvalues of A)", "phugoid", "time to double [s]"):
        assert label in text, label
    records = json.loads(out.read_text())
    assert [r["speed_kt"] for r in records] == [0, 80]
    model = HelicopterModel()
    for r in records:
        lin = linearize_float(model, r["speed_kt"] * KT)
        A, B, C, D = (np.array(r[k]) for k in "ABCD")
        np.testing.assert_allclose(A, lin.A, rtol=0, atol=0)
        np.testing.assert_allclose(D, lin.D, rtol=0, atol=0)
        assert [s["name"] for s in r["states"]] == ["u", "w", "q", "theta", "lambda_i"]
        assert [s["unit"] for s in r["states"]] == ["m/s", "m/s", "rad/s", "rad", "-"]
        assert [s["name"] for s in r["inputs"]] == ["col", "lon"]
        assert [s["name"] for s in r["outputs"]] == ["q", "theta", "n_x", "n_z", "TAS", "beta_0"]
        assert B.shape == (5, 2) and C.shape == (6, 5) and D.shape == (6, 2)
        _eigen_checks(A, r["modes"])
        # the model's hover and 80 kt phugoid is a slow unstable oscillation (period tens of seconds)
        ph = [m for m in r["modes"] if m["mode"].startswith("phugoid")]
        assert len(ph) == 1 and 5 < ph[0]["period [s]"] < 60 and ph[0]["time to double [s]"] > 0


def test_mode_table_of_a_known_system():
    """A block-diagonal A with a known oscillation in (u, theta), a heave subsidence in w, a pitch subsidence
    in q and an inflow divergence: frequencies, damping, periods and names from their definitions."""
    wn, zeta = 0.5, 0.1
    osc = np.array([[0.0, 1.0], [-wn ** 2, -2 * zeta * wn]])  # x'' + 2 zeta wn x' + wn^2 x = 0
    A = np.zeros((5, 5))
    A[np.ix_([0, 3], [0, 3])] = osc  # u, theta
    A[1, 1], A[2, 2], A[4, 4] = -0.7, -3.0, 0.2
    lin = LinearModel(V=0.0, A=A, B=np.zeros((5, 2)), C=np.zeros((6, 5)), D=np.zeros((6, 2)),
                      states=("u", "w", "q", "theta", "lambda_i"))
    t = mode_table(lin).set_index("mode")
    assert set(t.index) == {"phugoid", "heave subsidence", "pitch subsidence", "inflow divergence"}
    assert t.loc["phugoid", "frequency [rad/s]"] == pytest.approx(wn, rel=1e-12)
    assert t.loc["phugoid", "damping [-]"] == pytest.approx(zeta, rel=1e-12)
    assert t.loc["phugoid", "period [s]"] == pytest.approx(2 * math.pi / (wn * math.sqrt(1 - zeta ** 2)), rel=1e-12)
    assert t.loc["heave subsidence", "time to half [s]"] == pytest.approx(math.log(2) / 0.7, rel=1e-12)
    assert t.loc["pitch subsidence", "damping [-]"] == pytest.approx(1.0)
    assert t.loc["inflow divergence", "time to double [s]"] == pytest.approx(math.log(2) / 0.2, rel=1e-12)
    labels = labelled_matrices(lin)
    assert list(labels["A"].index)[0] == "du/dt [m/s^2]" and list(labels["B"].columns) == ["col [rad]", "lon [rad]"]


def test_bode_gain_units():
    assert gain_unit("q", "lon") == "(rad/s)/rad"
    assert gain_unit("theta", "lon") == "-"
    assert gain_unit("n_z", "col") == "g/rad"


def test_a_trim_at_another_speed_is_refused_not_labelled_with_the_speed_asked():
    """linearize_float(model, V, trim) with a trim of another speed would return that speed's model labelled V."""
    from pyomo_heli.simulation.trim import trim_float

    model = HelicopterModel()
    at_80 = trim_float(model, 80 * KT)
    with pytest.raises(ValueError, match=r"trim given is at V = 41\.1\d* m/s, not at V = 0 m/s"):
        linearize_float(model, 0.0, at_80)
    same = linearize_float(model, 80 * KT, at_80)  # the trim of that speed: the same model as trimming inside
    np.testing.assert_array_equal(same.A, linearize_float(model, 80 * KT).A)
