"""pyomo_heli: multi-objective parameter identification of nonlinear helicopter flight models.

The Python API (docs/api.md)::

    import pyomo_heli as ph
    res = ph.identify(ph.load_config("studies/case1.toml"), out="results/case1")
    print(res.estimates())

Importing the package also registers the solver ``casadi_ipopt`` (Ipopt inside casadi, no executable
needed) with Pyomo's ``SolverFactory`` (:mod:`pyomo_heli.solvers.pyomo_plugin`).
"""
from ._version import __version__

_API = ("load_config", "identify", "load_results", "Results", "load_flight_test", "write_flight_test",
        "FlightTest", "ConfigError")

__all__ = ["__version__", *_API]


def __getattr__(name):  # the API loads pandas and Pyomo models: only when first used
    if name in _API:
        from . import api

        return getattr(api, name)
    raise AttributeError(f"module 'pyomo_heli' has no attribute {name!r}")


def _register_solver() -> None:
    try:
        from .solvers.pyomo_plugin import register
    except ImportError:  # Pyomo missing: the package cannot work anyway; the import error comes where it is used
        return
    register()


_register_solver()
