"""Classic single-shooting output-error fit (the method the paper compares against).

An independent route to point A of the front: the same model, data, outputs
and likelihood, but the outputs come from integrating the float model with
scipy (``solve_ivp``) from the model's trim, and the parameters from
``scipy.optimize.least_squares``. R is estimated by the usual relaxation of
output-error methods: fix R, solve the weighted least-squares problem, update
R = S/N (+ the same resolution floor as the NLP), repeat. Its fixed point is
a stationary point of the concentrated likelihood J_time, so at convergence it
is the same estimate as the full-discretisation NLP.

Three integrators: ``"rk4"`` (fixed-step, 4 steps per sample interval; fast on
sampled, piecewise-linear inputs; the Python integrator of the simulator),
``"rk4-casadi"`` (the same RK4 evaluated by casadi, about 20x faster per
simulation; what a classic tool with a compiled simulator would do) and
``"solve_ivp"`` (scipy's adaptive ``solve_ivp``, the textbook classic route).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..physics.model import HelicopterModel
from ..simulation.replay import maneuver_outputs, replay
from ..simulation.trim import trim_float
from .objectives import R_FLOOR, j_time_value
from .parameters import FreeParameter


@dataclass
class ShootingResult:
    parameters: dict
    J_time: float
    R: dict
    outer_iterations: int
    function_evaluations: int
    wall_time: float
    integrator: str = "rk4"
    converged: bool = True  # False when max_simulations stopped the fit first


#: solve_ivp settings of the "solve_ivp" route: tight enough that the optimum
#: matches the collocation NLP to 1e-3 relative (the RK4 route agrees to 1e-6)
IVP_METHOD = "LSODA"
IVP_RTOL = 1e-8
IVP_ATOL = 1e-10


def simulate_outputs(model: HelicopterModel, maneuvers, outputs, integrator: str = "rk4") -> dict[str, np.ndarray]:
    """Model outputs at the samples of every maneuver, concatenated per output."""
    if integrator in ("rk4", "rk4-casadi"):
        return maneuver_outputs(model, maneuvers, outputs, substeps=4, compiled=integrator == "rk4-casadi")
    if integrator != "solve_ivp":
        raise ValueError(f"integrator must be 'rk4', 'rk4-casadi' or 'solve_ivp', got {integrator!r}")
    out = {o: [] for o in outputs}
    for mv in maneuvers:
        df = replay(model, mv, trim_float(model, mv.trim_speed), check=False, method=IVP_METHOD, rtol=IVP_RTOL,
                    atol=IVP_ATOL)
        for o in outputs:
            out[o].append(df[o].to_numpy())
    return {o: np.concatenate(v) if v else np.zeros(0) for o, v in out.items()}


def fit_single_shooting(model: HelicopterModel, maneuvers, free: list[FreeParameter], outputs,
                        max_outer: int = 30, rtol: float = 1e-10, integrator: str = "rk4",
                        max_simulations: int | None = None) -> ShootingResult:
    """Output-error fit by single shooting; parameters scaled as in the NLP.

    ``integrator``: "rk4", "rk4-casadi" or "solve_ivp" (see the module docstring).
    ``max_simulations``: stop after about this many simulations of the
    maneuver set (``converged`` is then False); None: no limit.
    """
    t0 = time.perf_counter()
    meas = {o: np.concatenate([mv.data[o].to_numpy() for mv in maneuvers]) for o in outputs}
    names = [f.name for f in free]
    scale = np.array([f.scale for f in free])
    lo = np.array([f.lower for f in free]) / scale
    hi = np.array([f.upper for f in free]) / scale
    z = np.array([f.initial for f in free]) / scale
    nfev = 0

    def residuals_of(zz):
        nonlocal nfev
        nfev += 1
        y = simulate_outputs(model.with_parameters(**dict(zip(names, zz * scale))), maneuvers, outputs, integrator)
        return {o: meas[o] - y[o] for o in outputs}

    e = residuals_of(z)
    R = {o: float(np.mean(e[o] ** 2) + R_FLOOR[o] ** 2) for o in outputs}
    k = 0
    done = False
    for k in range(1, max_outer + 1):
        w = {o: 1.0 / np.sqrt(R[o]) for o in outputs}
        budget = None if max_simulations is None else max_simulations - nfev - 1
        if budget is not None and budget < 1:
            break
        sol = least_squares(lambda zz: np.concatenate([residuals_of(zz)[o] * w[o] for o in outputs]), z,
                            bounds=(lo, hi), x_scale=1.0, xtol=1e-12, ftol=1e-12, gtol=1e-12, diff_step=1e-6,
                            max_nfev=budget)
        z_new = sol.x
        e = residuals_of(z_new)
        R_new = {o: float(np.mean(e[o] ** 2) + R_FLOOR[o] ** 2) for o in outputs}
        # converged: the inner fit ended on its own tolerances (status > 0; 0 is the evaluation budget, which
        # returns the start unchanged when it allows one evaluation), and the outer iteration stopped moving
        done = sol.status > 0 and np.max(np.abs(z_new - z)) < rtol * max(1.0, np.max(np.abs(z))) and \
            max(abs(R_new[o] / R[o] - 1) for o in outputs) < 1e-9
        z, R = z_new, R_new
        if done:
            break
    return ShootingResult(parameters=dict(zip(names, z * scale)), J_time=j_time_value(e, list(outputs)), R=R,
                          outer_iterations=k, function_evaluations=nfev, wall_time=time.perf_counter() - t0,
                          integrator=integrator, converged=bool(done))
