"""Does the noise on the measured inputs move the time-domain estimate? Anchor A with the model of the truth's form.

    python studies/input_noise_check.py --seeds 20261122,20261125,20261126,20261127 --config studies/close_loop.toml \
        --out results/input_noise_check [--data-config data/bo105_synthetic.toml]

Evaluation only: it reads the generated flight tests' ``truth.json`` (the identification and the loop never do).
Every seed generates the flight test of ``--data-config`` (its truth effects kept, its seed replaced) twice, into
``OUT/data/<seed>`` and ``OUT/data/<seed>_no_input_noise``: as configured (sensor noise on every channel, the
control positions col and lon included), and with the inputs' sigma set to 0. The generator draws every channel's
noise whatever its sigma, so every other channel keeps exactly the same noise. On each it solves the time-domain
anchor A (min J_time) of ``--config`` (the loop's: Case 2 parameters) with the **truth's own model form**: M0 plus
the truth's effects at their true geometry, the first effect parameter that is not fixed geometry (the strength,
K_lamT for the wake on the tail) freed from 1.0. So the form is exactly right and only the noise is left.

Once, and the same for every seed, the flight test without any noise (``[sensors] noise = false``: exact samples of
the truth simulator, no filter) is solved the same way twice: with the config's ``[data] resample_inputs`` and with
``"project"``. What error is left there is the resampling's and the discretisation's (docs/model_nlp.md 10.3).

Each finished seed is ``OUT/seed_<seed>.json``, the noise-free rows ``OUT/no_noise.json`` (a rerun reuses them; the
generated data are deleted once they are done).
Written: ``OUT/summary.csv`` and ``OUT/summary.md``: per seed and data, the solver status and the errors of the
free parameters against truth.
"""
from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path

import pandas as pd

from .seeded import cached_seed, seed_flight_test, seeded_study_main

#: the two versions of every seed's flight test: the input channels' noise as configured, and set to zero
VARIANTS = ("bundled", "no_input_noise")
#: the strength freed with the configured parameters (initial, lower, upper, scale), per truth effect parameter
STRENGTHS = {"K_lamT": (1.0, 0.0, 5.0, 1.0)}


def flight_test(seed: int, data_config: Path, out: Path, input_noise: bool) -> Path:
    """``OUT/data/<seed>[_no_input_noise]``: ``data_config``'s flight test (truth effects kept) with ``seed``."""
    folder = out / "data" / (str(seed) if input_noise else f"{seed}_no_input_noise")
    return seed_flight_test(seed, data_config, folder, input_noise=input_noise)


def noise_free_flight_test(data_config: Path, out: Path) -> Path:
    """``OUT/data/no_noise``: ``data_config``'s flight test with ``[sensors] noise = false``."""
    from pyomo_heli.flighttest.config import load_config
    from pyomo_heli.flighttest.generate import generate

    data = out / "data" / "no_noise"
    if not (data / "truth.json").is_file():
        text = Path(data_config).read_text()
        if text.count("noise = true") != 1:
            raise ValueError(f"--data-config {data_config}: expected one 'noise = true' line to switch the noise off")
        gen = out / "data" / "no_noise.toml"
        gen.parent.mkdir(parents=True, exist_ok=True)
        gen.write_text(text.replace("noise = true", "noise = false"))
        generate(load_config(gen), data, force=True)
        gen.unlink()
    return data


