"""The identification config (a TOML file) and its validation.

Every error names the file and the field at fault. Parameter values are
given in the unit named by ``unit`` (the parameter's SI unit or its display
unit, e.g. deg/m for theta_twist) and converted to SI here.
Example: studies/case1.toml.
"""
from __future__ import annotations

import math

from dataclasses import dataclass, field
from pathlib import Path

from .tomlfile import read_toml

from .nlp.identification import NLPOptions
from .nlp.parameters import FreeParameter
from .pareto.front import ParetoSettings
from .physics.model import HelicopterModel
from .settings import ConfigError, Problems, validate
from .settings.common import SIGMA_MAX_SI  # noqa: F401 - re-exported
from .settings.identification import (OBJECTIVE_SETS, IdentificationFile, LinearTable, LoopTable,
                                      unread_discovery_fields)
from .units import SENSOR_SIGMA_KEYS
from .solvers import validate_solver_options


@dataclass
class IdentificationConfig:
    path: Path
    dataset: Path
    maneuvers: object  # "identification" or a list of names
    validation: object  # "validation" or a list of names
    resample_hz: float | None
    max_duration: float | None
    model: HelicopterModel
    free: list
    nlp: NLPOptions
    pareto: ParetoSettings
    raw: dict = field(default_factory=dict)
    objectives: tuple = ("time", "trim")  # [objectives] use
    linear: object = None  # LinearSettings when "linear" is used
    input_reference_s: float = 0.0  # [data] input_reference_s (0: increments from the first sample)
    resample_inputs: str = "project"  # [data] resample_inputs: "sample" | "project" (nlp.identification.prepare_data)
    diagnosis: "DiagnosisSettings" = None  # [diagnosis]; None: as the identification ([objectives] input_errors)

    @property
    def diagnosis_settings(self) -> "DiagnosisSettings":
        """The residual analysis's input-noise model: ``[diagnosis]``, else the identification's own."""
        return self.diagnosis or DiagnosisSettings(tuple(self.nlp.input_errors), self.nlp.noise_sigma,
                                                   input_error_ar=self.nlp.input_error_ar)


@dataclass(frozen=True)
class DiagnosisSettings:
    """``[diagnosis]``: the input-noise model of the residual analysis (docs/diagnosis.md).

    ``input_noise``: the input channels whose measurement noise the whiteness test takes out (the
    residuals' innovations, :mod:`pyomo_heli.diagnosis.innovations`); default the identification's
    ``[objectives] input_errors``. Giving it to an output-error identification (inputs taken as exact)
    keeps the exact model from being called "not white" because its replay is driven by noisy inputs.
    ``noise_sigma``: the sigmas [SI] of the input and output channels (``[diagnosis.noise_sigma]``, same
    keys and units as ``[objectives.noise_sigma]``); None: from the records' quiet lead-in.
    ``replay``: the model outputs the innovations compare with the records: ``"record"`` (default), the replay
    driven by the recorded inputs at the record's own rate, taken at the NLP's samples (the input-noise model and
    the sensitivities stay the NLP's); ``"fit"``, the replay driven by the inputs as the NLP takes them (``[data]
    resample_hz``, ``resample_inputs``), which differ from the recorded ones and leave a deterministic residual
    that the input path reads as an input error. Without resampling the two are the same. docs/diagnosis.md,
    step 7. ``input_path_family``: the input path's dictionary, ``"standard"`` or ``"extended"`` (each input's free
    play and dead zone too; :mod:`pyomo_heli.diagnosis.input_path`). ``input_error_ar``: the order of the AR model
    of the input errors (the identification's ``[objectives] input_error_ar`` where the analysis takes its input
    model; 0, independent errors, with ``[diagnosis] input_noise``).
    """
    input_noise: tuple = ()
    noise_sigma: dict | None = None
    replay: str = "record"
    input_path_family: str = "standard"
    input_error_ar: int = 0


def unit_factor(spec, unit: str | None) -> float:
    """The factor from ``unit`` (a parameter's SI unit, "SI" or its display unit) to SI; ValueError otherwise."""
    if unit in (None, spec.unit, "SI", ""):
        return 1.0
    if spec.display is not None and unit == spec.display[0]:
        return 1.0 / spec.display[1]
    allowed = [spec.unit] + ([spec.display[0]] if spec.display else [])
    raise ValueError(f"unit '{unit}' not recognised for {spec.name}; use {' or '.join(allowed)}")


