"""M0 physics against independent references (model_spec.md sections 1.11, 3, 6.1)."""
import math
from pathlib import Path

import numpy as np
import pytest

from pyomo_heli.physics import rotor
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.physics.parameters import bo105, teaching_model
from pyomo_heli.simulation.inputs import InputSignal
from pyomo_heli.simulation.integrate import simulate
from pyomo_heli.simulation.trim import TrimPoint, trim_float, trim_sweep
from pyomo_heli.units import DEG, KT


def test_hover_momentum_and_closed_form_collective():
    """Hover: C_T = W/(rho A V_tip^2), lambda_i = sqrt(C_T/2), col from blade-element theory (spec 6.1)."""
    m = HelicopterModel()
    tp = trim_float(m, 0.0)
    p = m.parameters
    c_t = p["m"] * p["g"] / (p["rho"] * math.pi * p["R"] ** 2 * (p["Omega"] * p["R"]) ** 2)
    assert c_t == pytest.approx(0.004887, abs=5e-7)
    assert tp.lambda_i == pytest.approx(0.0494, abs=1e-4)
    assert tp.lambda_i == pytest.approx(math.sqrt(c_t / 2), rel=1e-6)
    assert tp.col / DEG == pytest.approx(8.58, abs=0.02)
    # hover attitude: shaft tilt plus the small disc tilt from the hub offset
    assert tp.theta / DEG == pytest.approx(3.0, abs=0.02)
    T = c_t * p["rho"] * math.pi * p["R"] ** 2 * (p["Omega"] * p["R"]) ** 2
    b1c = (p["x_h"] - p["h"] * p["gamma_s"]) * T / (p["Nb"] / 2 * p["K_beta"] + T * p["h"])
    assert tp.beta_1c == pytest.approx(b1c, abs=2e-5)


def test_flapping_hover_limits():
    """Hover, no spring: beta_1c = -theta_1s + 16 qbar/gamma, beta_1s = qbar (spec 1.4 checks)."""
    p = bo105().with_values(K_beta=0.0)
    lock, _, lb2 = rotor.rotor_constants(p)
    assert lb2 == 1.0
    flow = rotor.HubFlow(mu=0.0, mu_z=0.0, qbar=0.01, v_tip=218.0)
    pitch = rotor.BladePitch(theta_0=0.2, theta_tw=-0.14, theta_1s=0.03)
    b0, b1c, b1s = rotor.solve_flapping(flow, pitch, 0.05, p)
    assert b1c == pytest.approx(-0.03 + 16 * 0.01 / lock, rel=1e-12)
    assert b1s == pytest.approx(0.01, rel=1e-12)
    assert b0 == pytest.approx(lock * (0.2 / 8 - 0.14 / 10 - 0.05 / 6), rel=1e-12)


def test_flapping_closed_form_solves_the_nlp_equations():
    p = bo105()
    flow = rotor.HubFlow(mu=0.2, mu_z=-0.01, qbar=0.003, v_tip=218.0)
    pitch = rotor.BladePitch(theta_0=0.25, theta_tw=-0.14, theta_1s=-0.04)
    beta = rotor.solve_flapping(flow, pitch, 0.02, p)
    res = rotor.flapping_residuals(beta, flow, pitch, 0.02, p)
    assert np.max(np.abs(res)) < 1e-14
    A, _ = rotor.flapping_system(flow, pitch, 0.02, p)
    lock, _, lb2 = rotor.rotor_constants(p)
    assert math.degrees(math.atan((lb2 - 1) * 8 / lock)) == pytest.approx(21.0, abs=0.5)


# teaching-model reference trims (theta_0, theta_c, theta_f in deg; lambda_i), spec 1.11
TEACHING = [(0.0, 5.213, 0.000, 0.000, 0.0362), (20.0, 3.422, 0.734, -0.976, 0.0129),
            (40.0, 4.082, 1.618, -3.897, 0.0065), (60.0, 7.057, 3.448, -8.713, 0.0044)]


@pytest.mark.parametrize("V, th0, thc, thf, lam", TEACHING)
def test_teaching_model_trims(V, th0, thc, thf, lam):
    tol = 0.01 if V <= 30 else 0.1
    m = HelicopterModel(teaching_model())
    tp = trim_sweep(m, [V])[0]
    assert tp.col / DEG == pytest.approx(th0, abs=tol)
    assert -tp.lon / DEG == pytest.approx(thc, abs=tol)  # teaching theta_c is forward-positive
    assert tp.theta / DEG == pytest.approx(thf, abs=tol)
    assert tp.lambda_i == pytest.approx(lam, abs=1e-4)


