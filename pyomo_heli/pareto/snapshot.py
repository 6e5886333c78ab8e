"""A snapshot of a solved Pyomo model: every variable's value and the stored multipliers.

The fronts (:mod:`.front`, :mod:`.tri_front`) keep one per solved point, to restore it as the
warm start of the next solve or to extrapolate from two of them (the secant predictor).
"""
from __future__ import annotations

import numpy as np
import pyomo.environ as pyo
from pyomo.common.gc_manager import PauseGC

_MULTIPLIER_SUFFIXES = ("dual", "ipopt_zL_out", "ipopt_zU_out")


class Snapshot:
    """Values of every variable and the stored multipliers, to restore a solution as a warm start.

    Values are kept as numpy arrays beside one list of the components, not as (component, value)
    pairs: a few hundred thousand pairs per snapshot made Python's cyclic garbage collector walk
    the whole Pyomo model again and again (with the collector paused as well, the Python work of a
    Case 1 front halved, docs/performance.md). A variable without a value is stored as nan and
    restored as None.
    """

    def __init__(self, m):
        self.m = m
        with PauseGC():
            self.vars = list(m.component_data_objects(pyo.Var, descend_into=True))
            self.values = np.array([v.value for v in self.vars], dtype=float)
            self.multipliers = {}  # suffix name -> (components, values)
            for name in _MULTIPLIER_SUFFIXES:
                suffix = m.component(name)
                if isinstance(suffix, pyo.Suffix):
                    keys = list(suffix.keys())
                    self.multipliers[name] = (keys, np.array([suffix[k] for k in keys], dtype=float))

    def extrapolated(self, previous: "Snapshot", t: float) -> "Snapshot":
        """The secant predictor ``self + t (self - previous)`` of primal values and multipliers.

        Primal values are kept within their variable bounds; a multiplier that
        would change sign keeps this snapshot's value (a multiplier's sign is
        fixed by its bound or inequality).
        """
        if len(previous.vars) != len(self.vars):
            raise ValueError("snapshots of different models")
        with PauseGC():
            out = Snapshot.__new__(Snapshot)
            out.m, out.vars = self.m, self.vars
            val, old = self.values, previous.values
            move = np.isfinite(val) & np.isfinite(old) & ~np.array([v.fixed for v in self.vars], dtype=bool)
            bounds = [v.bounds for v in self.vars]
            lb = np.array([b[0] for b in bounds], dtype=float)  # None -> nan: no bound
            ub = np.array([b[1] for b in bounds], dtype=float)
            new = val + t * (val - old)
            new = np.where(np.isnan(lb), new, np.maximum(new, lb))
            new = np.where(np.isnan(ub), new, np.minimum(new, ub))
            out.values = np.where(move, new, val)
            out.multipliers = {}
            for name, (keys, vals) in self.multipliers.items():
                before_keys, before_vals = previous.multipliers.get(name, ([], np.zeros(0)))
                position = {id(k): i for i, k in enumerate(before_keys)}
                idx = np.array([position.get(id(k), -1) for k in keys], dtype=int)
                prior = np.where(idx >= 0, before_vals[np.maximum(idx, 0)] if len(before_vals) else np.nan, np.nan)
                moved = vals + t * (vals - prior)
                keep = np.isnan(prior) | np.isnan(vals) | ~(moved * vals > 0)
                out.multipliers[name] = (keys, np.where(keep, vals, moved))
            return out

    def restore(self):
        with PauseGC():
            for v, val, fixed in zip(self.vars, self.values.tolist(), [v.fixed for v in self.vars]):
                if not fixed:
                    v.set_value(None if val != val else val, skip_validation=True)
            for name, (keys, vals) in self.multipliers.items():
                suffix = self.m.component(name)
                suffix.clear()
                for key, val in zip(keys, vals.tolist()):
                    suffix[key] = val
