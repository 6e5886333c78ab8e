"""The trim-loop config (``pyomo-heli trim-loop``; e.g. studies/bo105_flight_trims.toml).

The rules that look at the model (parameter names, the pitch-attitude datum, default bounds) and at the
dataset folder are the loader's (:func:`pyomo_heli.workflows.trim_loop.load_trim_loop_config`).
"""
from __future__ import annotations

from typing import Optional

from pydantic import Field

from .base import Table
from .common import Finite, ParameterTable, ParameterValues, SolverTable
from .identification import ALPHA, CONFOUND_CORR, GENERIC_MESSAGES, RATIO, GenericFamily, GenericTerms


class TrimDataTable(Table):
    """``[data]``: the flight test (trim points) and the held-out points."""

    messages = {"holdout_every": "field 'holdout_every' must be 0 (hold nothing out) or an integer >= 2, got {v!r}"}

    dataset: str = Field(description="the flight-test folder (with manifest.json), relative to the config's folder")
    holdout_every: int = Field(3, ge=0, description="every this many-th trim point of each channel (in speed "
                                                    "order) is held out for validation; 0: none")


class TrimModelTable(Table):
    """``[model]``: fixed parameter values [SI]."""

    parameters: ParameterValues = Field(default_factory=dict, description="fixed parameter values [SI]")


class TrimLoopTable(Table):
    """``[loop]``: the trim loop's iterations and statistical thresholds."""

    number_words = "a finite number"
    messages = {"max_iterations": "field 'max_iterations' must be an integer >= 0, got {v!r}",
                "candidates": "field 'candidates' must be a list of names",
                "alpha": (None, "field 'alpha' = {v!r} is out of range"),
                "ratio": (None, "field 'ratio' = {v!r} is out of range"),
                "confound_corr": (None, "field 'confound_corr' = {v!r} is out of range"),
                **GENERIC_MESSAGES}

    max_iterations: int = Field(2, ge=0, description="most loop iterations after the first fit")
    candidates: Optional[list[str]] = Field(None, description="the candidate effects offered (names of "
                                                              "pyomo_heli.diagnosis.candidates; default all)")
    alpha: Finite = Field(ALPHA, gt=0, lt=1, description="significance level of the score test, in (0, 1)")
    ratio: Finite = Field(RATIO, ge=1, description="how much the best candidate must beat the runner-up, >= 1")
    confound_corr: Finite = Field(CONFOUND_CORR, gt=0, le=1, description="correlation above which two candidates "
                                                                          "are confounded, in (0, 1]")
    discovery: bool = Field(False, description="structure determination: the generic discrepancy family scored "
                                               "with the candidates, physics named by encompassing "
                                               "(docs/real_data.md)")
    generic_family: GenericFamily = Field(
        "standard", description="the generic family offered with discovery when no 'generic' list is given")
    generic: GenericTerms = Field(None, description="the generic terms offered with discovery (default the whole "
                                                    "family)")


class TrimLoopFile(Table):
    """A trim-loop config: the tables of a TOML file read by ``pyomo-heli trim-loop``."""

    data: TrimDataTable
    model: TrimModelTable = Field(default_factory=TrimModelTable)
    parameters: dict[str, ParameterTable] = Field(description="the free parameters, [parameters.<name>]")
    loop: TrimLoopTable = Field(default_factory=TrimLoopTable)
    solver: SolverTable = Field(default_factory=SolverTable)
