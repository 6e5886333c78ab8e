"""The local-linear-model checks of docs/linear.md, sections 1-3, on a noise-free flight test of M0.

    python studies/linear_checks.py [--dataset data/bo105_clean] [--out results/linear_checks]

1. The data's frequency responses (H1 estimates in the coherent band) against the model's own, from the float
   simulator's finite-difference linearisation at each trim speed: largest gain and phase error per response.
2. The NLP's symbolic linearisation (``nlp/linear_model.py``) at its own trim blocks, parameters held at the
   truth, against those finite differences: largest relative entry error of A, B, C, D, and J_linear there.
3. J_linear alone from 30 % off: CL_alpha_HT and Iyy free, then with theta_twist free too.

The dataset must be M0 itself without noise (``bo105_clean``; another is refused): the reference is the nominal
model. Writes ``OUT/linear_checks.md`` (the three tables) and ``OUT/linear_checks.json``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the checkout: data/

#: the parameter sets J_linear alone estimates (section 3)
FREE_SETS = (("CL_alpha_HT", "Iyy"), ("theta_twist", "CL_alpha_HT", "Iyy"))
#: the start of every free parameter, relative to its nominal value
START = 1.3


def max_relative_error(E: np.ndarray, F: np.ndarray) -> float:
    """Largest |E - F| / |F| over the entries; entries below 1e-6 of F's largest are compared against that floor
    (structural zeros, round-off of the finite differences)."""
    return float(np.max(np.abs(E - F) / np.maximum(np.abs(F), 1e-6 * np.abs(F).max())))


def response_errors(model, responses) -> list[dict]:
    """Section 1: per response, the coherent bins and the largest gain [dB] and phase [deg] error against the
    float model's finite-difference frequency response."""
    from pyomo_heli.simulation.linearize import linearize_float

    rows = []
    for r in responses:
        b = r.band()
        G = linearize_float(model, r.speed).frequency_response(r.output, r.input, b.omega)
        ratio = b.T / G
        rows.append({"response": r.label, "bins": int(len(b.omega)), "band_low_rad_s": float(b.omega.min()),
                     "band_high_rad_s": float(b.omega.max()),
                     "max_gain_error_dB": float(np.abs(20 * np.log10(np.abs(ratio))).max()),
                     "max_phase_error_deg": float(np.abs(np.degrees(np.angle(ratio))).max()),
                     "min_coherence": float(b.coherence.min())})
    return rows


def j_linear_runs(model, ft, responses) -> tuple[list[dict], list[dict], float]:
    """Sections 2 and 3: the symbolic linearisation against finite differences (parameters held at the truth),
    J_linear at the truth, and J_linear alone from ``START`` times the truth for each of ``FREE_SETS``."""
    import pyomo.environ as pyo

    from pyomo_heli.nlp.identification import IdentificationData, NLPOptions, build_identification_nlp, set_objective
    from pyomo_heli.nlp.linear_model import matrices
    from pyomo_heli.nlp.parameters import FreeParameter, free_parameter_values
    from pyomo_heli.simulation.linearize import linearize_float
    from pyomo_heli.solvers import make_solver
    from pyomo_heli.units import KT

    P = model.parameters
    # one NLP with the largest set free; a set leaves the others held at the truth by their bounds
    free = [FreeParameter.from_spec(P, n, initial=P[n] * START) for n in FREE_SETS[-1]]
    data = IdentificationData(maneuvers=[], trims=ft.trims.iloc[0:0])
    m = build_identification_nlp(data, model, free, NLPOptions(), responses=[r.band() for r in responses])

    def hold(names) -> None:
        """Bounds and start: ``names`` free from ``START`` times the truth, the others held at the truth."""
        for f in free:
            at = P[f.name] / f.scale
            m.theta_s[f.name].setlb(f.lower / f.scale if f.name in names else at)
            m.theta_s[f.name].setub(f.upper / f.scale if f.name in names else at)
            m.theta_s[f.name].set_value(f.initial / f.scale if f.name in names else at)

    hold(())  # section 2: every parameter at the truth
    set_objective(m, 0.0 * m.J_linear)
    res = make_solver(m, "casadi-ipopt", {"tol": 1e-12}).solve()
    if not res.success:
        raise RuntimeError(f"the trim and linearisation blocks at the truth did not solve: {res.status}")
    lin_rows = [{"speed_kt": round(V / KT, 6), **{k: max_relative_error(matrices(m.lin[i])[k],
                                                                         getattr(linearize_float(model, V), k))
                                                   for k in "ABCD"}}
                for i, V in enumerate(m.lin_speed_values)]
    j_truth = float(pyo.value(m.J_linear))
    set_objective(m, m.J_linear)
    fits = []
    for names in FREE_SETS:
        hold(names)
        res = make_solver(m, "casadi-ipopt", {"tol": 1e-10}).solve()
        est = free_parameter_values(m)
        at_bound = [f.name for f in free if f.name in names and min(abs(est[f.name] - f.lower),
                                                                    abs(est[f.name] - f.upper))
                    <= 1e-6 * max(abs(f.lower), abs(f.upper), 1.0)]
        fits.append({"free": list(names), "status": str(res.status), "J_linear": float(pyo.value(m.J_linear)),
                     "truth": {n: float(P[n]) for n in names}, "estimate": {n: float(est[n]) for n in names},
                     "error_percent": {n: float(100 * (est[n] / P[n] - 1)) for n in names},
                     "at_bound": at_bound})
    return lin_rows, fits, j_truth


