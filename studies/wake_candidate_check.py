"""Diagnostic of the rotor_wake_on_tail candidate against the truth effect E1 (docs/close_loop.md, "Wake candidate").

    python studies/wake_candidate_check.py [--loop docs/results/close_loop_fixed_profile/loop.json] [--fit]

Evaluation only: it reads the dataset's truth.json (the identification never does). It compares

- E1 at its bundled strength and truth parameters (data/bo105_synthetic/truth.json),
- the candidate form before branch loop2 (``OldRotorWakeOnTail`` below: tail position in body axes,
  immersion 1/(1 + xi^6)) at the strength and parameters of the full-size loop's iteration 1 (``--loop``),
- the candidate of pyomo_heli.diagnosis.candidates at the same parameters,

by their trim increments over M0 (col, lon, theta vs speed), their immersion fraction, the pitch derivative
M_w at 60 and 80 kt, the sensitivity of the tail's wake coordinate to w, and the validation RMS (80 kt doublets) of the loop's iteration-1 parameters with each
form, and the effect of the input reference (first sample or lead-in mean). ``--fit`` adds a noise-free check: (twist, CL_alpha_HT, strength) of each form fitted by least squares
to E1's exact trim curves; a form that matched E1 would return the truth values (a few minutes).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from pyomo_heli.dataset import load_flight_test
from pyomo_heli.diagnosis.candidates import Candidate, make_candidate
from pyomo_heli.flighttest.truth_effects import WakeOnTail
from pyomo_heli.nlp.identification import prepare_data
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.physics.parameters import ParameterSpec
from pyomo_heli.report.identification import predict, validation_rms
from pyomo_heli.simulation.linearize import linearize_float
from pyomo_heli.simulation.trim import trim_float, trim_sweep
from pyomo_heli.units import DEG, KT

ROOT = Path(__file__).resolve().parent.parent
SPEEDS_KT = [0, 10, 20, 30, 40, 50, 60, 70, 80, 100, 120]
FREE = ("theta_twist", "CL_alpha_HT", "Iyy")


class OldRotorWakeOnTail(Candidate):
    """The candidate as it was before branch loop2, kept here for the comparison only."""

    name = "rotor_wake_on_tail_old"
    strength = "k_wt"

    def parameters(self):
        return [ParameterSpec("k_wt", 0.0, "-", "old candidate strength", "choice", (0.0, 5.0), 1.0),
                ParameterSpec("z_ht", 1.7, "m", "stabiliser depth below the hub", "choice")]

    @staticmethod
    def immersion(ctx):
        tan_chi = ctx.disc.mu_d / ctx.disc.lambda_d
        xi = (ctx.l_t + ctx.x_h - ctx.p["z_ht"] * tan_chi) / ctx.p["R"]
        return xi, 1.0 / (1.0 + xi**6)

    def tail_downwash(self, ctx):
        _, g = self.immersion(ctx)
        return ctx.p["k_wt"] * g * 2.0 * ctx.x["lambda_i"] * ctx.flow.v_tip


def models(truth: dict, it1: dict) -> dict:
    tp = {k: truth["parameters"][k] for k in FREE}
    e1 = {k: truth["parameters"][k] for k in ("K_lamT", "d_t", "s_w")}
    return {
        "E1 (truth)": (HelicopterModel(extensions=(WakeOnTail(),)).with_parameters(**tp, **e1),
                       HelicopterModel().with_parameters(**tp)),
        "old form, iter-1 params": (HelicopterModel(extensions=(OldRotorWakeOnTail(),)).with_parameters(**it1),
                                    HelicopterModel().with_parameters(**{k: it1[k] for k in FREE})),
        "new form, iter-1 params": (
            HelicopterModel(extensions=(make_candidate("rotor_wake_on_tail"),)).with_parameters(**it1),
            HelicopterModel().with_parameters(**{k: it1[k] for k in FREE})),
    }


def immersion(model: HelicopterModel, tp) -> float:
    ctx = model.evaluate(tp.state(), tp.inputs())
    if hasattr(ctx, "wake_fraction"):
        return float(ctx.wake_fraction)
    return float(model.extensions[0].immersion(ctx)[1])


def trim_table(mods: dict) -> None:
    print("## Trim increments over M0 [deg] and immersion fraction vs speed\n")
    print("| V [kt] | " + " | ".join(f"{k}: dcol, dlon, dtheta, f" for k in mods) + " |")
    print("|---|" + "---|" * len(mods))
    sweeps = {k: (trim_sweep(m, [v * KT for v in SPEEDS_KT]), trim_sweep(b, [v * KT for v in SPEEDS_KT]))
              for k, (m, b) in mods.items()}
    for i, v in enumerate(SPEEDS_KT):
        cells = []
        for k, (m, _) in mods.items():
            a, b = sweeps[k][0][i], sweeps[k][1][i]
            cells.append(f"{(a.col - b.col) / DEG:+.3f}, {(a.lon - b.lon) / DEG:+.3f}, {(a.theta - b.theta) / DEG:+.3f}, "
                         f"{immersion(m, a):.3g}")
        print(f"| {v} | " + " | ".join(cells) + " |")
    print()


def derivative_table(mods: dict) -> None:
    print("## Pitch derivative M_w [1/(m s)] with the effect and without (same parameters)\n")
    print("| model | M_w 60 kt | M0 | M_w 80 kt | M0 |")
    print("|---|---|---|---|---|")
    for k, (m, b) in mods.items():
        row = []
        for v in (60, 80):
            for mm in (m, b):
                lm = linearize_float(mm, v * KT)
                i = {s: j for j, s in enumerate(lm.states)}
                row.append(f"{lm.A[i['q'], i['w']]:+.5f}")
        print(f"| {k} | " + " | ".join(row) + " |")
    print()


def skew_sensitivity(mods: dict) -> None:
    """How fast the wake boundary sweeps past the tail when w changes: d(xi)/dw of the new form at trim."""
    m = mods["new form, iter-1 params"][0]
    cand = m.extensions[0]
    print("## Wake skew and tail position of the new form at trim; d(xi)/dw by central difference (w +- 0.5 m/s)\n")
    print("| V [kt] | tan chi | xi | d(xi)/dw [1/(m/s)] |")
    print("|---|---|---|---|")
    for v in (40, 50, 60, 80, 100):
        tp = trim_float(m, v * KT)
        x = tp.state()
        ctx = m.evaluate(x, tp.inputs())
        xi = [float(cand.immersion(m.evaluate({**x, "w": x["w"] + d}, tp.inputs()))[0]) for d in (-0.5, 0.5)]
        print(f"| {v} | {float(ctx.disc.mu_d / ctx.disc.lambda_d):.2f} | {float(cand.immersion(ctx)[0]):+.3f} | "
              f"{xi[1] - xi[0]:+.3f} |")
    print()


def validation_table(mods: dict, dataset: Path, it0: dict) -> None:
    val = list(prepare_data(load_flight_test(dataset), "validation").maneuvers)
    print("## Validation RMS, 80 kt doublets (first-sample input reference, as in the loop)\n")
    outs = ("q", "theta", "n_x", "n_z", "TAS", "beta_0")
    shown = {"q": 1 / DEG, "theta": 1 / DEG, "beta_0": 1 / DEG}
    print("| model | " + " | ".join(outs) + " |")
    print("|---|" + "---|" * len(outs))
    rows = {**{k: m for k, (m, _) in mods.items()}, "iter 0 (M0)": HelicopterModel().with_parameters(**it0)}
    for k, m in rows.items():
        r = validation_rms(predict(k, m, {}, [], val), val)["all"]
        print(f"| {k} | " + " | ".join(f"{r[o] * shown.get(o, 1.0):.4g}" for o in outs) + " |")
    print("\n(q in deg/s, theta and beta_0 in deg, n_x and n_z in g, TAS in m/s)\n")


def input_reference_table(truth: dict, dataset: Path) -> None:
    """The first-sample input reference: how much a constant input offset moves theta, and what the lead-in mean
    changes in the truth model's own validation replay."""
    from pyomo_heli.simulation.integrate import simulate

    tp = {k: truth["parameters"][k] for k in FREE}
    e1 = {k: truth["parameters"][k] for k in ("K_lamT", "d_t", "s_w")}
    tm = HelicopterModel(extensions=(WakeOnTail(),)).with_parameters(**tp, **e1)
    print("## Input reference\n")
    print("Truth model, constant input offset of 0.01 deg from trim: theta change [deg] after 1, 2, 5, 10, 15 s\n")
    print("| V [kt] | input | 1 s | 2 s | 5 s | 10 s | 15 s |")
    print("|---|---|---|---|---|---|---|")
    t = np.linspace(0.0, 15.0, 751)
    for v in (20, 80):
        tr = trim_float(tm, v * KT)
        for ch in ("lon", "col"):
            sim = simulate(tm, tr, t, {ch: lambda tt: 0.01 * DEG + 0.0 * tt}, method="rk4", substeps=2)
            d = [(float(np.interp(x, t, sim["theta"])) - tr.theta) / DEG for x in (1, 2, 5, 10, 15)]
            print(f"| {v} | {ch} | " + " | ".join(f"{x:+.3f}" for x in d) + " |")
    ft = load_flight_test(dataset)
    print("\nBundled dataset: first input sample minus the mean of the 1.9 s lead-in [deg] of each maneuver's excited"
          " channel\n")
    for mv in ft.maneuvers.values():
        ch = mv.inputs[0]
        x, tt = mv.data[ch].to_numpy(), mv.t
        print(f"- {mv.name} ({ch}): {(x[0] - x[tt <= tt[0] + 1.9].mean()) / DEG:+.4f}")
    outs = ("q", "theta", "n_x", "n_z", "TAS", "beta_0")
    shown = {"q": 1 / DEG, "theta": 1 / DEG, "beta_0": 1 / DEG}
    print("\nTruth model's validation RMS on the bundled data (80 kt doublets) by input reference\n")
    print("| input_reference_s | " + " | ".join(outs) + " |")
    print("|---|" + "---|" * len(outs))
    for ref in (0.0, 1.9):
        val = list(prepare_data(ft, "validation", input_reference_s=ref).maneuvers)
        r = validation_rms(predict("t", tm, {}, [], val), val)["all"]
        print(f"| {ref:g} | " + " | ".join(f"{r[o] * shown.get(o, 1.0):.4g}" for o in outs) + " |")
    print()


