"""The identification config (``pyomo-heli identify``, ``close-loop``, ``diagnose`` ...; e.g. studies/case1.toml).

Every table declared once: its fields, defaults, domains, units and meaning. Display units (deg, kt) appear
only where the field's name says so; pyomo_heli.config converts them to SI. The rules that compare fields or
look at the data (a maneuver listed as fitted and validation, the dataset folder, the parameter names of the
model) are the loader's (:func:`pyomo_heli.config.load_identification_config`).
"""
from __future__ import annotations

from typing import Any, Literal, Optional, Union

from pydantic import Field, ValidationInfo, field_validator, model_validator

from ..channels import INPUTS, OUTPUTS, TRIM_CHANNELS
from ..physics.discrepancy import generic_names
from .base import Table, fail, names_check
from .common import Finite, Names, ParameterTable, ParameterValues, SolverTable, SIGMA_MAX_SI, sigma_table
from ..units import SENSOR_SIGMA_KEYS

#: the outputs J_time fits by default (every recorded output but the flapping angle)
DEFAULT_TIME_OUTPUTS = ("q", "theta", "n_x", "n_z", "TAS")
#: the objective sets an identification can use ([objectives] use)
OBJECTIVE_SETS = (("time", "trim"), ("time", "trim", "linear"))
#: Pareto front vocabularies (pyomo_heli.pareto.front; tests/test_settings.py keeps them equal)
SPACINGS = ("geometric", "linear")
WARM_STARTS = ("continuation", "full", "primal", "none")
PREDICTORS = ("secant", "none")
#: the loop's statistical thresholds (pyomo_heli.diagnosis.attribution uses the same defaults)
ALPHA = 0.01
RATIO = 2.0
CONFOUND_CORR = 0.7
#: outputs and inputs of the frequency-response pairs of J_linear
LINEAR_OUTPUTS = ("q", "theta", "n_x", "n_z")
LINEAR_INPUTS = ("col", "lon")
DEFAULT_PAIRS = (("q", "lon"), ("n_z", "col"))
#: most epsilon grid points on J_linear: the front is [pareto] points x this many solves
MAX_LINEAR_POINTS = 50


def _names_or(word: str, allow_empty: bool):
    """A wrap validator for "identification" / "validation" or a list of maneuver names."""

    def check(cls, v, handler, info: ValidationInfo):
        key = info.field_name
        if v != word and not isinstance(v, list):
            fail(info, f"field '{key}' must be \"{word}\" or a list of names")
        if v == word:
            return v
        if not all(isinstance(x, str) for x in v):
            fail(info, f"field '{key}' must be a list of names, got {v!r}")
        return names_check(handler(v), info, allow_empty=allow_empty)

    return check


def InputChannels(field: str):
    """The type of a list of input channels, possibly empty; an unknown channel is named with ``field``."""
    return Names(INPUTS, allow_empty=True,
                 unknown=f"unknown input channel(s) {{bad}} in {field}; choose from {{choices}}")


class DataTable(Table):
    """``[data]``: the flight test and the records the fit and the validation use."""

    number_words = "a finite number"
    messages = {
        "resample_hz": (None, "field 'resample_hz' must be a positive number"),
        "max_duration_s": (None, "field 'max_duration_s' must be a positive number"),
        "resample_inputs": "field 'resample_inputs' must be \"sample\", \"project\" or \"record\", got {v!r}",
        "input_reference_s": "field 'input_reference_s' must be a number >= 0, got {v!r}",
    }

    dataset: str = Field(description="the flight-test folder (with manifest.json; docs/data_format.md), relative "
                                     "to the config's folder")
    maneuvers: Union[Literal["identification"], list[str]] = Field(
        "identification", description="the fitted records: \"identification\" (every record of that role in the "
                                      "manifest) or a list of maneuver names")
    validation: Union[Literal["validation"], list[str]] = Field(
        "validation", description="the validation records: \"validation\" (every record of that role) or a list "
                                  "of maneuver names (may be empty)")
    resample_hz: Optional[Finite] = Field(None, gt=0, description="resample the records to this rate [Hz] "
                                                                  "(default: as recorded)")
    resample_inputs: Literal["sample", "project", "record"] = Field(
        "project", description="how the inputs reach the resampled grid: \"sample\" (take the recorded value), "
                               "\"project\" (average over the interval) or \"record\" (every recorded sample "
                               "drives the model; input errors at the recorded rate)")
    max_duration_s: Optional[Finite] = Field(None, gt=0, description="cut every record after this time [s]")
    input_reference_s: Finite = Field(0.0, ge=0, description="inputs are increments from their mean over the "
                                                             "first this many seconds [s] (0: from the first sample)")

    _maneuvers = field_validator("maneuvers", mode="wrap")(_names_or("identification", False))
    _validation = field_validator("validation", mode="wrap")(_names_or("validation", True))


