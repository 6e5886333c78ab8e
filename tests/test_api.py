"""The Python API (docs/api.md): the documented example runs, and its pieces agree with the modules they wrap."""
import json
import math
import os
from pathlib import Path

import numpy as np
import pytest

import pyomo_heli as ph
from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import DatasetError
from pyomo_heli.resources import bundled_flight_test

HERE = Path(__file__).parent
EXAMPLE = HERE / "data" / "api_example.py"  # the example of docs/api.md


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """Run the API example (tests/data/api_example.py, shown in docs/api.md) in an empty folder; return its
    namespace and folder."""
    cwd = tmp_path_factory.mktemp("api_example")
    old = os.getcwd()
    os.chdir(cwd)
    try:
        ns = {}
        exec(compile(EXAMPLE.read_text(), str(EXAMPLE), "exec"), ns)
    finally:
        os.chdir(old)
    return ns, cwd


def test_example_estimates_are_the_folders_in_display_units_with_standard_errors(example):
    ns, cwd = example
    est = ns["est"]
    assert est["point"].tolist() == ["A", "A", "C", "C", "direct", "direct"]
    chosen = json.loads((cwd / "api_example" / "chosen.json").read_text())
    td = json.loads((cwd / "api_example" / "time_domain.json").read_text())
    n_se = 0
    for point, rec in (("A", td), ("C", chosen["chosen"]), ("direct", chosen["direct"])):
        for name, unit, factor in (("theta_twist", "deg/m", 180 / math.pi), ("CL_alpha_HT", "1/rad", 1.0)):
            row = est[(est.point == point) & (est.parameter == name)].iloc[0]
            assert row["unit"] == unit
            assert row["estimate"] == pytest.approx(rec["parameters"][name] * factor, rel=1e-12)
            se = rec["uncertainty"]["se"][name]  # uncertainty="chosen": A, C and the direct solve have them
            bound = rec["uncertainty"]["at_bound"][name]
            assert row["at_bound"] == bound
            if bound:  # projected out: no standard error
                assert se is None and math.isnan(row["standard_error"])
                continue
            assert se > 0
            assert row["standard_error"] == pytest.approx(se * factor, rel=1e-12)
            assert row["relative_se_percent"] == pytest.approx(100 * se / abs(rec["parameters"][name]), rel=1e-12)
            n_se += 1
    assert n_se >= 4
    # the estimates are those of the run: A is the time-domain optimum on the front
    front = ns["res"].front
    a = front[front.kind == "A"].iloc[0]
    assert est[(est.point == "A") & (est.parameter == "CL_alpha_HT")]["estimate"].iloc[0] == pytest.approx(
        a["CL_alpha_HT"], rel=1e-12)


def test_example_flight_test_round_trip(example):
    ns, cwd = example
    ft, mine = ns["ft"], ns["mine"]
    assert mine.path is None and list(mine.maneuvers) == ns["names"]
    back = ph.load_flight_test(cwd / "my_flight_test")
    for n in ns["names"]:
        np.testing.assert_allclose(back.maneuvers[n].data[["t", "q", "theta", "col", "lon"]].to_numpy(),
                                   ft.maneuvers[n].data[["t", "q", "theta", "col", "lon"]].to_numpy(),
                                   rtol=1e-8, atol=1e-12)
    assert len(back.trims) == int((ft.trims["source"] == "level").sum())


def test_dict_config_equals_toml_config():
    toml = load_identification_config(HERE / "configs" / "small_case1_noisy.toml")
    raw = dict(toml.raw)
    raw["data"] = {**raw["data"], "dataset": str(bundled_flight_test())}
    d = ph.load_config(raw)
    assert d.dataset == toml.dataset
    assert [(f.name, f.initial, f.lower, f.upper, f.scale) for f in d.free] == \
           [(f.name, f.initial, f.lower, f.upper, f.scale) for f in toml.free]
    assert d.pareto == toml.pareto and d.nlp == toml.nlp and d.maneuvers == toml.maneuvers


def test_dict_config_errors_name_the_field(tmp_path):
    with pytest.raises(ph.ConfigError, match=r"<dict config> \[data\]: field 'dataset': folder .*nowhere not found"):
        ph.load_config({"data": {"dataset": "nowhere"}, "parameters": {}}, base_dir=tmp_path)
    with pytest.raises(ph.ConfigError, match=r"<dict config>: unknown table\(s\) \['paretto'\]"):
        ph.load_config({"data": {"dataset": str(bundled_flight_test())}, "paretto": {}})
    with pytest.raises(TypeError, match="path or a dict"):
        ph.load_config(3)


def test_from_frames_rejects_bad_data_naming_the_column():
    ft = ph.load_flight_test(bundled_flight_test())
    name = "lon3211_80kt_a"
    data = ft.maneuvers[name].data.copy()
    manifest = {"aircraft": "x", "mass_kg": ft.mass, "atmosphere": {"rho_kg_m3": ft.rho, "g_m_s2": ft.g},
                "maneuvers": [{"name": name, "role": "identification", "trim_speed_kt": 80.0, "inputs": ["lon"]}]}
    level = ft.trims[ft.trims["source"] == "level"]
    bad = data.copy()
    bad.loc[10, "q"] = float("nan")
    with pytest.raises(DatasetError) as exc:
        ph.FlightTest.from_frames(manifest, {name: bad}, level)
    text = str(exc.value)
    assert "<FlightTest.from_frames>" in text and "q_deg_s" in text, text
    with pytest.raises(DatasetError, match="theta"):
        ph.FlightTest.from_frames(manifest, {name: data.drop(columns=["theta"])}, level)
    ok = ph.FlightTest.from_frames(manifest, {name: data}, level)
    np.testing.assert_allclose(ok.maneuvers[name].data["q"].to_numpy(), data["q"].to_numpy(), rtol=1e-8, atol=1e-12)


