"""The extension seam: zero strength gives M0 exactly, in every route."""
import numpy as np
import pytest

from pyomo_heli.flighttest.truth_effects import TRUTH_EFFECTS, make_effect
from pyomo_heli.nlp.trim_table import trim_table
from pyomo_heli.physics.extensions import PitchMomentOffset
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.inputs import InputSignal
from pyomo_heli.simulation.integrate import simulate
from pyomo_heli.simulation.trim import trim_float
from pyomo_heli.units import DEG, KT

EFFECTS = sorted({cls().name for cls in TRUTH_EFFECTS.values()})


@pytest.mark.parametrize("name", EFFECTS + ["pitch_moment_offset"])
def test_zero_strength_gives_m0_outputs_identically(name):
    ext = PitchMomentOffset() if name == "pitch_moment_offset" else make_effect(name)
    m0 = HelicopterModel()
    me = HelicopterModel(extensions=[ext])
    V = 30 * KT
    sig = {"lon": InputSignal("lon", "doublet", 0.5 * DEG, 1.0, t_start=0.5, ramp=0.1)}
    t = np.linspace(0, 4, 81)
    a = simulate(m0, trim_float(m0, V), t, sig, max_step=0.05)
    b = simulate(me, trim_float(me, V), t, sig, max_step=0.05)
    for k in ("q", "theta", "n_x", "n_z", "TAS", "beta_0"):
        assert np.array_equal(a[k].to_numpy(), b[k].to_numpy()), k


@pytest.mark.parametrize("name", EFFECTS)
def test_zero_strength_in_pyomo_trim_block(name):
    """In the NLP, state-adding extensions stay in implicit form; at zero they give M0's trim."""
    ext = make_effect(name)
    a = trim_table(HelicopterModel(), [30 * KT]).iloc[0]
    b = trim_table(HelicopterModel(extensions=[ext]), [30 * KT]).iloc[0]
    for k in ("col", "lon", "theta", "lambda_i"):
        assert b[k] == pytest.approx(a[k], abs=1e-9)


def test_nonzero_strength_changes_the_model():
    ext = PitchMomentOffset()
    m = HelicopterModel(extensions=[ext]).with_parameters(dM_offset=500.0)
    a = trim_float(HelicopterModel(), 30 * KT)
    b = trim_float(m, 30 * KT)
    assert abs(b.lon - a.lon) > 0.01 * DEG


def test_extension_parameters_join_the_table():
    m = HelicopterModel(extensions=[make_effect("wake_on_tail")])
    assert m.parameters["K_lamT"] == 0.0
    assert "d_t" in m.parameters
    with pytest.raises(KeyError, match="unknown parameter"):
        m.with_parameters(K_lam=1.0)