class ModelTable(Table):
    """``[model]``: the model's structure and its fixed parameter values."""

    extensions: Names(allow_empty=True) = Field(
        default_factory=list, description="candidate effects added to the model (names of "
                                          "pyomo_heli.diagnosis.candidates)")
    parameters: ParameterValues = Field(default_factory=dict, description="fixed parameter values [SI] that "
                                                                          "replace the nominal ones")


def _sigma_max(table):
    """No sensor is that poor: a sigma above SIGMA_MAX_SI in SI is a unit slip."""
    lines = []
    for key, (_, factor) in SENSOR_SIGMA_KEYS.items():
        v = getattr(table, key)
        if v is not None and v * factor > SIGMA_MAX_SI:
            lines.append(f"'{key}' = {v!r} is not a sensor noise sigma (above {SIGMA_MAX_SI:g} in SI: rad, rad/s, "
                         f"g or m/s); a unit slip?")
    if lines:
        fail(None, "\n".join(lines))
    return table


NoiseSigmaTable = sigma_table(
    "NoiseSigmaTable", positive=True,
    doc="Noise sigmas of the channels, display units in the key names (q_deg_s [deg/s], theta_deg [deg], nx_g [g], "
        "nz_g [g], tas_m_s [m/s], beta0_deg [deg], col_deg [deg], lon_deg [deg]).",
    messages={k: "'{name}' must be a positive number, got {v!r}" for k in SENSOR_SIGMA_KEYS},
    validators={"_sigma_max": model_validator(mode="after")(_sigma_max)})


class ObjectivesTable(Table):
    """``[objectives]``: what the fit measures."""

    use: Names(("time", "trim", "linear"), unknown="field 'use': unknown objective(s) {bad}; choose from "
                                                   "{choices}") = Field(
        default_factory=lambda: ["time", "trim"], description="the objectives: [\"time\", \"trim\"] or "
                                                              "[\"time\", \"trim\", \"linear\"]")
    time_outputs: Names(OUTPUTS, unknown="unknown output '{one}' in time_outputs; choose from {choices}") = Field(
        default_factory=lambda: list(DEFAULT_TIME_OUTPUTS), description="outputs J_time fits")
    trim_outputs: Names(TRIM_CHANNELS, unknown="unknown output '{one}' in trim_outputs; choose from {choices}") = \
        Field(default_factory=lambda: list(TRIM_CHANNELS), description="trim channels J_trim fits")
    covariance: Literal["diagonal", "full"] = Field("diagonal", description="the output-error weighting: the "
                                                                            "residual covariance's diagonal or all")
    input_errors: InputChannels("input_errors") = Field(
        default_factory=list, description="input channels with measurement errors estimated by the fit (errors "
                                          "in variables)")
    noise_sigma: Optional[NoiseSigmaTable] = Field(None, description="the sigmas of input_errors' fit (default: "
                                                                     "from the records' quiet lead-in)")
    input_error_ar: int = Field(0, ge=0, le=8, description="order of the autoregressive model of the input errors, "
                                                           "fitted to the records' quiet lead-in (0: independent "
                                                           "errors)")
    output_error_ar: int = Field(0, ge=0, le=8, description="order of the autoregressive model of the output noise, "
                                                             "fitted to the records' quiet lead-in (0: independent "
                                                             "residuals); with input_errors")
    input_reference_error: bool = Field(False, description="estimate each record's input reference error too: the "
                                                           "noise mean of the quiet lead-in the increments are "
                                                           "referred to")

    messages = {"covariance": "field 'covariance' must be diagonal or full",
                "input_error_ar": (None, "field 'input_error_ar' must be an integer 0..8"),
                "output_error_ar": (None, "field 'output_error_ar' must be an integer 0..8")}


class DiscretizationTable(Table):
    """``[discretization]``: the collocation of the maneuvers."""

    messages = {"ncp": (None, "field 'ncp' must be 1..5")}

    ncp: int = Field(2, ge=1, le=5, description="Radau collocation points per finite element")


