"""A table of trims from one Pyomo trim block, re-solved along the speeds.

The block is built once; each speed changes only the mutable Param
``V_target`` (a constraint bound), and each solve starts from the previous
solution: continuation in speed without rebuilding the model.
"""
from __future__ import annotations

import numpy as np
import pandas as pd
import pyomo.environ as pyo

from ..physics.model import HelicopterModel
from ..simulation.trim import hover_guess
from ..solvers import make_solver
from ..solvers.errors import SolverFailedError
from .parameters import add_parameters
from .trim_block import build_trim_block, trim_block_values


def build_trim_model(model: HelicopterModel, V: float = 0.0) -> pyo.ConcreteModel:
    m = pyo.ConcreteModel(name="trim")
    pmap = add_parameters(m, model.parameters, [])
    m.trim = pyo.Block()
    build_trim_block(m.trim, model, pmap, V, guess=hover_guess(model))
    m.objective = pyo.Objective(expr=0.0)  # square system: any feasible point is the trim
    return m


def trim_table(model: HelicopterModel, speeds, solver: str = "casadi-ipopt", step: float = 5.0,
               solver_options: dict | None = None) -> pd.DataFrame:
    """Trim at each speed [m/s] (SI columns), by continuation from hover in steps <= ``step`` m/s."""
    speeds = [float(v) for v in speeds]
    m = build_trim_model(model)
    opt = make_solver(m, solver, solver_options)
    rows = {}
    v_cur = 0.0
    res = opt.solve(warm_start="none")
    if not res.success:
        raise SolverFailedError(f"hover trim failed: {res.status}")
    for target in sorted(set(speeds)):
        n = max(1, int(np.ceil(abs(target - v_cur) / step)))
        for v in np.linspace(v_cur, target, n + 1)[1:]:
            m.trim.V_target = float(v)
            res = opt.solve(warm_start="primal")
            if not res.success:
                raise SolverFailedError(f"trim at {v:.2f} m/s failed: {res.status} ({res.message})")
        rows[target] = trim_block_values(m.trim)
        v_cur = target
    return pd.DataFrame([rows[v] for v in speeds])