def markdown(dataset: Path, resp: list[dict], lin: list[dict], fits: list[dict], j_truth: float) -> str:
    """The three tables of docs/linear.md."""
    out = [f"# Local-linear-model checks on {dataset.name}", "",
           "Command: `python studies/linear_checks.py --dataset data/bo105_clean --out <folder>`", "",
           "## 1. Data frequency responses against the model's own (coherent band)", "",
           "| response | bins | band [rad/s] | max gain error [dB] | max phase error [deg] | min coherence |",
           "|---|---|---|---|---|---|"]
    out += [f"| {r['response']} | {r['bins']} | {r['band_low_rad_s']:.2f}..{r['band_high_rad_s']:.2f} | "
            f"{r['max_gain_error_dB']:.2f} | {r['max_phase_error_deg']:.2f} | {r['min_coherence']:.3f} |" for r in resp]
    out += ["", "## 2. NLP linearisation against central differences of the float simulator", "",
            "Largest relative entry error (entries below 1e-6 of the matrix's largest against that floor).", "",
            "| speed [kt] | A | B | C | D |", "|---|---|---|---|---|"]
    out += [f"| {r['speed_kt']:g} | " + " | ".join(f"{r[k]:.1e}" for k in "ABCD") + " |" for r in lin]
    out += ["", f"J_linear at the truth: {j_truth:.4f}", "",
            f"## 3. J_linear alone, started {100 * (START - 1):.0f} % off", "",
            "| free | status | J_linear | " + " | ".join(f"{n} error [%]" for n in FREE_SETS[-1]) + " | at a bound |",
            "|---|---|---|" + "---|" * len(FREE_SETS[-1]) + "---|"]
    for f in fits:
        cells = [f"{f['error_percent'][n]:+.2f}" if n in f["error_percent"] else "fixed" for n in FREE_SETS[-1]]
        out.append(f"| {', '.join(f['free'])} | {f['status']} | {f['J_linear']:.4f} | " + " | ".join(cells)
                   + f" | {', '.join(f['at_bound']) or '-'} |")
    return "\n".join(out) + "\n"


def not_m0_itself(dataset: Path) -> str | None:
    """Why ``dataset`` is not M0 itself without noise (its ``truth.json``: effects, noise, parameters off the
    nominal table), None when it is."""
    from pyomo_heli.physics.model import HelicopterModel

    f = dataset / "truth.json"
    if not f.is_file():
        return "no truth.json (measured data)"
    truth = json.loads(f.read_text())
    if truth.get("effects"):
        return f"its truth has effects ({', '.join(truth['effects'])})"
    if truth.get("noise", True):
        return "its records have noise"
    nominal = HelicopterModel().parameters.to_dict()
    off = [n for n, v in truth.get("parameters", {}).items() if n in nominal
           and not np.isclose(v, nominal[n], rtol=1e-12, atol=0.0)]
    return f"its truth's parameters differ from the nominal ones ({', '.join(off)})" if off else None


def main(argv=None) -> int:
    from pyomo_heli.studies.args import flight_test_folder, out_folder

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", type=Path, default=ROOT / "data" / "bo105_clean",
                    help="a flight-test folder of M0 without noise (default data/bo105_clean)")
    ap.add_argument("--out", default="results/linear_checks")
    a = ap.parse_args(argv)
    out = out_folder(ap, a.out)
    flight_test_folder(ap, a.dataset, "--dataset")
    problem = not_m0_itself(a.dataset)
    if problem:
        ap.error(f"--dataset {a.dataset}: {problem}; the checks' reference is the nominal model (data/bo105_clean)")

    from pyomo_heli.dataset import load_flight_test
    from pyomo_heli.dataset.frequency_response import frequency_responses
    from pyomo_heli.physics.model import HelicopterModel
    from pyomo_heli.units import KT

    model = HelicopterModel()
    ft = load_flight_test(a.dataset)
    responses = frequency_responses(ft.identification(), speeds=[0.0, 80 * KT])
    resp = response_errors(model, responses)
    lin, fits, j_truth = j_linear_runs(model, ft, responses)
    out.mkdir(parents=True, exist_ok=True)
    text = markdown(a.dataset, resp, lin, fits, j_truth)
    (out / "linear_checks.md").write_text(text)
    (out / "linear_checks.json").write_text(json.dumps(
        {"dataset": str(a.dataset.name), "responses": resp, "linearisation": lin, "J_linear_truth": j_truth,
         "J_linear_alone": fits}, indent=1))
    print(text)
    return 0
