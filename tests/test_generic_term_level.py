"""The generic-term level study (pyomo_heli.studies.generic_term_level): generic terms estimated alone in the NLP on
flight tests of M0 + noise, where every true strength is zero."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats

ROOT = Path(__file__).resolve().parent.parent


def test_summary_gives_the_estimates_and_z_moments_over_the_seeds():
    """Mean and sd of c and z, the mean's t statistic and the |z| shares, computed by hand; a failed fit is left
    out of its term's row."""
    from pyomo_heli.studies.generic_term_level import per_seed, summary

    def doc(seed, c, z, ok=True):
        return {"seed": seed, "fits": {"col_scale": {"estimate": c, "z": z, "LR": z * z, "success": ok}}}
    docs = [doc(1, -0.01, -3.4), doc(2, 0.002, 0.5), doc(3, -0.004, -2.1), doc(4, 0.5, 9.0, ok=False)]
    row = summary(docs, ["col_scale"]).iloc[0]
    c = np.array([-0.01, 0.002, -0.004])
    assert row["seeds"] == 3
    assert row["mean c"] == pytest.approx(c.mean()) and row["sd c"] == pytest.approx(c.std(ddof=1))
    assert row["t of mean c"] == pytest.approx(c.mean() / (c.std(ddof=1) / math.sqrt(3)))
    assert row["mean z"] == pytest.approx(-5.0 / 3)
    assert row["z beyond +-2 [%]"] == pytest.approx(200 / 3) and row["z beyond +-3 [%]"] == pytest.approx(100 / 3)
    assert list(per_seed(docs, ["col_scale"])["col_scale z"]) == [-3.4, 0.5, -2.1, 9.0]


def test_where_the_score_test_decides_the_tables_add_what_the_corrected_lr_would_have():
    """Output error (the score test's own p decides): the summary adds z_LR's moments and the per-seed table each
    term's z_LR and, over the terms, the largest |z_p| and |z_LR| with their term (a failed fit left out); with the
    corrected LR deciding (z_p is z_LR) neither is added."""
    from pyomo_heli.studies.generic_term_level import per_seed, summary

    def fit(c, z_p, z_lr, ok=True, criterion="score test"):
        return {"estimate": c, "z": z_lr, "LR": z_lr * z_lr, "z_p": z_p, "z_LR": z_lr, "success": ok,
                "criterion": criterion}
    docs = [{"seed": 1, "fits": {"dM_one": fit(0.01, 1.5, 4.0), "dZ_one": fit(-0.02, -2.5, -3.0)}},
            {"seed": 2, "fits": {"dM_one": fit(-0.01, -0.5, -1.0), "dZ_one": fit(0.3, 9.0, 9.0, ok=False)}}]
    row = summary(docs, ["dM_one", "dZ_one"]).set_index("term").loc["dM_one"]
    assert row["mean z_LR"] == pytest.approx(1.5) and row["z_LR beyond +-2 [%]"] == pytest.approx(50.0)
    tab = per_seed(docs, ["dM_one", "dZ_one"])
    assert list(tab["largest |z_p| term"]) == ["dZ_one", "dM_one"] and list(tab["largest |z_p|"]) == [2.5, 0.5]
    assert list(tab["largest |z_LR| term"]) == ["dM_one", "dM_one"] and list(tab["largest |z_LR|"]) == [4.0, 1.0]
    assert list(tab["dZ_one z_LR"]) == [-3.0, 9.0]
    for d in docs:
        for f in d["fits"].values():
            f["criterion"] = "likelihood ratio"
    assert "z_LR beyond +-2 [%]" not in summary(docs, ["dM_one"]).columns
    assert not [c for c in per_seed(docs, ["dM_one"]).columns if "z_LR" in c]


def _seed_7(out) -> list:
    """The study's arguments for seed 7 of the small held-out flight test into ``out``."""
    return ["--seeds", "7", "--config", str(ROOT / "studies" / "held_out_small.toml"),
            "--data-config", str(ROOT / "studies" / "held_out_small_gen.toml"), "--out", str(out)]


