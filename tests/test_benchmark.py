"""The benchmark study (studies/benchmark.py = pyomo_heli.studies.benchmark) --quick: JSON structure and the
ratio arithmetic (no timing asserts).

Timings are machine-dependent and never asserted; what is checked is that
every ratio in the JSON is the stated function of the raw numbers in the
same JSON, that the growth exponent is the least-squares slope of the
log-log data, and that the front and point A are real solves.
"""
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from pyomo_heli.workflows.benchmark import (compute_ratios, growth_exponent, parameter_difference, repeat_maneuvers,
                                  solve_breakdown)

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "benchmark.json"
    proc = subprocess.run([sys.executable, "-m", "pyomo_heli.studies.benchmark", "--quick", "--repeat", "2",
                           "--compare-nl-route", "--out", str(out)],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(out.read_text()), proc.stdout


def test_quick_json_structure(quick):
    res, stdout = quick
    assert [s["size"] for s in res["sizes"]] == [1, 2]
    one, two = res["sizes"]
    assert two["samples"] == 2 * one["samples"]  # the maneuver set repeated twice
    assert two["variables"] > 1.9 * one["variables"]
    for s in res["sizes"]:
        assert s["build_time"] > 0 and s["setup_time"] > 0 and s["a_solve_time"] > 0
        assert s["point_a"]["success"] and s["point_a"]["kind"] == "A"
        assert sum(s["setup_breakdown"].values()) == pytest.approx(s["setup_time"], rel=0.05)
    # the repeated problem has the same optimum (the same residuals twice)
    for n, v in one["point_a"]["parameters"].items():
        assert two["point_a"]["parameters"][n] == pytest.approx(v, rel=1e-5, abs=1e-5), n
    assert two["point_a"]["J_time"] == pytest.approx(2 * one["point_a"]["J_time"], rel=1e-6)
    f = one["front"]
    assert f["n_points"] == 3 and f["all_success"]
    assert [p["kind"] for p in f["points"]] == ["A", "eps", "B"]
    assert f["points"][1]["cold_iterations"] > 0
    assert "front_over_cold_a" in stdout and "| size |" in stdout
    # --repeat 2: the size without a front solves point A twice from the same cold start, the same way each
    # time (same iterations), and its solve time is the median of the two
    assert len(two["a_solve_times"]) == 2 and len(set(two["a_solve_iterations"])) == 1
    assert two["a_solve_time"] == pytest.approx(float(np.median(two["a_solve_times"])))
    assert len(one["a_solve_times"]) == 1  # the front's size: one point A
    # --compare-nl-route: the same point A with every row through the NL file (the second route to the
    # same NLP): the same optimum; the ratio of the set-ups is printed. The rows and variables are in
    # another order there, which can change MUMPS' pivots and so an iteration or two (here 35 and 36).
    nl = res["nl_route"]
    assert abs(nl["a_iterations"] - one["a_iterations"]) <= 2 and nl["point_a"]["success"]
    assert nl["point_a"]["J_time"] == pytest.approx(one["point_a"]["J_time"], rel=1e-9)
    for n, v in one["point_a"]["parameters"].items():
        # twist is nearly flat on this 1 s instance: absolute 1e-6 rad/m (its scale is 1 deg/m = 0.017 rad/m)
        assert nl["point_a"]["parameters"][n] == pytest.approx(v, rel=1e-6, abs=1e-6), n
    assert nl["setup_breakdown"]["nl_write"] > one["setup_breakdown"]["nl_write"]  # every row in the NL file
    assert res["ratios"]["nl_route_setup_over_point_rows_setup"] == pytest.approx(nl["setup_time"] / one["setup_time"])
    assert "NL file only" in stdout


def test_quick_ratio_arithmetic(quick):
    res, _ = quick
    r, one = res["ratios"], res["sizes"][0]
    f = one["front"]
    assert f["solve_time"] == pytest.approx(sum(p["wall_time"] for p in f["points"]))
    assert r["front_over_cold_a"] == pytest.approx(f["solve_time"] / one["a_solve_time"])
    fixed = one["build_time"] + one["setup_time"]
    assert r["setup_share_of_front"] == pytest.approx(fixed / (fixed + f["solve_time"]))
    p1 = f["points"][1]
    assert r["warm_over_cold_iterations"] == pytest.approx(p1["iterations"] / p1["cold_iterations"])
    samples = [s["samples"] for s in res["sizes"]]
    times = [s["a_solve_time"] for s in res["sizes"]]
    # two sizes: the slope is exactly the log ratio
    assert r["solve_time_exponent"] == pytest.approx(math.log(times[1] / times[0]) / math.log(samples[1] / samples[0]))
    for key, t in res["targets"].items():
        if t["value"] is not None:
            assert t["met"] == (t["value"] <= t["limit"] if t["kind"] == "max" else t["value"] >= t["limit"])


def test_shooting_ratio_and_exponent_arithmetic():
    """The single-shooting ratios and the fit, on hand-made numbers."""
    res = {"sizes": [{"build_time": 1.0, "setup_time": 2.0, "a_solve_time": 3.0, "samples": 100,
                      "a_time_per_iteration": 0.1}],
           "single_shooting": {"wall_time": 60.0, "parameter_difference": 2e-4}}
    r = compute_ratios(res)
    assert r["shooting_over_full_discretization"] == pytest.approx(10.0)
    assert r["shooting_over_a_solve_only"] == pytest.approx(20.0)
    samples = np.array([1, 2, 4, 8]) * 1000.0
    assert growth_exponent(samples, 0.5 * samples**1.25) == pytest.approx(1.25)
    assert growth_exponent([1000], [1.0]) is None
    # relative to the magnitude, or to the scale for a value at 0
    assert parameter_difference({"a": 1.0001, "b": 1e-5}, {"a": 1.0, "b": 0.0}, {"a": 0.5, "b": 0.01}) == \
        pytest.approx(1e-3)  # b: 1e-5 / scale 0.01 dominates a: 1e-4 / |1.0|


def test_solve_breakdown_splits_function_time_from_the_rest():
    stats = {"t_wall_nlp_f": 0.5, "t_wall_nlp_grad_f": 0.5, "t_wall_nlp_g": 1.0, "t_wall_nlp_jac_g": 1.0,
             "t_wall_nlp_hess_l": 2.0, "iter_count": 5}
    b = solve_breakdown(stats, 10.0)
    assert b["ipopt_rest"] == pytest.approx(5.0) and b["total"] == 10.0 and b["nlp_hess_l"] == 2.0
    assert solve_breakdown(None, 1.0) is None and solve_breakdown({"iter_count": 3}, 1.0) is None


def test_repeat_maneuvers_renames_copies():
    import dataclasses

    import pandas as pd

    from pyomo_heli.nlp.identification import IdentificationData

    @dataclasses.dataclass
    class Mv:
        name: str
        trim_speed: float
        data: object

    d = IdentificationData(maneuvers=[Mv("m", 0.0, pd.DataFrame({"t": [0.0, 0.1]}))], trims=pd.DataFrame({"V": [0.0]}))
    assert [m.name for m in repeat_maneuvers(d, 3).maneuvers] == ["m", "m~2", "m~3"]
    with pytest.raises(ValueError, match="size"):
        repeat_maneuvers(d, 0)


def test_bad_size_option_exits_2():
    proc = subprocess.run([sys.executable, "-m", "pyomo_heli.studies.benchmark", "--size", "1,x"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2 and "--size" in proc.stderr
