"""How much of the full-size loop's remaining parameter error is the wake candidate's form? (docs/close_loop.md)

    python studies/wake_form_study.py --out results/wake_form [--loop docs/results/close_loop_fixed_profile]
                                      [--variants truth_form,...] [--dataset DIR]

Evaluation only: it uses the truth simulator's own effect and reads the dataset's truth.json; the
identification and the loop never do. On the loop's config (studies/close_loop.toml: Case 2 parameters,
11 front points, inputs referred to the lead-in mean) and starting, like the loop's iteration 1, from
iteration 0's diagnosed parameters, it re-identifies the whole front with M0 plus

- ``truth_form``: the truth simulator's effect E1 itself (pyomo_heli/flighttest/truth_effects.py), its
  strength K_lamT free from 1.0, its geometry (d_t, s_w) at the truth values: what a candidate of exactly
  the right form would give on this noise realisation;
- ``free_width``: the project's candidate (pyomo_heli/diagnosis/candidates.py, tail position in the disc
  frame) with its fixed profile 2^(-xi^6) replaced by a top hat with logistic edges
  S((1 - xi)/w) S((1 + xi)/w) whose width w (wake radii, from 0.1 = the fixed profile's sharpness) is
  freed with the strength: the variant tried in this study, not adopted (see docs/close_loop.md);
- ``width_from_a``: the same soft-edged candidate with the width held at the value the time series chose
  at free_width's anchor A (identifiable there), only the strength freed, so that the trims cannot trade
  the width against CL_alpha_HT along the front (needs free_width first);

and tabulates both beside the loop's own iterations (``--loop``: iter_0 and iter_1): J_time and J_trim
at the time-domain anchor A and at the Eq. 11 point solved directly, and the errors of twist,
CL_alpha_HT and Iyy against truth at both; then, at the Eq. 11 point, the loop's own error measures
(pyomo_heli.close_loop.errors_of: pooled trim RMS, validation RMS of data minus model per output) as
changes against the loop's iteration 0. Each identification writes its points to OUT/<variant> as they
finish; a finished OUT/<variant> is tabulated without solving again. About 6 minutes per variant on one
core.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

from pyomo_heli.close_loop import errors_of, model_with_candidates
from pyomo_heli.config import load_identification_config
from pyomo_heli.dataset import load_flight_test
from pyomo_heli.diagnosis.candidates import RotorWakeOnTail
from pyomo_heli.flighttest.truth_effects import WakeOnTail
from pyomo_heli.identify import run_identification
from pyomo_heli.nlp.identification import identification_data, prepare_data
from pyomo_heli.nlp.parameters import FreeParameter
from pyomo_heli.pareto.result import IdentificationResult
from pyomo_heli.physics.model import HelicopterModel
from pyomo_heli.physics.parameters import ParameterSpec
from pyomo_heli.units import DEG

ROOT = Path(__file__).resolve().parent.parent
FREE = ("theta_twist", "CL_alpha_HT", "Iyy")


class SoftEdgedWake(RotorWakeOnTail):
    """The candidate with logistic edges of free width w_wt (wake radii) instead of 2^(-xi^6); study only."""

    name = "rotor_wake_on_tail_free_width"

    def parameters(self):
        return super().parameters() + [
            ParameterSpec("w_wt", 0.1, "-", "study: width of the wake boundary [wake radii]", "choice",
                          (0.03, 1.0), 0.1)]

    def immersion(self, ctx):
        xi, _ = RotorWakeOnTail.immersion(ctx)
        ops, w = ctx.ops, ctx.p["w_wt"]

        def edge(z):
            return 1.0 / (1.0 + ops.exp(-z))

        return xi, edge((1.0 - xi) / w) * edge((1.0 + xi) / w)
    # tail_downwash is the candidate's own: it calls self.immersion


def width_at_free_width_a(out: Path) -> dict:
    """w_wt of the free_width variant's time-domain anchor A (that variant must have run first)."""
    f = out / "free_width" / "time_domain.json"
    if not f.is_file():
        raise SystemExit(f"wake_form_study: variant width_from_a needs {f}: run the free_width variant first")
    return {"w_wt": float(json.loads(f.read_text())["parameters"]["w_wt"])}


VARIANTS = {
    # name: (effect, extra free parameters (name, initial, lower, upper, scale), fixed values from OUT or None)
    "truth_form": (WakeOnTail, [("K_lamT", 1.0, 0.0, 5.0, 1.0)], None),
    "free_width": (SoftEdgedWake, [("k_wt", 0.7, 0.0, 5.0, 1.0), ("w_wt", 0.1, 0.03, 1.0, 0.1)], None),
    # the width the time series chose at free_width's anchor A, held fixed along the whole front
    "width_from_a": (SoftEdgedWake, [("k_wt", 0.7, 0.0, 5.0, 1.0)], width_at_free_width_a),
}


def model_of(variant: str, cfg, out: Path) -> HelicopterModel:
    effect, _, fixed = VARIANTS[variant]
    model = HelicopterModel(parameters=cfg.model.parameters, extensions=(effect(),))
    return model.with_parameters(**fixed(out)) if fixed else model