def anchor_a(config: Path, data: Path, resample_inputs: str | None = None) -> dict:
    """Anchor A of ``config`` on ``data`` with the truth's model form, its strength free: status and errors.
    ``resample_inputs`` replaces the config's ``[data] resample_inputs``."""
    from pyomo_heli.config import load_identification_config
    from pyomo_heli.flighttest.generate import truth_model_of
    from pyomo_heli.nlp.identification import build_problem
    from pyomo_heli.nlp.parameters import FreeParameter, free_parameter_values
    from pyomo_heli.pareto.front import ParetoSolver

    over = {"dataset": str(data.resolve()), **({"resample_inputs": resample_inputs} if resample_inputs else {})}
    cfg = load_identification_config(config, overrides={"data": over})
    truth = json.loads((data / "truth.json").read_text())
    strengths = [n for e in truth["effects"].values() for n in e if n in STRENGTHS]
    if not strengths:
        raise ValueError(f"{data / 'truth.json'}: no effect strength this study frees ({', '.join(STRENGTHS)})")
    model = truth_model_of(data)
    free = list(cfg.free) + [FreeParameter(n, *STRENGTHS[n]) for n in strengths]
    cfg = dataclasses.replace(cfg, model=model, free=free)
    m, _, _ = build_problem(cfg)
    a = ParetoSolver(m, dataclasses.replace(cfg.pareto, cold_check=False)).point_a()
    est = free_parameter_values(m)
    return {"status": a.status, "iterations": a.iterations, "J_time": a.J_time,
            "resample_inputs": cfg.resample_inputs,
            "estimate": {n: float(v) for n, v in est.items()},
            "truth": {n: float(truth["parameters"][n]) for n in est},
            "error_percent": {n: float(100 * (est[n] - truth["parameters"][n]) / abs(truth["parameters"][n]))
                              for n in est}}


def one_seed(seed: int, config: Path, data_config: Path, out: Path) -> dict:
    """Anchor A on both versions of one seed's flight test (read back from ``OUT/seed_<seed>.json``)."""
    done = cached_seed(out, seed)
    if done is not None:
        return done
    doc = {"seed": seed}
    for v in VARIANTS:
        data = flight_test(seed, data_config, out, input_noise=(v == "bundled"))
        doc[v] = anchor_a(config, data)
        shutil.rmtree(data, ignore_errors=True)
    (out / f"seed_{seed}.json").write_text(json.dumps(doc, indent=1))
    return doc


def noise_free(config: Path, data_config: Path, out: Path) -> dict:
    """Anchor A on the noise-free flight test with the config's input resampling and projected (read back from
    ``OUT/no_noise.json``)."""
    f = out / "no_noise.json"
    if f.is_file():
        return json.loads(f.read_text())
    data = noise_free_flight_test(data_config, out)
    doc = {"config": anchor_a(config, data), "project": anchor_a(config, data, resample_inputs="project")}
    shutil.rmtree(data, ignore_errors=True)
    f.write_text(json.dumps(doc, indent=1))
    return doc


def _row(seed, data: str, r: dict) -> dict:
    return {"seed": seed, "data": data, "inputs": r["resample_inputs"], "status": r["status"], "J_time A": r["J_time"],
            **{f"{n} error [%]": e for n, e in r["error_percent"].items()}}


def summary(docs: list[dict]) -> tuple[pd.DataFrame, str]:
    rows = [_row(d["seed"], v, d[v]) for d in docs for v in VARIANTS]
    rows += [_row("-", "no_noise", d) for d in docs[0]["no_noise"].values()]
    tab = pd.DataFrame(rows)
    span = {v: tab[tab["data"] == v]["theta_twist error [%]"] for v in VARIANTS}
    free = {r["inputs"]: r["theta_twist error [%]"] for r in rows if r["data"] == "no_noise"}
    header = (f"Anchor A with the truth's model form on {len(docs)} noise realisations: the twist error spans "
              f"{span['bundled'].min():+.1f} to {span['bundled'].max():+.1f} % with the inputs' noise and "
              f"{span['no_input_noise'].min():+.1f} to {span['no_input_noise'].max():+.1f} % without it "
              f"(every other channel's noise the same); without any noise "
              + ", ".join(f"{e:+.2f} % with the inputs by {k!r}" for k, e in free.items()) + ".")
    return tab, header


def main(argv=None) -> int:
    def with_noise_free(seed, config, data_config, out):
        doc = one_seed(seed, config, data_config, out)
        return {**doc, "no_noise": noise_free(config, data_config, out)}

    return seeded_study_main(__doc__.split("\n\n")[0], argv, with_noise_free, summary,
                             seeds_example="20261122,20261125")


if __name__ == "__main__":
    sys.exit(main())
