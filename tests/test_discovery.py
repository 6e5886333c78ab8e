"""Structure determination ([loop] discovery = true, pyomo_heli.diagnosis.discovery) on small generated flight tests.

The undeclared effects come from pyomo_heli.flighttest.held_out_effects, which the diagnosis never imports
(tests/test_held_out_effects.py). Small instances as in tests/test_close_loop.py (two 6 s maneuvers at 20 and
80 kt, eleven trims, a 2-point front), the measured inputs' errors estimated, and a short generic library so
that one loop takes about a minute or two.
"""
import json

import numpy as np
import pytest
from test_close_loop import WAKE_MANEUVERS, _pooled_trim, make_case

from pyomo_heli.cli import main
from pyomo_heli.workflows.close_loop import validation_check
from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.diagnosis.candidates import CANDIDATES
from pyomo_heli.nlp.identification import prepare_data
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.provenance import source_sha256
from pyomo_heli.report.loop import JOINT

#: a short generic library for the small instances: moment and force terms over speed, and a sensor term
GENERIC = ["dM_one", "dM_mu2", "dM_bump00", "dM_bump05", "dM_bump10", "dX_mu4", "dZ_one", "dZ_bump00", "TAS_scale"]


def _loop(tmp_path, effect_table: str, seed: int, extra: str = "", max_iterations: int = 0, generic=GENERIC,
          uncertainty: str = "none", figures: bool = False, data_cache=None):
    """One loop through the command line; its report's figures only with ``figures`` (CI time: drawing them takes
    about 5 s a loop, and tests/test_close_loop_wake.py checks them)."""
    loop = ('\n[objectives]\ninput_errors = ["col", "lon"]\n\n[loop]\ndiscovery = true\n'
            f'uncertainty = "{uncertainty}"\nmax_iterations = {max_iterations}\n'
            f"generic = {json.dumps(list(generic))}\n{extra}")
    cfg = make_case(tmp_path, effect_table, seed=seed, points=2, loop=loop, maneuvers=WAKE_MANEUVERS,
                    input_reference_s=1.9, data_cache=data_cache)
    assert main(["close-loop", str(cfg.path), "--out", str(tmp_path / "loop"),
                 *([] if figures else ["--figure-format", "none"])]) == 0
    return cfg, json.loads((tmp_path / "loop" / "loop.json").read_text())


def test_the_deciding_test_study_runs_this_library():
    """docs/results/deciding_test (docs/discovery.md, "Which test decides") measures the tests' level on these
    small instances with this library."""
    from pyomo_heli.studies.regenerate import TEST_GENERIC

    assert TEST_GENERIC.split() == GENERIC


def test_noise_only_nothing_is_accepted(tmp_path, monkeypatch, flight_test_cache):
    """M0 plus sensor noise: no term of the library (10 physical + 9 generic) is significant, nothing is added.
    A rerun into the same folder reads the finished step back (the screen's solves are not done again)."""
    _cfg, doc = _loop(tmp_path, "", seed=21, data_cache=flight_test_cache)
    its = doc["iterations"]
    print(its[0]["discovery"]["message"])
    assert len(its) == 1 and its[0]["extensions"] == []
    assert its[0]["discovery"]["criterion"] == "likelihood ratio"  # input errors estimated: the NLP's LR decides
    assert its[0]["discovery"]["decision"] == "none"
    assert doc["stopped"].startswith("nothing accepted (none)")
    assert its[0]["discovery"]["library_size"] == len(CANDIDATES) + len(GENERIC)
    report = (tmp_path / "loop" / "loop_report.md").read_text()
    assert "Structure determination over a library of 19 terms" in report
    # what is left, with the size from which a term of its shape would be significant (the corrected LR decides)
    best = its[0]["discovery"]["best_generic"]
    assert best["detectable"] > abs(best["estimate"])
    assert f"a term of its shape is significant from |c| >= {best['detectable']:.2g}" in its[0]["discovery"]["message"]
    assert "detectable |c|" in report
    # the step is kept on disk; a rerun reads it back instead of solving the screen again (the identification is
    # reused as well), and records the same
    steps = list((tmp_path / "loop" / "steps").glob("step_*.json"))
    assert len(steps) == 1
    stored = json.loads(steps[0].read_text())
    assert {k: v for k, v in stored["result"].items() if k != "attribution"} == its[0]["discovery"]
    assert stored["inputs"]["source"] == source_sha256()  # a step made by other code is not reused
    import pyomo_heli.diagnosis.discovery as disc

    def no_step(*args, **kwargs):
        raise AssertionError("a finished structure step was done again")

    monkeypatch.setattr(disc, "discovery_step", no_step)
    assert main(["close-loop", str(_cfg.path), "--out", str(tmp_path / "loop"), "--figure-format", "none"]) == 0
    rerun = json.loads((tmp_path / "loop" / "loop.json").read_text())
    assert rerun["iterations"][0]["discovery"] == its[0]["discovery"] and rerun["stopped"] == doc["stopped"]


def test_a_finished_structure_step_is_read_back_not_redone(tmp_path):
    """stored_step: computed once per set of inputs, read back after; the same record either way (through JSON);
    other inputs get their own file; restart and a damaged file compute again."""
    from pyomo_heli.workflows.close_loop import stored_step

    calls = []

    def compute():
        calls.append(1)
        return {"decision": "none", "J0": np.float64(-1.5), "levels": (1, 2), "p": float("inf")}

    inputs = {"fingerprint": "abc", "parameters": {"Iyy": 4973.123456789012}, "physical": ["cg_offset"],
              "generic": ["dM_one"]}
    first = stored_step(tmp_path, inputs, compute)
    assert first == stored_step(tmp_path, dict(inputs), compute) == {"decision": "none", "J0": -1.5,
                                                                       "levels": [1, 2], "p": float("inf")}
    assert len(calls) == 1
    stored_step(tmp_path, {**inputs, "parameters": {"Iyy": 4973.0}}, compute)
    assert len(calls) == 2 and len(list(tmp_path.glob("step_*.json"))) == 2
    stored_step(tmp_path, inputs, compute, restart=True)
    assert len(calls) == 3
    for f in tmp_path.glob("step_*.json"):
        f.write_text("{")
    assert stored_step(tmp_path, inputs, compute) == first and len(calls) == 4


@pytest.mark.parametrize("iterations", [0, pytest.param(1, marks=pytest.mark.slow)])
def test_held_out_fuselage_download_is_discovered_with_its_shape(tmp_path, iterations, flight_test_cache):
    """Truth: M0 + a download on the fuselage at low speed (held out). No physical candidate may be named (cg_offset
    is significant on its own here, and must not be); the discovered (or, if not significant, the described)
    generic term must have the truth's sign and speed shape: a nose-up moment or a download that is largest at low
    speed and gone by 60 kt. With one more iteration (slow) the term is added, re-identified, checked by the
    validation rule and drawn in the report."""
    _cfg, doc = _loop(tmp_path, "[truth.effects.fuselage_download]\nk_fd = 0.03\n", seed=5, max_iterations=iterations,
                      figures=bool(iterations), data_cache=flight_test_cache)
    its = doc["iterations"]
    d = its[0]["discovery"]
    print(d["message"])
    kept = its[doc["final_iteration"]]
    assert not [n for n in kept["extensions"] if n in CANDIDATES], kept["extensions"]  # no wrong acceptance
    fit = d.get("discovered") or d.get("best_generic")
    assert fit is not None
    # truth: dZ = +k T f(mu) (down) and dM = +0.8 dZ (nose-up), f = exp(-(mu/0.06)^2)
    assert fit["name"] in ("dM_bump00", "dM_bump05", "dZ_bump00", "dZ_one") and fit["estimate"] > 0
    if d["decision"] == "discovered":
        assert "not explained by any library effect" in d["message"]
        assert [r["candidate"] for r in d["encompassing"] if not r["encompasses"]]  # a physical one was tested
    if d["decision"] == "discovered" and iterations:
        assert kept["extensions"] == [fit["name"]]
        # the validation rule ran on the step and passed, and the trim error did not rise
        assert its[1]["validation_check"] and not its[1].get("rejected")
        assert _pooled_trim(kept["trim_rms"]) < _pooled_trim(its[0]["trim_rms"])
        report = (tmp_path / "loop" / "loop_report.md").read_text()
        assert "## Discovered, not explained by any library effect" in report
        assert (tmp_path / "loop" / f"loop_discovered_{fit['name']}.png").is_file()


def test_held_out_accelerometer_filter_is_discovered_as_an_output_time_shift(tmp_path, flight_test_cache):
    """Truth: the n_z record passed through a first-order filter, tau 0.08 s (held out). Offered the output and
    input time shifts with the short library, the step discovers nz_delay (not the input shift col_delay, which the
    full-size loops took for it before the family had output shifts), not explained by any library effect, with
    the truth's time constant within three standard errors."""
    _cfg, doc = _loop(tmp_path, "[truth.effects.accelerometer_filter]\ntau_nz = 0.08\n", seed=5,
                      generic=[*GENERIC, "nz_delay", "nx_delay", "col_delay", "lon_delay"],
                      data_cache=flight_test_cache)
    d = doc["iterations"][0]["discovery"]
    print(d["message"])
    assert d["decision"] == "discovered" and d["discovered"]["name"] == "nz_delay", d["message"]
    assert "not explained by any library effect" in d["message"]
    assert abs(d["discovered"]["estimate"] - 0.08) < 3 * d["discovered"]["se"], d["discovered"]


@pytest.mark.parametrize("effect, truth, term, sign", [
    pytest.param("cyclic_gearing", "k_cg = 0.05", "lon_scale", +1, marks=pytest.mark.slow),  # CI time: one runs
    ("fuselage_pitch_damping", "k_fq = 1.0", "dM_qmu", -1),
])
def test_the_extended_family_describes_two_held_out_effects_the_standard_one_cannot(tmp_path, effect, truth, term,
                                                                                     sign, flight_test_cache):
    """Truths the standard family has no term for: a cyclic gearing error (theta_1s = 1.05 lon) and a fuselage pitch
    damping that grows with speed (dM ~ -q V). Offered the short library plus their neighbours of the extended family
    (input scale factors, q and q x speed), the step's discovered or described term is the one of the truth's form,
    with the truth's sign and size within three standard errors. The damping's equivalent coefficient, taking
    V = mu Omega R: dM = -0.25 rho V (12 m^2)(4 m)^2 q = c m g R (q/0.2)(mu/0.3)."""
    _cfg, doc = _loop(tmp_path, f"[truth.effects.{effect}]\n{truth}\n", seed=5,
                      generic=[*GENERIC, "lon_scale", "col_scale", "dM_q", "dM_qmu", "dM_lon"],
                      data_cache=flight_test_cache)
    d = doc["iterations"][0]["discovery"]
    print(d["message"])
    kept = doc["iterations"][doc["final_iteration"]]
    assert not [n for n in kept["extensions"] if n in CANDIDATES], kept["extensions"]  # no wrong acceptance
    fit = d.get("discovered") or d.get("best_generic")
    assert fit is not None and fit["name"] == term, d["message"]
    assert np.sign(fit["estimate"]) == sign
    p = HelicopterModel().parameters
    c_true = 0.05 if term == "lon_scale" else (-0.25 * p["rho"] * 12.0 * 16.0 * p["Omega"] * p["R"] * 0.2 * 0.3
                                               / (p["m"] * p["g"] * p["R"]))
    assert abs(fit["estimate"] - c_true) < 3 * fit["se"], (fit, c_true)


