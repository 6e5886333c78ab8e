"""Test an effect of one's own against a finished closed loop: "is the missing effect this?"

The loop (:mod:`.close_loop`) names physics only from its library. When it reports a residual "not explained by
any library effect; discovered dM = c ...", the engineer writes the effect they suspect as an extension
(:mod:`pyomo_heli.physics.extensions`, its strength with bounds) and asks whether the data name it:

    from pyomo_heli.workflows.check_effect import check_effect
    r = check_effect("results/loop", MyMixing(), iteration=0)     # at iteration 0's model
    print(r["significant"], r["term"]["estimate"], r["encompassing"]["encompasses"])

or ``pyomo-heli check-effect results/loop --effect my_effects.py:MyMixing``. The term is tested at that
iteration's model and estimate exactly as a step tests a library term
(:func:`pyomo_heli.diagnosis.discovery.check_term`): significant at the step's level (alpha over the library),
and, against the generic term the step discovered or described, the encompassing test both ways: it explains
the data as well as that term does when the term adds nothing once it is in.
"""
from __future__ import annotations

import json
from pathlib import Path

from ..config import IdentificationConfig, config_of_result, load_identification_config
from ..dataset import load_flight_test
from ..diagnosis.discovery import check_term, library
from ..diagnosis.residuals import find_config
from ..log import info
from ..nlp.identification import identification_data
from ..pareto.result import IdentificationResult
from ..provenance import ResultsMismatchError, check_results_match, dataset_sha256
from ..report.loop import final_index, load_loop
from .close_loop import loop_settings, score_test_inputs


def loop_dataset(loop_dir, doc: dict, config) -> Path:
    """The flight test the loop in ``loop_dir`` ran on (``doc``: its ``loop.json``; ``config``: the loop's config
    file). A loop folder made on another machine (a committed one) names a path that is not here: then the
    config's own flight test, when its content is the one the loop's first identification records.
    ResultsMismatchError (one line, naming the path) otherwise."""
    loop_dir = Path(loop_dir)
    dataset = Path(doc["dataset"])
    if dataset.is_dir():
        return dataset
    own = Path(load_identification_config(config).dataset)
    chosen = loop_dir / doc["iterations"][0]["results_dir"] / "chosen.json"
    recorded = json.loads(chosen.read_text()).get("info", {}).get("dataset_sha256") if chosen.is_file() else None
    if own.is_dir() and recorded and dataset_sha256(own) == recorded:
        return own
    why = ("has other content than the loop's" if recorded and own.is_dir() else
           "is not there either" if recorded else "cannot stand in for it: the loop's results record no content")
    raise ResultsMismatchError(f"{loop_dir / 'loop.json'} names the dataset {dataset}, which is not there, and the "
                               f"config's own ({own}) {why}; regenerate it (pyomo-heli generate-data --config "
                               "data/bo105_synthetic.toml --seed N --out ...)")


def loop_iteration(loop_dir, iteration: int | None = None, config=None) -> tuple[dict, dict, IdentificationConfig]:
    """A finished loop's ``loop.json``, the record of iteration ``iteration`` (default: the model the loop kept) and
    that iteration's config: ``config`` (else the one its ``chosen.json`` names) on the loop's dataset (the config's
    own when the loop's path is not on this machine and the results record the content it must have), plus the
    effects the loop had added, checked against the iteration's results folder. ValueError for an iteration the
    loop did not run."""
    loop_dir = Path(loop_dir)
    doc = load_loop(loop_dir)
    its = doc["iterations"]
    if iteration is None:
        it = its[final_index(doc)]
    else:
        it = next((r for r in its if r["iteration"] == iteration), None)
        if it is None:
            ran = ", ".join(str(r["iteration"]) for r in its)
            raise ValueError(f"{loop_dir}: no iteration {iteration} (the loop ran iterations {ran})")
    folder = loop_dir / it["results_dir"]
    res = IdentificationResult.load(folder)
    config = config or find_config(folder, res)
    cfg = load_identification_config(config, overrides={"data": {"dataset": str(loop_dataset(loop_dir, doc, config))}})
    if res.info.get("extensions"):
        cfg = config_of_result(cfg, res)
    check_results_match(cfg, res, folder)
    return doc, it, cfg


def check_effect(loop_dir, term, iteration: int | None = None, config=None, against: str | None = "auto",
                 progress=info) -> dict:
    """Test ``term`` (an extension object, or a library name) at iteration ``iteration`` of the finished loop in
    ``loop_dir`` (default: the model the loop kept).

    ``config``: the loop's config (default: the one the iteration's ``chosen.json`` names, found as ``diagnose``
    finds it), with the dataset ``loop.json`` names;
    the iteration's effects are added and the whole checked against its results folder. ``against``: a generic
    term's name for the encompassing test, "auto" for the one the step at that iteration discovered or described
    (none if it ran no discovery), None for no encompassing test. The level is the one the step used (alpha over
    the library it scored), else alpha over the library at that model. Returns
    :func:`~pyomo_heli.diagnosis.discovery.check_term`'s dict plus ``iteration``."""
    doc, it, cfg = loop_iteration(loop_dir, iteration, config)
    settings = loop_settings(cfg)
    model = cfg.model.with_parameters(**it["parameters"])
    name = term if isinstance(term, str) else term.name
    if name in {e.name for e in model.extensions}:
        raise ValueError(f"{name!r} is in the model of iteration {it['iteration']} already; test it at an earlier "
                         f"iteration (--iteration)")
    step = it.get("discovery") or {}
    if against == "auto":
        against = (step.get("discovered") or step.get("best_generic") or {}).get("name")
    if against is not None and against in {e.name for e in model.extensions}:
        raise ValueError(f"against = {against!r}: that term is in the model of iteration {it['iteration']} already")
    level = step.get("level") or settings.alpha / len(library(model, settings.candidates or None,
                                                               settings.generic or None))
    out = check_term(cfg, model, it["parameters"], identification_data(cfg, load_flight_test(cfg.dataset)), term,
                     level=level, against=against, alpha=settings.alpha, robust=settings.robust,
                     score_kw=score_test_inputs(cfg, settings), progress=progress)
    return {"iteration": it["iteration"], **out}
