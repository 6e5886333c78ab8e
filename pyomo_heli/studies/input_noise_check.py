"""Does the noise on the measured inputs move the time-domain estimate? Anchor A with the model of the truth's form.

    python studies/input_noise_check.py --seeds 20261122,20261125,20261126,20261127 --config studies/close_loop.toml \
        --out results/input_noise_check [--data-config data/bo105_synthetic.toml]

Evaluation only: it reads the generated flight tests' ``truth.json`` (the identification and the loop never do).
Every seed generates the flight test of ``--data-config`` (its truth effects kept, its seed replaced) twice, into
``OUT/data/<seed>_truth`` and ``OUT/data/<seed>_truth_no_input_noise``: as configured (sensor noise on every
channel, the control positions col and lon included), and with the inputs' sigma set to 0. The generator draws every
channel's noise whatever its sigma, so every other channel keeps exactly the same noise. On each it solves the
time-domain anchor A (min J_time) of ``--config`` (the loop's: Case 2 parameters, output error) with the **truth's
own model form**: M0 plus the truth's effects at their true geometry, the effect's strength (K_lamT for the wake on
the tail) freed from 1.0. So the form is exactly right and only the noise is left. On the first version it also
solves anchor A with the inputs' errors estimated (``[objectives] input_errors = ["col", "lon"]``, their sigma from
the config's quiet lead-in). The output-error rows have the Cramer-Rao bounds (sensitivities by simulation), the
input-error rows the inverse reduced Hessian of the NLP (observed information with the input errors eliminated).

Once, and the same for every seed, the flight test without any noise (``[sensors] noise = false``: exact samples of
the truth simulator, no filter) is solved the same way with the config's ``[data] resample_inputs`` and with
``"project"``. What error is left there is the resampling's and the discretisation's (docs/model_nlp.md 10.3).

Each finished seed is ``OUT/seed_<seed>.json``, the noise-free rows ``OUT/no_noise.json`` (a rerun reuses them; the
generated data are deleted once they are done). Written: ``OUT/summary.csv`` and ``OUT/summary.md``: per seed and
data, the solver status, the errors of the free parameters against truth and the twist's standard errors, all in %
of truth.
"""
from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path

import pandas as pd

from .seeded import cached_seed, seed_flight_test, seeded_study_main

#: the rows of every seed: anchor A on its flight test, on the same without the inputs' noise, and on the first with
#: the inputs' errors estimated
VARIANTS = ("bundled", "no_input_noise", "input_errors")
#: the strength freed with the configured parameters (initial, lower, upper, scale), per truth effect parameter
STRENGTHS = {"K_lamT": (1.0, 0.0, 5.0, 1.0)}
#: what ``--data-config`` says to switch the noise off for the noise-free rows
NOISE_ON = "noise = true"


def check_data_config(data_config: Path) -> None:
    """ValueError naming ``--data-config`` unless it has an effect whose strength this study frees and one
    ``noise = true`` line (checked before any work)."""
    from pyomo_heli.flighttest.config import load_config

    g = load_config(data_config)
    if not any(n in STRENGTHS for e in g.effects.values() for n in e):
        raise ValueError(f"--data-config {data_config}: no truth effect with a strength this study frees "
                         f"({', '.join(STRENGTHS)})")
    noise_off_text(data_config)


def noise_off_text(data_config: Path) -> str:
    """``data_config``'s text with its one ``noise = true`` line switched off; ValueError naming ``--data-config``
    without exactly one."""
    text = Path(data_config).read_text()
    if text.count(NOISE_ON) != 1:
        raise ValueError(f"--data-config {data_config}: expected one '{NOISE_ON}' line to switch the noise off")
    return text.replace(NOISE_ON, "noise = false")


def flight_test(seed: int, data_config: Path, out: Path, input_noise: bool) -> Path:
    """``OUT/data/<seed>_truth[_no_input_noise]``: ``data_config``'s flight test (truth effects kept) with ``seed``."""
    folder = out / "data" / (f"{seed}_truth" if input_noise else f"{seed}_truth_no_input_noise")
    return seed_flight_test(seed, data_config, folder, input_noise=input_noise)