def test_level_study_writes_each_seed_and_resumes(tmp_path):
    """One seed of the small held-out flight test (three records), M0 + noise: both input scale factors estimated
    about their true zero (|c| well inside the family's +-0.2 bounds, |z| < 4), z = sign(c) sqrt(LR), the seed's data
    removed once done, and a rerun reads the seed back instead of solving again."""
    from pyomo_heli.studies.generic_term_level import main

    argv = _seed_7(tmp_path)
    assert main(argv) == 0
    doc = json.loads((tmp_path / "seed_7.json").read_text())
    for n in ("col_scale", "lon_scale"):
        f = doc["fits"][n]
        assert f["success"] and abs(f["estimate"]) < 0.05 and abs(f["z"]) < 4.0, (n, f)
        assert f["z"] == pytest.approx(math.copysign(math.sqrt(max(f["LR"], 0.0)), f["estimate"]))
        # the deciding test of a structure step: the LR corrected by the robust score test (never upwards), referred
        # to F(1, df); z_p is its p as a normal deviate with the estimate's sign
        assert f["criterion"] == "likelihood ratio" and 0.0 <= f["LR_robust"] <= f["LR"] * (1 + 1e-12)
        p = stats.f(1, f["df"]).sf(f["LR_robust"]) if math.isfinite(f["df"]) else stats.chi2(1).sf(f["LR_robust"])
        assert f["p"] == pytest.approx(p, rel=1e-9)
        assert 2 * stats.norm.sf(abs(f["z_p"])) == pytest.approx(p, rel=1e-9)
        assert math.copysign(1.0, f["z_p"]) == math.copysign(1.0, f["estimate"]) and abs(f["z_p"]) <= abs(f["z"])
    assert not (tmp_path / "data").exists()
    assert list(pd.read_csv(tmp_path / "summary.csv")["term"]) == ["col_scale", "lon_scale"]
    doc["fits"]["col_scale"]["estimate"] = 0.123  # a rerun reads the stored seed
    (tmp_path / "seed_7.json").write_text(json.dumps(doc))
    assert main(argv) == 0
    assert pd.read_csv(tmp_path / "summary.csv").set_index("term").loc["col_scale", "mean c"] == 0.123


# slow (15 s; CI time): a second identification and screen
@pytest.mark.slow
def test_level_study_with_the_measured_inputs_taken_as_exact_fits_again(tmp_path):
    """--identification oe: the measured inputs taken as exact, a fit of its own (another J) into OUT/oe."""
    from pyomo_heli.studies.generic_term_level import main

    argv = _seed_7(tmp_path)
    assert main(argv) == 0
    doc = json.loads((tmp_path / "seed_7.json").read_text())
    assert main([*argv, "--identification", "oe"]) == 0
    oe = json.loads((tmp_path / "oe" / "seed_7.json").read_text())
    assert oe["identification"] == "oe" and oe["J0"] != pytest.approx(doc["J0"], rel=1e-3)
    assert all(f["success"] and abs(f["z"]) < 4.0 for f in oe["fits"].values())
    # in output error the score test's own p decides; z_LR is the corrected LR's p, referred to F(1, df), as with
    # input errors, where it is z_p itself
    for f in oe["fits"].values():
        assert f["criterion"] == "score test"
        p_lr = stats.f(1, f["df"]).sf(f["LR_robust"]) if math.isfinite(f["df"]) else stats.chi2(1).sf(f["LR_robust"])
        assert f["p_LR"] == pytest.approx(p_lr, rel=1e-9) and 2 * stats.norm.sf(abs(f["z_LR"])) == pytest.approx(p_lr)
    assert all(f["z_LR"] == f["z_p"] for f in doc["fits"].values())