class ParetoTable(Table):
    """``[pareto]``: the epsilon-constraint front of paper Eq. 10 (docs/robustness.md, docs/performance.md)."""

    messages = {
        "points": (None, "field 'points': the epsilon grid needs 2 (the anchors) to 1000 points, got {v!r}"),
        "spacing": (None, "pareto.spacing must be 'geometric' or 'linear', got {v!r}"),
        "warm_start": (None, "pareto.warm_start must be one of " + ", ".join(WARM_STARTS) + ", got {v!r}"),
        "predictor": (None, "pareto.predictor must be one of " + ", ".join(PREDICTORS) + ", got {v!r}"),
        "nadir": (None, "pareto.nadir must be one of payoff, nondominated, got {v!r}"),
        "placement": (None, "pareto.placement must be one of uniform, adaptive, got {v!r}"),
        "max_solves": (None, "pareto.max_solves must be 4 to 1000, got {v!r}"),
        "max_iter": (None, "field 'max_iter' must be a positive integer, got {v!r}"),
    }

    points: Union[int, list[int]] = Field(11, description="epsilon grid points, the two anchors included; a list "
                                                          "gives one count per bounded objective (e.g. [5, 5])")
    spacing: Literal[SPACINGS] = Field("geometric", description="epsilon grid spacing on J_trim")
    warm_start: Literal[WARM_STARTS] = Field("continuation", description="how an interior point starts from "
                                                                         "the previous one")
    cold_check: bool = Field(False, description="also solve every interior point cold (measures warm starts)")
    predictor: Literal[PREDICTORS] = Field("secant", description="start of interior point k >= 3: secant "
                                                                 "extrapolation or none")
    max_iter: Optional[int] = Field(None, ge=1, description="Ipopt iteration cap of each front solve (none: the "
                                                            "solver's own)")
    nadir: Literal["payoff", "nondominated"] = Field("payoff", description="Eq. 11 nadir: payoff table, or the "
                                                                           "worst non-dominated front point")
    placement: Literal["uniform", "adaptive"] = Field("uniform", description="epsilon placement: uniform grid, "
                                                                             "or arc length + refinement at C")
    max_solves: int = Field(14, ge=4, le=1000, description="adaptive placement: front solves, anchors included")

    @field_validator("points", mode="before")
    @classmethod
    def _points(cls, v, info: ValidationInfo):
        counts = v if isinstance(v, list) else [v]
        if not counts or not all(isinstance(n, int) and not isinstance(n, bool) and 2 <= n <= 1000 for n in counts):
            fail(info, f"field 'points': the epsilon grid needs 2 (the anchors) to 1000 points, got {v!r}")
        return v


class IdentificationSolverTable(SolverTable):
    """``[solver]``: the NLP solver, its options and where the collocation rows are assembled."""

    point_rows: bool = Field(True, description="casadi-ipopt only: assemble the collocation rows compiled "
                                               "(false: every row through the NL file)")