def test_teaching_model_lecture_cyclic_pulse():
    """Lecture case: untrimmed hover start, col 6 deg, theta_c = +1 deg for 0.5 <= t <= 1 s."""
    m = HelicopterModel(teaching_model())
    p = m.parameters
    lam0 = math.sqrt(p["m"] * p["g"] / (math.pi * p["R"] ** 2 * 2 * p["rho"])) / (p["Omega"] * p["R"])
    start = TrimPoint(V=0, gamma_fp=0, col=6 * DEG, lon=0.0, theta=0.0, lambda_i=lam0, beta_0=0, beta_1c=0,
                      beta_1s=0, u=0.0, w=0.0)
    pulse = InputSignal("lon", "pulse", -1 * DEG, 0.5, t_start=0.5)
    df = simulate(m, start, [0.0, 2.0, 4.0], {"lon": pulse}, max_step=0.01).set_index("t")
    ref = {(2.0, "q"): -0.84 * DEG, (2.0, "theta"): -1.22 * DEG, (2.0, "w"): -2.14,
           (4.0, "q"): -0.48 * DEG, (4.0, "theta"): -2.53 * DEG, (4.0, "u"): 0.74}
    for (t, k), v in ref.items():
        assert df.loc[t, k] == pytest.approx(v, rel=0.02), (t, k)


def test_trim_curve_shapes():
    """Collective U-shaped with its minimum at 50-80 kt; lon and attitude nose-down above 20 kt (spec 3)."""
    speeds_kt = np.arange(0, 121, 5.0)
    tps = trim_sweep(HelicopterModel(), speeds_kt * KT)
    col = np.array([t.col for t in tps])
    lon = np.array([t.lon for t in tps])
    th = np.array([t.theta for t in tps])
    kmin = int(np.argmin(col))
    assert 50 <= speeds_kt[kmin] <= 80
    assert col[0] - col[kmin] > 1.5 * DEG and col[-1] > col[kmin] + 1.0 * DEG
    above = speeds_kt >= 20
    assert np.all(np.diff(lon[above]) < 0)
    assert np.all(np.diff(th[above]) < 0)
    # thrust carries the weight in level flight (within 2 %)
    m = HelicopterModel()
    for tp in tps:
        ctx = m.evaluate(tp.state(), tp.inputs())
        assert ctx.thrust == pytest.approx(m.parameters["m"] * m.parameters["g"], rel=0.02)


def test_parameter_table_rejects_unknown_names():
    with pytest.raises(KeyError, match="Iyx.*did you mean Iyy"):
        bo105().with_values(Iyx=1.0)
    p = bo105()
    assert p.spec("theta_twist").shown()[0] == pytest.approx(-1.6329)
    assert p["theta_twist"] * p["R"] == pytest.approx(-0.14, abs=2e-4)


DOCS = Path(__file__).resolve().parents[1] / "docs"


def _doc_rows(page: str, first_cell: str) -> list[list[str]]:
    """The rows of the markdown tables of docs/``page`` whose first cell matches ``first_cell`` (a regex)."""
    import re

    return [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in (DOCS / page).read_text().splitlines() if re.match(rf"^\| {first_cell} \|", line)]


def test_the_documented_parameter_table_is_the_codes():
    """docs/model_parameters.md's table of the nominal Bo-105: every parameter of bo105(), the value the code has."""
    p = bo105()
    rows = {r[0].strip("`"): float(r[2]) for r in _doc_rows("model_parameters.md", r"`\w+`") if r[0].strip("`") in p}
    assert set(rows) == set(p)
    for name, value in rows.items():
        assert value == pytest.approx(p[name], rel=5e-4, abs=1e-9), name


def test_the_documented_m0_trim_table_is_what_the_code_trims():
    """docs/model_forces.md 9.4: the M0 trims at 0-120 kt, to the digits printed (the command printed there)."""
    m = HelicopterModel()
    p = m.parameters
    rows = _doc_rows("model_forces.md", r"\d+")
    rows = [r for r in rows if len(r) == 11]
    assert [int(r[0]) for r in rows] == [0, 20, 40, 60, 80, 100, 120]
    for r, tp in zip(rows, trim_sweep(m, [int(r[0]) * 0.514444 for r in rows])):
        thrust = m.evaluate(tp.state(), tp.inputs()).thrust / (p["m"] * p["g"])
        theta0 = tp.col - p["r_ref"] * p["theta_twist"] * p["R"]
        got = [tp.V, tp.col / DEG, theta0 / DEG, tp.lon / DEG, tp.theta / DEG, tp.lambda_i, tp.beta_0 / DEG,
               tp.beta_1c / DEG, tp.beta_1s / DEG, thrust]
        for doc, value in zip(r[1:], got):
            step = 10.0 ** -len(doc.split(".")[1])  # the printed resolution
            assert abs(float(doc) - value) <= 0.51 * step, (r[0], doc, value)