def free_parameter_unit(parameters, name: str, unit: str | None, problems, where: str):
    """(spec, factor of ``unit`` to SI) of the parameter ``name`` a config frees; None when the name or the unit is
    unknown (the error added to ``problems`` under ``where``)."""
    if name not in parameters:
        problems.add(where, parameters._unknown(name))
        return None
    spec = parameters.spec(name)
    try:
        return spec, unit_factor(spec, unit)
    except ValueError as exc:
        problems.add(where, str(exc))
        return None


def load_identification_config(path: str | Path, overrides: dict | None = None,
                               raw: dict | None = None) -> IdentificationConfig:
    """Read and check an identification config. ``overrides`` replace top-level tables (tests, CLI); a relative
    ``[data] dataset`` among them is relative to the working directory (one in the file, to the file's folder).

    ``raw``: the config's tables as a dict (the parsed TOML) instead of reading ``path``; ``path`` then
    only names the config in messages and is the base of relative paths (its folder).
    The tables are declared in :mod:`pyomo_heli.settings.identification`; every error of their fields is
    reported at once (one line each), then every error of the rules across fields and of the data folder.
    """
    path = Path(path)
    if raw is None:
        raw = read_toml(path, ConfigError)
    else:
        import copy

        if not isinstance(raw, dict):
            raise ConfigError(f"{path}: a config must be a dict of tables, got {type(raw).__name__}")
        raw = copy.deepcopy(raw)
    for k, v in (overrides or {}).items():
        if k == "data" and isinstance(v, dict) and isinstance(v.get("dataset"), (str, Path)) \
                and not Path(v["dataset"]).is_absolute():
            # a path given as an override (a command line, a study) is relative to the working directory, as one
            # written in the config is relative to the config's folder
            v = {**v, "dataset": str(Path(v["dataset"]).resolve())}
        raw[k] = {**raw.get(k, {}), **v} if isinstance(v, dict) else v
    f = str(path)
    problems = Problems(f, ConfigError)
    s = validate(IdentificationFile, raw, problems)
    problems.raise_if_any()
    data = s.data

    # ---- the data folder and the records
    ds = Path(data.dataset)
    if not ds.is_absolute():
        ds = (path.parent / ds).resolve()
    if not ds.is_dir():
        problems.add("data", f"field 'dataset': folder {ds} not found")
    elif not (ds / "manifest.json").is_file():
        problems.add("data", f"field 'dataset': {ds} is not a flight-test folder (no manifest.json; "
                             f"docs/data_format.md)")
    mans, val = data.maneuvers, data.validation
    both = [n for n in val if isinstance(mans, list) and n in mans] if isinstance(val, list) else []
    if both:  # a record the fit has seen validates nothing
        problems.add("data", f"maneuver(s) {', '.join(both)} listed in both 'maneuvers' (fitted) and "
                             f"'validation'; a validation record must be one the fit has not seen")
    in_ref = data.input_reference_s

    # ---- the model and its free parameters
    extensions = []
    if s.model.extensions:
        from .diagnosis.candidates import make_candidate

        for n in s.model.extensions:
            try:
                extensions.append(make_candidate(n))
            except KeyError as exc:
                problems.add("model", f"field 'extensions': {exc.args[0]}")
    model = HelicopterModel(extensions=extensions)
    fixed = s.model.parameters
    unknown = [k for k in fixed if k not in model.parameters]
    for k in unknown:
        problems.add("model.parameters", f"unknown parameter name '{k}'")
    if fixed and not unknown:
        try:
            model = model.with_parameters(**fixed)
        except ValueError as exc:
            problems.add("model.parameters", str(exc))
    if not s.parameters:
        problems.add("parameters", "no free parameter given")
    free = []
    for name, p in s.parameters.items():
        where = f"parameters.{name}"
        found = free_parameter_unit(model.parameters, name, p.unit, problems, where)
        if found is None:
            continue
        spec, fac = found
        if name in fixed and p.initial is not None and not math.isclose(p.initial * fac, float(fixed[name]),
                                                                           rel_tol=1e-12, abs_tol=0.0):
            # two starts: one would be dropped
            problems.add(where, f"'initial' and [model.parameters] {name} = {fixed[name]!r} (SI) give two values: "
                                "a free parameter starts at one (drop either; without 'initial' it starts at the "
                                "[model.parameters] value)")
            continue
        lo_d, hi_d = spec.bounds or (None, None)
        initial = spec.value if p.initial is None else p.initial * fac
        lower = lo_d if p.lower is None else p.lower * fac
        upper = hi_d if p.upper is None else p.upper * fac
        scale = spec.scale if p.scale is None else p.scale * fac
        if lower is None or upper is None:
            problems.add(where, f"give 'lower' and 'upper' (no default range for {name})")
            continue
        try:
            # both bounds must be values the physics can take (a negative mass, a zero air density, ...)
            spec.check(lower)
            spec.check(upper)
            free.append(FreeParameter(name, initial, lower, upper, scale if scale else max(abs(initial), 1.0)))
        except ValueError as exc:
            problems.add(where, f"{exc} (bounds in SI: [{lower:g}, {upper:g}])")

    # ---- the objectives
    obj = s.objectives
    t_out, r_out = tuple(obj.time_outputs), tuple(obj.trim_outputs)
    in_err, noise_sigma = _input_errors(obj, problems, in_ref, "objectives", "input_errors")
    if noise_sigma is not None:
        lacking = [c for c in t_out + in_err if c not in noise_sigma]
        if lacking:
            problems.add("objectives.noise_sigma", f"no sigma for {lacking} (every time output and every channel of "
                                                   f"input_errors needs one); keys: {', '.join(SENSOR_SIGMA_KEYS)}")
    # the errors-in-variables refinements: (key, what it needs input_errors for, what it needs the lead-in for)
    for key, without_errors, without_lead_in in (
            ("input_error_ar", "models the input errors", "the errors' model comes from the records' quiet lead-in"),
            ("output_error_ar", "weighs the known-noise J_time of the errors in variables",
             "the noise model comes from the records' quiet lead-in"),
            ("input_reference_error", "is an error of the input errors' reference",
             "the inputs are referred to their first sample")):
        if getattr(obj, key) and not in_err:
            problems.add("objectives", f"field '{key}' {without_errors}: give input_errors too")
        elif getattr(obj, key) and not in_ref:
            problems.add("objectives", f"field '{key}': {without_lead_in}; give [data] input_reference_s > 0")
    if obj.covariance == "full" and in_err:
        problems.add("objectives", "field 'covariance' = \"full\" is not used with input_errors (their J_time has "
                                   "the known noise sigmas, diagonal); give one of the two")
    use, linear = _objectives_use(s, raw, problems)
    diagnosis = None
    if s.diagnosis is not None:
        # input_noise without its own sigmas takes [objectives.noise_sigma] where given (docs/diagnosis.md)
        chans, sigma = _input_errors(s.diagnosis, problems, in_ref, "diagnosis", "input_noise", noise_sigma)
        ar = 0
        if "input_noise" not in (raw.get("diagnosis") or {}) and s.diagnosis.noise_sigma is None:
            # a [diagnosis] table of other settings: the identification's model
            chans, sigma, ar = in_err, noise_sigma, obj.input_error_ar
        diagnosis = DiagnosisSettings(chans, sigma, s.diagnosis.replay, s.diagnosis.input_path_family, ar)

    # ---- the solver and the front
    sol = s.solver
    solver_options = dict(sol.options)
    if "point_rows" in solver_options:
        problems.add("solver", "point_rows is a [solver] field, not an Ipopt option")
    else:
        try:  # a bad option must not reach the solver: a NaN tol hung Ipopt, an absent linear solver crashed it
            validate_solver_options(sol.name, solver_options)
        except ValueError as exc:
            problems.add_text(f"[solver] options: {exc}")
    if not sol.point_rows:
        # every row through the NL file (docs/performance.md, "What was done" 8)
        if sol.name != "casadi-ipopt":
            problems.add("solver", "field 'point_rows' applies to casadi-ipopt only (the AMPL solvers read every "
                                   "row from the NL file anyway)")
        solver_options["point_rows"] = False
    problems.raise_if_any()
    nlp = NLPOptions(time_outputs=t_out, trim_outputs=r_out, covariance=obj.covariance, ncp=s.discretization.ncp,
                     input_errors=in_err, noise_sigma=noise_sigma, input_error_ar=obj.input_error_ar,
                     input_reference_error=obj.input_reference_error, output_error_ar=obj.output_error_ar)
    par = s.pareto
    counts = par.points if isinstance(par.points, list) else [par.points]
    if not counts or not all(2 <= n <= 1000 for n in counts):
        raise ConfigError(f"{f} [pareto]: field 'points': the epsilon grid needs 2 (the anchors) to 1000 points "
                          f"per bounded objective, got {par.points}")
    if isinstance(par.points, list) and len(par.points) != len(use) - 1:
        raise ConfigError(f"{f} [pareto]: field 'points': a list gives one count per bounded objective "
                          f"({len(use) - 1} with [objectives] use = {list(use)}), got {par.points}")
    if isinstance(par.points, list) and "points" in raw.get("linear", {}):
        raise ConfigError(f"{f} [linear]: field 'points': the grid is [pareto] points = {par.points}; give it once")
    # a field the chosen front does not read is refused, not dropped (only the fields the file gives)
    given = raw.get("pareto", {}) if isinstance(raw.get("pareto"), dict) else {}
    # ([pareto] points with placement = "adaptive" is let through: identify --placement adaptive switches a
    # uniform config's front, whose points the adaptive placement then replaces by max_solves)
    unread = ([] if par.placement == "adaptive" else [("max_solves", "it applies to placement = 'adaptive'")]) + \
             ([("cold_check", "the cold solves are made on the uniform bi-objective front only")]
              if par.cold_check and (par.placement == "adaptive" or len(use) > 2) else []) + \
             ([("predictor", "it extrapolates warm starts, and warm_start = 'none' has none")]
              if par.warm_start == "none" else [])
    for key, why in unread:
        if key in given:
            raise ConfigError(f"{f} [pareto]: field '{key}' is not read here: {why}")
    if "resample_inputs" in (raw.get("data") or {}) and not data.resample_hz:
        raise ConfigError(f"{f} [data]: field 'resample_inputs' is not read here: it says how the inputs reach "
                          f"the grid of resample_hz, and none is given (the records are fitted as recorded)")
    try:
        pareto = ParetoSettings(points=par.points, spacing=par.spacing, warm_start=par.warm_start,
                                cold_check=par.cold_check, predictor=par.predictor, max_iter=par.max_iter,
                                nadir=par.nadir, placement=par.placement, max_solves=par.max_solves, solver=sol.name,
                                solver_options=solver_options)
    except ValueError as exc:
        raise ConfigError(f"{f} [pareto]: {exc}") from None
    if "loop" in raw:  # close-loop's table: checked here too, so that identify and diagnose refuse a bad one
        loop_table(raw["loop"], path, nlp.input_errors)
    return IdentificationConfig(path=path, dataset=ds, maneuvers=mans, validation=val,
                                resample_hz=float(data.resample_hz) if data.resample_hz else None,
                                max_duration=float(data.max_duration_s) if data.max_duration_s else None,
                                model=model, free=free, nlp=nlp, pareto=pareto, raw=raw, objectives=use,
                                linear=linear, input_reference_s=float(in_ref), resample_inputs=data.resample_inputs,
                                diagnosis=diagnosis)