class LinearTable(Table):
    """``[linear]``: the frequency responses J_linear fits (with [objectives] use = [..., "linear"])."""

    unknown_style = "fields"
    number_words = "a finite number"
    messages = {
        "pairs": ("field 'pairs' must be a list of [output, input] pairs", None),
        "speeds_kt": "field 'speeds_kt' must be a non-empty list of speeds in 0..150 kt, got {v!r}",
        "points": f"field 'points' must be an integer in 2..{MAX_LINEAR_POINTS}, got {{v!r}}",
        "weighting": "field 'weighting' must be one of bins, tischler_remple, got {v!r}",
    }

    pairs: list[list[str]] = Field(default_factory=lambda: [list(p) for p in DEFAULT_PAIRS],
                                   json_schema_extra={"items": {"type": "array", "minItems": 2, "maxItems": 2,
                                                                "prefixItems": [{"enum": list(LINEAR_OUTPUTS)},
                                                                                {"enum": list(LINEAR_INPUTS)}]}},
                                   description="(output, input) pairs of the frequency responses")
    speeds_kt: list[Finite] = Field(default_factory=lambda: [0.0, 80.0], min_length=1,
                                    json_schema_extra={"items": {"type": "number", "minimum": 0, "maximum": 150}},
                                    description="flight conditions, maneuver trim speeds [kt] (display unit)")
    coherence_min: Optional[Finite] = Field(None, description="coherent band: coherence at least this (default "
                                                              "0.9)")
    input_power_min: Optional[Finite] = Field(None, description="... and input autospectrum at least this "
                                                                "fraction of its peak (default 0.2)")
    window_s: Optional[Finite] = Field(None, description="Welch segment length [s] (default 5.12)")
    overlap: Optional[Finite] = Field(None, description="Welch segment overlap, fraction (default 0.75)")
    omega_min_rad_s: Optional[Finite] = Field(None, description="lowest frequency [rad/s] (default 0.9)")
    omega_max_rad_s: Optional[Finite] = Field(None, description="highest frequency [rad/s] (default 20)")
    points: int = Field(3, ge=2, le=MAX_LINEAR_POINTS, description="epsilon grid points on J_linear (the front "
                                                                   "is [pareto] points x this)")
    weighting: Literal["bins", "tischler_remple"] = Field("bins", description="J_linear frequencies: every coherent "
                                                          "bin of the identification maneuvers, or Tischler-Remple "
                                                          "(20 log-spaced frequencies of the sweep records)")
    # the composite estimator of the sweep records (weighting = "tischler_remple"); unset: its defaults
    # (pyomo_heli.dataset.frequency_response.SWEEP_SETTINGS, TR_POINTS). A study pins them to keep its numbers.
    sweep_windows_s: Optional[list[Finite]] = Field(None, min_length=1, description="composite window lengths [s]")
    sweep_min_periods: Optional[Finite] = Field(None, gt=0, description="a window counts where it holds this many "
                                                                        "periods")
    sweep_record_periods: Optional[Finite] = Field(None, ge=0, description="lowest frequency: this many periods in "
                                                                           "the longest record")
    sweep_overlap: Optional[Finite] = Field(None, ge=0, lt=1, description="Welch segment overlap, fraction")
    sweep_coherence_min: Optional[Finite] = Field(None, gt=0, lt=1, description="coherent band: composite "
                                                                                "coherence at least this")
    sweep_omega_min_rad_s: Optional[Finite] = Field(None, gt=0, description="lowest grid frequency [rad/s]")
    sweep_omega_max_rad_s: Optional[Finite] = Field(None, gt=0, description="highest grid frequency [rad/s]")
    sweep_n_omega: Optional[int] = Field(None, ge=2, le=10000, description="logarithmic grid points")
    sweep_max_window_fraction: Optional[Finite] = Field(None, gt=0, le=1, description="longest window / record "
                                                                                      "length (records shorter are "
                                                                                      "left out of that window)")
    sweep_coherence_span: Optional[Finite] = Field(None, ge=0, le=10, description="a window's coherence at omega is "
                                                   "its smallest within this many 1/T_w of omega (2: the Hann "
                                                   "main lobe; 0: at omega alone)")
    sweep_points: Optional[int] = Field(None, ge=2, le=1000, description="Tischler-Remple cost frequencies per "
                                                                         "response")

    @field_validator("pairs")
    @classmethod
    def _pairs(cls, pairs, info: ValidationInfo):
        if not all(len(p) == 2 for p in pairs):
            fail(info, "field 'pairs' must be a list of [output, input] pairs")
        for o, i in pairs:
            if o not in LINEAR_OUTPUTS:
                fail(info, f"field 'pairs': unknown output '{o}'; choose from {', '.join(LINEAR_OUTPUTS)}")
            if i not in LINEAR_INPUTS:
                fail(info, f"field 'pairs': unknown input '{i}'; choose from {', '.join(LINEAR_INPUTS)}")
        dup = sorted({tuple(p) for p in pairs if pairs.count(p) > 1})
        if dup:
            fail(info, f"field 'pairs' names {[list(p) for p in dup]} more than once")
        return pairs

    @field_validator("speeds_kt")
    @classmethod
    def _speeds(cls, speeds, info: ValidationInfo):
        if not all(0 <= v <= 150 for v in speeds):
            fail(info, f"field 'speeds_kt' must be a non-empty list of speeds in 0..150 kt, got {speeds!r}")
        if len(set(speeds)) != len(speeds):
            fail(info, f"field 'speeds_kt' names a speed more than once: {speeds}")
        return speeds

    @model_validator(mode="after")
    def _keys_of_the_weighting(self):
        """A key the chosen weighting does not read is refused, not silently ignored: the Welch keys
        (coherence_min, ..., omega_max_rad_s) set the bins of weighting = "bins", the sweep_* keys the
        composite responses of weighting = "tischler_remple"."""
        bins_keys = ("coherence_min", "input_power_min", "window_s", "overlap", "omega_min_rad_s", "omega_max_rad_s")
        unused = (tuple(k for k in type(self).model_fields if k.startswith("sweep_")) if self.weighting == "bins"
                  else bins_keys)
        given = [k for k in unused if getattr(self, k) is not None]
        if given:
            fail(None, f"field(s) {', '.join(given)} are not used with weighting = '{self.weighting}' (the Welch "
                       f"keys set weighting = 'bins', the sweep_* keys weighting = 'tischler_remple'); remove them")
        return self


