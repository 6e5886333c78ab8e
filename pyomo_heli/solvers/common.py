"""Option merging, warm-start modes and model-suffix helpers shared by the solver adapters.

:func:`resolve_options` merges the defaults, the warm-start options and the user's options in one
order for every backend; the multipliers a warm start passes live in the model suffixes ``dual``,
``ipopt_zL_out`` and ``ipopt_zU_out`` (:func:`ensure_suffix`, :func:`scale_multipliers`).
"""

from __future__ import annotations

import pyomo.environ as pyo
from pyomo.common.gc_manager import PauseGC

#: Options every backend gets unless the caller overrides them.
DEFAULT_OPTIONS = {"tol": 1e-8, "max_iter": 3000, "max_wall_time": 3600.0}

#: Options of a *full* warm start (primal + duals). Without the duals,
#: ``warm_start_init_point=yes`` is far worse than a cold start (measured),
#: so these are only used together with the multipliers.
WARM_START_OPTIONS = {
    "warm_start_init_point": "yes",
    "warm_start_bound_push": 1e-6,
    "warm_start_mult_bound_push": 1e-6,
    "mu_init": 1e-4,
}

#: ``"none"``: start from the Pyomo values as given (first solve).
#: ``"primal"``: the same mechanics, meant as a re-solve from the previous
#: solution loaded into the model.
#: ``"full"``: primal + multipliers from the model suffixes + WARM_START_OPTIONS.
#: ``"continuation"``: as ``"full"``, but the barrier restarts at ``tol / 10``
#: instead of 1e-4: the start is the solution of a neighbouring problem (the
#: previous epsilon of a front), so Ipopt only has to correct it, not follow
#: the central path down again. Measured on the identification fronts: 3-4
#: iterations per front point against 15-23 with ``"full"`` and 20-32 with
#: ``"primal"`` (docs/performance.md). The Pareto default.
WARM_START_MODES = ("none", "primal", "full", "continuation")
#: warm-start modes that pass the multipliers stored in the model suffixes
MULTIPLIER_MODES = ("full", "continuation")


def resolve_options(base: dict | None, call: dict | None, warm_start: str) -> tuple[dict, bool, set]:
    """Merge defaults < warm-start options < constructor options < call options.

    Returns ``(ipopt_options, verbose, keys_set_by_user)``; ``verbose`` is our
    own key and is removed from the Ipopt options.
    """
    if warm_start not in WARM_START_MODES:
        raise ValueError(f"warm_start must be one of {WARM_START_MODES}, got {warm_start!r}")
    user = {**(base or {}), **(call or {})}
    verbose = bool(user.pop("verbose", False))
    merged = dict(DEFAULT_OPTIONS)
    if warm_start in MULTIPLIER_MODES:
        merged.update(WARM_START_OPTIONS)
    merged.update(user)
    if warm_start == "continuation" and "mu_init" not in user:
        merged["mu_init"] = float(merged["tol"]) / 10.0
    return merged, verbose, set(user)


def scale_multipliers(model, factor: float) -> None:
    """Multiply the multipliers stored in the model suffixes by ``factor``.

    Multipliers scale with the objective: when the next solve minimises
    ``factor`` times the objective the stored multipliers belong to (a new
    objective scale, paper Fig. 4), this keeps a multiplier warm start
    consistent.
    """
    with PauseGC():  # one entry per row and bound (see CasadiIpoptSolver.rebuild)
        for name in ("dual", "ipopt_zL_out", "ipopt_zU_out"):
            suffix = model.component(name)
            if isinstance(suffix, pyo.Suffix):
                for key, value in list(suffix.items()):
                    suffix[key] = value * factor


def ensure_suffix(model, name: str, direction) -> pyo.Suffix:
    """Return ``model.<name>`` as a Suffix with the given direction, creating it if missing."""
    suffix = model.component(name)
    if suffix is None:
        suffix = pyo.Suffix(direction=direction)
        model.add_component(name, suffix)
    elif not isinstance(suffix, pyo.Suffix):
        raise TypeError(f"model.{name} exists but is not a Suffix; the solver layer needs that name")
    else:
        suffix.direction = direction
    return suffix


def _active_objective(model):
    objs = list(model.component_data_objects(pyo.Objective, active=True, descend_into=True))
    if len(objs) > 1:
        raise ValueError(f"model has {len(objs)} active objectives; exactly one is supported")
    return objs[0] if objs else None


def _bound(value, default):
    return default if value is None else float(value)
