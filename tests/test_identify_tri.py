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