class DiagnosisTable(Table):
    """``[diagnosis]``: the input-noise model of the residual analysis (docs/diagnosis.md)."""

    messages = {"replay": "field 'replay' must be \"fit\" or \"record\", got {v!r}",
                "input_path_family": "field 'input_path_family' must be \"standard\" or \"extended\", got {v!r}"}

    input_noise: InputChannels("input_noise") = Field(
        default_factory=list, description="input channels whose measurement noise the whiteness test takes out "
                                          "(default: [objectives] input_errors)")
    noise_sigma: Optional[NoiseSigmaTable] = Field(None, description="their sigmas (default: from the records' "
                                                                     "quiet lead-in)")
    replay: Literal["fit", "record"] = Field(
        "record", description="the replay the innovations compare with the records: \"fit\" (the inputs as the NLP "
                           "takes them) or \"record\" (the recorded inputs at the record's rate)")
    input_path_family: Literal["standard", "extended"] = Field(
        "standard", description="the input path's dictionary: \"standard\" (the inputs, q, theta, TAS and the inputs' "
                                "rates) or \"extended\" (also each input's free play and dead zone)")


NON_EMPTY = "field '{field}' must be a non-empty list of names"
#: the generic discrepancy family and terms offered with discovery: one declaration for every [loop] table
GenericFamily = Literal["standard", "extended", "control"]
GenericTerms = Optional[Names(generic_names("control"), empty=NON_EMPTY,
                              unknown="field 'generic': unknown discrepancy term {one!r}; choose from {choices}")]
GENERIC_MESSAGES = {"generic": ("field 'generic' must be a non-empty list of names", None),
                    "generic_family": "field 'generic_family' must be \"standard\", \"extended\" or \"control\", "
                                      "got {v!r}"}
#: the [loop] fields read with ``discovery = true`` only (a config without discovery that gives one is refused)
DISCOVERY_ONLY_LOOP_FIELDS = ("generic", "generic_family", "generic_rank")


def unread_discovery_fields(given, discovery: bool) -> list[tuple[str, str]]:
    """The discovery fields of a [loop] table that nothing reads, as (field, why): every one of
    :data:`DISCOVERY_ONLY_LOOP_FIELDS` given without discovery; with it ``ratio`` and ``confound_corr`` (the score
    test's own decision, which discovery does not read) and ``generic_family`` given beside ``generic``.
    ``given``: the field names the file gives (not the defaults). One rule for every [loop] table (close-loop and
    trim-loop), so a field given that nothing reads is refused, not dropped."""
    given = set(given)
    if not discovery:
        return [(k, "it is read with discovery = true only") for k in DISCOVERY_ONLY_LOOP_FIELDS if k in given]
    out = [(k, "the score test's ratio and confounding rules decide without discovery only (with it the screen and "
               "encompassing decide)") for k in ("ratio", "confound_corr") if k in given]
    if {"generic", "generic_family"} <= given:
        out.append(("generic_family", "'generic' names the terms (give one of the two)"))
    return out


