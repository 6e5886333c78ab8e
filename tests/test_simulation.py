"""Two routes agree: float simulator vs Pyomo trim block and Pyomo collocation."""
import math

import numpy as np
import pyomo.environ as pyo
import pytest

from pyomo_heli.nlp.maneuver_block import build_maneuver_block
from pyomo_heli.nlp.parameters import add_parameters
from pyomo_heli.nlp.trim_block import build_trim_block, trim_block_values
from pyomo_heli.nlp.trim_table import trim_table
from pyomo_heli.physics.model import STATES, HelicopterModel
from pyomo_heli.simulation.inputs import InputSignal
from pyomo_heli.simulation.integrate import sampled, simulate
from pyomo_heli.simulation.trim import TrimPoint, trim_float, trim_sweep
from pyomo_heli.solvers import make_solver
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


@pytest.mark.parametrize("speed_kt", [0.0, 80.0])
def test_simulator_started_at_pyomo_trim_stays_at_trim(speed_kt):
    model = HelicopterModel()
    tp = _trimpoint(trim_table(model, [speed_kt * KT]).iloc[0].to_dict())
    df = simulate(model, tp, np.linspace(0, 10, 11))
    for s in STATES:
        assert np.max(np.abs(df[s].to_numpy() - df[s].iloc[0])) < 1e-6, s


def test_collocation_matches_scipy_simulation():
    """A 80 kt lon 3-2-1-1 as a square collocation problem equals solve_ivp to 1e-3 of each output's range."""
    model = HelicopterModel()
    V = 80 * KT
    tp = trim_float(model, V)
    t = np.arange(0.0, 8.0 + 1e-9, 0.02)
    dlon = InputSignal("lon", "3211", 0.5 * DEG, 0.5, t_start=1.0, ramp=0.1)(t)
    ref = simulate(model, tp, t, {"lon": sampled(t, dlon)}, max_step=0.02)

    m = pyo.ConcreteModel()
    pmap = add_parameters(m, model.parameters, [])
    m.trim = pyo.Block()
    build_trim_block(m.trim, model, pmap, V, guess=tp.to_dict())
    m.man = pyo.Block()
    # start the NLP from the trim held constant, not from the answer
    build_maneuver_block(m.man, model, pmap, t, {"lon": dlon}, m.trim, ncp=3)
    for (s, tt), v in m.man.x.items():
        v.set_value(tp.state()[s])
    m.obj = pyo.Objective(expr=0.0)
    res = make_solver(m).solve(warm_start="none")
    assert res.success, res
    for k in ("q", "theta", "n_x", "n_z", "TAS", "beta_0"):
        y = np.array([pyo.value(m.man.y[k, tt]) for tt in m.man.samples])
        r = ref[k].to_numpy()
        assert np.max(np.abs(y - r)) <= 1e-3 * (r.max() - r.min()), k
