"""Two routes agree: float simulator vs Pyomo trim block and Pyomo collocation."""

import numpy as np
import pyomo.environ as pyo
import pytest

from pyomo_heli.nlp.maneuver_block import build_maneuver_block
from pyomo_heli.nlp.parameters import add_parameters
from pyomo_heli.nlp.trim_block import build_trim_block
from pyomo_heli.nlp.trim_table import trim_table
from pyomo_heli.physics.model import STATES, HelicopterModel
from pyomo_heli.simulation.inputs import InputSignal
from pyomo_heli.diagnosis.candidates import candidate_names, make_candidate
from pyomo_heli.simulation.compiled import simulate_outputs as compiled_outputs
from pyomo_heli.simulation.integrate import sampled, simulate
from pyomo_heli.simulation.trim import TrimPoint, trim_float, trim_sweep
from pyomo_heli.solvers import available_solvers, make_solver
from pyomo_heli.units import DEG, KT


def _trimpoint(d):
    return TrimPoint(V=d["V"], gamma_fp=0.0, col=d["col"], lon=d["lon"], theta=d["theta"], lambda_i=d["lambda_i"],
                     beta_0=d["beta_0"], beta_1c=d["beta_1c"], beta_1s=d["beta_1s"], u=d["u"], w=d["w"])


@pytest.mark.parametrize("speed_kt", [0.0, 20.0, 80.0, 120.0])
def test_pyomo_trim_equals_float_trim(speed_kt):
    table = trim_table(HelicopterModel(), [speed_kt * KT])
    ref = trim_sweep(HelicopterModel(), [speed_kt * KT])[0]
    row = table.iloc[0]
    for k in ("col", "lon", "theta"):
        assert row[k] == pytest.approx(getattr(ref, k), abs=1e-7)
    assert row["lambda_i"] == pytest.approx(ref.lambda_i, abs=1e-9)


def test_a_trim_block_re_solves_at_another_speed_by_its_param_alone():
    """Built once at 80 kt, the trim block re-solved at 60 and 120 kt by changing only the mutable Param
    ``V_target`` (no rebuild) agrees with the float trim (``trim_float``, Newton on the float equations) to 1e-10
    in col, lon, theta, lambda_i and the three flapping angles."""
    from pyomo_heli.nlp.trim_block import trim_block_values

    model = HelicopterModel()
    m = pyo.ConcreteModel()
    pmap = add_parameters(m, model.parameters, [])
    m.trim = pyo.Block()
    build_trim_block(m.trim, model, pmap, 80 * KT)
    m.obj = pyo.Objective(expr=0.0)
    solver = make_solver(m, "casadi-ipopt", {"tol": 1e-12})
    for kt in (80.0, 60.0, 120.0):
        m.trim.V_target.set_value(kt * KT)
        assert solver.solve().success, kt
        got, ref = trim_block_values(m.trim), trim_float(model, kt * KT)
        for k in ("col", "lon", "theta", "lambda_i", "beta_0", "beta_1c", "beta_1s"):
            assert got[k] == pytest.approx(getattr(ref, k), abs=1e-10), (kt, k)


@pytest.mark.parametrize("speed_kt", [0.0, 80.0])
def test_simulator_started_at_pyomo_trim_stays_at_trim(speed_kt):
    model = HelicopterModel()
    tp = _trimpoint(trim_table(model, [speed_kt * KT]).iloc[0].to_dict())
    df = simulate(model, tp, np.linspace(0, 10, 11))
    for s in STATES:
        assert np.max(np.abs(df[s].to_numpy() - df[s].iloc[0])) < 1e-6, s


@pytest.mark.parametrize("candidate", [None] + candidate_names())
def test_compiled_rk4_equals_python_rk4(candidate):
    """The casadi-evaluated RK4 (simulation.compiled, used by the sensitivities) gives the Python RK4's
    outputs to rounding, for M0 and M0 + each candidate extension at its parameter scale."""
    model = HelicopterModel()
    if candidate is not None:
        ext = make_candidate(candidate)
        model = HelicopterModel(extensions=[ext])
        spec = model.parameters.spec(ext.strength)
        model = model.with_parameters(**{ext.strength: float(spec.scale)})
    tp = trim_float(model, 80 * KT)
    t = np.arange(0.0, 3.0 + 1e-9, 0.04)
    dlon = InputSignal("lon", "3211", 0.5 * DEG, 0.5, t_start=0.5, ramp=0.1)(t)
    ref = simulate(model, tp, t, {"lon": sampled(t, dlon)}, method="rk4", substeps=4)
    outputs = ["q", "theta", "n_x", "n_z", "TAS", "beta_0"]
    got = compiled_outputs(model, tp, t, {"lon": dlon}, outputs, substeps=4)
    for o in outputs:
        r = ref[o].to_numpy()
        assert np.max(np.abs(got[o] - r)) <= 1e-12 * max(np.max(np.abs(r)), 1e-3), (candidate, o)
    with pytest.raises(ValueError, match="unknown output"):
        compiled_outputs(model, tp, t, {"lon": dlon}, ["alpha"])