class LoopTable(Table):
    """``[loop]``: the close-loop settings (docs/close_loop.md), read by ``pyomo-heli close-loop``."""

    unknown_style = "fields"
    bool_words = "true or false"
    messages = {
        "max_iterations": "field 'max_iterations' must be an integer >= 0, got {v!r}",
        "candidates": ("field 'candidates' must be a non-empty list of names", None),
        "alpha": "field 'alpha' must be a number in (0, 1], got {v!r}",
        "ratio": "field 'ratio' must be a number in (1, inf], got {v!r}",
        "confound_corr": "field 'confound_corr' must be a number in (0, 1], got {v!r}",
        "point": "field 'point' must be \"direct\" or \"chosen\", got {v!r}",
        "shape": "field 'shape' must be \"time_domain\" or \"default\", got {v!r}",
        "uncertainty": "field 'uncertainty' must be \"chosen\" or \"none\", got {v!r}",
        "score_inputs": "field 'score_inputs' must be \"eliminated\" or \"measured\", got {v!r}",
        **GENERIC_MESSAGES,
        "after_rejection": "field 'after_rejection' must be \"next\" or \"stop\", got {v!r}",
        "generic_rank": "field 'generic_rank' must be \"p\" or \"likelihood_ratio\", got {v!r}",
    }

    max_iterations: int = Field(3, ge=0, description="most loop iterations after the first identification (a "
                                "backward-check removal goes past it)")
    candidates: Optional[Names(empty=NON_EMPTY)] = Field(None, description="the candidate effects offered (names of "
                                                            "pyomo_heli.diagnosis.candidates; default all)")
    alpha: Finite = Field(ALPHA, gt=0, le=1, description="significance level of the score test")
    ratio: Finite = Field(RATIO, gt=1, description="how much the best candidate must beat the runner-up")
    confound_corr: Finite = Field(CONFOUND_CORR, gt=0, le=1, description="correlation above which two candidates "
                                                                          "are confounded")
    robust: bool = Field(True, description="the score test robust to non-white residuals")
    point: Literal["direct", "chosen"] = Field("direct", description="the front point diagnosed")
    shape: Literal["time_domain", "default"] = Field("time_domain", description="how an accepted effect's shape "
                                                                                "parameters are chosen")
    uncertainty: Literal["chosen", "none"] = Field("chosen", description="Cramer-Rao bounds of the chosen point")
    score_inputs: Literal["eliminated", "measured"] = Field(
        "eliminated", description="with input_errors: the score test eliminates the input errors or takes the "
                                  "measured inputs as exact")
    discovery: bool = Field(False, description="structure determination over the candidates and the generic "
                                               "discrepancy family (docs/discovery.md)")
    generic_family: GenericFamily = Field(
        "standard", description="the generic family offered with discovery when no 'generic' list is given: "
                                "standard, extended (+ speed products and input scale factors) or control "
                                "(extended + control-path feedback terms; docs/discovery.md)")
    generic: GenericTerms = Field(
        None, description="the generic terms offered with discovery (default the whole family named by "
                          "'generic_family', pyomo_heli.physics.discrepancy.generic_names(generic_family))")
    validation_rule: bool = Field(True, description="reject a step whose model makes the validation error rise "
                                                    "significantly on any output")
    validation_joint: bool = Field(False, description="the validation rule also rejects a significant rise of all "
                                                      "outputs' error at once (joint paired test, reported either "
                                                      "way)")
    after_rejection: Literal["next", "stop"] = Field(
        "next", description="after a step the validation rule rejected: back to the kept model and the next "
                            "significant term, the rejected ones left out (next), or stop there (stop)")
    generic_rank: Literal["p", "likelihood_ratio"] = Field(
        "p", description="which screened generic term a step takes as the best (the one it asks the significance "
                         "of, the competitor a physical candidate must encompass, the description of what is "
                         "left): the smallest deciding p (p) or the largest raw likelihood ratio "
                         "(likelihood_ratio; docs/discovery_results.md says which held-out tables each ranked)")


class IdentificationFile(Table):
    """An identification config: the tables of a TOML file read by ``pyomo-heli identify`` and the commands
    that take an identification config."""

    unknown_style = "tables"

    data: DataTable
    model: ModelTable = Field(default_factory=ModelTable)
    parameters: dict[str, ParameterTable] = Field(description="the free parameters, one table each, "
                                                              "[parameters.<name>] (at least one)")
    objectives: ObjectivesTable = Field(default_factory=ObjectivesTable)
    discretization: DiscretizationTable = Field(default_factory=DiscretizationTable)
    pareto: ParetoTable = Field(default_factory=ParetoTable)
    solver: IdentificationSolverTable = Field(default_factory=IdentificationSolverTable)
    linear: Optional[LinearTable] = None
    diagnosis: Optional[DiagnosisTable] = None
    #: checked when the config is read (:func:`pyomo_heli.config.loop_table`)
    loop: dict[str, Any] = Field(default_factory=dict, description="close-loop settings (read by pyomo-heli "
                                                                   "close-loop; declared by LoopTable)")
    study: dict[str, Any] = Field(default_factory=dict, description="free notes of a study (not read)")


def identification_schema() -> dict:
    """The JSON Schema of an identification config; [loop] declared by :class:`LoopTable`."""
    schema = IdentificationFile.model_json_schema()
    loop = LoopTable.model_json_schema()
    schema.setdefault("$defs", {})["LoopTable"] = loop
    schema["properties"]["loop"] = {"$ref": "#/$defs/LoopTable",
                                    "description": schema["properties"]["loop"]["description"]}
    return schema
