"""validate_solver_options: bad ``[solver] options`` are refused in one line before any solve.

The audit cases: with casadi-ipopt ``tol = nan`` hung, ``linear_solver = "ma97"``
segfaulted, unknown/out-of-range/mistyped options printed raw Ipopt text and
``max_iter = 2.5`` was silently accepted; with pounce every bad option became
a per-point failure. No test solves anything; none is timed.
"""

from __future__ import annotations

import glob
import math
import os
import re

import pytest

try:
    import tomllib
except ModuleNotFoundError:  # Python < 3.11
    import tomli as tomllib

from pyomo_heli.solvers import SOLVER_NAMES, validate_solver_options
from pyomo_heli.solvers.options import _ipopt, _pounce_executable

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

needs_ipopt = pytest.mark.skipif(_ipopt() is None, reason="casadi's Ipopt library not loadable")
needs_pounce = pytest.mark.skipif(_pounce_executable() is None, reason="pounce not installed")

#: (options, option the message must name, another word it must contain)
AUDIT_CASES = [
    ({"tol": math.nan}, "tol", "finite"),
    ({"tol": math.inf}, "tol", "finite"),
    ({"linear_solver": "ma97"}, "linear_solver", "ma97"),
    ({"max_iter": "many"}, "max_iter", "integer"),
    ({"bogus_option": 3}, "bogus_option", "unknown"),
    ({"tol": -1}, "tol", "range"),
    ({"max_iter": -5}, "max_iter", "range"),
    ({"print_level": 99}, "print_level", "range"),
    ({"max_iter": 2.5}, "max_iter", "integer"),
    ({"max_iter": 0}, "max_iter", "at least 1 iteration"),  # Ipopt takes it: no step, every solve "stopped"
]


def _refusal(name, options) -> str:
    with pytest.raises(ValueError) as info:
        validate_solver_options(name, options)
    msg = str(info.value)
    assert "\n" not in msg, msg
    return msg


@needs_ipopt
@pytest.mark.parametrize("options, key, word", AUDIT_CASES, ids=lambda c: repr(c) if isinstance(c, dict) else "")
def test_casadi_ipopt_refuses_audit_cases(options, key, word, capfd):
    msg = _refusal("casadi-ipopt", {"tol": 1e-8, **options})
    assert f"'{key}'" in msg and word in msg, msg
    out, err = capfd.readouterr()
    assert out == "" and err == "", (out, err)  # Ipopt's own complaint must not reach the terminal


@needs_ipopt
def test_casadi_ipopt_messages():
    assert _refusal("casadi-ipopt", {"max_iter": 2.5}) == "option 'max_iter' must be an integer, got 2.5"
    assert _refusal("casadi-ipopt", {"bogus_option": 3}) == "unknown Ipopt option 'bogus_option'"
    msg = _refusal("casadi-ipopt", {"linear_solver": "ma97"})
    assert msg.startswith("option 'linear_solver' = 'ma97' is not available in this Ipopt build; available: ")
    assert "mumps" in msg.split("available: ")[1]
    assert "not available in this Ipopt build" in _refusal("casadi-ipopt", {"linear_solver": "foo"})
    assert "0 <= print_level <= 12" in _refusal("casadi-ipopt", {"print_level": 99})
    assert "monotone, adaptive" in _refusal("casadi-ipopt", {"mu_strategy": "fast"})
    assert "must be a string" in _refusal("casadi-ipopt", {"mu_strategy": 3})
    assert "\"yes\"/\"no\"" in _refusal("casadi-ipopt", {"warm_start_init_point": True})
    assert "list" in _refusal("casadi-ipopt", {"tol": [1e-8]})


@needs_ipopt
def test_casadi_ipopt_accepts_what_casadi_converts():
    # casadi converts numbers to the registered type: an int for a real option, an integral float
    # for an integer one; option names and strings are case-insensitive in Ipopt
    validate_solver_options("casadi-ipopt", {"obj_scaling_factor": 1, "max_wall_time": 600, "max_iter": 1000.0})
    validate_solver_options("casadi-ipopt", {"linear_solver": "MUMPS", "mu_strategy": "adaptive"})
    validate_solver_options("casadi-ipopt", {"hessian_approximation": "limited-memory", "acceptable_tol": 1e-6})


