"""The replay module: model trims with a per-speed fallback, and one maneuver replayed from the model's trim."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from pyomo_heli.dataset import load_flight_test
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation import replay as rp
from pyomo_heli.simulation.compiled import simulate_outputs
from pyomo_heli.simulation.integrate import sampled, simulate
from pyomo_heli.simulation.trim import trim_float
from pyomo_heli.units import DEG, KT

DATA = Path(__file__).resolve().parents[1] / "data" / "bo105_synthetic"


@pytest.fixture(scope="module")
def maneuver():
    ft = load_flight_test(DATA)
    mv = next(m for m in ft.maneuvers.values() if m.role == "identification")
    return dataclasses.replace(mv, data=mv.data[mv.data["t"] <= mv.data["t"].iloc[0] + 3.0].reset_index(drop=True))


def test_checked_replay_in_pieces_is_the_one_piece_integration(maneuver):
    """The Python RK4's divergence check integrates in 1 s pieces; that is the same RK4 arithmetic as one piece, to
    the bit, and the same as calling the integrator directly. The compiled replay (the default) is the same record
    to rounding, column for column."""
    model = HelicopterModel()
    tp = trim_float(model, maneuver.trim_speed)
    checked = rp.replay(model, maneuver, tp, compiled=False)
    whole = rp.replay(model, maneuver, tp, check=False, compiled=False)
    fast = rp.replay(model, maneuver, tp)
    assert list(fast.columns) == list(checked.columns)
    for c in fast.columns:
        np.testing.assert_allclose(fast[c].to_numpy(), checked[c].to_numpy(), rtol=1e-10,
                                   atol=1e-12 * max(1.0, float(np.max(np.abs(checked[c])))), err_msg=c)
    t = maneuver.data["t"].to_numpy()
    direct = simulate(model, tp, t, {k: sampled(t, v) for k, v in maneuver.increments().items()}, method="rk4",
                      substeps=4)
    assert len(checked) == len(t) > 2 * (1 + rp.CHUNK_S * maneuver.sample_rate)  # at least three pieces
    for c in direct.columns:
        np.testing.assert_array_equal(checked[c].to_numpy(), whole[c].to_numpy(), err_msg=c)
        np.testing.assert_array_equal(whole[c].to_numpy(), direct[c].to_numpy(), err_msg=c)


def test_maneuver_outputs_without_compilation_is_the_python_rk4(maneuver):
    """``maneuver_outputs(compiled=False)`` (single shooting's ``"rk4"``, the benchmark's Python route) integrates by
    the Python RK4, to the bit, not by the compiled one (equal only to rounding)."""
    model = HelicopterModel()
    tp = trim_float(model, maneuver.trim_speed)
    t = maneuver.data["t"].to_numpy()
    direct = simulate(model, tp, t, {k: sampled(t, v) for k, v in maneuver.increments().items()}, method="rk4",
                      substeps=4)
    outputs = ["q", "theta", "n_z"]
    python = rp.maneuver_outputs(model, [maneuver], outputs, compiled=False)
    fast = rp.maneuver_outputs(model, [maneuver], outputs)
    for o in outputs:
        np.testing.assert_array_equal(python[o], direct[o].to_numpy(), err_msg=o)
        np.testing.assert_allclose(fast[o], direct[o].to_numpy(), rtol=1e-10, atol=1e-12, err_msg=o)
    assert any(not np.array_equal(fast[o], python[o]) for o in outputs)  # the two routes really are two


def test_a_diverging_replay_stops_at_the_same_sample_compiled_or_not(maneuver):
    """A pitch-unstable model (a generic pitch-damping term of the wrong sign, five times its NLP bound): both RK4s
    raise Diverged at the same first implausible sample and carry the same record up to it."""
    from pyomo_heli.physics.discrepancy import generic_term

    term = generic_term("dM_q")
    model = HelicopterModel(extensions=(term,)).with_parameters(**{term.strength: 0.1})
    tp = trim_float(model, maneuver.trim_speed)
    got = []
    for compiled in (True, False):
        with pytest.raises(rp.Diverged) as exc:
            rp.replay(model, maneuver, tp, compiled=compiled)
        got.append((str(exc.value), exc.value.partial))
    (msg_c, part_c), (msg_p, part_p) = got
    assert msg_c == msg_p and "left its plausible range" in msg_c and 2 < len(part_c) < len(maneuver.data)
    assert len(part_c) == len(part_p) and list(part_c.columns) == list(part_p.columns)
    np.testing.assert_allclose(part_c["q"].to_numpy(), part_p["q"].to_numpy(), rtol=1e-8)


def test_a_constant_input_offset_moves_the_replay_like_an_increment(maneuver):
    model = HelicopterModel()
    tp = trim_float(model, maneuver.trim_speed)
    a = rp.replay(model, maneuver, tp, offsets={"lon": 0.1 * DEG})
    b = rp.replay(model, maneuver, tp)
    np.testing.assert_allclose(a["lon"] - b["lon"], 0.1 * DEG, rtol=0, atol=1e-15)
    assert np.allclose(a["col"], b["col"], rtol=0, atol=1e-15) and not np.allclose(a["q"], b["q"], atol=1e-9)


def test_divergence_limits_are_the_dataset_plausibility_limits():
    from pyomo_heli.dataset.schema import MANEUVER_QUANTITIES

    expected = {q.si: q.limit for q in MANEUVER_QUANTITIES if q.limit}
    assert rp.DIVERGENCE_LIMITS == {k: v for k, v in expected.items() if k in rp.OUTPUTS}
    assert rp.DIVERGENCE_LIMITS["q"] == pytest.approx(360 * DEG)
    assert rp.DIVERGENCE_LIMITS["TAS"] == pytest.approx(250 * KT)


def test_model_trims_fall_back_to_one_speed_at_a_time(monkeypatch):
    """A sweep that breaks costs only the speed that fails; the others are the sweep's own trims."""
    model = HelicopterModel()
    real = rp.trim_sweep
    bad = 40 * KT

    def sweep(m, speeds, gamma_fp=0.0):
        if any(abs(v - bad) < 1e-6 for v in speeds):
            raise RuntimeError("no trim here\nsecond line")
        return real(m, speeds, gamma_fp=gamma_fp)

    monkeypatch.setattr(rp, "trim_sweep", sweep)
    speeds = [0.0, 20 * KT, bad, 60 * KT]
    trims, failed = rp.model_trims(model, speeds)
    assert failed == [(rp.speed_key(bad), "no trim here")]
    assert trims[rp.speed_key(bad)] is None
    for v in (0.0, 20 * KT, 60 * KT):
        assert trims[rp.speed_key(v)].theta == pytest.approx(real(model, [v])[0].theta, abs=1e-8)  # trim tolerance