def test_load_results_of_the_committed_case1():
    """The committed Case 1 results (a copy in tests/results/case1) read through the API: C of docs/results.md."""
    res = ph.load_results(HERE / "results" / "case1")
    est = res.estimates().set_index(["point", "parameter"])
    chosen = json.loads((HERE / "results" / "case1" / "chosen.json").read_text())["chosen"]
    assert est.loc[("C", "theta_twist"), "estimate"] == pytest.approx(
        chosen["parameters"]["theta_twist"] * 180 / math.pi, rel=1e-12)
    assert est.loc[("C", "theta_twist"), "unit"] == "deg/m"
    assert est.loc[("C", "CL_alpha_HT"), "standard_error"] == pytest.approx(
        chosen["uncertainty"]["se"]["CL_alpha_HT"], rel=1e-12)


def test_a_point_that_did_not_converge_is_not_shown_as_an_estimate():
    """A failed direct Eq. 11 solve keeps its last iterate in chosen.json: ``Results.estimates()`` says so (success,
    status), the parameter table and its errors against truth leave it out (n/a), and the printed result marks it."""
    from pyomo_heli.diagnosis.residuals import find_config
    from pyomo_heli.report.identification import parameter_table

    res = ph.load_results(HERE / "results" / "case1")
    res.result.direct.update(success=False, status="Maximum_Iterations_Exceeded")
    est = res.estimates()
    assert not est[est["point"] == "direct"]["success"].any() and est[est["point"] != "direct"]["success"].all()
    assert (est[est["point"] == "direct"]["status"] == "Maximum_Iterations_Exceeded").all()
    cfg = load_identification_config(find_config(HERE / "results" / "case1", res.result))
    tab = parameter_table(res.result, cfg, truth={n: 1.0 for n in res.parameters})
    assert tab["Eq. 11 direct"].isna().all() and tab["Eq. 11 direct error %"].isna().all()
    assert tab["multi-objective"].notna().all()
    assert "NOT CONVERGED (Maximum_Iterations_Exceeded)" in str(res.result)


def test_the_console_standard_errors_are_in_display_units(tmp_path):
    """The "standard errors, point k" console lines show values and SEs in the config's units (deg/m for the twist),
    as every other console line, and name a parameter the solver left at its bound (a review: the line was in SI
    without units, the twist of point A -0.174527+-5.55 next to -9.99964 deg/m on the line before)."""
    import re

    lines = []
    res = ph.identify(HERE / "configs" / "tiny_case1_noisy.toml", tmp_path / "o", uncertainty="chosen",
                      progress=lines.append)
    se_lines = [ln for ln in lines if "standard errors, point" in ln]
    assert se_lines
    chosen = json.loads((tmp_path / "o" / "chosen.json").read_text())["chosen"]
    k = int(chosen["index"])
    line = next(ln for ln in se_lines if re.search(rf"point +{k}:", ln))
    u = chosen["uncertainty"]
    if u["at_bound"]["theta_twist"]:
        assert f"theta_twist at {u['at_bound']['theta_twist']} bound" in line
    else:
        m = re.search(r"theta_twist=(\S+)\+-(\S+) deg/m", line)
        assert m, line
        assert float(m.group(1)) == pytest.approx(chosen["parameters"]["theta_twist"] * 180 / math.pi, rel=1e-5)
        assert float(m.group(2)) == pytest.approx(u["se"]["theta_twist"] * 180 / math.pi, rel=5e-3)  # 3 digits
    assert re.search(r"CL_alpha_HT=\S+\+-\S+ 1/rad", line), line
    assert res.result.chosen["index"] == k  # the returned result is the one on disk


def test_estimates_of_a_loop_iteration_with_a_candidate_strength():
    """A closed-loop iteration's folder (the wake's k_wt free beside the model's parameters): ``estimates()`` gives
    every free parameter in display units, the candidate strength as chosen.json has it (a review: the import of
    the candidate model had moved, and every folder with a candidate strength raised ImportError)."""
    folder = HERE.parent / "docs" / "results" / "close_loop" / "iter_1"
    chosen = json.loads((folder / "chosen.json").read_text())["chosen"]
    est = ph.load_results(folder).estimates()
    c = est[est.point == "C"].set_index("parameter")
    assert "k_wt" in c.index and c.loc["k_wt", "unit"] == "-"
    assert c.loc["k_wt", "estimate"] == pytest.approx(chosen["parameters"]["k_wt"], rel=1e-12)
    assert c.loc["theta_twist", "estimate"] == pytest.approx(chosen["parameters"]["theta_twist"] * 180 / math.pi,
                                                             rel=1e-12)