def loop_table(raw, path, input_errors) -> LoopTable:
    """The ``[loop]`` table of an identification config (close-loop's settings, declared by
    :class:`pyomo_heli.settings.identification.LoopTable`), checked: its fields, the candidate names and every
    field given that nothing reads (refused, not dropped). ``input_errors``: the config's [objectives]
    input_errors. Checked when the config is read, so ``identify`` and ``diagnose`` refuse a bad [loop] too."""
    from .diagnosis.candidates import CANDIDATES

    problems = Problems(str(path), ConfigError)
    if not isinstance(raw, dict):
        problems.add("loop", "must be a table")
        problems.raise_if_any()
    table = validate(LoopTable, raw, problems, "loop")
    if table is not None:
        for n in table.candidates or ():
            if n not in CANDIDATES:
                problems.add("loop", f"field 'candidates': unknown candidate {n!r}; choose from "
                                     f"{', '.join(CANDIDATES)}")
        # a field given that nothing reads is refused, not dropped (the fields the file gives, not the defaults)
        unread = (unread_discovery_fields(raw, table.discovery)
                  + [(k, "it is read with validation_rule = true only") for k in ("validation_joint", "after_rejection")
                     if not table.validation_rule]
                  + ([("score_inputs", "it says how the score test treats the input errors, and [objectives] "
                                       "input_errors has none")] if not input_errors else []))
        for key, why in unread:
            if key in raw:
                problems.add("loop", f"field '{key}' is not read here: {why}")
    problems.raise_if_any()
    return table


