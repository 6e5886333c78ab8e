"""Math back ends, so that one set of physics functions serves three callers.

The physics modules never import numpy, pyomo or casadi for arithmetic: they
receive an ``ops`` namespace with ``sin``, ``cos``, ``sqrt`` and ``exp``.

- ``NUMPY``: plain floats or numpy arrays (the simulator, the truth model).
- ``PYOMO``: Pyomo expressions (collocation equations and trim blocks).
- ``CASADI``: CasADi symbols (the RK4 simulation evaluated by casadi,
  :mod:`pyomo_heli.simulation.compiled`).

A back end may also carry ``share(name, expr)``: :func:`.model.evaluate`
passes the intermediates listed in ``model.SHARED`` through it. The
collocation blocks use it to make each of them a named Pyomo Expression
(written once to the NL file); without it they are used as they are.
"""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np

NUMPY = SimpleNamespace(name="numpy", sin=np.sin, cos=np.cos, sqrt=np.sqrt, exp=np.exp)


def _pyomo_ops() -> SimpleNamespace:
    import pyomo.environ as pyo

    return SimpleNamespace(name="pyomo", sin=pyo.sin, cos=pyo.cos, sqrt=pyo.sqrt, exp=pyo.exp)


def _casadi_ops() -> SimpleNamespace:
    import casadi as ca

    return SimpleNamespace(name="casadi", sin=ca.sin, cos=ca.cos, sqrt=ca.sqrt, exp=ca.exp)


_CACHE: dict[str, SimpleNamespace] = {"numpy": NUMPY}


def get_ops(name: str) -> SimpleNamespace:
    """Return the back end called ``name`` ('numpy', 'pyomo' or 'casadi')."""
    if name not in _CACHE:
        makers = {"pyomo": _pyomo_ops, "casadi": _casadi_ops}
        if name not in makers:
            raise ValueError(f"unknown math back end {name!r}; choose numpy, pyomo or casadi")
        _CACHE[name] = makers[name]()
    return _CACHE[name]