def test_exact_inputs_keep_every_other_draw_and_give_the_generator_sigmas(tmp_path):
    """--exact-inputs: the flight test of the same seed with the recorded inputs' noise removed: inputs constant over
    the lead-in, every output and trim exactly as in the noisy flight test (the same draws); the fit's sigmas are the
    generator's for the inputs and the lead-in's for the outputs."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.studies.generic_term_level import given_sigmas
    from pyomo_heli.studies.seeded import m0_noise_data

    gen = ROOT / "studies" / "held_out_small_gen.toml"
    noisy = load_flight_test(m0_noise_data(7, gen, tmp_path / "a"))
    exact = load_flight_test(m0_noise_data(7, gen, tmp_path / "b", input_noise=False))
    for name, mv in noisy.maneuvers.items():
        rec, ex = mv.data, exact.maneuvers[name].data
        lead = ex["t"] <= ex["t"].iloc[0] + 1.9
        assert ex.loc[lead, ["col", "lon"]].std().max() < 1e-12 and rec.loc[lead, "col"].std() > 1e-5
        for ch in ("q", "theta", "n_x", "n_z", "TAS"):
            assert np.array_equal(ex[ch].to_numpy(), rec[ch].to_numpy()), (name, ch)
    pd.testing.assert_frame_equal(exact.trims, noisy.trims)
    cfg = load_identification_config(ROOT / "studies" / "held_out_small.toml", overrides={
        "data": {"dataset": str(tmp_path / "b" / "data" / "7")}})
    sig = given_sigmas(cfg, gen)
    assert sig["col_deg"] == pytest.approx(0.02) and sig["lon_deg"] == pytest.approx(0.02)
    assert sig["q_deg_s"] > 0.1 and sig["nz_g"] > 0.005  # the lead-in's noise (and vibration) of the outputs


# slow (20-30 s each; CI time): each option's seed run; the default run has the study's own seed run and resume
# (test_level_study_writes_each_seed_and_resumes) and each option's data and sigmas (the tests above)
@pytest.mark.slow
def test_exact_inputs_run_one_seed_into_their_own_folder(tmp_path):
    """--exact-inputs: one seed runs and is stored under exact_inputs/, every fit about its true zero."""
    from pyomo_heli.studies.generic_term_level import main

    gen = ROOT / "studies" / "held_out_small_gen.toml"
    argv = ["--seeds", "7", "--config", str(ROOT / "studies" / "held_out_small.toml"), "--data-config", str(gen),
            "--out", str(tmp_path / "c"), "--exact-inputs"]
    assert main(argv) == 0
    doc = json.loads((tmp_path / "c" / "exact_inputs" / "seed_7.json").read_text())
    assert doc["exact_inputs"] and all(f["success"] and abs(f["z"]) < 4.0 for f in doc["fits"].values())


def test_input_sigma_scale_multiplies_the_lead_in_sigmas_of_the_inputs_only(tmp_path):
    """--input-sigma-scale K: the fit's input-error sigmas are K times the records' lead-in sigmas (computed here
    from the records), the outputs' stay the lead-in's."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.nlp.identification import identification_data
    from pyomo_heli.studies.generic_term_level import given_sigmas
    from pyomo_heli.studies.seeded import m0_noise_data

    gen = ROOT / "studies" / "held_out_small_gen.toml"
    data = m0_noise_data(7, gen, tmp_path / "a")
    cfg = load_identification_config(ROOT / "studies" / "held_out_small.toml",
                                     overrides={"data": {"dataset": str(data)}})
    recs = [mv.data for mv in identification_data(cfg).maneuvers]  # the records as the NLP takes them (25 Hz)
    ref = cfg.input_reference_s

    def pooled_deg(ch):  # the pooled variance about each lead-in's mean
        ss = dof = 0
        for d in recs:
            x = np.degrees(d.loc[d["t"] <= d["t"].iloc[0] + ref, ch].to_numpy())
            ss, dof = ss + float(np.sum((x - x.mean()) ** 2)), dof + len(x) - 1
        return math.sqrt(ss / dof)
    one, two = given_sigmas(cfg, None), given_sigmas(cfg, None, 2.0)
    for key, ch in (("col_deg", "col"), ("lon_deg", "lon")):
        assert one[key] == pytest.approx(pooled_deg(ch), rel=1e-9) and two[key] == pytest.approx(2 * one[key])
    assert {k: v for k, v in two.items() if k not in ("col_deg", "lon_deg")} == \
        {k: v for k, v in one.items() if k not in ("col_deg", "lon_deg")}