# slow (80 s; CI time): the default run has the trim loop's way back to a kept model (its own code:
# tests/test_trim_loop.py::test_trim_loop_name_check_withdraws_a_named_candidate_that_leaves_a_generic_term) and the
# study's reading of a loop that went back (tests/test_held_out_effects.py)
@pytest.mark.slow
def test_after_a_rejected_step_the_loop_tries_the_next_term_at_the_kept_model(tmp_path, monkeypatch, flight_test_cache):
    """The small wake instance of tests/test_close_loop.py with discovery. Iteration 0 names the wake candidate,
    because with it fitted the best generic term adds nothing (encompassing). The validation rule is then made to
    reject the step that adds it (the test's stand-in for a real rise; the paired test itself runs): the loop goes
    back to iteration 0's model and runs its structure determination again without the wake, on the same base (same
    J0, one term fewer), adds what that step finds, and judges that step against iteration 0's model, not the
    rejected one."""
    import pyomo_heli.workflows.close_loop as cl

    real, calls = cl.validation_check, []

    def check(model0, params0, model1, params1, val_mans, alpha=0.01, joint=False):
        out = real(model0, params0, model1, params1, val_mans, alpha, joint)
        added = [e.name for e in model1.extensions]
        calls.append((dict(params0), [e.name for e in model0.extensions], added))
        if "rotor_wake_on_tail" in added:
            out = {**out, "rise": True, "message": "made the validation error rise significantly on theta (test)"}
        return out

    monkeypatch.setattr(cl, "validation_check", check)
    _cfg, doc = _loop(tmp_path, "[truth.effects.wake_on_tail]\nK_lamT = 1.5\nd_t = 1.8\ns_w = 0.5\n", seed=25,
                      max_iterations=2, data_cache=flight_test_cache)
    its = doc["iterations"]
    print([(it["extensions"], (it.get("discovery") or {}).get("message")) for it in its])
    d = its[0]["discovery"]
    assert d["decision"] == "named" and d["added"] == "rotor_wake_on_tail"
    row = next(r for r in d["encompassing"] if r["candidate"] == "rotor_wake_on_tail")
    assert row["encompasses"] and row["p_G_given_P"] >= 0.01
    assert its[1]["extensions"] == ["rotor_wake_on_tail"] and "(test)" in its[1]["rejected"]
    assert its[1]["step_from"] == {"iteration": 0, "without": ["rotor_wake_on_tail"]}
    retry = its[1]["discovery"]
    assert retry["library_size"] == its[0]["discovery"]["library_size"] - 1
    assert "rotor_wake_on_tail" not in [r["name"] for r in its[1]["attribution"]["scores"]]
    assert retry["screen"]["J0"] == pytest.approx(its[0]["discovery"]["screen"]["J0"], rel=1e-6)
    assert doc["final_iteration"] in (0, 2)
    if retry["added"]:  # the next term was identified and judged against iteration 0's model
        assert len(its) == 3 and its[2]["extensions"] == [retry["added"]]
        assert calls[1][1] == [] and calls[1][0] == its[0]["parameters"] and calls[1][2] == [retry["added"]]
    report = (tmp_path / "loop" / "loop_report.md").read_text()
    assert "Step rejected: back to the model of iteration 0; its structure determination again without " \
           "rotor_wake_on_tail" in report


# slow (90 s; CI time): the default run has the trim loop's name check (tests/test_trim_loop.py)
@pytest.mark.slow
def test_a_named_candidate_that_leaves_a_generic_term_significant_is_withdrawn(tmp_path, monkeypatch,
                                                                               flight_test_cache):
    """The name check. The wake instance: the wake is named at iteration 0; at iteration 1 (M0 + wake) the real
    step finds no generic term significant, so on these data the name would stand. The test's stand-in then marks
    the best generic term of that step significant (the step itself runs): the loop withdraws the wake, goes back
    to iteration 0's model and runs its structure determination again without the wake, on the same base."""
    import pyomo_heli.diagnosis.discovery as disc

    real, seen = disc.discovery_step, []

    def step(cfg, model, *a, **kw):
        out = real(cfg, model, *a, **kw)
        if "rotor_wake_on_tail" in [e.name for e in model.extensions]:
            seen.append(out["generic_significant"])
            out = {**out, "generic_significant": True}  # the stand-in
        return out

    monkeypatch.setattr(disc, "discovery_step", step)
    _cfg, doc = _loop(tmp_path, "[truth.effects.wake_on_tail]\nK_lamT = 1.5\nd_t = 1.8\ns_w = 0.5\n", seed=25,
                      max_iterations=1, data_cache=flight_test_cache)
    its = doc["iterations"]
    print([(it["extensions"], (it.get("discovery") or {}).get("message")) for it in its])
    assert its[0]["discovery"]["decision"] == "named" and its[0]["discovery"]["added"] == "rotor_wake_on_tail"
    assert seen == [False]  # the real step at M0 + wake: nothing generic left, the name would stand
    assert its[1]["extensions"] == ["rotor_wake_on_tail"] and "(name check)" in its[1]["rejected"]
    assert its[1]["name_check"]["best_generic_fit"]["name"] in GENERIC
    assert its[1]["step_from"] == {"iteration": 0, "without": ["rotor_wake_on_tail"]}
    assert doc["final_iteration"] == 0
    retry = its[1]["discovery"]
    assert retry["library_size"] == its[0]["discovery"]["library_size"] - 1
    assert retry["screen"]["J0"] == pytest.approx(its[0]["discovery"]["screen"]["J0"], rel=1e-6)
    report = (tmp_path / "loop" / "loop_report.md").read_text()
    assert "Name check (a physical candidate the loop added must leave the generic family nothing significant" \
           in report

@pytest.mark.slow
def test_held_out_drag_rise_gives_no_wrong_acceptance(tmp_path, flight_test_cache):
    """Truth: M0 + a drag rise above 80 kt (held out): whatever the loop decides, no library effect is kept."""
    _cfg, doc = _loop(tmp_path, "[truth.effects.drag_rise]\nk_dr = 0.15\n", seed=6, data_cache=flight_test_cache)
    kept = doc["iterations"][doc["final_iteration"]]
    print([it.get("discovery", {}).get("message") for it in doc["iterations"]])
    assert not [n for n in kept["extensions"] if n in CANDIDATES], kept["extensions"]


def test_validation_rule_flags_a_worse_model_and_passes_a_better_one():
    """close_loop.validation_check on the committed small M0 flight test: a model with a 40 % Iyy error against the
    truth model is a significant rise in the other direction and none in this one."""
    from pathlib import Path

    root = Path(__file__).resolve().parent
    cfg = load_identification_config(root / "configs" / "m0_noise_small.toml")
    val = list(prepare_data(load_flight_test(cfg.dataset), ["londoublet_80kt_val"]).maneuvers)
    m0 = HelicopterModel()
    good = {"Iyy": m0.parameters["Iyy"]}
    bad = {"Iyy": 0.6 * m0.parameters["Iyy"], "theta_twist": 1.4 * m0.parameters["theta_twist"]}
    worse = validation_check(m0, good, m0, bad, val)
    better = validation_check(m0, bad, m0, good, val)
    print(worse["message"])
    assert worse["rise"] and "rise significantly" in worse["message"]
    assert not better["rise"] and better["message"] == ""
    assert {r["output"] for r in worse["rows"]} >= {"q", "theta", "n_z"}
    # the joint row: a rise too (not significant here: one record, six batches, dominated by q's doubling)
    joint = {r["output"]: r for r in worse["rows"]}[JOINT]
    assert joint["change [%]"] > 0 and joint["z"] > 0


def test_validation_rule_rejects_a_model_that_cannot_be_replayed_on_a_validation_record(monkeypatch):
    """A step whose model diverges on a validation record the kept model replays is a rise (the test table, over the
    records both replay, cannot show it); the message names the record and the replay's problem. A record only the
    kept model cannot replay is left out of the test, and said so, without a rise."""
    from pathlib import Path

    import pyomo_heli.workflows.loop_steps as steps

    root = Path(__file__).resolve().parent
    cfg = load_identification_config(root / "configs" / "m0_noise_small.toml")
    val = list(prepare_data(load_flight_test(cfg.dataset), ["londoublet_80kt_val"]).maneuvers)
    m0 = HelicopterModel()
    real = steps.predict

    def diverging(which):
        def predict(label, *args):
            pred = real(label, *args)
            if label == which:
                pred.maneuvers["londoublet_80kt_val"] = None
                pred.problems.append("maneuver londoublet_80kt_val: simulation diverged at t = 3.1 s (test)")
            return pred
        return predict

    monkeypatch.setattr(steps, "predict", diverging("after"))
    check = validation_check(m0, {}, m0, {}, val)
    assert check["rise"] and check["not_replayed"] == ["londoublet_80kt_val"]
    assert "could not be replayed on validation record(s) londoublet_80kt_val" in check["message"]
    assert "diverged at t = 3.1 s" in check["message"] and check["rows"] == []
    monkeypatch.setattr(steps, "predict", diverging("before"))
    check = validation_check(m0, {}, m0, {}, val)
    assert not check["rise"] and "tested on no validation record: the kept model could not replay" in check["message"]


def test_validation_rule_rejects_a_joint_rise_only_when_told(monkeypatch):
    """A step whose error rises on every output, significantly on none alone but significantly all at once, passes
    the per-output rule (the default) and is rejected by the joint row with ``joint=True`` (``[loop]
    validation_joint = true``); the joint row is in the check's table either way."""
    import pandas as pd

    import pyomo_heli.report.loop as report_loop
    import pyomo_heli.workflows.loop_steps as steps

    rows = [{"output": o, "change [%]": 3.0, "p (rise)": 0.1, "significant rise": False}
            for o in ("q", "theta", "n_z")] + [{"output": JOINT, "change [%]": 3.0, "p (rise)": 0.004,
                                                  "significant rise": True}]
    monkeypatch.setattr(report_loop, "validation_change_table", lambda *a, **k: pd.DataFrame(rows))
    monkeypatch.setattr(steps, "predict", lambda *a, **k: None)
    m0 = HelicopterModel()
    on = validation_check(m0, {}, m0, {}, [], joint=True)
    off = validation_check(m0, {}, m0, {}, [])
    assert on["rise"] and on["message"] == (f"made the validation error rise significantly on {JOINT} "
                                            "(+3.0 %, p = 0.004)")
    assert not off["rise"] and off["message"] == "" and len(off["rows"]) == 4