def _input_errors(table, problems: Problems, in_ref, name: str, key: str,
                  fallback: dict | None = None) -> tuple[tuple, dict | None]:
    """[objectives] input_errors (errors in variables) and the optional [objectives.noise_sigma] table; the
    same for [diagnosis] input_noise and [diagnosis.noise_sigma] (``name``, ``key``): the channels and the
    sigmas in SI. ``fallback``: the sigmas [SI] taken when the table gives none ([objectives.noise_sigma] for
    the diagnosis), which must cover the channels; else the records' lead-in."""
    chans = tuple(getattr(table, key))
    given = table.noise_sigma
    if given is not None and not chans:
        problems.add(name, f"noise_sigma is only used with {key}")
    if chans and given is None and fallback is not None:
        lacking = [c for c in chans if c not in fallback]
        if lacking:
            problems.add(name, f"{key} {list(chans)} takes its sigmas from [objectives.noise_sigma], which has "
                               f"none for {lacking}; give [{name}.noise_sigma]")
        return chans, fallback
    if chans and given is None and not in_ref > 0:
        problems.add(name, f"{key} takes the noise sigmas from the records' quiet lead-in; set [data] "
                           f"input_reference_s > 0 or give [{name}.noise_sigma]")
    sigma = None
    if given is not None:
        sigma = {SENSOR_SIGMA_KEYS[k][0]: float(v) * SENSOR_SIGMA_KEYS[k][1]
                 for k, v in given.model_dump(exclude_none=True).items()}
    return chans, sigma