def _square_maneuver(model, V, tp, t, dlon):
    """A trim block and a lon maneuver at V as a square NLP (zero objective), started from the trim
    held constant, not from the answer."""
    m = pyo.ConcreteModel()
    pmap = add_parameters(m, model.parameters, [])
    m.trim = pyo.Block()
    build_trim_block(m.trim, model, pmap, V, guess=tp.to_dict())
    m.man = pyo.Block()
    build_maneuver_block(m.man, model, pmap, t, {"lon": dlon}, m.trim, ncp=3)
    for (s, tt), v in m.man.x.items():
        v.set_value(tp.state()[s])
    m.obj = pyo.Objective(expr=0.0)
    return m


def test_collocation_matches_scipy_simulation():
    """A 80 kt lon 3-2-1-1 as a square collocation problem equals solve_ivp to 1e-3 of each output's range."""
    model = HelicopterModel()
    V = 80 * KT
    tp = trim_float(model, V)
    t = np.arange(0.0, 8.0 + 1e-9, 0.02)
    dlon = InputSignal("lon", "3211", 0.5 * DEG, 0.5, t_start=1.0, ramp=0.1)(t)
    ref = simulate(model, tp, t, {"lon": sampled(t, dlon)}, max_step=0.02)

    m = _square_maneuver(model, V, tp, t, dlon)
    res = make_solver(m).solve(warm_start="none")
    assert res.success, res
    for k in ("q", "theta", "n_x", "n_z", "TAS", "beta_0"):
        y = np.array([pyo.value(m.man.y[k, tt]) for tt in m.man.samples])
        r = ref[k].to_numpy()
        assert np.max(np.abs(y - r)) <= 1e-3 * (r.max() - r.min()), k


def test_shared_intermediates_equal_float_model_and_are_defined_variables(tmp_path):
    """blk.shared (rotor flow, c_t, T, X, Z, M) at a time point equals the float model's values for the same
    states, flapping and inputs, and the NL writer exports each once as a defined variable."""
    from pyomo.repn.plugins.nl_writer import NLWriter

    from pyomo_heli.physics.model import SHARED, evaluate

    model = HelicopterModel()
    tp = trim_float(model, 60 * KT)
    t = np.arange(0.0, 0.1 + 1e-9, 0.02)
    m = pyo.ConcreteModel()
    pmap = add_parameters(m, model.parameters, [])
    m.trim = pyo.Block()
    build_trim_block(m.trim, model, pmap, 60 * KT, guess=tp.to_dict())
    m.man = pyo.Block()
    build_maneuver_block(m.man, model, pmap, t, {"col": 0.01 * t}, m.trim, ncp=3)
    rng = np.random.default_rng(7)
    tt = list(m.man.t)[4]
    x = {s: tp.state()[s] * (1 + 0.05 * rng.standard_normal()) + 0.01 * rng.standard_normal() for s in STATES}
    beta = [0.01 * rng.standard_normal() for _ in range(3)]
    for s in STATES:
        m.man.x[s, tt].set_value(x[s])
    for b, v in zip(("beta_0", "beta_1c", "beta_1s"), beta):
        m.man.beta[b, tt].set_value(v)
    u = {k: pyo.value(getattr(m.trim, k)) + pyo.value(m.man.du[k, tt]) for k in ("col", "lon")}
    ref = evaluate(x, u, model.parameters, beta=beta)
    expected = {"mu": ref.flow.mu, "mu_z": ref.flow.mu_z, "lam": ref.lam, "c_t": ref.c_t, "T": ref.thrust,
                "X": ref.forces.X, "Z": ref.forces.Z, "M": ref.forces.M}
    assert set(expected) == set(SHARED)
    for k, v in expected.items():
        assert pyo.value(m.man.shared[k, tt]) == pytest.approx(v, rel=1e-12, abs=1e-14), k
    m.obj = pyo.Objective(expr=0.0)
    lines = {}
    for export in (True, False):
        with open(tmp_path / "m.nl", "w") as f:
            NLWriter().write(m, f, linear_presolve=False, scale_model=False, export_defined_variables=export)
        lines[export] = (tmp_path / "m.nl").read_text().splitlines()
    # every shared intermediate of every time point is a defined variable (Pyomo may add one more
    # for the linear part of a nonlinear one), and the file is half the size of the inlined one
    assert sum(1 for line in lines[True] if line.startswith("V")) >= len(SHARED) * len(m.man.t)
    assert len(lines[True]) < 0.6 * len(lines[False])


@pytest.mark.skipif("pounce" not in available_solvers(), reason="pounce not available")
def test_pounce_solves_collocation_with_defined_variables():
    """The AMPL route (pounce reads the same NL file, shared intermediates as defined variables) gives the
    casadi route's maneuver: a 2 s lon 3-2-1-1 at 80 kt as a square problem, outputs equal to 1e-9."""
    model = HelicopterModel()
    V = 80 * KT
    tp = trim_float(model, V)
    t = np.arange(0.0, 2.0 + 1e-9, 0.02)
    dlon = InputSignal("lon", "3211", 0.5 * DEG, 0.5, t_start=0.2, ramp=0.1)(t)
    got = {}
    for name in ("casadi-ipopt", "pounce"):
        m = _square_maneuver(model, V, tp, t, dlon)
        res = make_solver(m, name).solve(warm_start="none")
        assert res.success, (name, res)
        got[name] = np.array([[pyo.value(m.man.y[k, tt]) for tt in m.man.samples] for k in ("q", "theta", "n_z")])
    assert np.ptp(got["casadi-ipopt"][1]) > 1e-3  # the maneuver moves theta
    assert np.max(np.abs(got["casadi-ipopt"] - got["pounce"])) < 1e-9