@needs_ipopt
def test_casadi_ipopt_accepts_the_options_the_package_uses(capfd):
    from pyomo_heli.pareto.front import FRONT_STEP_OPTIONS, LEAVE_ANCHOR_OPTIONS
    from pyomo_heli.solvers.casadi_ipopt import DEFAULT_OPTIONS, WARM_START_OPTIONS

    # what CasadiIpoptSolver._solver_for adds (the AR output model's ipopt_defaults included), plus our own keys
    adapter = {"linear_solver": "mumps", "mumps_permuting_scaling": 0, "mumps_pivot_order": 6, "mumps_pivtol": 1e-4,
               "print_level": 0, "sb": "yes", "point_rows": False, "verbose": True}
    for opts in (DEFAULT_OPTIONS, WARM_START_OPTIONS, FRONT_STEP_OPTIONS, LEAVE_ANCHOR_OPTIONS, adapter):
        validate_solver_options("casadi-ipopt", dict(opts))
    assert capfd.readouterr() == ("", "")


@needs_pounce
@pytest.mark.parametrize("options, key, word", AUDIT_CASES, ids=lambda c: repr(c) if isinstance(c, dict) else "")
def test_pounce_refuses_audit_cases(options, key, word, capfd):
    msg = _refusal("pounce", {"tol": 1e-8, **options})
    assert f"'{key}'" in msg and word in msg, msg
    assert capfd.readouterr() == ("", "")


@needs_pounce
def test_pounce_messages_and_accepted():
    assert _refusal("pounce", {"bogus_option": 3}) == "unknown pounce option 'bogus_option'"
    assert "feral" in _refusal("pounce", {"linear_solver": "mumps"})
    assert "must be a string" in _refusal("pounce", {"mu_strategy": 3})
    # the option AmplSolver adds for pounce, and our own key
    validate_solver_options("pounce", {"solver_selection": "nlp", "print_level": 5, "verbose": False})


def test_ipopt_executable_types_only():
    # no executable to ask: the values that would reach it as text must at least be finite scalars
    assert "finite" in _refusal("ipopt", {"tol": math.nan})
    assert "finite" in _refusal("ipopt", {"max_wall_time": -math.inf})
    assert "number or a string" in _refusal("ipopt", {"max_iter": {"a": 1}})
    assert "true" in _refusal("ipopt", {"sb": True})
    validate_solver_options("ipopt", {"tol": 1e-8, "max_iter": 1000, "mu_strategy": "adaptive"})


def test_adapter_keys_and_names():
    validate_solver_options("casadi-ipopt", {"point_rows": False, "verbose": True})
    assert "true or false" in _refusal("casadi-ipopt", {"verbose": "yes"})
    assert "casadi-ipopt only" in _refusal("pounce", {"point_rows": False})
    assert "unknown solver" in _refusal("knitro", {})
    for name in SOLVER_NAMES:
        validate_solver_options(name, {})


def _committed_configs():
    """The test configs by default; the study configs of the checkout (studies/*.toml) with --runslow."""
    studies = sorted(glob.glob(os.path.join(ROOT, "studies", "*.toml")))
    paths = sorted(glob.glob(os.path.join(ROOT, "tests", "configs", "*.toml"))) + studies
    out = []
    for path in paths:
        with open(path, "rb") as fh:
            text = fh.read().decode()
        solver = tomllib.loads(text).get("solver", {})
        # a config whose [solver] name comment offers pounce ("# or pounce, ipopt") must suit it too
        offers_pounce = re.search(r"(?m)^name\s*=\s*\"casadi-ipopt\"\s*#.*\bpounce\b", text) is not None
        out.append(pytest.param(solver.get("name", "casadi-ipopt"), dict(solver.get("options", {})), offers_pounce,
                                id=os.path.relpath(path, ROOT), marks=[pytest.mark.slow] if path in studies else []))
    return out


@pytest.mark.parametrize("name, options, offers_pounce", _committed_configs())
def test_committed_configs_pass(name, options, offers_pounce):
    validate_solver_options(name, options)
    if offers_pounce:
        validate_solver_options("pounce", options)
