"""The command line shared by the Monte Carlo level studies on the bundled records (validation_test_level,
record_bias_level, input_path_level): seeds, the loop config and the generator config, one JSON per seed in OUT, a
summary."""
from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Callable

from pyomo_heli.channels import INPUTS
from pyomo_heli.config import ConfigError, load_identification_config
from pyomo_heli.flighttest.config import load_config
from pyomo_heli.flighttest.generate import generate
from pyomo_heli.report.identification import markdown_table

from .args import claim_inputs, in_file, out_folder
from .score_test_level import seeds_of

ROOT = Path(__file__).resolve().parents[2]


def seeded_study_main(description: str, argv, one_seed: Callable[..., dict],
                      summarise: Callable[[list], tuple], seeds_example: str = "20261122-20261147",
                      check_config: Callable | None = None, data_overrides: bool = False,
                      input_path_family: bool = False, check_data_config: Callable | None = None,
                      default_config: str = "studies/held_out_discovery.toml") -> int:
    """Parse ``--seeds --config --data-config --out`` (both configs checked before any work), run ``one_seed(seed,
    config, data_config, out)`` for every seed (printing each as it ends); ``summarise(docs)`` gives the summary
    table and the sentence above it: ``OUT/summary.csv``, ``OUT/summary.md``, printed. ``OUT/data`` is removed when
    the seeds left it empty (another run into the same OUT may still be using it). ``check_config(cfg)``: what the
    study needs of the loop config, a ValueError naming ``--config`` otherwise. ``data_overrides``: the study also
    takes ``--resample-inputs`` and ``--replay`` (replace the config's ``[data] resample_inputs`` and ``[diagnosis]
    replay``; with ``input_path_family`` also ``--input-path-family``, its ``[diagnosis] input_path_family``) and
    passes ``one_seed`` the config's overrides as a fifth argument (a dict, empty without them).
    ``check_data_config(path)``: what the study needs of the generator config, a ValueError naming
    ``--data-config`` otherwise. ``default_config``: ``--config``'s default, relative to the checkout. OUT records
    the study (``one_seed``'s module) with the inputs: another study's OUT is refused."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--seeds", required=True, help=f"e.g. {seeds_example}")
    ap.add_argument("--config", default=str(ROOT / default_config))
    ap.add_argument("--data-config", default=str(ROOT / "data" / "bo105_synthetic.toml"))
    ap.add_argument("--out", required=True)
    if data_overrides:
        from ..nlp.identification import RESAMPLE_INPUTS

        ap.add_argument("--resample-inputs", choices=RESAMPLE_INPUTS,
                        help="[data] resample_inputs of the config replaced: the inputs picked like the outputs, "
                             "projected, or every recorded sample (default: the config's)")
        ap.add_argument("--replay", choices=("fit", "record"),
                        help="[diagnosis] replay of the config replaced: the residuals against the replay of the "
                             "inputs as the NLP takes them or as recorded (default: the config's)")
    if data_overrides and input_path_family:
        ap.add_argument("--input-path-family", choices=("standard", "extended"),
                        help="[diagnosis] input_path_family of the config replaced: the input path's dictionary, "
                             "extended with each input's free play and dead zone (default: the config's)")
    a = ap.parse_args(argv)
    overrides = {}
    if data_overrides and a.resample_inputs:
        overrides["data"] = {"resample_inputs": a.resample_inputs}
    if data_overrides and a.replay:
        overrides["diagnosis"] = {"replay": a.replay}
    if getattr(a, "input_path_family", None):
        overrides.setdefault("diagnosis", {})["input_path_family"] = a.input_path_family
    try:
        seeds = seeds_of(a.seeds)
    except ValueError as exc:
        ap.error(f"--seeds: {exc}")
    config, data_config = in_file(ap, a.config, "--config"), in_file(ap, a.data_config, "--data-config")
    try:
        load_config(data_config)
        cfg = load_identification_config(config, overrides=overrides)
    except ConfigError as exc:
        ap.error(str(exc))
    for check, arg in ((check_config, cfg), (check_data_config, data_config)):
        if check:
            try:
                check(arg)
            except ValueError as exc:  # only the study's own check: a ValueError from loading is no usage error
                ap.error(str(exc))
    out = out_folder(ap, a.out)
    # the seeds and OUT/data are kept for a rerun: refused when made from other configs
    claim_inputs(ap, out, study=one_seed.__module__, config=config, data_config=data_config)
    docs = []
    for s in seeds:
        args = (s, config.resolve(), data_config.resolve(), out) + ((overrides,) if data_overrides else ())
        docs.append(one_seed(*args))
        print(f"seed {s} done", flush=True)
    try:
        (out / "data").rmdir()
    except OSError:
        pass
    tab, header = summarise(docs)
    tab.to_csv(out / "summary.csv", index=False)
    (out / "summary.md").write_text(header + "\n\n" + markdown_table(tab, digits=3) + "\n")
    print(tab.to_string(index=False))
    return 0


def cached_seed(out: Path, seed: int, overrides: dict | None = None) -> dict | None:
    """A finished seed's ``OUT/seed_<seed>.json``; None when it is missing, was cut short by a kill, or was made with
    other config ``overrides`` than these (its ``overrides`` key; none when absent)."""
    f = out / f"seed_{seed}.json"
    if f.is_file():
        try:
            doc = json.loads(f.read_text())
        except ValueError:
            return None
        return doc if doc.get("overrides", {}) == (overrides or {}) else None
    return None


def seed_flight_test(seed: int, data_config: Path, data: Path, input_noise: bool = True,
                     truth_effects: bool = True) -> Path:
    """``data``: the flight test of ``data_config`` with its seed replaced; kept if it is already there.
    ``input_noise=False``: the recorded inputs without their noise, every other draw (outputs, trims) unchanged (the
    generator draws every channel's noise whatever its sigma). ``truth_effects=False``: M0 with sensor noise only."""
    if not (data / "truth.json").is_file():
        g = load_config(data_config)
        if not input_noise:
            sigma = {k: 0.0 if k in INPUTS else v for k, v in g.sensors.sigma.items()}
            g = dataclasses.replace(g, sensors=dataclasses.replace(g.sensors, sigma=sigma))
        generate(dataclasses.replace(g, seed=seed, **({} if truth_effects else {"effects": {}})), data, force=True)
    return data


def m0_noise_data(seed: int, data_config: Path, out: Path, input_noise: bool = True) -> Path:
    """``OUT/data/<seed>``: :func:`seed_flight_test` from M0 with sensor noise only (``data_config``'s truth effects
    removed)."""
    return seed_flight_test(seed, data_config, out / "data" / str(seed), input_noise, truth_effects=False)


def truth_residuals(seed: int, config: Path, data_config: Path, out: Path, overrides: dict | None = None):
    """The residuals (:func:`pyomo_heli.diagnosis.residuals.compute_residuals`) of the exact model at its true
    parameters on :func:`m0_noise_data`'s flight test, every identification and validation record as ``config``
    (with ``overrides``, e.g. ``{"data": {"resample_inputs": "sample"}}``) prepares them; their innovations carry
    the record biases and the input path. Returns (residuals, data folder)."""
    from pyomo_heli.diagnosis.residuals import compute_residuals
    from pyomo_heli.flighttest.generate import truth_model_of

    data = m0_noise_data(seed, data_config, out)
    over = dict(overrides or {})
    over["data"] = {**over.get("data", {}), "dataset": str(data)}
    cfg = load_identification_config(config, overrides=over)
    model = truth_model_of(data)
    return compute_residuals(dataclasses.replace(cfg, model=model), model.parameters.to_dict(), label="truth",
                             input_offsets=False, trim_sensitivities=False), data


def overrides_note(docs: list) -> str:
    """The summary's words for the config overrides the seeds were made with ("" without any)."""
    o = docs[0].get("overrides") or {}
    ri, rp = o.get("data", {}).get("resample_inputs"), o.get("diagnosis", {}).get("replay")
    fam = o.get("diagnosis", {}).get("input_path_family")
    return ((f"; inputs resampled by {ri!r} (--resample-inputs)" if ri else "")
            + (f"; residuals against the replay {rp!r} (--replay)" if rp else "")
            + (f"; the input path's {fam} dictionary (--input-path-family)" if fam else ""))


def needs_innovations(test: str) -> Callable:
    """A ``check_config`` for :func:`seeded_study_main`: ``test`` (a residual test on the innovations, e.g. "the
    record-bias test") needs the config's input-noise model."""
    def check(cfg) -> None:
        if not cfg.diagnosis_settings.input_noise:
            raise ValueError(f"--config {cfg.path}: {test} needs the residuals' innovations; set "
                             f"[objectives] input_errors or [diagnosis] input_noise")
    return check
