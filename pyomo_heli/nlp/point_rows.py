"""The physics rows of a collocation block, described point by point for a compiling solver.

Why: a maneuver block repeats the same physics at every collocation point (6,610 points in
Case 1). Written to an NL file and imported, that is one large expression graph whose derivatives
casadi works out symbolically for the whole graph: most of the solver set-up (docs/performance.md).
Described as *one function of the point's own variables, mapped over the points*, the derivatives
are those of a single point, found once. The Pyomo constraints stay the model (inspection, the AMPL
back ends, duals); :mod:`pyomo_heli.solvers.point_rows` evaluates exactly those rows this way, and
``tests/test_point_rows.py`` checks that rows, Jacobian and Hessian equal the NL route's.

The description (:class:`PointRows`, attached to a block as ``blk.point_rows``) is the contract
between the two layers; the solver needs nothing else from the model:

- ``function(casadi)``: a casadi Function ``F(z, d) -> r`` of one point: ``z`` the point's leaves
  (variables, or numbers where the model has a number or a fixed variable), ``d`` its data;
- ``leaves[p]``: the Pyomo VarData (or float) of each leaf at point ``p``;
- ``data()``: the data of every point (n_points x n_data), read when the solver (re)builds;
- ``rows``: ``(ConstraintData, point, local row)`` for every constraint the function evaluates;
  ``r[local row]`` at that point equals the constraint's ``body`` (its bounds are both zero).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import pyomo.environ as pyo


@dataclass(eq=False)
class PointRows:
    """One collocation block's physics rows as a function mapped over its points (module docstring)."""

    leaf_names: tuple
    data_names: tuple
    make_function: Callable
    leaves: list = field(default_factory=list)
    data_values: list = field(default_factory=list)
    rows: list = field(default_factory=list)

    def function(self, ca):
        return self.make_function(ca)

    def data(self) -> np.ndarray:
        """n_points x n_data; Pyomo Params are read now (a rebuild picks up changed values)."""
        return np.array([[pyo.value(v) for v in row] for row in self.data_values], dtype=float).reshape(
            len(self.data_values), len(self.data_names))