def identify(variant: str, cfg, start: dict, out: Path) -> IdentificationResult:
    if (out / variant / "chosen.json").is_file():
        return IdentificationResult.load(out / variant)
    free = [dataclasses.replace(f, initial=start[f.name]) for f in cfg.free]
    free += [FreeParameter(*e) for e in VARIANTS[variant][1]]
    return run_identification(dataclasses.replace(cfg, model=model_of(variant, cfg, out), free=free), out / variant,
                              progress=lambda s: print(f"[{variant}] {s}", flush=True), uncertainty=False)


def pooled(trim_rms: dict) -> float:
    """Root mean square over the col, lon and theta trim RMS [deg] (the loop report's pooled value)."""
    return (sum(trim_rms[c] ** 2 for c in ("col", "lon", "theta")) / 3) ** 0.5 / DEG


def row(label: str, res: IdentificationResult, truth: dict) -> str:
    a, d = res.time_domain, res.direct
    cells = [label, f"{a['J_time']:.1f}", f"{d['J_time']:.1f}", f"{d['J_trim']:.5f}"]
    for n in FREE:
        for p in (a, d):
            cells.append(f"{100 * (p['parameters'][n] - truth[n]) / truth[n]:+.2f}")
    effect = {k: v for k, v in d["parameters"].items() if k not in FREE}
    cells.append(", ".join(f"{k} {v:.3g}" for k, v in effect.items()) or "-")
    return "| " + " | ".join(cells) + " |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--loop", type=Path, default=ROOT / "docs/results/close_loop_fixed_profile",
                    help="the full-size loop's results folder (loop.json, iter_0, iter_1); default: the loop run with "
                         "the candidate's fixed profile, before the shape rule")
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated: " + ", ".join(VARIANTS))
    ap.add_argument("--dataset", type=Path, default=None,
                    help="flight-test folder replacing the config's (another noise realisation, e.g. from "
                         "studies/close_loop_seeds.py); it must be the dataset the --loop folder was run on")
    args = ap.parse_args()
    unknown = [v for v in args.variants.split(",") if v not in VARIANTS]
    if unknown:
        ap.error(f"--variants: unknown {unknown}; choose from {', '.join(VARIANTS)}")
    overrides = None if args.dataset is None else {"data": {"dataset": str(args.dataset.resolve())}}
    cfg = load_identification_config(ROOT / "studies/close_loop.toml", overrides)
    loop = json.loads((args.loop / "loop.json").read_text())
    ran_on = Path(loop["dataset"]) if Path(loop["dataset"]).is_absolute() else ROOT / loop["dataset"]
    if ran_on.resolve() != Path(cfg.dataset).resolve():
        ap.error(f"--loop {args.loop} was run on {loop['dataset']}, not on {cfg.dataset}; pass --dataset")
    start = loop["iterations"][0]["parameters"]
    truth = json.loads((cfg.dataset / "truth.json").read_text())["parameters"]
    results, models = {}, {}
    for it in loop["iterations"]:
        label = f"loop iter {it['iteration']} ({' + '.join(['M0'] + it['extensions'])})"
        results[label] = IdentificationResult.load(args.loop / it["results_dir"])
        models[label] = model_with_candidates(cfg.model, it["extensions"], it.get("shape_parameters"))
    for v in args.variants.split(","):
        results[f"M0 + {v}"] = identify(v, cfg, start, args.out)
        models[f"M0 + {v}"] = model_of(v, cfg, args.out)
    print("\nErrors against truth in % (A = time-domain anchor, E = Eq. 11 solved directly); "
          f"truth: twist {truth['theta_twist'] / DEG:.4f} deg/m, CL_alpha_HT {truth['CL_alpha_HT']:.4f} 1/rad, "
          f"Iyy {truth['Iyy']:.0f} kg m^2\n")
    print("| model | J_time A | J_time E | J_trim E | twist A | twist E | CL_alpha_HT A | CL_alpha_HT E "
          "| Iyy A | Iyy E | effect at E |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for label, res in results.items():
        print(row(label, res, truth))

    ft = load_flight_test(cfg.dataset)
    id_mans = identification_data(cfg, ft).maneuvers
    val_mans = prepare_data(ft, cfg.validation, input_reference_s=cfg.input_reference_s).maneuvers
    trims = ft.trims.reset_index(drop=True)
    errs = {label: errors_of(models[label], res.direct["parameters"], id_mans, val_mans, trims, label)
            for label, res in results.items()}
    base = next(iter(errs.values()))
    outs = list(base["validation_rms"])
    print("\nAt the Eq. 11 point: pooled trim RMS [deg] and validation RMS of data minus model per output, "
          "change against the first row in %\n")
    print("| model | pooled trim [deg] | change | " + " | ".join(outs) + " |")
    print("|---|---|---|" + "---|" * len(outs))
    for label, e in errs.items():
        p0, p = pooled(base["trim_rms"]), pooled(e["trim_rms"])
        val = [f"{100 * (e['validation_rms'][o] / base['validation_rms'][o] - 1):+.1f}" for o in outs]
        print(f"| {label} | {p:.4f} | {100 * (p / p0 - 1):+.1f} % | " + " | ".join(val) + " |")


if __name__ == "__main__":
    main()