@pytest.mark.slow
def test_input_sigma_scale_runs_one_seed_into_its_own_folder(tmp_path):
    """--input-sigma-scale 2: one seed runs into input_sigma_x2/ and records its K; a doc of another K is not taken
    for it."""
    from pyomo_heli.studies.generic_term_level import main

    gen = ROOT / "studies" / "held_out_small_gen.toml"
    argv = ["--seeds", "7", "--config", str(ROOT / "studies" / "held_out_small.toml"), "--data-config", str(gen),
            "--out", str(tmp_path / "c"), "--input-sigma-scale", "2"]
    assert main(argv) == 0
    f = tmp_path / "c" / "input_sigma_x2" / "seed_7.json"
    doc = json.loads(f.read_text())
    assert doc["input_sigma_scale"] == 2.0 and all(r["success"] for r in doc["fits"].values())
    doc["input_sigma_scale"] = 3.0  # a stored seed of another K is solved again, not read back
    f.write_text(json.dumps(doc))
    assert main(argv) == 0
    assert json.loads(f.read_text())["input_sigma_scale"] == 2.0


def test_resample_inputs_picks_the_recorded_samples_it_names(tmp_path):
    """--resample-inputs sample: the fit's [data] resample_inputs overridden (the NLP's inputs are then the recorded
    samples at its grid's times, checked here against the record; with ``record`` every recorded sample)."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.nlp.identification import identification_data
    from pyomo_heli.studies.seeded import m0_noise_data

    gen, small = ROOT / "studies" / "held_out_small_gen.toml", ROOT / "studies" / "held_out_small.toml"
    data = m0_noise_data(7, gen, tmp_path / "a")
    rec = load_flight_test(data).maneuvers
    for how in ("sample", "project", "record"):
        cfg = load_identification_config(small, overrides={"data": {"dataset": str(data), "resample_inputs": how}})
        mv = identification_data(cfg).maneuvers[0]
        raw = rec[mv.name].data.set_index("t")
        picked = raw["col"].reindex(mv.data["t"].to_numpy(), method="nearest").to_numpy()
        same = np.allclose(mv.data["col"].to_numpy(), picked, rtol=0, atol=1e-12)
        assert same == (how == "sample"), how
        # "record" keeps every recorded input sample up to the last fitted one beside the projected samples
        assert (mv.inputs_record is not None) == (how == "record"), how
        if how == "record":
            kept = raw.loc[raw.index <= mv.data["t"].iloc[-1] + 1e-9, "col"].to_numpy()
            np.testing.assert_array_equal(mv.inputs_record["col"].to_numpy(), kept)


@pytest.mark.slow
def test_resample_inputs_sample_runs_one_seed_into_its_own_folder(tmp_path):
    """--resample-inputs sample: one seed runs into inputs_sample/ and records the choice; a stored seed of the
    config's own resampling is not taken for it."""
    from pyomo_heli.studies.generic_term_level import main

    gen, small = ROOT / "studies" / "held_out_small_gen.toml", ROOT / "studies" / "held_out_small.toml"
    argv = ["--seeds", "7", "--config", str(small), "--data-config", str(gen), "--out", str(tmp_path / "c"),
            "--resample-inputs", "sample"]
    assert main(argv) == 0
    f = tmp_path / "c" / "inputs_sample" / "seed_7.json"
    doc = json.loads(f.read_text())
    assert doc["resample_inputs"] == "sample" and all(r["success"] and abs(r["z"]) < 4.0 for r in doc["fits"].values())
    doc["resample_inputs"] = None  # a stored seed of the config's resampling is solved again, not read back
    f.write_text(json.dumps(doc))
    assert main(argv) == 0
    assert json.loads(f.read_text())["resample_inputs"] == "sample"
