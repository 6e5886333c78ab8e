"""Checks of the local-linear-model information on bo105_clean, printed as tables.

    PYTHONPATH=. python studies/linear_checks.py

1. NLP linearisation (symbolic) vs float finite differences: max relative entry error.
2. Data frequency responses vs the model's own in the coherent band (gain dB, phase deg).
3. J_linear alone from 30 % off: estimates of CL_alpha_HT and Iyy (theta_twist free too).
"""
import numpy as np
import pyomo.environ as pyo

from pyomo_heli.dataset import load_flight_test
from pyomo_heli.dataset.frequency_response import frequency_responses
from pyomo_heli.nlp.identification import IdentificationData, NLPOptions, build_identification_nlp, set_objective
from pyomo_heli.nlp.linear_model import matrices
from pyomo_heli.nlp.parameters import FreeParameter, free_parameter_values
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.simulation.linearize import linearize_float
from pyomo_heli.solvers import make_solver
from pyomo_heli.units import KT

model = HelicopterModel()
P = model.parameters
ft = load_flight_test("data/bo105_clean")
responses = frequency_responses(ft.identification(), speeds=[0.0, 80 * KT])

print("2. data vs model frequency response in the coherent band (bo105_clean)")
print(f"{'response':22s}{'bins':>5s}{'band [rad/s]':>16s}{'max |dB|':>10s}{'max |deg|':>10s}{'min coh':>9s}")
for r in responses:
    b = r.band()
    G = linearize_float(model, r.speed).frequency_response(r.output, r.input, b.omega)
    print(f"{r.label:22s}{len(b.omega):5d}{b.omega.min():8.2f}..{b.omega.max():5.2f}"
          f"{np.abs(20 * np.log10(np.abs(b.T / G))).max():10.2f}{np.abs(np.degrees(np.angle(b.T / G))).max():10.2f}"
          f"{b.coherence.min():9.3f}")

for names in (["CL_alpha_HT", "Iyy"], ["theta_twist", "CL_alpha_HT", "Iyy"]):
    free = [FreeParameter.from_spec(P, n, initial=P[n] * 1.3) for n in names]
    data = IdentificationData(maneuvers=[], trims=ft.trims.iloc[0:0])
    m = build_identification_nlp(data, model, free, NLPOptions(), responses=[r.band() for r in responses])
    if names == ["CL_alpha_HT", "Iyy"]:
        print("1. NLP linearisation vs finite differences (max relative entry error, floor 1e-6 of the matrix max)")
        for n in m.free_parameters:
            m.theta_s[n].setlb(P[n] / m.theta_scale[n])
            m.theta_s[n].setub(P[n] / m.theta_scale[n])
        set_objective(m, 0.0 * m.J_linear)
        make_solver(m, "casadi-ipopt", {"tol": 1e-12}).solve()
        for i, V in enumerate(m.lin_speed_values):
            M, fd = matrices(m.lin[i]), linearize_float(model, V)
            errs = {k: np.max(np.abs(M[k] - getattr(fd, k)) / np.maximum(np.abs(getattr(fd, k)),
                                                                           1e-6 * np.abs(getattr(fd, k)).max()))
                    for k in "ABCD"}
            print(f"   {V / KT:3.0f} kt: " + ", ".join(f"{k} {v:.1e}" for k, v in errs.items()))
        print(f"   J_linear at the truth: {pyo.value(m.J_linear):.4f}")
        for f in free:
            m.theta_s[f.name].setlb(f.lower / f.scale)
            m.theta_s[f.name].setub(f.upper / f.scale)
            m.theta_s[f.name].set_value(f.initial / f.scale)
    set_objective(m, m.J_linear)
    res = make_solver(m, "casadi-ipopt", {"tol": 1e-10}).solve()
    est = free_parameter_values(m)
    print(f"3. J_linear alone, free {names}: {res.status}, J_linear {pyo.value(m.J_linear):.4f}")
    for n in names:
        print(f"   {n:12s} truth {P[n]:10.5g}  start {P[n] * 1.3:10.5g}  estimate {est[n]:10.5g}  "
              f"error {100 * (est[n] / P[n] - 1):+7.2f} %")