def test_a_fast_lag_gets_enough_rk4_steps_and_matches_a_stiff_integrator(maneuver):
    """A discovered input time shift of 1 ms (tau dx/dt = col - x) is far below the sample interval: four RK4
    steps per sample diverge, the replay takes enough of them and agrees with scipy's Radau, and the compiled
    (casadi) RK4 of the diagnosis takes the same steps."""
    from pyomo_heli.physics.discrepancy import generic_term

    term = generic_term("col_delay")
    model = HelicopterModel(extensions=(term,)).with_parameters(**{term.strength: 1e-3})
    tp = trim_float(model, maneuver.trim_speed)
    assert model.lag_rates(tp.state(), tp.inputs())[term.states[0]] == pytest.approx(1e3, rel=1e-5)
    t = maneuver.data["t"].to_numpy()
    inc = {k: sampled(t, v) for k, v in maneuver.increments().items()}
    dt = float(np.max(np.diff(t)))
    assert rp.stable_substeps(model, tp, dt, 4) >= dt / 1e-3
    with np.errstate(all="ignore"), pytest.raises(RuntimeError, match="diverged"):
        simulate(model, tp, t, inc, method="rk4", substeps=4)
    got = rp.replay(model, maneuver, tp)
    ref = simulate(model, tp, t, inc, method="Radau", rtol=1e-8, atol=1e-10)
    fast = simulate_outputs(model, tp, t, maneuver.increments(), ("q", "theta", "n_z", "TAS"), substeps=2)
    for c in ("q", "theta", "n_z", "TAS"):
        np.testing.assert_allclose(got[c].to_numpy(), ref[c].to_numpy(), rtol=0,
                                   atol=1e-4 * max(1.0, float(np.max(np.abs(ref[c])))), err_msg=c)
        np.testing.assert_allclose(fast[c], got[c].to_numpy(), rtol=1e-9, atol=1e-9, err_msg=c)  # casadi's RK4


@pytest.mark.parametrize("name, c", [("lon_scale", 0.05), ("dM_qmu", -0.003)])
def test_the_extended_family_replays_the_same_compiled_or_not(maneuver, name, c):
    """An input scale factor (applied to the control the rotor sees) and a speed product: the compiled replay and
    the Python RK4 give the same record, and the term moves it."""
    from pyomo_heli.physics.discrepancy import generic_term

    term = generic_term(name)
    model = HelicopterModel(extensions=(term,)).with_parameters(**{term.strength: c})
    tp = trim_float(model, maneuver.trim_speed)
    fast, slow = rp.replay(model, maneuver, tp), rp.replay(model, maneuver, tp, compiled=False)
    for col in ("q", "theta", "n_z", "TAS"):
        np.testing.assert_allclose(fast[col].to_numpy(), slow[col].to_numpy(), rtol=1e-9, atol=1e-12, err_msg=col)
    m0 = rp.replay(HelicopterModel(), maneuver, trim_float(HelicopterModel(), maneuver.trim_speed))
    assert np.max(np.abs(fast["q"].to_numpy() - m0["q"].to_numpy())) > 1e-4
