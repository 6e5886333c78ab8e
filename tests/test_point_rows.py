"""The maneuver blocks' physics rows evaluated point by point (solvers/point_rows.py) against the NL route.

The second method here is the NL file itself: the same Pyomo model solved with every row written to the
NL file and differentiated by casadi as one graph (``CasadiSettings(point_rows=False)``). Rows,
Jacobian and Lagrangian Hessian must agree entry by entry at the same point, and the solves must agree.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pyomo.environ as pyo
import pytest
import scipy.sparse as sp

from pyomo_heli.config import load_identification_config
from pyomo_heli.workflows.identify import build_problem
from pyomo_heli.nlp.parameters import free_parameter_values
from pyomo_heli.pareto.front import ParetoSolver
from pyomo_heli.solvers.casadi_ipopt import CasadiIpoptSolver, CasadiSettings
from pyomo_heli.uncertainty.reduced_hessian import _sparse

HERE = Path(__file__).parent
CONFIGS = {"input_errors": HERE / "configs" / "tiny_case1_input_errors.toml",
           "output_error": HERE / "configs" / "mc_time_small.toml"}


def _solver(m, point_rows: bool, first: bool = True) -> CasadiIpoptSolver:
    return CasadiIpoptSolver(m, settings=CasadiSettings(point_rows=point_rows, point_rows_first=first))


@pytest.mark.parametrize("case, first", [("input_errors", True), ("output_error", True), ("output_error", False)])
def test_rows_jacobian_and_hessian_equal_the_nl_route(case, first):
    bundled = str(HERE.parent / "data" / "bo105_synthetic")
    cfg = load_identification_config(CONFIGS[case], {"data": {"dataset": bundled}})
    m, _, _ = build_problem(cfg)
    ParetoSolver(m, cfg.pareto).set_objective("time")  # the objective every front point solves
    nl, pr = _solver(m, False), _solver(m, True, first)
    assert pr._assembly is not None and nl._assembly is None
    assert len(pr._assembly.constraints) > 0.5 * len(pr.constraints), "most rows are point-described"
    col = {id(v): i for i, v in enumerate(nl.variables)}
    row = {id(c): i for i, c in enumerate(nl.constraints)}
    perm = np.array([col[id(v)] for v in pr.variables])
    rperm = np.array([row[id(c)] for c in pr.constraints])
    assert sorted(perm) == list(range(len(nl.variables))) and sorted(rperm) == list(range(len(nl.constraints)))

    rng = np.random.default_rng(7)
    x = np.array([v.value or 0.0 for v in nl.variables]) * (1 + 1e-3 * rng.standard_normal(len(nl.variables)))
    lam = rng.standard_normal(len(nl.constraints))
    g_nl, J_nl = nl._jac_g(x, [])
    g_pr, J_pr = pr._jac_g(x[perm], [])
    # the NL file moves constants of a row into its bounds; the adapters remember by how much
    body_nl = np.asarray(g_nl).ravel() - nl._row_offset
    body_pr = np.asarray(g_pr).ravel() - pr._row_offset
    scale = np.abs(body_nl).max()
    np.testing.assert_allclose(body_pr, body_nl[rperm], rtol=0, atol=1e-12 * scale)
    J_nl, J_pr = _sparse(J_nl).tocsr()[rperm][:, perm], _sparse(J_pr).tocsr()
    assert abs(J_nl - J_pr).max() <= 1e-12 * abs(J_nl).max()
    H_nl = _sparse(nl._hessian_function()(x, [], 0.7, lam))
    H_pr = _sparse(pr._hessian_function()(x[perm], [], 0.7, lam[rperm]))
    H_nl, H_pr = H_nl + sp.triu(H_nl, 1).T, H_pr + sp.triu(H_pr, 1).T
    H_nl = H_nl.tocsr()[perm][:, perm]
    assert abs(H_nl - H_pr).max() <= 1e-12 * abs(H_nl).max()
    # a point-described row is its Pyomo constraint's body
    for v, val in zip(pr.variables, x[perm]):
        v.set_value(val, skip_validation=True)
    mapped = {id(c) for c in pr._assembly.constraints}
    rows = [i for i, c in enumerate(pr.constraints) if id(c) in mapped]
    for i in np.array(rows)[np.linspace(0, len(rows) - 1, 25).astype(int)]:
        assert body_pr[i] == pytest.approx(pyo.value(pr.constraints[i].body), rel=1e-12, abs=1e-12 * scale)


def test_point_a_is_the_same_solve():
    """Point A through both routes: the same iterations and the same estimate (to solver tolerance)."""
    out = {}
    for flag in (False, True):
        cfg = load_identification_config(CONFIGS["input_errors"])
        m, _, _ = build_problem(cfg)
        pareto = dataclasses.replace(cfg.pareto, solver_options={**cfg.pareto.solver_options, "point_rows": flag})
        p = ParetoSolver(m, pareto).point_a()
        assert p.success, p.status
        out[flag] = (p.iterations, p.J_time, free_parameter_values(m))
    print("NL route vs point rows:", out)
    assert out[True][0] == out[False][0]
    assert out[True][1] == pytest.approx(out[False][1], rel=1e-9)
    for n, v in out[False][2].items():
        assert out[True][2][n] == pytest.approx(v, rel=1e-6), n


@pytest.mark.parametrize("text, message", [
    ("[solver]\npoint_rows = false\n", None),
    ("[solver]\nname = \"pounce\"\npoint_rows = false\n", "point_rows' applies to casadi-ipopt only"),
    ("[solver]\npoint_row = false\n", "unknown key\\(s\\) point_row"),
    ("[solver]\noptions = { point_rows = false }\n", "point_rows is a \\[solver\\] field"),
    ("[solver]\npoint_rows = 0\n", "'point_rows' must be bool"),
])
def test_solver_point_rows_setting(tmp_path, text, message):
    """`[solver] point_rows = false` sends every row through the NL file; wrong uses are named."""
    from pyomo_heli.config import ConfigError

    src = CONFIGS["input_errors"].read_text().replace("../../data", str(HERE.parent / "data"))
    assert '[solver]\nname = "casadi-ipopt"' in src
    f = tmp_path / "c.toml"
    f.write_text(src.replace('[solver]\nname = "casadi-ipopt"', text))
    if message is not None:
        with pytest.raises(ConfigError, match=message):
            load_identification_config(f)
        return
    cfg = load_identification_config(f)
    m, _, _ = build_problem(cfg)
    solver = ParetoSolver(m, cfg.pareto).solver
    assert solver.settings.point_rows is False and solver._assembly is None
    assert "point_rows" not in solver.options  # not handed to Ipopt
