"""The tri-objective identification workflow on a tiny problem (2 s of one record, one frequency response, 5 x 5 grid).

Every grid point converges or is reported infeasible within the [pareto] max_iter cap, and the nadir of the
non-dominated points equals the one recomputed here from front.csv by brute force.
"""
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pyomo_heli.config import load_identification_config
from pyomo_heli.workflows.identify import run_identification

CONFIG = Path(__file__).parent / "configs" / "tiny_case1_tri.toml"


@pytest.fixture(scope="module")
def tri_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("tri")
    res = run_identification(load_identification_config(CONFIG), out, progress=lambda *_: None)
    return res, pd.read_csv(out / "front.csv")


def test_every_grid_point_converges_or_is_infeasible_within_the_cap(tri_run):
    res, front = tri_run
    grid = front[front.kind == "eps"]
    assert res.info["grid"] == [5, 5] and len(grid) == 5 * 5 - 1
    assert set(zip(grid.i_trim, grid.i_linear)) == {(i, j) for i in range(5) for j in range(5)} - {(0, 0)}
    ok = grid.success.astype(bool) | (grid.status == "infeasible")
    assert ok.all(), grid.loc[~ok, ["index", "status", "iterations"]]
    assert (grid.iterations < 100).all() and res.info["max_iterations_grid"] < 100
    for _, p in grid[grid.success.astype(bool)].iterrows():  # the bounds hold
        assert p.J_trim <= p.epsilon * (1 + 1e-6) and p.J_linear <= p.epsilon_linear * (1 + 1e-6)


def test_nadir_rules_and_the_choice_under_both(tri_run):
    res, front = tri_run
    choices = res.info["eq11_by_nadir"]
    assert set(choices) == {"payoff", "nondominated"}
    anchors = front[front.kind.isin(["A", "B", "C"])][["J_time", "J_trim", "J_linear"]].to_numpy()
    np.testing.assert_allclose(choices["payoff"]["nadir"], anchors.max(axis=0), rtol=1e-10)  # front.csv keeps 12 digits
    # brute force: converged points inside the box of A's J_trim and J_linear, no other one at least as good
    a = front[front.kind == "A"].iloc[0]
    pts = front[front.success.astype(bool) & front.kind.isin(["A", "B", "C", "eps"])]
    pts = pts[(pts.J_trim <= a.J_trim * (1 + 1e-9) + 1e-12) & (pts.J_linear <= a.J_linear * (1 + 1e-9) + 1e-12)]
    J = pts[["J_time", "J_trim", "J_linear"]].to_numpy()
    nd = [p for p in J if not any((q <= p).all() and (q < p).any() for q in J)]
    np.testing.assert_allclose(choices["nondominated"]["nadir"], np.max(nd, axis=0), rtol=1e-10)
    # the chosen point is the default (payoff) rule's
    assert res.chosen["index"] == choices["payoff"]["index"]


def test_each_grid_point_starts_from_the_solution_nearest_to_being_one_at_its_bounds(tri_run):
    """Recomputed from front.csv and the row minima of the run's info: the start each grid point records is, of
    anchor A, the grid points solved before it and the row minima (row 0: anchor C when it lies in A's J_trim
    bound), one with the least distance in anchor ranges from its bounds to the bounds where that start is still
    a solution (its J meets them; no bound active at it loosened, bounds above A's values read as A's values).
    A start at distance 0 is the answer already: at most 2 iterations, the same J_time. No grid solve takes more
    than 20 iterations (each of the 24 took 3-11, then the nearest grid neighbour's took 3-9)."""
    res, front = tri_run
    a = front[front.kind == "A"].iloc[0]
    b, c = front[front.kind == "B"].iloc[0], front[front.kind == "C"].iloc[0]
    keys, lo = ("trim", "linear"), {"trim": b.J_trim, "linear": c.J_linear}
    rng = {k: a[f"J_{k}"] - lo[k] for k in keys}

    def dist(J, bounds, eps):
        d = 0.0
        for k in keys:
            d += max(0.0, J[k] - eps[k]) / rng[k]
            if np.isfinite(bounds[k]) and J[k] >= bounds[k] - 1e-4 * rng[k]:
                d += max(0.0, min(eps[k], a[f"J_{k}"]) - min(bounds[k], a[f"J_{k}"])) / rng[k]
        return d

    starts = {"anchor A": ({"trim": a.J_trim, "linear": a.J_linear}, {"trim": np.inf, "linear": np.inf}, -1)}
    if c.J_trim <= a.J_trim:
        starts["row 0 minimum (anchor C)"] = ({"trim": c.J_trim, "linear": c.J_linear},
                                              {"trim": np.inf, "linear": c.J_linear}, 0)
    for r in res.info["row_minima"]:
        starts[f"row {r['row']} minimum"] = ({"trim": r["J_trim"], "linear": r["min_J_linear"]},
                                             {"trim": r["epsilon_trim"], "linear": r["min_J_linear"]}, r["row"])
    grid = front[front.kind == "eps"].sort_values("index")
    for _, p in grid.iterrows():
        eps = {"trim": p.epsilon, "linear": p.epsilon_linear}
        if p.status == "infeasible" and p.iterations == 0:
            continue
        # the row minima the run had solved by then: those of rows up to this one (rows are visited in order)
        d = {lab: dist(J, bd, eps) for lab, (J, bd, row) in starts.items() if row <= p.i_trim}
        assert d[p.start] <= min(d.values()) * (1 + 1e-4) + 1e-9, (p["index"], p.start, d)
        if d[p.start] == 0.0:
            assert p.iterations <= 2
            if p.start.startswith("point"):
                assert p.J_time == pytest.approx(front.loc[front["index"] == int(p.start.split()[1])].J_time.iloc[0])
        if p.success:
            starts[f"point {p['index']} ({p.i_trim}, {p.i_linear})"] = (
                {"trim": p.J_trim, "linear": p.J_linear}, eps, -1)
    assert grid.iterations.max() <= 20