def fit_table(truth: dict) -> None:
    """Noise-free: fit (twist, CL_alpha_HT, strength) of each form to E1's exact trim curves."""
    from scipy.optimize import least_squares

    speeds = [0, 10, 15, 20, 25, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120]
    tp = {k: truth["parameters"][k] for k in FREE}
    e1 = {k: truth["parameters"][k] for k in ("K_lamT", "d_t", "s_w")}
    target = np.array([[t.col, t.lon, t.theta] for t in trim_sweep(
        HelicopterModel(extensions=(WakeOnTail(),)).with_parameters(**tp, **e1), [v * KT for v in speeds])]) / DEG
    print("## Noise-free trim fit to E1 (twist, CL_alpha_HT, strength free)\n")
    print("| form | twist error | CL_alpha_HT error | strength (shape) | pooled trim misfit [deg] | largest theta misfit [deg] at |")
    print("|---|---|---|---|---|---|")
    forms = {"M0 (no wake)": (None, []), "old form": (OldRotorWakeOnTail(), ["k_wt"]),
             "new form": (make_candidate("rotor_wake_on_tail"), ["k_wt"]),
             "new form, z_ht free": (make_candidate("rotor_wake_on_tail"), ["k_wt", "z_ht"])}
    for label, (ext, extra) in forms.items():
        base = HelicopterModel(extensions=(ext,) if ext else ())
        names = ["theta_twist", "CL_alpha_HT"] + extra

        def res(x):
            s = trim_sweep(base.with_parameters(**dict(zip(names, x))), [v * KT for v in speeds])
            return (np.array([[t.col, t.lon, t.theta] for t in s]) / DEG - target).ravel()

        x0 = [-0.03, 6.0] + [{"k_wt": 0.6, "z_ht": 1.7}[n] for n in extra]
        sol = least_squares(res, x0, x_scale=[0.05 if n == "theta_twist" else 1.0 for n in names], diff_step=1e-4)
        est = dict(zip(names, sol.x))
        r = sol.fun.reshape(-1, 3)
        pooled = float(np.sqrt((r**2).mean(axis=0).sum()))
        j = int(np.argmax(np.abs(r[:, 2])))
        print(f"| {label} | {100 * (est['theta_twist'] / tp['theta_twist'] - 1):+.2f} % | "
              f"{100 * (est['CL_alpha_HT'] / tp['CL_alpha_HT'] - 1):+.2f} % | "
              f"{est.get('k_wt', float('nan')):.3f}" + (f", z_ht {est['z_ht']:.3f} m" if "z_ht" in est else "")
              + f" | {pooled:.4f} | {r[j, 2]:+.3f} at {speeds[j]} kt |")
    print()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", default=str(ROOT / "data" / "bo105_synthetic"))
    ap.add_argument("--loop", default=str(ROOT / "docs" / "results" / "close_loop_fixed_profile" / "loop.json"),
                    help="loop.json of a full-size loop run with the old form (iteration 1 = M0 + wake)")
    ap.add_argument("--fit", action="store_true", help="add the noise-free trim fit (a few minutes)")
    a = ap.parse_args()
    truth = json.loads((Path(a.dataset) / "truth.json").read_text())
    its = json.loads(Path(a.loop).read_text())["iterations"]
    mods = models(truth, its[1]["parameters"])
    print(f"iteration-1 parameters of {a.loop}: {its[1]['parameters']}\n")
    trim_table(mods)
    derivative_table(mods)
    skew_sensitivity(mods)
    validation_table(mods, Path(a.dataset), its[0]["parameters"])
    input_reference_table(truth, Path(a.dataset))
    if a.fit:
        fit_table(truth)


if __name__ == "__main__":
    main()
