"""Does the noise on the measured inputs move the time-domain estimate? (docs/close_loop.md)

    python studies/input_noise_check.py --seeds 20261122 20261125 20261126 --out results/input_noise_check \
        [--variants bundled,no_input_noise,no_noise]

Evaluation only: it uses the truth simulator's own wake effect and reads truth.json; the identification and
the loop never do. For every seed it generates the flight test of ``data/bo105_synthetic.toml`` with that
seed in up to three versions that differ in one setting each:

- ``bundled``: as configured (sensor noise on every channel, the control positions col and lon at
  0.02 deg);
- ``no_input_noise``: the same with ``[sensors] sigma`` of col and lon set to 0. The generator draws every
  channel's noise whatever its sigma, so every other channel keeps exactly the same noise;
- ``no_noise``: ``[sensors] noise = false`` (no noise, no anti-alias filtering of the records);
- ``input_noise_after_lead_in`` / ``input_noise_in_lead_in``: made from the first two, the col and lon
  records of ``no_input_noise`` plus the input noise of ``bundled`` (their difference) only after, or only
  within, the quiet lead-in (t <= t0 + 1.9 s, the config's ``input_reference_s``). The first keeps the
  noise that drives the model sample by sample; the second only the error of the input reference.

On each it solves the time-domain anchor A (min J_time) of the loop's config (studies/close_loop.toml,
Case 2 parameters) with M0 plus the truth simulator's own effect E1 (its strength K_lamT free, geometry at
the truth values: the model of exactly the right form, as ``truth_form`` in studies/wake_form_study.py),
and prints the errors of twist, CL_alpha_HT and Iyy against truth, and their standard errors from the
NLP's reduced Hessian at the solution (``uncertainty/reduced_hessian.py``; "-" for results written before
that column existed). With ``--input-errors`` the same
anchor estimates the col and lon errors with the parameters (``[objectives] input_errors``, noise sigmas
from the lead-in; results get the suffix ``_eiv``). Each finished solve is written to
``OUT/<seed>_<variant>.json``; a rerun reads it instead of solving again. About 80 s per solve on one core.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "studies"))

import wake_form_study as W  # noqa: E402  (the truth-form variant is defined there)

from pyomo_heli.cli import main as cli_main  # noqa: E402
from pyomo_heli.config import load_identification_config  # noqa: E402
from pyomo_heli.identify import build_problem  # noqa: E402
from pyomo_heli.nlp.parameters import FreeParameter, free_parameter_values  # noqa: E402
from pyomo_heli.pareto.front import ParetoSolver  # noqa: E402
from pyomo_heli.uncertainty.reduced_hessian import reduced_hessian_covariance  # noqa: E402

VARIANTS = ("bundled", "no_input_noise", "no_noise", "input_noise_after_lead_in", "input_noise_in_lead_in")
#: variants made from two generated ones (the others come from the generator)
SPLIT = {"input_noise_after_lead_in": False, "input_noise_in_lead_in": True}
LEAD_IN_S = 1.9  # studies/close_loop.toml [data] input_reference_s


def split_noise(seed: int, variant: str, out: Path) -> Path:
    """Dataset of a SPLIT variant: no_input_noise's col/lon plus bundled's input noise after/in the lead-in."""
    import shutil

    import pandas as pd

    noisy, clean = out / f"data_{seed}_bundled", out / f"data_{seed}_no_input_noise"
    for d, v in ((noisy, "bundled"), (clean, "no_input_noise")):
        if not (d / "truth.json").is_file():
            assert cli_main(["generate-data", "--config", str(data_config(v, out)), "--seed", str(seed),
                             "--out", str(d)]) == 0
    dst = out / f"data_{seed}_{variant}"
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(noisy, dst)
    for f in sorted((noisy / "maneuvers").glob("*.csv")):
        a, c = pd.read_csv(f), pd.read_csv(clean / "maneuvers" / f.name)
        if not a["t_s"].equals(c["t_s"]):
            raise SystemExit(f"{f}: sample times differ from {clean}")
        in_lead = a["t_s"] <= a["t_s"].iloc[0] + LEAD_IN_S
        keep = in_lead if SPLIT[variant] else ~in_lead
        for ch in ("col_deg", "lon_deg"):
            a[ch] = c[ch] + (a[ch] - c[ch]).where(keep, 0.0)
        a.to_csv(dst / "maneuvers" / f.name, index=False, float_format="%.10g")
    return dst
FREE = ("theta_twist", "CL_alpha_HT", "Iyy")


def data_config(variant: str, out: Path) -> Path:
    """The generator config of a variant (bundled: the committed file; else a copy with one setting changed)."""
    src = ROOT / "data" / "bo105_synthetic.toml"
    if variant == "bundled":
        return src
    text = src.read_text()
    if variant == "no_input_noise":
        old = "col_deg = 0.02, lon_deg = 0.02"
        new = "col_deg = 0.0, lon_deg = 0.0"
    else:
        old, new = "noise = true", "noise = false"
    if text.count(old) != 1:
        raise SystemExit(f"{src}: expected one '{old}' to change for variant {variant}")
    path = out / f"{variant}.toml"
    path.write_text(text.replace(old, new))
    tomllib.loads(path.read_text())  # still valid TOML
    return path


def anchor_a(dataset: Path, input_errors: bool = False, overrides: dict | None = None,
             standard_errors: bool = True) -> dict:
    """Anchor A of the loop's config with the truth form on ``dataset``: its parameters and solver status.

    input_errors: estimate the col and lon measurement errors (errors in variables, noise sigmas from the
    records' lead-in; ``NLPOptions.input_errors``). overrides: config tables' fields to change, e.g.
    ``{"data": {"resample_hz": 50}}``. standard_errors: False skips the reduced Hessian (minutes).
    """
    over = {k: dict(v) for k, v in (overrides or {}).items()}
    over.setdefault("data", {})["dataset"] = str(dataset.resolve())
    cfg = load_identification_config(ROOT / "studies" / "close_loop.toml", over)
    free = list(cfg.free) + [FreeParameter(*e) for e in W.VARIANTS["truth_form"][1]]
    nlp = dataclasses.replace(cfg.nlp, input_errors=("col", "lon")) if input_errors else cfg.nlp
    cfg = dataclasses.replace(cfg, model=W.model_of("truth_form", cfg, dataset), free=free, nlp=nlp)
    m, _, _ = build_problem(cfg)
    solver = ParetoSolver(m, cfg.pareto)
    point = solver.point_a()
    out = {"status": point.status, "iterations": point.iterations, "J_time": point.J_time,
           "parameters": free_parameter_values(m)}
    if point.success and standard_errors:  # standard errors from the NLP's reduced Hessian (uncertainty/reduced_hessian.py)
        out["se"] = reduced_hessian_covariance(m, solver.solver, 1.0 / solver.s_time)["se"]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--variants", default=",".join(VARIANTS), help="comma-separated: " + ", ".join(VARIANTS))
    ap.add_argument("--input-errors", action="store_true",
                    help="estimate the input errors (errors in variables); results get the suffix _eiv")
    a = ap.parse_args()
    variants = a.variants.split(",")
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        ap.error(f"--variants: unknown {unknown}; choose from {', '.join(VARIANTS)}")
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in a.seeds:
        for v in variants:
            f = a.out / f"{seed}_{v}{'_eiv' if a.input_errors else ''}.json"
            if not f.is_file():
                data = a.out / f"data_{seed}_{v}"
                if v in SPLIT:
                    data = split_noise(seed, v, a.out)
                elif not (data / "truth.json").is_file():
                    assert cli_main(["generate-data", "--config", str(data_config(v, a.out)), "--seed", str(seed),
                                     "--out", str(data)]) == 0
                try:
                    res = anchor_a(data, a.input_errors)
                except ValueError as exc:  # e.g. input errors on records without input noise: refused
                    res = {"status": f"refused: {exc}", "parameters": None}
                res["truth"] = json.loads((data / "truth.json").read_text())["parameters"]
                f.write_text(json.dumps(res, indent=2))
            res = json.loads(f.read_text())
            p, t = res["parameters"], res["truth"]
            label = v + (" + input errors" if a.input_errors else "")
            if p is None:
                rows.append([str(seed), label, res["status"].split(":")[0], "-"] + ["-"] * (2 * len(FREE) + 1))
            else:
                se = res.get("se")  # absent in results written before the standard errors were added
                rows.append([str(seed), label, res["status"], f"{res['J_time']:.1f}"]
                            + [f"{100 * (p[n] - t[n]) / abs(t[n]):+.2f}" for n in FREE] + [f"{p['K_lamT']:.3f}"]
                            + [f"{100 * se[n] / abs(t[n]):.2f}" if se else "-" for n in FREE])
            print(" ".join(rows[-1]), flush=True)
    head = ["seed", "data", "status", "J_time A", "twist err %", "CL_alpha_HT err %", "Iyy err %", "K_lamT (truth 1.5)",
            "twist SE %", "CL_alpha_HT SE %", "Iyy SE %"]
    text = "\n".join(["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + ["| " + " | ".join(r) + " |" for r in rows])
    (a.out / f"input_noise_check{'_eiv' if a.input_errors else ''}.md").write_text(text + "\n")
    print("\n" + text)


if __name__ == "__main__":
    main()