def noise_free_flight_test(data_config: Path, out: Path) -> Path:
    """``OUT/data/no_noise``: ``data_config``'s flight test with ``[sensors] noise = false``."""
    from pyomo_heli.flighttest.config import load_config
    from pyomo_heli.flighttest.generate import generate

    data = out / "data" / "no_noise"
    if not (data / "truth.json").is_file():
        text = noise_off_text(data_config)
        gen = out / "data" / "no_noise.toml"
        gen.parent.mkdir(parents=True, exist_ok=True)
        gen.write_text(text)
        generate(load_config(gen), data, force=True)
        gen.unlink()
    return data


#: the standard errors of a row: the Cramer-Rao bound (sensitivities by simulation) and the inverse reduced Hessian
#: of the NLP (:mod:`pyomo_heli.uncertainty.reduced_hessian`; about 11 GB resident at full size)
STANDARD_ERRORS = ("cramer_rao", "reduced_hessian")


def anchor_a(config: Path, data: Path, resample_inputs: str | None = None, input_errors: bool = False,
             standard_errors: tuple = ()) -> dict:
    """Anchor A of ``config`` on ``data`` with the truth's model form, its strength free: status, errors and the
    ``standard_errors`` asked for (of :data:`STANDARD_ERRORS`), in % of truth. ``resample_inputs`` replaces the
    config's ``[data] resample_inputs``; ``input_errors`` estimates the errors of col and lon."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.flighttest.generate import truth_model_of
    from pyomo_heli.nlp.identification import build_problem
    from pyomo_heli.nlp.parameters import FreeParameter, free_parameter_values
    from pyomo_heli.pareto.front import ParetoSolver
    from pyomo_heli.uncertainty.front import point_standard_errors
    from pyomo_heli.uncertainty.reduced_hessian import reduced_hessian_covariance

    over = {"data": {"dataset": str(data.resolve()), **({"resample_inputs": resample_inputs} if resample_inputs
                                                           else {})}}
    if input_errors:
        over["objectives"] = {"input_errors": ["col", "lon"]}
    cfg = load_identification_config(config, overrides=over)
    truth = json.loads((data / "truth.json").read_text())
    strengths = [n for e in truth["effects"].values() for n in e if n in STRENGTHS]
    if not strengths:
        raise ValueError(f"{data / 'truth.json'}: no effect strength this study frees ({', '.join(STRENGTHS)})")
    free = list(cfg.free) + [FreeParameter(n, *STRENGTHS[n]) for n in strengths]
    cfg = dataclasses.replace(cfg, model=truth_model_of(data), free=free)
    m, ident, _ = build_problem(cfg)
    ps = ParetoSolver(m, dataclasses.replace(cfg.pareto, cold_check=False))
    a = ps.point_a()
    est = free_parameter_values(m)
    t = {n: float(truth["parameters"][n]) for n in est}

    def percent(values: dict) -> dict:
        return {n: float(100 * values[n] / abs(t[n])) for n in est}

    se = {}
    if a.success and "cramer_rao" in standard_errors:
        se["cramer_rao"] = percent(point_standard_errors(cfg, ident, est, kind="A"))
    if a.success and "reduced_hessian" in standard_errors:
        se["reduced_hessian"] = percent(reduced_hessian_covariance(m, ps.solver, 1.0 / ps.s_time)["se"])
    return {"status": a.status, "iterations": a.iterations, "J_time": a.J_time,
            "resample_inputs": cfg.resample_inputs, "input_errors": list(cfg.nlp.input_errors),
            "estimate": {n: float(v) for n, v in est.items()}, "truth": t,
            "error_percent": percent({n: est[n] - t[n] for n in est}), "se_percent": se}


def one_seed(seed: int, config: Path, data_config: Path, out: Path) -> dict:
    """The rows of one seed (read back from ``OUT/seed_<seed>.json``)."""
    done = cached_seed(out, seed)
    if done is not None:
        return done
    doc = {"seed": seed}
    data = flight_test(seed, data_config, out, input_noise=True)
    doc["bundled"] = anchor_a(config, data, standard_errors=("cramer_rao",))
    doc["input_errors"] = anchor_a(config, data, input_errors=True, standard_errors=("reduced_hessian",))
    shutil.rmtree(data, ignore_errors=True)
    data = flight_test(seed, data_config, out, input_noise=False)
    doc["no_input_noise"] = anchor_a(config, data, standard_errors=("cramer_rao",))
    shutil.rmtree(data, ignore_errors=True)
    _write(out / f"seed_{seed}.json", doc)
    return doc


def _write(f: Path, doc: dict) -> None:
    """``doc`` as JSON, whole or not at all (a kill leaves no half-written file to resume from)."""
    from pyomo_heli.ioerrors import atomic_write

    atomic_write(f, lambda fh: fh.write(json.dumps(doc, indent=1).encode()))


def noise_free(config: Path, data_config: Path, out: Path) -> dict:
    """Anchor A on the noise-free flight test with the config's input resampling and projected (read back from
    ``OUT/no_noise.json``; one solve when the config projects already)."""
    f = out / "no_noise.json"
    if f.is_file():
        try:
            return json.loads(f.read_text())
        except ValueError:
            pass  # cut short: solved again
    data = noise_free_flight_test(data_config, out)
    doc = {"config": anchor_a(config, data)}
    if doc["config"]["resample_inputs"] != "project":
        doc["project"] = anchor_a(config, data, resample_inputs="project")
    shutil.rmtree(data, ignore_errors=True)
    _write(f, doc)
    return doc


def _row(seed, data: str, r: dict) -> dict:
    se = r["se_percent"]
    return {"seed": seed, "data": data, "inputs": r["resample_inputs"],
            "input errors": ", ".join(r["input_errors"]) or "-", "status": r["status"], "J_time A": r["J_time"],
            **{f"{n} error [%]": e for n, e in r["error_percent"].items()},
            "twist SE Cramer-Rao [%]": se.get("cramer_rao", {}).get("theta_twist"),
            "twist SE reduced Hessian [%]": se.get("reduced_hessian", {}).get("theta_twist")}


def summary(docs: list[dict]) -> tuple[pd.DataFrame, str]:
    rows = [_row(d["seed"], "bundled" if v == "input_errors" else v, d[v]) for d in docs for v in VARIANTS]
    rows += [_row("-", "no_noise", d) for d in docs[0]["no_noise"].values()]
    tab = pd.DataFrame(rows)

    def span(data: str, errors: bool, col: str = "theta_twist error [%]") -> str:
        x = tab[(tab["data"] == data) & ((tab["input errors"] != "-") == errors)][col]
        return f"{x.min():+.1f} to {x.max():+.1f} %"

    free = {r["inputs"]: r["theta_twist error [%]"] for r in rows if r["data"] == "no_noise"}
    header = (f"Anchor A with the truth's model form on {len(docs)} noise realisations: the twist error spans "
              f"{span('bundled', False)} with the inputs' noise and {span('no_input_noise', False)} without it "
              f"(every other channel's noise the same); with the input errors estimated {span('bundled', True)}, "
              f"its reduced-Hessian standard error "
              f"{span('bundled', True, 'twist SE reduced Hessian [%]').replace('+', '')} (output error, "
              f"Cramer-Rao: {span('bundled', False, 'twist SE Cramer-Rao [%]').replace('+', '')}); without any noise "
              + ", ".join(f"{e:+.2f} % with the inputs by {k!r}" for k, e in free.items()) + ".")
    return tab, header


def main(argv=None) -> int:
    def with_noise_free(seed, config, data_config, out):
        doc = one_seed(seed, config, data_config, out)
        return {**doc, "no_noise": noise_free(config, data_config, out)}

    with_noise_free.__module__ = __name__
    return seeded_study_main(__doc__.split("\n\n")[0], argv, with_noise_free, summary,
                             seeds_example="20261122,20261125", check_data_config=check_data_config,
                             default_config="studies/close_loop.toml")


if __name__ == "__main__":
    sys.exit(main())
