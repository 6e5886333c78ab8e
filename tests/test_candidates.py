"""The candidate library: every candidate is M0 at zero strength and acts where its physics says."""
import numpy as np
import pytest

from pyomo_heli.diagnosis.candidates import CANDIDATES, make_candidate
from pyomo_heli.nlp.trim_table import trim_table
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.inputs import InputSignal
from pyomo_heli.simulation.integrate import simulate
from pyomo_heli.simulation.trim import trim_float, trim_sweep
from pyomo_heli.units import DEG, KT


def test_registry_lists_every_required_effect():
    required = {"rotor_wake_on_tail", "flapping_lag", "inflow_time_constant", "cg_offset", "lon_rigging",
                "col_rigging", "accel_position_x", "nz_bias", "nx_bias"}
    assert required <= set(CANDIDATES)
    for name in CANDIDATES:
        c = make_candidate(name)
        assert c.name == name and c.parameters()[0].name == c.strength
        assert c.parameters()[0].value == 0.0 and c.parameters()[0].bounds is not None


def test_unknown_candidate_names_the_known_ones():
    with pytest.raises(KeyError, match="unknown candidate extension 'cg_ofset'.*did you mean cg_offset"):
        make_candidate("cg_ofset")


@pytest.mark.parametrize("name", list(CANDIDATES))
def test_zero_strength_is_m0_in_float_and_pyomo_trims_and_simulation(name):
    m0, me = HelicopterModel(), HelicopterModel(extensions=[make_candidate(name)])
    V = 30 * KT
    sig = {"lon": InputSignal("lon", "doublet", 0.5 * DEG, 1.0, t_start=0.5, ramp=0.1)}
    t = np.linspace(0, 3, 61)
    a = simulate(m0, trim_float(m0, V), t, sig, method="rk4", substeps=2)
    b = simulate(me, trim_float(me, V), t, sig, method="rk4", substeps=2)
    for k in ("q", "theta", "n_x", "n_z", "TAS", "beta_0"):
        assert np.array_equal(a[k].to_numpy(), b[k].to_numpy()), k
    ta, tb = trim_table(m0, [V]).iloc[0], trim_table(me, [V]).iloc[0]
    for k in ("col", "lon", "theta"):
        assert tb[k] == pytest.approx(ta[k], abs=1e-9)


def test_signatures_in_trim():
    """Rigging moves lon only; a CG shift moves lon and theta (the attitude tells them apart); the wake
    acts only at low speed and not in hover; a flapping lag leaves the trim alone."""
    speeds = [v * KT for v in (0, 20, 40, 80, 120)]
    base = trim_sweep(HelicopterModel(), speeds)

    def delta(name, **v):
        tps = trim_sweep(HelicopterModel(extensions=[make_candidate(name)]).with_parameters(**v), speeds)
        return (np.array([(a.lon - b.lon) / DEG for a, b in zip(tps, base)]),
                np.array([(a.theta - b.theta) / DEG for a, b in zip(tps, base)]))

    lon, th = delta("lon_rigging", b_lon=-0.3 * DEG)
    assert lon == pytest.approx(0.3, abs=1e-6) and np.abs(th).max() < 1e-6   # theta_1s = lon + b fixed
    lon, th = delta("cg_offset", dx_fwd=0.05)
    assert np.all(lon > 0.2) and np.all(th < -0.15)
    lon, th = delta("rotor_wake_on_tail", k_wt=1.0)
    assert abs(lon[0]) < 1e-6 and lon[1] < -0.3 and th[1] > 0.3 and abs(lon[3]) < 0.05
    lon, th = delta("flapping_lag", tau_b=0.07)
    assert np.abs(lon).max() < 1e-6 and np.abs(th).max() < 1e-6