@pytest.mark.parametrize("loop, message", [
    ('discovery = "yes"', "[loop]: field 'discovery' must be true or false"),
    ('generic = ["dM_bump99"]', "[loop]: field 'generic': unknown discrepancy term 'dM_bump99'"),
    ("generic = []", "[loop]: field 'generic' must be a non-empty list of names"),
    ('generic_family = "big"',
     "[loop]: field 'generic_family' must be \"standard\", \"extended\" or \"control\", got 'big'"),
    ("validation_rule = 1", "[loop]: field 'validation_rule' must be true or false"),
    ('validation_joint = "no"', "[loop]: field 'validation_joint' must be true or false"),
    ('after_rejection = "retry"', "[loop]: field 'after_rejection' must be \"next\" or \"stop\", got 'retry'"),
    ('generic_rank = "LR"', "[loop]: field 'generic_rank' must be \"p\" or \"likelihood_ratio\", got 'LR'"),
])
def test_bad_discovery_fields_are_one_line_exit_2(tmp_path, capsys, loop, message):
    from pathlib import Path

    cfgf = tmp_path / "c.toml"
    data = Path(__file__).resolve().parent.parent / "data" / "bo105_synthetic"
    cfgf.write_text(f'[data]\ndataset = "{data}"\n\n[parameters.Iyy]\ninitial = 5000.0\n\n[loop]\n{loop}\n')
    assert main(["close-loop", str(cfgf), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_robust_p_never_more_liberal_than_the_plain_likelihood_ratio():
    """The LR correction: factor LM/LM_white capped at 1 and an F(1, df) reference, so p >= the chi-square(1) p."""
    from scipy import stats

    from pyomo_heli.diagnosis.discovery import robust_p

    for lm, lmw, df in ((5.0, 20.0, 6.0), (30.0, 10.0, 40.0), (10.0, 10.0, float("inf"))):
        p, adj, _ = robust_p(25.0, {"LM": lm, "LM_white": lmw, "df": df})
        assert p >= stats.chi2.sf(25.0, 1) and adj <= 25.0
    p, adj, _ = robust_p(25.0, {"LM": 10.0, "LM_white": 10.0, "df": float("inf")})
    assert p == pytest.approx(stats.chi2.sf(25.0, 1)) and adj == 25.0
    assert np.isnan(robust_p(float("nan"), {"LM": 1.0, "LM_white": 1.0, "df": 3.0})[0])


def test_shape_by_channel_reads_speed_shape_state_and_sign_from_the_score_table():
    """The per-channel shape of what is left: per dX/dZ/dM the generic term of largest LM among the speed shapes and
    among the states, with the sign of its one-step estimate in words; a bump's mu in knots from Omega R."""
    import pandas as pd

    from pyomo_heli.diagnosis.discovery import channel_shapes, shapes_sentence
    from pyomo_heli.physics.discrepancy import generic_names
    from pyomo_heli.units import KT

    names = generic_names() + ["cg_offset"]
    lm = {n: 1.0 for n in names}
    kappa = {n: 1.0 for n in names}
    lm.update(dM_bump05=30.0, dM_w=5.0, dZ_mu4=8.0, dZ_alpha=12.0, dX_one=2.0, dX_q=3.0, cg_offset=99.0)
    kappa.update(dM_bump05=-0.004, dZ_mu4=0.01, dZ_alpha=-0.02, dX_one=-0.1)
    sc = pd.DataFrame({"name": names, "LM": [lm[n] for n in names], "kappa_hat": [kappa[n] for n in names],
                       "p_value": [1e-3 if lm[n] > 1 else 0.5 for n in names]})
    rows = {r["channel"]: r for r in channel_shapes(sc, omega_r=0.05 ** -1 * 20 * KT)}  # mu 0.05 at 20 kt
    assert set(rows) == {"dX", "dZ", "dM"}
    assert rows["dM"]["speed term"] == "dM_bump05" and rows["dM"]["speed shape"] == "nose-down dM, a bump at 20 kt"
    assert rows["dM"]["state term"] == "dM_w"
    assert rows["dZ"]["speed shape"] == "down dZ, growing as speed^4 (a high-speed rise)"
    assert rows["dZ"]["state shape"] == "dZ falling with angle of attack (up per +alpha)"
    assert rows["dX"]["speed shape"] == "aft dX, constant over speed" and rows["dX"]["state term"] == "dX_q"
    text = shapes_sentence(list(rows.values()))
    assert text.index("angle of attack") < text.index("speed^4")  # the stronger (LM 12 > 8) first
    assert "cg_offset" not in text


@pytest.mark.slow
def test_bundled_flight_test_names_the_wake_through_encompassing(tmp_path):
    """Full size (slow, `pytest --runslow -k bundled_flight_test_names`): the bundled flight test with discovery
    (studies/held_out_discovery.toml, = studies/close_loop_eiv.toml + discovery): the wake candidate is named first
    through encompassing, the pooled trim error falls by at least 50 % and twist, CL_alpha_HT and Iyy end within 5 %
    of truth (issue 5's criteria)."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    assert main(["close-loop", str(root / "studies" / "held_out_discovery.toml"), "--dataset",
                 str(root / "data" / "bo105_synthetic"), "--out", str(tmp_path / "loop")]) == 0
    doc = json.loads((tmp_path / "loop" / "loop.json").read_text())
    its = doc["iterations"]
    d = its[0]["discovery"]
    assert d["decision"] == "named" and d["added"] == "rotor_wake_on_tail", d["message"]
    kept = its[doc["final_iteration"]]
    assert "rotor_wake_on_tail" in kept["extensions"]
    assert not [n for n in kept["extensions"] if n in CANDIDATES and n != "rotor_wake_on_tail"]
    assert _pooled_trim(kept["trim_rms"]) <= 0.5 * _pooled_trim(its[0]["trim_rms"])
    truth = json.loads((root / "data" / "bo105_synthetic" / "truth.json").read_text())["parameters"]
    for n in ("theta_twist", "CL_alpha_HT", "Iyy"):
        assert kept["parameters"][n] == pytest.approx(truth[n], rel=0.05), n


def test_a_rejected_discovered_term_is_reported_unexplained_with_its_shape(tmp_path):
    """A loop document whose iteration 1 added a discovered dX ~ mu^4 and was rejected by the validation rule: the
    kept model is iteration 0's, and the report says the residual stays unexplained, with the rejected iteration's
    estimate and a figure of the term, which is a drag growing with speed (negative X, |dX| rising with mu)."""
    from types import SimpleNamespace

    from pyomo_heli.report.loop import (discovered_curve, discovery_summary, iteration_model, rejected_discovery,
                                        unexplained_statement)

    fit = {"name": "dX_mu4", "formula": "dX = c m g (mu/0.3)^4", "strength": "c_dX_mu4", "estimate": -0.0148,
           "se": 0.00095}
    its = [{"iteration": 0, "extensions": [], "parameters": {"Iyy": 4900.0},
            "discovery": {"decision": "discovered", "added": "dX_mu4", "discovered": fit}},
           {"iteration": 1, "extensions": ["dX_mu4"], "parameters": {"Iyy": 4890.0, "c_dX_mu4": -0.0221},
            "standard_errors": {"c_dX_mu4": 0.0018},
            "rejected": "made the validation error rise significantly on beta_0 (+1.9 %, p = 0.00097)"}]
    doc = {"iterations": its, "final_iteration": 0}
    rejected, found = rejected_discovery(doc)
    assert rejected is its[1] and found is fit
    line = unexplained_statement(rejected, found)
    assert "unexplained" in line and "c = -0.0221 +- 0.0018" in line and "iteration 1" in line
    L = discovery_summary(doc, SimpleNamespace(model=HelicopterModel()), tmp_path)
    text = "\n".join(L)
    assert "## Discovered, not kept (validation rule): the residual stays unexplained" in text
    assert "rise significantly on beta_0" in text
    assert f"pyomo-heli check-effect {tmp_path} --effect FILE.py:CLASS" in text  # how to test a suspected effect
    assert (tmp_path / "loop_discovered_dX_mu4.png").is_file()
    tab = discovered_curve(iteration_model(HelicopterModel(), rejected), rejected["parameters"], "dX_mu4",
                           [0, 40, 80, 120])
    assert (tab["value"] <= 0).all() and (np.diff(np.abs(tab["value"])) > 0).all()
    # kept (no rejection) or no discovery: nothing to report as unexplained
    assert rejected_discovery({"iterations": its[:1], "final_iteration": 0}) is None
    assert rejected_discovery({"iterations": [its[0], {**its[1], "rejected": None}], "final_iteration": 1}) is None


def test_a_kept_term_without_its_own_standard_error_says_whose_the_report_quotes(tmp_path):
    """Where the kept model has no standard error of a discovered term (``[loop] uncertainty = "none"``, a bound),
    the report quotes the structure step's and says so; with its own, it quotes that."""
    from types import SimpleNamespace

    from pyomo_heli.report.loop import SCREEN_SE, discovery_summary, term_estimate, unexplained_statement

    fit = {"name": "dX_mu4", "formula": "dX = c m g (mu/0.3)^4", "strength": "c_dX_mu4", "estimate": -0.0148,
           "se": 0.00095}
    its = [{"iteration": 0, "extensions": [], "parameters": {"Iyy": 4900.0},
            "discovery": {"decision": "discovered", "added": "dX_mu4", "discovered": fit}},
           {"iteration": 1, "extensions": ["dX_mu4"], "parameters": {"Iyy": 4890.0, "c_dX_mu4": -0.0221},
            "standard_errors": None}]
    doc = {"iterations": its, "final_iteration": 1}
    cfg = SimpleNamespace(model=HelicopterModel())
    assert term_estimate(its[1], fit) == (-0.0221, 0.00095, False)
    text = "\n".join(discovery_summary(doc, cfg, tmp_path, figures=False))
    assert f"c = -0.0221 +- 0.00095 (the kept model's estimate; {SCREEN_SE})" in text
    assert SCREEN_SE in unexplained_statement(its[1], fit)
    its[1]["standard_errors"] = {"c_dX_mu4": float("nan")}  # at a bound
    assert term_estimate(its[1], fit) == (-0.0221, 0.00095, False)
    its[1]["standard_errors"] = {"c_dX_mu4": 0.0018}
    assert term_estimate(its[1], fit) == (-0.0221, 0.0018, True)
    text = "\n".join(discovery_summary(doc, cfg, tmp_path, figures=False))
    assert "c = -0.0221 +- 0.0018 (the kept model's estimate and standard error)" in text and SCREEN_SE not in text


def test_at_the_iteration_limit_the_stop_message_reports_the_term_left_unexplained():
    """The loop stops at its iteration limit after a step that discovered dX_mu4: the stop message says the residual
    stays unexplained and gives that term's formula, estimate, standard error and p against the step's level; after
    a step that named a physical candidate (or decided nothing) it adds nothing."""
    from pyomo_heli.report.loop import limit_statement

    fit = {"name": "dX_mu4", "formula": "dX = c m g (mu/0.3)^4", "estimate": -0.0148, "se": 0.00095, "LR": 93.6,
           "p": 6.2e-08}
    line = limit_statement({"discovery": {"decision": "discovered", "added": "dX_mu4", "discovered": fit,
                                         "level": 0.00013}})
    assert line.startswith("; the residual stays unexplained: not explained by any library effect")
    assert "dX = c m g (mu/0.3)^4, c = -0.0148 +- 0.00095" in line and "p = 6.2e-08 < 0.00013" in line
    assert limit_statement({"discovery": {"decision": "named", "added": "wake_tail"}}) == ""
    assert limit_statement({"attribution": {}}) == ""


def test_the_report_adds_the_kept_discovered_terms_together(tmp_path):
    """A loop that kept two discovered moment terms and one force term: the report shows, beside each term, the
    discrepancy they add together per channel along the kept model's level trims (loop_discovered_total.png and
    its table); in each channel the sum of the terms' own curves (each read on its own at the same model); with one
    force or moment term kept there is no total."""
    from types import SimpleNamespace

    from pyomo_heli.report.loop import discovered_curve, discovered_total, discovery_summary, iteration_model

    fits = [{"name": n, "formula": n, "strength": f"c_{n}", "estimate": c, "se": 0.001}
            for n, c in (("dX_bump10", -0.003), ("dM_one", -0.0067), ("dM_bump00", 0.0067))]
    its = [{"iteration": k, "extensions": [f["name"] for f in fits[:k]],
            "parameters": {"Iyy": 4900.0, **{f["strength"]: f["estimate"] for f in fits[:k]}},
            "discovery": {"decision": "discovered", "added": fits[k]["name"], "discovered": fits[k]} if k < 3 else {}}
           for k in range(4)]
    doc = {"iterations": its, "final_iteration": 3}
    text = "\n".join(discovery_summary(doc, SimpleNamespace(model=HelicopterModel()), tmp_path))
    assert "The kept discovered terms together (dX_bump10, dM_one, dM_bump00)" in text
    assert (tmp_path / "loop_discovered_total.png").is_file()
    model, pars, speeds = iteration_model(HelicopterModel(), its[3]), its[3]["parameters"], [0, 20, 60, 120]
    tab = discovered_total(model, pars, ["dX_bump10", "dM_one", "dM_bump00"], speeds)
    assert list(tab.columns) == ["V [kt]", "dX [N]", "dM [N m]"]
    alone = {n: discovered_curve(model, pars, n, speeds)["value"].to_numpy() for n in ("dX_bump10", "dM_one",
                                                                                          "dM_bump00")}
    assert tab["dX [N]"].to_numpy() == pytest.approx(alone["dX_bump10"])
    assert tab["dM [N m]"].to_numpy() == pytest.approx(alone["dM_one"] + alone["dM_bump00"])
    assert tab["dM [N m]"].iloc[0] == pytest.approx(0.0, abs=1e-9) and tab["dM [N m]"].iloc[-1] < -600  # 0 in hover
    one = {**doc, "iterations": its[:2], "final_iteration": 1}
    (tmp_path / "one").mkdir()
    assert "together" not in "\n".join(discovery_summary(one, SimpleNamespace(model=HelicopterModel()),
                                                          tmp_path / "one"))
    assert not (tmp_path / "one" / "loop_discovered_total.png").exists()


#: the J of the stubbed NLP screens' base
J0 = -117175.06


def _fit(name, generic, lr, estimate, formula):
    """An NLP screen's fit of one term with likelihood ratio ``lr`` against the base J0."""
    from scipy.stats import chi2

    return {"name": name, "generic": generic, "success": True, "LR": lr, "J": J0 - lr / 2, "estimate": estimate,
            "formula": formula, "shape": {}, "p": float(chi2.sf(lr, 1))}


def _stubbed_step(monkeypatch, p_values, LM, screen, rejected=(), generic=("col_delay",), LM_white=None, **kw):
    """discovery_step on lon_rigging (physical) and ``generic`` (default col_delay), and the generic terms
    ``rejected`` by earlier steps, with the score test (``p_values``, ``LM`` in that order, ``LM_white`` default
    LM: white = robust, df infinite) and the NLP screen (``screen``) stubbed; input errors on. ``kw`` go to
    discovery_step."""
    from types import SimpleNamespace

    import pandas as pd

    from pyomo_heli.diagnosis import discovery

    names = ["lon_rigging", *generic, *rejected]
    scores = pd.DataFrame({"name": names, "p_value": p_values, "LM": LM,
                           "LM_white": LM if LM_white is None else LM_white, "df": [np.inf] * len(names),
                           "kappa_hat": [1e-3] * len(names)})
    monkeypatch.setattr(discovery.attr, "attribute",
                        lambda *a, **k: SimpleNamespace(scores=scores, to_dict=lambda: {}, __str__=lambda s: ""))

    def checked(cfg, start, terms, pairs=(), **kw):
        assert set(terms) == set(names)
        return screen(pairs)

    monkeypatch.setattr(discovery, "nlp_screen", checked)
    cfg = SimpleNamespace(free=[SimpleNamespace(name="Iyy")],
                          nlp=SimpleNamespace(time_outputs=["q"], trim_outputs=["lon"], input_errors=True))
    model = SimpleNamespace(extensions=(), parameters={"Omega": 44.4, "R": 4.91})
    return discovery.discovery_step(cfg, model, {}, None, physical=["lon_rigging"], generic=list(generic),
                                    rejected_generic=list(rejected), progress=lambda s: None, **kw)


def test_best_fit_ranks_by_the_deciding_p_and_breaks_ties_by_the_corrected_lr():
    """M0 + noise seed 37 (docs/results/generic_term_level): col_scale has the larger raw LR (14.7, z -3.83) but its
    corrected test the larger p (z_p -2.48, p = 0.0131); lon_scale LR 8.94 (z -2.99), z_p -2.61 (p = 0.0091). By
    the deciding p lon_scale is the best; by raw LR col_scale. p that underflow to 0 are ordered by the corrected
    LR; a term without a p comes last; an unknown rank is an error naming it."""
    from scipy.stats import norm

    from pyomo_heli.diagnosis.discovery import best_fit

    def fit(name, lr, z_p, lr_robust=None):
        return {"name": name, "generic": True, "success": True, "LR": lr, "J": J0 - lr / 2,
                "p": float(2 * norm.sf(abs(z_p))), "LR_robust": lr if lr_robust is None else lr_robust}

    fits = {"col_scale": fit("col_scale", 14.7, -2.48), "lon_scale": fit("lon_scale", 8.94, -2.61),
            "dM_one": {**fit("dM_one", 30.0, 0.0), "p": float("nan")}}
    assert fits["col_scale"]["p"] == pytest.approx(0.0131, abs=1e-4)
    assert fits["lon_scale"]["p"] == pytest.approx(0.0091, abs=1e-4)
    assert best_fit(fits, True)["name"] == "lon_scale"
    assert best_fit(fits, True, "likelihood_ratio")["name"] == "dM_one"
    del fits["dM_one"]
    assert best_fit(fits, True, "likelihood_ratio")["name"] == "col_scale"
    ties = {"a": fit("a", 900.0, 40.0, lr_robust=500.0), "b": fit("b", 800.0, 40.0, lr_robust=700.0)}
    assert ties["a"]["p"] == ties["b"]["p"] == 0.0
    assert best_fit(ties, True)["name"] == "b"
    assert best_fit(ties, False) is None
    with pytest.raises(ValueError, match="rank must be one of .*'lr'"):
        best_fit(ties, True, "lr")


def test_a_step_asks_the_significance_of_the_generic_term_of_smallest_deciding_p(monkeypatch):
    """Two generic terms whose orders by raw LR and by the deciding p differ: col_delay LR 30 on coloured residuals
    (the score test's robust LM a fifth of its white one: corrected LR 6, one-sided p = 0.0072) and lon_delay LR 20
    on white ones (one-sided p = 3.9e-6); Bonferroni level 0.01 / 3. Ranked by p (the default) the step discovers
    lon_delay; ranked by raw LR it asks only col_delay, not significant, and decides nothing, while lon_delay is
    significant; the name check's question (is any generic term significant?) is answered over every fit: yes."""
    fits = {"col_delay": _fit("col_delay", True, 30.0, 0.0016, "c d(col_d)/dt = col - col_d"),
            "lon_delay": _fit("lon_delay", True, 20.0, 0.03, "c d(lon_d)/dt = lon - lon_d"),
            "lon_rigging": _fit("lon_rigging", False, 2.0, -0.0022, "lon offset")}

    def screen(pairs):
        offered = {n: dict(f) for n, f in fits.items()}
        assert pairs(offered) == []  # lon_rigging is not significant: no pair
        return {"J0": J0, "fits": offered, "pairs": {}}

    args = ([0.16, 2e-3, 8e-6], [2.0, 10.0, 20.0], screen)
    kw = dict(generic=("col_delay", "lon_delay"), LM_white=[2.0, 50.0, 20.0])
    by_p = _stubbed_step(monkeypatch, *args, **kw)
    assert by_p["decision"] == "discovered" and by_p["added"] == "lon_delay"
    assert by_p["discovered"]["p"] == pytest.approx(3.87e-6, rel=1e-2)
    by_lr = _stubbed_step(monkeypatch, *args, rank="likelihood_ratio", **kw)
    assert by_lr["decision"] == "none" and by_lr["best_generic"]["name"] == "col_delay"
    assert by_lr["best_generic"]["p"] == pytest.approx(0.00715, rel=1e-2) and by_lr["generic_significant"]


def test_a_physical_candidate_is_named_only_if_it_encompasses_the_best_generic_term_by_either_ranking(monkeypatch):
    """held_out control_mixing 23 in miniature: no generic term significant (level 0.01 / 3), and the best by the
    deciding p (lon_delay, LR 7 on white residuals: one-sided p = 0.0041) is not the best by raw LR (col_delay,
    LR 30 on coloured ones: corrected LR 6, p = 0.0072). lon_rigging (LR 60) leaves lon_delay nothing (LR 0.5)
    but not col_delay (LR 20): under either ranking both pairs are solved and nothing is named ("ambiguous"), where
    a test against the best by p alone named it. When col_delay adds nothing either, lon_rigging is named, and the
    message says both."""
    fits = {"col_delay": _fit("col_delay", True, 30.0, 0.0016, "c d(col_d)/dt = col - col_d"),
            "lon_delay": _fit("lon_delay", True, 7.0, 0.03, "c d(lon_d)/dt = lon - lon_d"),
            "lon_rigging": _fit("lon_rigging", False, 60.0, -0.0022, "lon offset")}

    def screen_with(adds_col_delay):
        pair_J = {"lon_rigging+lon_delay": fits["lon_rigging"]["J"] - 0.25,
                  "lon_rigging+col_delay": fits["lon_rigging"]["J"] - adds_col_delay / 2}

        def screen(pairs):
            offered = {n: dict(f) for n, f in fits.items()}
            wanted = pairs(offered)
            assert sorted(wanted) == [("lon_rigging", "col_delay"), ("lon_rigging", "lon_delay")]
            return {"J0": J0, "fits": offered,
                    "pairs": {f"{a}+{b}": {"success": True, "J": pair_J[f"{a}+{b}"]} for a, b in wanted}}
        return screen

    kw = dict(generic=("col_delay", "lon_delay"), LM_white=[60.0, 50.0, 7.0])
    args = ([1e-12, 2e-3, 8e-3], [60.0, 10.0, 7.0])
    for rank in ("p", "likelihood_ratio"):
        out = _stubbed_step(monkeypatch, *args, screen_with(20.0), rank=rank, **kw)
        assert out["decision"] == "ambiguous" and out["added"] is None
        assert out["screen"]["fits"]["lon_delay"]["p"] == pytest.approx(0.0041, rel=2e-2)
        assert out["screen"]["fits"]["col_delay"]["p"] == pytest.approx(0.00715, rel=1e-2)
        assert set(out["competitors"]) == {"col_delay", "lon_delay"}
        by = {r["generic"]: r for r in out["encompassing"]}
        assert by["lon_delay"]["encompasses"] and not by["col_delay"]["encompasses"]
        assert by["col_delay"]["LR_G_given_P"] == pytest.approx(20.0)
        assert ("col_delay adds to lon_rigging (p < 0.01)" if rank == "p"
                else "the best generic term col_delay adds to each of them") in out["message"]
    named = _stubbed_step(monkeypatch, *args, screen_with(1.0), **kw)
    assert named["decision"] == "named" and named["added"] == "lon_rigging"
    assert named["best_generic_fit"]["name"] == "lon_delay"
    assert "nor does col_delay, the best by raw likelihood ratio (p = 0.32)" in named["message"]


def test_the_detection_limit_is_where_the_corrected_likelihood_ratio_reaches_the_level():
    """The smallest |c| of a term's shape the step would call significant: with white residuals and infinite df a
    two-sided term at level 0.05 with se 1 is significant from the normal quantile 1.95996 (analytic); on coloured
    residuals and finite df (one-sided too) the LR of a quadratic profile scaled to that |c| has, by robust_p, p equal
    to the level; no standard error, no limit."""
    import math

    from pyomo_heli.diagnosis.discovery import detection_limit, judge, robust_p

    assert detection_limit({"se": 1.0, "df": math.inf}, 0.05) == pytest.approx(1.959964, rel=1e-6)
    row = {"LM": 5.0, "LM_white": 20.0, "df": 30.0}  # coloured: the LR is corrected by a factor 1/4
    for one_sided in (False, True):
        fit = judge({"LR": 9.0, "estimate": 0.01}, row, one_sided, "likelihood ratio")
        c = detection_limit(fit, 1.6e-4, one_sided)
        assert c > 0.01  # the fit itself (corrected LR 2.25) is far from significant
        p, _, _ = robust_p(9.0 * (c / 0.01) ** 2, row, one_sided)
        assert p == pytest.approx(1.6e-4, rel=1e-6)
    assert math.isnan(detection_limit({"se": float("nan"), "df": 30.0}, 1e-3))


def test_when_nothing_is_significant_the_step_says_from_what_size_a_term_of_the_shape_left_would_be(monkeypatch):
    """The "none" decision of test_a_step_asks_the_significance_of_the_generic_term_of_smallest_deciding_p ranked by
    raw LR: col_delay is reported as what is left, with its detection limit (every screened fit carries one, as the
    corrected LR decides), which lies above its estimate."""
    from pyomo_heli.diagnosis.discovery import robust_p

    fits = {"col_delay": _fit("col_delay", True, 30.0, 0.0016, "c d(col_d)/dt = col - col_d"),
            "lon_delay": _fit("lon_delay", True, 20.0, 0.03, "c d(lon_d)/dt = lon - lon_d"),
            "lon_rigging": _fit("lon_rigging", False, 2.0, -0.0022, "lon offset")}

    def screen(pairs):
        offered = {n: dict(f) for n, f in fits.items()}
        pairs(offered)
        return {"J0": J0, "fits": offered, "pairs": {}}

    step = _stubbed_step(monkeypatch, [0.16, 2e-3, 8e-6], [2.0, 10.0, 20.0], screen, generic=("col_delay", "lon_delay"),
                         LM_white=[2.0, 50.0, 20.0], rank="likelihood_ratio")
    G = step["best_generic"]
    assert step["decision"] == "none" and G["name"] == "col_delay"
    assert all("detectable" in f for f in step["screen"]["fits"].values())
    assert G["detectable"] > G["estimate"]
    # at that size the corrected LR (a fifth of the raw one here) reaches the level, one-sided as col_delay is
    p, _, _ = robust_p(30.0 * (G["detectable"] / 0.0016) ** 2, {"LM": 10.0, "LM_white": 50.0, "df": np.inf}, True)
    assert p == pytest.approx(step["level"], rel=1e-6)
    assert f"a term of its shape is significant from |c| >= {G['detectable']:.2g}" in step["message"]


def test_an_ambiguous_step_says_what_the_generic_term_left_looks_like(monkeypatch):
    """discovery_step's decision with the score test and the NLP screen stubbed: a physical candidate significant
    (LR 24.4), the best generic term not significant over the library (LR 6) but adding to the physical one (LR 7.5
    given it, p = 0.006 < 0.01): nothing is added ("ambiguous"), and the record and message carry the generic
    term's formula and estimate, so the report says what the missing effect looks like."""
    fits = {"col_delay": _fit("col_delay", True, 6.0, 0.0016, "c d(col_d)/dt = col - col_d"),
            "lon_rigging": _fit("lon_rigging", False, 24.37, -0.0022, "lon offset")}

    def screen(pairs):
        assert pairs(fits) == [("lon_rigging", "col_delay")]
        return {"J0": J0, "fits": fits, "pairs": {"lon_rigging+col_delay": {"success": True,
                                                                             "J": fits["lon_rigging"]["J"] - 3.75}}}

    out = _stubbed_step(monkeypatch, [1e-6, 0.01], [49.4, 29.2], screen)
    assert out["decision"] == "ambiguous" and out["added"] is None
    row, = out["encompassing"]
    assert row["LR_G_given_P"] == pytest.approx(7.5) and row["p_G_given_P"] < 0.01 and not row["encompasses"]
    assert out["best_generic"] is fits["col_delay"]
    assert "what is left looks like c d(col_d)/dt = col - col_d, c = 0.0016 +-" in out["message"]



def test_a_rejected_generic_term_is_not_added_again_but_a_physical_candidate_must_still_encompass_it(monkeypatch):
    """A generic term the validation rule rejected (lon_delay) stays in the screen: it is not added again, but a
    physical candidate is named only if it leaves that term nothing too. Here lon_rigging encompasses the best
    term that may be added (col_delay adds LR 0.5 to it) and not the rejected one (lon_delay adds LR 40): nothing is
    named, nothing added ("ambiguous"). Without the rejected term in the screen the same fits name lon_rigging."""
    fits = {"col_delay": _fit("col_delay", True, 6.0, 0.0016, "c d(col_d)/dt = col - col_d"),
            "lon_rigging": _fit("lon_rigging", False, 60.0, -0.0022, "lon offset"),
            "lon_delay": _fit("lon_delay", True, 80.0, 0.03, "c d(lon_d)/dt = lon - lon_d")}
    pair_J = {"lon_rigging+col_delay": fits["lon_rigging"]["J"] - 0.25,
              "lon_rigging+lon_delay": fits["lon_rigging"]["J"] - 20.0}

    def screen_of(terms):
        def screen(pairs):
            offered = {n: dict(fits[n]) for n in terms}
            wanted = pairs(offered)
            return {"J0": J0, "fits": offered,
                    "pairs": {f"{a}+{b}": {"success": True, "J": pair_J[f"{a}+{b}"]} for a, b in wanted}}
        return screen

    out = _stubbed_step(monkeypatch, [1e-9, 0.01, 1e-12], [60.0, 6.0, 80.0], screen_of(fits),
                        rejected=["lon_delay"])
    assert out["decision"] == "ambiguous" and out["added"] is None and out["rejected_generic"] == ["lon_delay"]
    row, = out["encompassing"]
    assert row["candidate"] == "lon_rigging" and not row["encompasses"] and row["LR_G_given_P"] == pytest.approx(40)
    assert out["generic_significant"]  # the name check counts the rejected term too
    assert "the best generic term lon_delay (rejected earlier) adds to each of them" in out["message"]
    named = _stubbed_step(monkeypatch, [1e-9, 0.01], [60.0, 6.0], screen_of(["lon_rigging", "col_delay"]))
    assert named["decision"] == "named" and named["added"] == "lon_rigging"


def test_a_physical_candidate_equivalent_to_a_rejected_term_is_taken_and_the_message_says_the_term_was_rejected(
        monkeypatch):
    """A physical candidate (lon_rigging) equivalent on these data to a generic term the validation rule rejected
    (lon_delay: neither adds to the other, LR 0.5 each way), no generic term that may be added significant: the
    library takes it (the validation rule then judges its model), and the message says that the significant term it
    is equivalent to was rejected earlier, not that no generic term is significant."""
    fits = {"col_delay": _fit("col_delay", True, 6.0, 0.0016, "c d(col_d)/dt = col - col_d"),
            "lon_rigging": _fit("lon_rigging", False, 80.0, -0.0022, "lon offset"),
            "lon_delay": _fit("lon_delay", True, 80.0, 0.03, "c d(lon_d)/dt = lon - lon_d")}

    def screen(pairs):
        wanted = pairs(fits)
        return {"J0": J0, "fits": fits, "pairs": {f"{a}+{b}": {"success": True, "J": fits[a]["J"] - 0.25}
                                                  for a, b in wanted}}

    out = _stubbed_step(monkeypatch, [1e-12, 0.01, 1e-12], [80.0, 6.0, 80.0], screen, rejected=["lon_delay"])
    assert out["decision"] == "accepted" and out["added"] == "lon_rigging"
    row, = out["encompassing"]
    assert row["equivalent"] and not row["encompasses"]
    assert out["generic_significant"]
    assert "no generic term that may be added is (the best, lon_delay, rejected earlier, p = " in out["message"]
    assert "is equivalent to it on these data): taken by the library" in out["message"]


def test_a_pair_fit_above_its_candidate_alone_is_no_encompassing_test(monkeypatch):
    """A pair nests each of its terms, so its fit cannot end above either alone except at a worse local optimum.
    lon_rigging (LR 80) and the discovered col_delay (LR 40), their pair's J 3 above lon_rigging's alone: read as
    it stands, col_delay would add LR 0 (clipped) to lon_rigging, lon_rigging LR 34 to col_delay, and lon_rigging
    would be named. The row says the joint fit is not a test, and nothing is named: col_delay is discovered. With
    the pair 0.1 above (within PAIR_SLACK, solver tolerance) the test stands and names lon_rigging."""
    from pyomo_heli.diagnosis.discovery import PAIR_SLACK

    fits = {"lon_rigging": _fit("lon_rigging", False, 80.0, -0.0022, "lon offset"),
            "col_delay": _fit("col_delay", True, 40.0, 0.0016, "c d(col_d)/dt = col - col_d")}

    def screen_above(dJ):
        def screen(pairs):
            wanted = pairs(fits)
            return {"J0": J0, "fits": fits,
                    "pairs": {f"{a}+{b}": {"success": True, "J": fits["lon_rigging"]["J"] + dJ} for a, b in wanted}}
        return screen

    args = ([1e-12, 1e-9], [80.0, 40.0])
    out = _stubbed_step(monkeypatch, *args, screen_above(3.0))
    row, = out["encompassing"]
    assert not row["encompasses"] and not row["equivalent"] and "LR_G_given_P" not in row
    assert row["note"] == "joint fit ended 3 above the better term alone (a worse local optimum)"
    assert out["decision"] == "discovered" and out["added"] == "col_delay"
    assert 0.1 < PAIR_SLACK
    named = _stubbed_step(monkeypatch, *args, screen_above(0.1))
    assert named["decision"] == "named" and named["added"] == "lon_rigging"
    assert named["encompassing"][0]["LR_P_given_G"] == pytest.approx(2 * (20.0 - 0.1))


def test_a_failed_base_solve_leaves_the_decision_to_the_score_test_and_says_so(monkeypatch):
    """The NLP screen's base solve failed (twice): no likelihood ratio exists (LR nan). With input errors the step
    would refer the LR; instead the score test's own p decides (lon_rigging p = 1e-6 < 0.01/2 significant,
    col_delay p = 0.02 not), the encompassing test runs on the fits' J, and the message names the failure, so
    "nothing significant" can never come from a failed solve."""
    J = -117175.06

    def fit(name, generic, dJ, estimate):
        return {"name": name, "generic": generic, "success": True, "LR": float("nan"), "p": float("nan"),
                "J": J - dJ, "estimate": estimate, "formula": name, "shape": {}}

    fits = {"col_delay": fit("col_delay", True, 3.0, 0.0016), "lon_rigging": fit("lon_rigging", False, 12.0, -0.002)}

    def screen(pairs):
        assert pairs(fits) == [("lon_rigging", "col_delay")]  # the score test's p picks the pair
        return {"J0": float("nan"), "base_success": False, "base_status": "Maximum_Iterations_Exceeded",
                "fits": fits, "pairs": {"lon_rigging+col_delay": {"success": True,
                                                                  "J": fits["lon_rigging"]["J"] - 0.5}}}

    out = _stubbed_step(monkeypatch, [1e-6, 0.02], [49.4, 9.2], screen)
    assert out["criterion"] == "score test" and out["base_failed"] == "Maximum_Iterations_Exceeded"
    assert fits["lon_rigging"]["p"] == 1e-6 and fits["col_delay"]["p"] == 0.02
    # with both fitted: col_delay adds LR 1 to lon_rigging (p = 0.32), lon_rigging adds 19 to col_delay: named
    assert out["decision"] == "named" and out["added"] == "lon_rigging", out["message"]
    assert "base solve failed: Maximum_Iterations_Exceeded" in out["message"]


def test_a_significant_term_whose_fit_failed_is_not_read_as_nothing_significant(monkeypatch):
    """The score test decides (the base solve failed) and finds col_delay significant (p = 1e-7), but its NLP fit
    failed: the step cannot say "nothing significant over the whole library". It says the decision is open, names
    the term, and leaves the residual unexplained."""
    J = -117175.06

    def fit(name, generic, ok):
        return {"name": name, "generic": generic, "success": ok, "LR": float("nan"), "p": float("nan"),
                "J": J - 1.0 if ok else float("nan"), "estimate": 0.001, "formula": name, "shape": {}}

    fits = {"col_delay": fit("col_delay", True, False), "lon_rigging": fit("lon_rigging", False, True)}
    out = _stubbed_step(monkeypatch, [0.02, 1e-7], [9.2, 49.4], lambda pairs: {
        "J0": float("nan"), "base_success": False, "base_status": "Maximum_Iterations_Exceeded", "fits": fits,
        "pairs": {}})
    assert out["decision"] == "none" and out["unexplained"] and out["significant_unfitted"] == ["col_delay"]
    assert out["message"].startswith("not decided: the NLP fit of col_delay failed"), out["message"]


def test_a_failed_fit_under_the_likelihood_ratio_is_flagged_by_its_score_test(monkeypatch):
    """Input errors on and the base solve fine: the likelihood ratio decides. col_delay's fit failed (no LR, p nan),
    its score test p = 1e-8: the step names it as significant but unfitted and leaves the residual unexplained (a
    review: its nan p read as "not significant", and the step said nothing significant over the library)."""
    fits = {"lon_rigging": _fit("lon_rigging", False, 1.0, -0.002, "lon offset"),
            "col_delay": {"name": "col_delay", "generic": True, "success": False, "LR": float("nan"),
                          "p": float("nan"), "J": float("nan"), "estimate": 0.03, "formula": "col_delay",
                          "shape": {}}}
    out = _stubbed_step(monkeypatch, [0.5, 1e-8], [1.0, 80.0],
                        lambda pairs: {"J0": J0, "base_success": True, "fits": fits, "pairs": {}})
    assert out["criterion"] == "likelihood ratio"
    assert out["decision"] == "none" and out["unexplained"] and out["significant_unfitted"] == ["col_delay"]
    assert out["message"].startswith("not decided: the NLP fit of col_delay failed"), out["message"]


def test_generic_significant_looks_at_every_generic_fit_under_the_raw_lr_ranking(monkeypatch):
    """generic_rank = "likelihood_ratio": the best generic term by raw LR (dM_one, LR 30, corrected by the residuals'
    colour to 6: p = 0.014) is not significant at 0.01 / 3, another (dM_mu2, LR 25, p = 6e-7) is. The name check asks
    whether any generic term is significant: yes (a review: only the raw-LR best was asked, "no")."""
    fits = {"lon_rigging": _fit("lon_rigging", False, 1.0, -0.002, "lon offset"),
            "dM_one": _fit("dM_one", True, 30.0, 0.003, "dM_one"),
            "dM_mu2": _fit("dM_mu2", True, 25.0, 0.002, "dM_mu2")}
    out = _stubbed_step(monkeypatch, [0.5, 0.01, 6e-7], [1.0, 6.0, 25.0],
                        lambda pairs: {"J0": J0, "base_success": True, "fits": fits, "pairs": {}},
                        generic=("dM_one", "dM_mu2"), LM_white=[1.0, 30.0, 25.0], rank="likelihood_ratio")
    assert fits["dM_one"]["p"] > out["level"] > fits["dM_mu2"]["p"]
    assert out["best_generic_fit"]["name"] == "dM_one" and out["generic_significant"] is True
    # the name check's reason names the significant term, not the raw-LR best (which read "p = 0.014 < 0.0033")
    assert out["most_significant_generic_fit"]["name"] == "dM_mu2"


def test_a_physical_candidate_significant_outside_the_screen_is_named(monkeypatch):
    """Four physical candidates, the screen estimates the best three by LM; the fourth (nx_bias: LM 20 on df 60,
    score test p = 3.5e-5 < 0.01 / 5) has a smaller p than those three (LM 23-25 on df 1.5, p about 0.07): never
    estimated, it is named in the "none" step instead of "nothing significant over the whole library"."""
    from types import SimpleNamespace

    import pandas as pd
    from scipy import stats

    from pyomo_heli.diagnosis import discovery

    names = ["cg_offset", "lon_rigging", "col_rigging", "nx_bias", "dM_one"]
    LM, df = [25.0, 24.0, 23.0, 20.0, 1.0], [1.5, 1.5, 1.5, 60.0, 10.0]
    scores = pd.DataFrame({"name": names, "LM": LM, "LM_white": LM, "df": df, "kappa_hat": [1e-3] * 5,
                           "p_value": [float(stats.f(1, d).sf(lm)) for lm, d in zip(LM, df)]})
    monkeypatch.setattr(discovery.attr, "attribute",
                        lambda *a, **k: SimpleNamespace(scores=scores, to_dict=lambda: {}, __str__=lambda s: ""))
    fits = {n: _fit(n, n == "dM_one", 1.0, 0.001, n) for n in ["cg_offset", "lon_rigging", "col_rigging", "dM_one"]}
    monkeypatch.setattr(discovery, "nlp_screen", lambda cfg, start, terms, pairs=(), **kw: {
        "J0": J0, "fits": {n: dict(fits[n]) for n in terms}, "pairs": {}})
    cfg = SimpleNamespace(free=[SimpleNamespace(name="Iyy")],
                          nlp=SimpleNamespace(time_outputs=["q"], trim_outputs=["lon"], input_errors=()))
    model = SimpleNamespace(extensions=(), parameters={"Omega": 44.4, "R": 4.91})
    out = discovery.discovery_step(cfg, model, {}, None, physical=names[:4], generic=["dM_one"],
                                   progress=lambda s: None)
    assert "nx_bias" not in out["screen"]["fits"] and out["decision"] == "none"
    assert out["significant_unscreened"] == ["nx_bias"] and "nx_bias (p = 3.5e-05)" in out["message"]


def test_of_two_named_candidates_from_separate_nlps_the_lower_j_against_its_own_base_is_named(monkeypatch):
    """The screen ran as separate NLPs (the joint base failed): cg_offset and lon_rigging both encompass the
    significant dM_one. cg_offset's fit is lower in raw J (-110 against -108) but on a base 10 lower: against its
    own base lon_rigging is the better fit (LR 36 against 20) and is named, as where no generic term is significant
    (a review: the raw J across NLPs chose cg_offset)."""
    from types import SimpleNamespace

    import pandas as pd

    from pyomo_heli.diagnosis import discovery

    names = ["cg_offset", "lon_rigging", "dM_one"]
    scores = pd.DataFrame({"name": names, "LM": [50.0] * 3, "LM_white": [50.0] * 3, "df": [np.inf] * 3,
                           "p_value": [1e-10] * 3, "kappa_hat": [1e-3] * 3})
    monkeypatch.setattr(discovery.attr, "attribute",
                        lambda *a, **k: SimpleNamespace(scores=scores, to_dict=lambda: {}, __str__=lambda s: ""))
    base = {"cg_offset": -100.0, "lon_rigging": -90.0, "dM_one": -95.0}  # each term's own NLP base
    single = {"cg_offset": -110.0, "lon_rigging": -108.0, "dM_one": -110.0}  # LR 20, 36, 30

    def screen(cfg, start, terms, pairs=(), **kw):
        fits = {n: {"name": n, "generic": n == "dM_one", "success": True, "J": single[n], "J0": base[n],
                    "LR": 2 * (base[n] - single[n]), "p": 0.0, "estimate": 0.01, "formula": n, "shape": {}}
                for n in terms}
        # the pair NLP on P's base: the singles solved there too (G adds nothing to P, P adds much to G)
        both = {f"{a}+{b}": {"J": single[a] - 0.5, "success": True, "J0": base[a],
                             "single_J": {a: single[a], b: base[a] - 5.0}} for a, b in pairs(fits)}
        return {"J0": -100.0, "base_success": False, "fits": fits, "pairs": both, "separate": {}}

    monkeypatch.setattr(discovery, "nlp_screen", screen)
    monkeypatch.setattr(discovery, "deciding_criterion", lambda cfg, screen: "likelihood ratio")
    cfg = SimpleNamespace(free=[SimpleNamespace(name="Iyy")],
                          nlp=SimpleNamespace(time_outputs=["q"], trim_outputs=["lon"], input_errors=("col",)))
    model = SimpleNamespace(extensions=(), parameters={"Omega": 44.4, "R": 4.91})
    out = discovery.discovery_step(cfg, model, {}, None, physical=["cg_offset", "lon_rigging"], generic=["dM_one"],
                                   progress=lambda s: None)
    assert {r["candidate"] for r in out["encompassing"] if r["encompasses"]} == {"cg_offset", "lon_rigging"}
    assert out["decision"] == "named" and out["added"] == "lon_rigging", out["message"]


def test_a_term_significant_by_the_score_test_that_the_screen_did_not_estimate_is_named(monkeypatch):
    """Four generic terms, the screen estimates the best three by LM. The fourth (dM_q: LM 20 on df 8, score test
    p = 2e-5 < 0.01 / 5) is significant by its own test and was never estimated; the three estimated are not
    significant by the likelihood ratio. The step decides "none" but does not say "nothing significant over the
    whole library": it names dM_q as not estimated (``significant_unscreened``). Without it the usual words stand."""
    from types import SimpleNamespace

    import pandas as pd

    from pyomo_heli.diagnosis import discovery

    generic = ["col_delay", "lon_delay", "dM_one", "dM_q"]
    names = ["lon_rigging", *generic]

    def step(p_q):
        scores = pd.DataFrame({"name": names, "p_value": [0.5, 0.02, 0.03, 0.04, p_q],
                               "LM": [1.0, 30.0, 28.0, 25.0, 20.0], "LM_white": [1.0, 30.0, 28.0, 25.0, 60.0],
                               "df": [np.inf, np.inf, np.inf, np.inf, 8.0], "kappa_hat": [1e-3] * 5})
        monkeypatch.setattr(discovery.attr, "attribute",
                            lambda *a, **k: SimpleNamespace(scores=scores, to_dict=lambda: {}, __str__=lambda s: ""))
        fits = {n: _fit(n, n != "lon_rigging", lr, 0.001, n) for n, lr in
                [("lon_rigging", 1.0), ("col_delay", 6.0), ("lon_delay", 5.0), ("dM_one", 4.0)]}
        screened = []

        def screen(cfg, start, terms, pairs=(), **kw):
            screened.extend(terms)
            pairs(fits) if callable(pairs) else None
            return {"J0": J0, "fits": {n: dict(fits[n]) for n in terms}, "pairs": {}}

        monkeypatch.setattr(discovery, "nlp_screen", screen)
        cfg = SimpleNamespace(free=[SimpleNamespace(name="Iyy")],
                              nlp=SimpleNamespace(time_outputs=["q"], trim_outputs=["lon"], input_errors=True))
        model = SimpleNamespace(extensions=(), parameters={"Omega": 44.4, "R": 4.91})
        out = discovery.discovery_step(cfg, model, {}, None, physical=["lon_rigging"], generic=generic,
                                       progress=lambda s: None)
        assert sorted(screened) == sorted(["lon_rigging", "col_delay", "lon_delay", "dM_one"])
        return out

    out = step(2e-5)
    assert out["decision"] == "none" and out["significant_unscreened"] == ["dM_q"]
    assert "nothing significant among the terms estimated" in out["message"]
    assert "dM_q (p = 2e-05)" in out["message"] and "over the whole library" not in out["message"]
    plain = step(0.05)
    assert plain["decision"] == "none" and "significant_unscreened" not in plain
    assert "nothing significant over the whole library of 5 terms" in plain["message"]


def test_a_hypothesis_checked_where_the_base_solve_failed_is_decided_by_the_score_test(monkeypatch):
    """check_term with input errors and the NLP screen's base failed (no likelihood ratio, LR nan): the score test's
    p decides (1e-6 < level 1e-3: significant), as in a structure step, instead of a nan p read as "not
    significant"."""
    from types import SimpleNamespace

    import pandas as pd

    from pyomo_heli.diagnosis import discovery

    scores = pd.DataFrame({"name": ["lon_rigging"], "p_value": [1e-6], "LM": [24.0], "LM_white": [24.0],
                           "df": [np.inf]})
    monkeypatch.setattr(discovery.attr, "attribute",
                        lambda *a, **k: SimpleNamespace(scores=scores, to_dict=lambda: {}, __str__=lambda s: ""))
    fit = {"name": "lon_rigging", "generic": False, "success": True, "LR": float("nan"), "p": float("nan"),
           "J": J0, "estimate": -0.002, "formula": "lon offset", "shape": {}}
    monkeypatch.setattr(discovery, "nlp_screen", lambda *a, **k: {"J0": float("nan"), "base_success": False,
                                                                  "fits": {"lon_rigging": fit}, "pairs": {}})
    cfg = SimpleNamespace(free=[SimpleNamespace(name="Iyy")],
                          nlp=SimpleNamespace(time_outputs=["q"], trim_outputs=["lon"], input_errors=True))
    out = discovery.check_term(cfg, SimpleNamespace(extensions=()), {}, None, "lon_rigging", level=1e-3,
                               progress=lambda s: None)
    assert out["criterion"] == "score test" and out["significant"] and out["term"]["p"] == 1e-6


#: the screen instance of the base-failure tests: a physical candidate and a generic term, and the two together
SCREEN_TERMS, SCREEN_PAIRS = ["dM_bump00", "cg_offset"], [("cg_offset", "dM_bump00")]


@pytest.fixture(scope="module")
def screen_case(tmp_path_factory, flight_test_cache):
    """The held-out fuselage download instance and its NLP screen with a normal base."""
    from pyomo_heli.diagnosis.discovery import nlp_screen

    cfg = make_case(tmp_path_factory.mktemp("screen"), "[truth.effects.fuselage_download]\nk_fd = 0.03\n", seed=5,
                    points=2, maneuvers=WAKE_MANEUVERS, input_reference_s=1.9, data_cache=flight_test_cache)
    start = {f.name: f.initial for f in cfg.free}
    normal = nlp_screen(cfg, start, SCREEN_TERMS, pairs=SCREEN_PAIRS, progress=lambda s: None)
    assert normal["base_refined"] is None and normal["base_success"]
    return cfg, start, normal


def _failing_solvers(monkeypatch, fails_of, log: list | None = None):
    """make_solver whose k-th solver (0: the first NLP's) fails its first ``fails_of(k)`` solves, stopped where they
    started; returns the list of (solver index, warm start, options) of the calls that failed (``log``: of every
    call, appended)."""
    from types import SimpleNamespace

    import pyomo_heli.solvers as solvers

    real, made, failed = solvers.make_solver, [], []

    def make(*a, **k):
        s, k_, calls = real(*a, **k), len(made), []
        made.append(s)

        class Failing:
            def solve(self, warm_start="none", options=None):
                calls.append(warm_start)
                if log is not None:
                    log.append((k_, warm_start, options))
                if len(calls) <= fails_of(k_):
                    failed.append((k_, warm_start, options))
                    return SimpleNamespace(success=False, status="Maximum_Iterations_Exceeded", iterations=0,
                                           wall_time=0.0)
                return s.solve(warm_start=warm_start, options=options)
        return Failing()

    monkeypatch.setattr(solvers, "make_solver", make)
    return made, failed


def _same_fits(got, normal):
    for t in SCREEN_TERMS:
        a, b = got["fits"][t], normal["fits"][t]
        assert a["estimate"] == pytest.approx(b["estimate"], rel=1e-3, abs=1e-3 * b["se"])
        assert a["LR"] == pytest.approx(b["LR"], rel=1e-3, abs=0.1)
        assert a["LR_trim"] + a["LR_time"] == pytest.approx(a["LR"], abs=1e-6)


def test_a_base_that_stopped_short_is_solved_again_from_the_best_fit_and_the_ratios_match(screen_case, monkeypatch):
    """The NLP screen's base solve made to fail twice without moving (the test's stand-in for a solve that stops
    at a worse point): its J is the start's, and every LR against it would be inflated. The base is then solved
    from the best single fit's solution with that term at zero, and the estimates and likelihood ratios equal
    those of a screen whose base solved normally. Every solve is capped (base and fits, their own caps)."""
    from pyomo_heli.diagnosis.discovery import SCREEN_BASE_MAX_ITER, SCREEN_CONTINUATION_MAX_ITER, nlp_screen

    cfg, start, normal = screen_case
    log = []
    _failing_solvers(monkeypatch, lambda k: 2, log)
    got = nlp_screen(cfg, start, SCREEN_TERMS, progress=print, separate_on_failure=False)
    assert got["base_refined"] and got["base_refined"]["status_before"] == "Maximum_Iterations_Exceeded"
    # the base again from the best fit, after the two base solves and one solve per term, is capped like them;
    # each term's fit (a continuation warm start) has its own cap
    caps = [(o or {}).get("max_iter") for _, _, o in log]
    n = len(SCREEN_TERMS)
    assert caps[:2] + caps[2 + n:3 + n] == [SCREEN_BASE_MAX_ITER] * 3
    assert caps[2:2 + n] == [SCREEN_CONTINUATION_MAX_ITER] * n
    assert got["base_success"] and got["J0"] == pytest.approx(normal["J0"], abs=0.05)
    _same_fits(got, normal)


def test_a_fit_whose_continuation_warm_starts_fail_is_solved_again_from_the_primal_values(screen_case, monkeypatch):
    """Each term's continuation warm starts made to fail, the first and the one with the curvature test (the
    stand-in for a fit stuck at SCREEN_CONTINUATION_MAX_ITER both times): the fit is solved again from the base's
    primal values alone under SCREEN_FIT_MAX_ITER, and its estimate and likelihood ratio equal the normal screen's
    (a second warm start to the same optimum)."""
    from types import SimpleNamespace

    import pyomo_heli.solvers as solvers
    from pyomo_heli.diagnosis.discovery import SCREEN_CURVATURE_TEST, SCREEN_FIT_MAX_ITER, nlp_screen

    cfg, start, normal = screen_case
    real, log = solvers.make_solver, []

    def make(*a, **k):
        s = real(*a, **k)

        class ContinuationFails:
            def solve(self, warm_start="none", options=None):
                log.append((warm_start, (options or {}).get("max_iter"),
                            all((options or {}).get(k) == v for k, v in SCREEN_CURVATURE_TEST.items())))
                if warm_start == "continuation":
                    return SimpleNamespace(success=False, status="Maximum_Iterations_Exceeded", iterations=0,
                                           wall_time=0.0)
                return s.solve(warm_start=warm_start, options=options)
        return ContinuationFails()

    monkeypatch.setattr(solvers, "make_solver", make)
    got = nlp_screen(cfg, start, SCREEN_TERMS, progress=print)
    n = len(SCREEN_TERMS)
    cap = log[1][1]
    assert log[1:1 + 3 * n] == [("continuation", cap, False), ("continuation", cap, True),
                                ("primal", SCREEN_FIT_MAX_ITER, False)] * n
    assert all(got["fits"][t]["success"] and got["fits"][t]["solved_from"] == "primal" for t in SCREEN_TERMS)
    _same_fits(got, normal)


def test_a_fit_whose_first_warm_start_fails_is_solved_with_the_curvature_test(screen_case, monkeypatch):
    """Each term's first continuation warm start made to fail: the fit is solved again from the base's solution
    with Ipopt's inertia-free curvature test (SCREEN_CURVATURE_TEST) under the same cap, the primal retry is not
    needed, and the estimates and likelihood ratios equal the normal screen's, which never needed the retry."""
    from types import SimpleNamespace

    import pyomo_heli.solvers as solvers
    from pyomo_heli.diagnosis.discovery import SCREEN_CONTINUATION_MAX_ITER, SCREEN_CURVATURE_TEST, nlp_screen

    cfg, start, normal = screen_case
    assert all(f["solved_from"] == "continuation" for f in normal["fits"].values())
    real, log = solvers.make_solver, []

    def make(*a, **k):
        s = real(*a, **k)

        class FirstContinuationFails:
            def solve(self, warm_start="none", options=None):
                curvature = "neg_curv_test_tol" in (options or {})
                log.append((warm_start, curvature))
                if warm_start == "continuation" and not curvature:
                    return SimpleNamespace(success=False, status="Maximum_Iterations_Exceeded", iterations=0,
                                           wall_time=0.0)
                assert not curvature or options == {"max_iter": SCREEN_CONTINUATION_MAX_ITER, **SCREEN_CURVATURE_TEST}
                return s.solve(warm_start=warm_start, options=options)
        return FirstContinuationFails()

    monkeypatch.setattr(solvers, "make_solver", make)
    got = nlp_screen(cfg, start, SCREEN_TERMS, progress=print)
    n = len(SCREEN_TERMS)
    assert log[1:1 + 2 * n] == [("continuation", False), ("continuation", True)] * n
    assert all(got["fits"][t]["success"] and got["fits"][t]["solved_from"] == "curvature test" for t in SCREEN_TERMS)
    _same_fits(got, normal)


def test_a_pair_fit_that_stops_above_its_term_alone_is_solved_again_from_that_terms_fit(screen_case, monkeypatch):
    """The pair's first solve made to stop where it started (the base's solution, both terms at zero) and report
    success: the test's stand-in for a pair that converged to a worse local optimum. Its J is the base's, above
    both terms alone, which a pair nesting each of them cannot be at its optimum. The screen solves the pair again
    from the better term's own fit and keeps that: its J and estimates equal the normal screen's pair, and the
    first start is recorded."""
    from types import SimpleNamespace

    import pyomo_heli.solvers as solvers
    from pyomo_heli.diagnosis.discovery import PAIR_SLACK, encompassing, nlp_screen

    cfg, start, normal = screen_case
    real, calls = solvers.make_solver, []

    def make(*a, **k):
        s = real(*a, **k)

        class PairStopsAtStart:
            def solve(self, warm_start="none", options=None):
                calls.append(warm_start)
                # the base, one fit per term, the base again from the best fit, then the pair's first solve
                if len(calls) == 3 + len(SCREEN_TERMS):
                    return SimpleNamespace(success=True, status="Solve_Succeeded", iterations=0, wall_time=0.0)
                return s.solve(warm_start=warm_start, options=options)
        return PairStopsAtStart()

    monkeypatch.setattr(solvers, "make_solver", make)
    got = nlp_screen(cfg, start, SCREEN_TERMS, pairs=SCREEN_PAIRS, progress=print)
    key = "+".join(SCREEN_PAIRS[0])
    pair, ref = got["pairs"][key], normal["pairs"][key]
    better = min(SCREEN_TERMS, key=lambda t: normal["fits"][t]["J"])
    assert pair["first_start"]["J"] == pytest.approx(got["J0"], abs=1e-6)
    assert pair["first_start"]["J"] > normal["fits"][better]["J"] + PAIR_SLACK
    assert pair["success"] and pair["solved_from"] == f"{better}'s fit"
    assert pair["J"] == pytest.approx(ref["J"], abs=0.05)
    assert normal["fits"][better]["J"] - pair["J"] > -PAIR_SLACK
    for t in SCREEN_TERMS:
        assert pair["terms"][t]["estimate"] == pytest.approx(ref["terms"][t]["estimate"], rel=1e-3, abs=1e-6)
    a, b = SCREEN_PAIRS[0]
    e_got = encompassing(got["fits"][a], got["fits"][b], pair, 0.01)
    e_ref = encompassing(normal["fits"][a], normal["fits"][b], ref, 0.01)
    assert e_got["LR_G_given_P"] == pytest.approx(e_ref["LR_G_given_P"], abs=0.1)
    assert e_got["encompasses"] == e_ref["encompasses"]


# slow (45 s; CI time): the fallback after the refined base's fallback; the default run has the base solved again
# (test_a_base_that_stopped_short_...) and a failed base left to the score test (test_a_failed_base_solve_...)
@pytest.mark.slow
def test_a_joint_base_that_fails_twice_is_replaced_by_one_nlp_per_term_and_pair(screen_case, monkeypatch):
    """The joint base made to fail twice (the stand-in for a base stuck under Hessian regularization, capped at
    SCREEN_BASE_MAX_ITER): the screen runs one NLP per term and one per pair, each with its own base. The
    estimates and likelihood ratios equal those of the joint screen (a second method on the same data), and so do
    the encompassing rows, whose pair carries its own NLP's single fits."""
    from pyomo_heli.diagnosis.discovery import SCREEN_BASE_MAX_ITER, encompassing, nlp_screen

    cfg, start, normal = screen_case
    made, failed = _failing_solvers(monkeypatch, lambda k: 2 if k == 0 else 0)
    got = nlp_screen(cfg, start, SCREEN_TERMS, pairs=SCREEN_PAIRS, progress=print)
    assert [(k, (o or {}).get("max_iter")) for k, _, o in failed] == [(0, SCREEN_BASE_MAX_ITER)] * 2
    assert len(made) == 1 + len(SCREEN_TERMS) + len(SCREEN_PAIRS)
    assert got["separate"]["joint_base_status"] == "Maximum_Iterations_Exceeded" and got["base_success"]
    _same_fits(got, normal)
    pa, pb = got["pairs"]["cg_offset+dM_bump00"], normal["pairs"]["cg_offset+dM_bump00"]
    assert pa["LR"] == pytest.approx(pb["LR"], rel=1e-3, abs=0.1)
    ea = encompassing(got["fits"]["cg_offset"], got["fits"]["dM_bump00"], pa, 0.01)
    eb = encompassing(normal["fits"]["cg_offset"], normal["fits"]["dM_bump00"], pb, 0.01)
    for k in ("LR_G_given_P", "LR_P_given_G"):
        assert ea[k] == pytest.approx(eb[k], rel=1e-3, abs=0.1), k
    assert ea["encompasses"] == eb["encompasses"] and ea["equivalent"] == eb["equivalent"]


# slow (28 s; CI time): a check of the warm start's speed-up, not of a result
@pytest.mark.slow
def test_the_screen_warm_start_from_the_base_multipliers_gives_the_primal_warm_starts_estimates(tmp_path,
                                                                                                 flight_test_cache):
    """nlp_screen frees each term from the base solution: warm from its multipliers with a small barrier parameter
    (the fronts' continuation) it reaches the estimate and LR that the primal-only warm start reaches, in fewer
    Ipopt iterations."""
    from pyomo_heli.diagnosis.discovery import nlp_screen

    cfg = make_case(tmp_path, "[truth.effects.fuselage_download]\nk_fd = 0.03\n", seed=5, points=2,
                    maneuvers=WAKE_MANEUVERS, input_reference_s=1.9, data_cache=flight_test_cache)
    start = {f.name: f.initial for f in cfg.free}
    terms = ["dM_bump00", "dZ_one"]
    got = {ws: nlp_screen(cfg, start, terms, progress=lambda s: None, warm_start=ws)
           for ws in ("continuation", "primal")}
    for t in terms:
        a, b = got["continuation"]["fits"][t], got["primal"]["fits"][t]
        assert a["success"] and b["success"]
        assert a["estimate"] == pytest.approx(b["estimate"], rel=1e-3, abs=1e-3 * b["se"])
        assert a["LR"] == pytest.approx(b["LR"], rel=1e-3, abs=0.05)
    its = {ws: sum(f["iterations"] for f in r["fits"].values()) for ws, r in got.items()}
    assert its["continuation"] < its["primal"], its


def test_the_backward_check_removes_at_the_level_the_terms_entered_at():
    """A term added earlier whose Wald z is 2.9 (two-sided p = 0.0037) is kept at alpha = 0.01 but not at the level
    it needed to enter, alpha / L = 0.01 / 58: the check tests at that level, the last step's. The last added term
    is not tested."""
    from types import SimpleNamespace

    from pyomo_heli.workflows.close_loop import _entry_level
    from pyomo_heli.workflows.loop_steps import backward_check

    ext = [SimpleNamespace(name=n, strength=f"c_{n}") for n in ("dX_bump10", "dM_mu", "dM_mu2")]
    cfg = SimpleNamespace(model=SimpleNamespace(extensions=ext))
    record = {"parameters": {"c_dX_bump10": -2.9e-3, "c_dM_mu": -0.02, "c_dM_mu2": 0.0},
              "standard_errors": {"c_dX_bump10": 1e-3, "c_dM_mu": 3.1e-3, "c_dM_mu2": 1e-9}}
    doc = {"iterations": [{"discovery": {"level": 0.01 / 57}}, {"discovery": {"level": 0.01 / 58}}, {}]}
    level = _entry_level(doc, 0.01)
    assert level == 0.01 / 58 and _entry_level({"iterations": [{}]}, 0.01) == 0.01
    rows = {r["name"]: r for r in backward_check(cfg, record, [], level)}
    assert set(rows) == {"dX_bump10", "dM_mu"}  # not the last added
    assert rows["dX_bump10"]["p"] == pytest.approx(0.003732, rel=1e-3) and not rows["dX_bump10"]["significant"]
    assert rows["dM_mu"]["significant"] and rows["dM_mu"]["level"] == level
    assert backward_check(cfg, record, [], 0.01)[0]["significant"]  # at alpha itself it would have stayed
    # a strength without a standard error (at its bound, or none computed) is a row that says it was not tested,
    # neither significant nor removed
    record["standard_errors"]["c_dM_mu"] = None
    row = {r["name"]: r for r in backward_check(cfg, record, [], level)}["dM_mu"]
    assert row["significant"] is None and "not tested" in row["note"]


def test_the_backward_check_removes_the_least_significant_term():
    """Three terms added before the last, two no longer significant: the one of largest Wald p goes (dZ_mu2, p 0.84),
    not the oldest (dM_one, p 0.0027), as stepwise regression removes (a review: the oldest went, and a dropped term
    is never offered again). None when every tested term stays or none was tested."""
    from types import SimpleNamespace

    from pyomo_heli.workflows.loop_steps import backward_check, term_to_drop

    ext = [SimpleNamespace(name=n, strength=f"c_{n}") for n in ("dM_one", "dZ_mu2", "dM_q", "dX_mu4")]
    cfg = SimpleNamespace(model=SimpleNamespace(extensions=ext))
    record = {"parameters": {"c_dM_one": 3.0e-3, "c_dZ_mu2": 2e-4, "c_dM_q": 0.05, "c_dX_mu4": 0.01},
              "standard_errors": {"c_dM_one": 1e-3, "c_dZ_mu2": 1e-3, "c_dM_q": 1e-3, "c_dX_mu4": 1e-3}}
    rows = backward_check(cfg, record, [], 0.01 / 60)
    assert [r["significant"] for r in rows] == [False, False, True]
    assert term_to_drop(rows)["name"] == "dZ_mu2"
    assert term_to_drop([r for r in rows if r["name"] != "dZ_mu2"])["name"] == "dM_one"
    assert term_to_drop([rows[2]]) is None and term_to_drop([]) is None


def test_the_model_without_a_removed_term_is_the_one_its_iteration_record_rebuilds():
    """The backward check removes dM_lon from M0 + dM_lon + dM_q: the model the loop identifies next is the one every
    reader of that iteration rebuilds from its record (``config_of_result``: the config plus the extensions its
    results list), so check-effect, uncertainty and the held-out study's evaluation accept the folder (a review:
    the removed term's strength stayed in the model, fixed at 0, and each refused the folder: "the model differs")."""
    from pathlib import Path
    from types import SimpleNamespace

    from pyomo_heli.config import config_of_result
    from pyomo_heli.provenance import model_fingerprint, model_record
    from pyomo_heli.workflows.loop_steps import _with_candidate, _without

    cfg = load_identification_config(Path(__file__).resolve().parent / "configs" / "m0_noise_small.toml")
    start = {f.name: f.initial for f in cfg.free}
    both = _with_candidate(_with_candidate(cfg, start, "dM_lon", 1e-3), {**start, "c_dM_lon": 1e-3}, "dM_q", 2e-3)
    after = _without(both, {**start, "c_dM_lon": 1e-3, "c_dM_q": 2e-3}, "dM_lon")
    assert [e.name for e in after.model.extensions] == ["dM_q"] and "c_dM_lon" not in after.model.parameters
    assert [f.name for f in after.free] == [*start, "c_dM_q"] and after.free[-1].initial == 2e-3
    record = SimpleNamespace(info={"extensions": ["dM_q"], "shape_parameters": {}},
                             parameters=[f.name for f in after.free])
    rebuilt = config_of_result(cfg, record)
    assert model_fingerprint(model_record(rebuilt)) == model_fingerprint(model_record(after))
    # a term's own parameters go with it, its shape parameters included; the base model's stay
    shaped = _with_candidate(cfg, start, "rotor_wake_on_tail", 0.5)
    assert {"z_ht", "n_wt"} <= set(shaped.model.parameters)
    assert list(_without(shaped, start, "rotor_wake_on_tail").model.parameters) == list(cfg.model.parameters)


# slow (108 s; CI time): four identifications and three screens. The default run has the check's levels and
# decisions (test_the_backward_check_removes_at_the_level_the_terms_entered_at above)
@pytest.mark.slow
def test_a_term_the_backward_check_rejects_is_removed_past_the_iteration_limit(tmp_path, monkeypatch,
                                                                               flight_test_cache):
    """M0 + noise, the first two steps made to add dM_one and then dZ_one (the test's stand-in; each step itself
    runs). At the iteration limit (2) the backward check finds dM_one not significant at the level the terms
    entered at: it is removed all the same, the model re-identified, and the next step does not offer it again."""
    import pyomo_heli.diagnosis.discovery as disc

    real, offered, forced = disc.discovery_step, [], ["dM_one", "dZ_one"]

    def step(cfg, model, start, data, **kw):
        offered.append(list(kw["generic"]))
        out = real(cfg, model, start, data, **kw)
        if forced:
            name = forced.pop(0)
            out = {**out, "decision": "accepted", "added": name, "initial": 0.0, "message": f"{name} (test)"}
        return out

    monkeypatch.setattr(disc, "discovery_step", step)
    _cfg, doc = _loop(tmp_path, "", seed=21, max_iterations=2, generic=["dM_one", "dZ_one", "dM_mu2"],
                      extra='candidates = ["nx_bias"]\nvalidation_rule = false\n', uncertainty="chosen",
                      data_cache=flight_test_cache)
    its = doc["iterations"]
    print([(it["extensions"], it.get("backward_check"), (it.get("decision") or {}).get("message")) for it in its])
    assert [it["extensions"] for it in its] == [[], ["dM_one"], ["dM_one", "dZ_one"], ["dZ_one"]]
    check = its[2]["backward_check"]
    assert [r["name"] for r in check] == ["dM_one"] and not check[0]["significant"]
    # alpha / L of the step that added dZ_one: its library was dZ_one, dM_mu2 and nx_bias
    assert check[0]["level"] == pytest.approx(0.01 / 3) == its[1]["discovery"]["level"]
    assert its[2]["decision"]["decision"] == "dropped" and ">= 0.0033" in its[2]["decision"]["message"]
    assert doc["final_iteration"] == 3 and "dM_one" not in offered[-1]
    # the iteration after the removal is the model its record rebuilds (check-effect and uncertainty read it)
    from pyomo_heli.workflows.check_effect import loop_iteration

    assert [e.name for e in loop_iteration(tmp_path / "loop", 3)[2].model.extensions] == ["dZ_one"]


# slow (CI time): four identifications and four screens. The default run has the name check's decision at its step
# (test_a_physical_candidate_is_named_only_if_it_encompasses_...) and the backward check's levels
@pytest.mark.slow
def test_the_name_check_runs_after_a_backward_check_drop_and_goes_back_to_before_the_name(tmp_path, monkeypatch,
                                                                                         flight_test_cache):
    """M0 + noise, the first two steps made to add the generic dM_one and then to name nx_bias, and the backward
    check at M0 + dM_one + nx_bias made to drop dM_one (the test's stand-ins; each step and check itself runs).
    The step after the drop is nx_bias's first with it fitted: its name check runs there (the stand-in marks the
    best generic term significant), nx_bias is withdrawn, and the loop goes back past both models that held it to
    iteration 1's (M0 + dM_one), not to the one before the drop."""
    import pyomo_heli.diagnosis.discovery as disc
    import pyomo_heli.workflows.close_loop as cl

    real_step, real_check = disc.discovery_step, cl.backward_check
    forced = [("accepted", "dM_one"), ("named", "nx_bias")]
    checked = []

    def step(cfg, model, start, data, **kw):
        out = real_step(cfg, model, start, data, **kw)
        ext = [e.name for e in model.extensions]
        if forced:
            decision, name = forced.pop(0)
            out = {**out, "decision": decision, "added": name, "initial": 0.0, "message": f"{name} (test)"}
        elif ext == ["nx_bias"]:  # the model after the drop: the name check's step
            checked.append(ext)
            out = {**out, "generic_significant": True}
        return out

    def check(cfg, record, base, level):
        rows = real_check(cfg, record, base, level)
        if [e.name for e in cfg.model.extensions] == ["dM_one", "nx_bias"]:
            rows = [{**r, "z": 0.5, "p": 0.62, "significant": False, "note": "test"} for r in rows]
        return rows

    monkeypatch.setattr(disc, "discovery_step", step)
    monkeypatch.setattr(cl, "backward_check", check)
    _cfg, doc = _loop(tmp_path, "", seed=21, max_iterations=3, generic=["dM_one", "dZ_one", "dM_mu2"],
                      extra='candidates = ["nx_bias"]\nvalidation_rule = false\n', data_cache=flight_test_cache)
    its = doc["iterations"]
    print([(it["extensions"], it.get("rejected"), (it.get("decision") or {}).get("message")) for it in its])
    assert [it["extensions"] for it in its[:4]] == [[], ["dM_one"], ["dM_one", "nx_bias"], ["nx_bias"]]
    assert its[2]["decision"]["decision"] == "dropped" and its[2]["decision"]["name"] == "dM_one"
    assert checked == [["nx_bias"]]
    assert "(name check)" in its[3]["rejected"] and its[3]["name_check"]["best_generic_fit"]["name"] in GENERIC
    assert its[3]["step_from"]["iteration"] == 1 and "nx_bias" in its[3]["step_from"]["without"]
    assert all(it["extensions"] == ["dM_one"] for it in its[4:])
    assert doc["final_iteration"] in (1, *(it["iteration"] for it in its[4:]))
    assert "nx_bias" not in its[doc["final_iteration"]]["extensions"]


def test_the_loop_report_names_the_test_that_decided_the_step():
    """The structure step's heading in loop_report.md says which test decided: the likelihood ratio (errors in
    variables) or the score test (output error, or a failed base); a review found it always said the likelihood
    ratio."""
    from pyomo_heli.report.loop import discovery_section

    for criterion, words in (("likelihood ratio", "the likelihood ratio of the NLP decides"),
                             ("score test", "the score test decides")):
        text = "\n".join(discovery_section({"discovery": {"library_size": 60, "level": 0.01 / 60,
                                                          "criterion": criterion, "decision": "none",
                                                          "message": "nothing"}}))
        assert f"{words} at p < 0.000167" in text, text