def _objectives_use(s, raw: dict, problems: Problems):
    """[objectives] use and the [linear] table (local linear models, J_linear)."""
    from .linear_settings import LinearSettings

    use = s.objectives.use
    order = tuple(k for k in ("time", "trim", "linear") if k in use)
    if order not in OBJECTIVE_SETS:
        problems.add("objectives", f"field 'use': {list(use)} is not supported; use "
                     + " or ".join(str(list(o)) for o in OBJECTIVE_SETS))
        return order, None
    if "linear" not in order:
        if raw.get("linear"):
            problems.add("linear", "given but [objectives] use does not include \"linear\"")
        return order, None
    try:
        return order, LinearSettings.from_table(s.linear or LinearTable())
    except (TypeError, ValueError) as exc:
        problems.add("linear", str(exc))
        return order, None


def config_of_result(cfg: IdentificationConfig, result) -> IdentificationConfig:
    """The config of a loop iteration's identification: ``cfg`` (the loop's config) plus the candidates the loop
    added (``result.info['extensions']``), their strengths free and their shape parameters at the values the
    iteration used (``result.info['shape_parameters']``). Lets commands that take a config and a results folder
    (``pyomo-heli uncertainty``) work on ``DIR/iter_i``. ConfigError if the folder does not fit the config.
    """
    import dataclasses

    from .diagnosis.candidates import model_with_candidates

    have = [e.name for e in cfg.model.extensions]
    listed = list(result.info.get("extensions", []))
    if listed[:len(have)] != have:
        raise ConfigError(f"{cfg.path}: the results were identified with extensions {listed}, "
                          f"the config declares {have}")
    model = model_with_candidates(cfg.model, listed[len(have):], result.info.get("shape_parameters"))
    free = list(cfg.free)
    for n in result.parameters[len(free):]:
        if n not in model.parameters:
            raise ConfigError(f"{cfg.path}: the results' free parameter {n!r} is neither in the config nor a "
                              f"strength of the effects {listed[len(have):]}")
        spec = model.parameters.spec(n)
        lo, hi = spec.bounds
        free.append(FreeParameter(n, min(max(spec.value, lo), hi), lo, hi, spec.scale or 1.0))
    if [f.name for f in free] != list(result.parameters):
        raise ConfigError(f"{cfg.path}: the results' free parameters {result.parameters} do not extend the config's "
                          f"{[f.name for f in cfg.free]}")
    return dataclasses.replace(cfg, model=model, free=free)


def load_result_config(results_dir: str | Path, config: str | Path | None = None, result=None,
                       warn=None) -> IdentificationConfig:
    """The identification config of a results folder (``config``, else the one named in ``chosen.json``, see
    :func:`pyomo_heli.diagnosis.residuals.find_config`), checked against the folder: free parameters, fitted
    maneuvers, dataset content and model must agree (:func:`pyomo_heli.provenance.check_results_match`,
    ResultsMismatchError otherwise). For an iteration of close-loop, the config plus the effects the loop added
    (:func:`config_of_result`)."""
    from .diagnosis.residuals import find_config
    from .pareto.result import IdentificationResult
    from .provenance import check_results_match

    res = result or IdentificationResult.load(results_dir)
    cfg = load_identification_config(config or find_config(results_dir, res))
    if res.info.get("extensions"):
        cfg = config_of_result(cfg, res)
    check_results_match(cfg, res, results_dir, **({"warn": warn} if warn else {}))
    return cfg
