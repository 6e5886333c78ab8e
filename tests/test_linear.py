"""Local linear models: NLP linearisation vs finite differences, poles, data frequency responses."""
import numpy as np
import pyomo.environ as pyo
import pytest

from pyomo_heli.nlp.linear_model import build_linearization, matrices
from pyomo_heli.nlp.parameters import FreeParameter, add_parameters
from pyomo_heli.nlp.trim_block import build_trim_block
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.linearize import linearize_float
from pyomo_heli.simulation.trim import trim_float
from pyomo_heli.solvers import make_solver
from pyomo_heli.units import KT

#: docs/model.md section 15 (pyomo-heli linearize --speeds-kt 0 80)
DOC_POLES = {0.0: [-3.7736, -3.7470, -0.2580, 0.0220 - 0.4056j, 0.0220 + 0.4056j],
             80.0: [-5.8486, -3.6994, -0.7155, 0.0099 - 0.2918j, 0.0099 + 0.2918j]}


def _sorted(z):
    z = np.asarray(z, complex)
    return z[np.lexsort((z.imag, z.real))]


@pytest.fixture(scope="module")
def nlp_linearizations():
    """Trim blocks + linearisation blocks at hover and 80 kt, solved (parameters free but fixed at nominal)."""
    model = HelicopterModel()
    m = pyo.ConcreteModel()
    free = [FreeParameter.from_spec(model.parameters, n) for n in ("theta_twist", "CL_alpha_HT", "Iyy")]
    pmap = add_parameters(m, model.parameters, free)
    speeds = [0.0, 80.0]
    m.trim = pyo.Block(range(2))
    m.lin = pyo.Block(range(2))
    for i, v in enumerate(speeds):
        tp = trim_float(model, v * KT)
        build_trim_block(m.trim[i], model, pmap, v * KT, guess=tp.to_dict())
        build_linearization(m.lin[i], model, pmap, m.trim[i])
    for n in m.free_parameters:
        m.theta_s[n].fix()
    m.obj = pyo.Objective(expr=0.0)
    res = make_solver(m, "casadi-ipopt", {"tol": 1e-12}).solve()
    assert res.success, res.status
    return model, {v: matrices(m.lin[i]) for i, v in enumerate(speeds)}


@pytest.mark.parametrize("speed_kt", [0.0, 80.0])
def test_nlp_linearization_matches_finite_differences(nlp_linearizations, speed_kt):
    """Symbolic A, B, C, D of the NLP equal central differences of the float simulator to 1e-5 relative.

    Relative per entry; entries below 1e-6 of their matrix's largest entry (structural zeros,
    round-off of the finite differences) are compared absolutely at 1e-5 * 1e-6 of that maximum.
    """
    model, mats = nlp_linearizations
    fd = linearize_float(model, speed_kt * KT)
    for k in "ABCD":
        E, F = mats[speed_kt][k], getattr(fd, k)
        floor = 1e-6 * np.abs(F).max()
        rel = np.abs(E - F) / np.maximum(np.abs(F), floor)
        assert rel.max() < 1e-5, (k, rel.max())


@pytest.mark.parametrize("speed_kt", [0.0, 80.0])
def test_poles_match_docs(nlp_linearizations, speed_kt):
    _, mats = nlp_linearizations
    poles = _sorted(np.linalg.eigvals(mats[speed_kt]["A"]))
    np.testing.assert_allclose(poles, _sorted(DOC_POLES[speed_kt]), atol=6e-5)
