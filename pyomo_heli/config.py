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

from .nlp.identification import TIME_OUTPUTS, TRIM_OUTPUTS, NLPOptions
from .nlp.parameters import FreeParameter
from .pareto.front import ParetoSettings
from .physics.model import INPUTS, HelicopterModel
from .units import SENSOR_SIGMA_KEYS
from .solvers import SOLVER_NAMES, validate_solver_options


#: largest noise sigma [SI: rad, rad/s, g, m/s] a config may give: no sensor is that poor; larger is a unit slip
SIGMA_MAX_SI = 10.0


class ConfigError(ValueError):
    """A bad identification config; the message names the file and field."""


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
        return self.diagnosis or DiagnosisSettings(tuple(self.nlp.input_errors), self.nlp.noise_sigma)


@dataclass(frozen=True)
class DiagnosisSettings:
    """``[diagnosis]``: the input-noise model of the residual analysis (docs/diagnosis.md).

    ``input_noise``: the input channels whose measurement noise the whiteness test takes out (the
    residuals' innovations, :mod:`pyomo_heli.diagnosis.innovations`); default the identification's
    ``[objectives] input_errors``. Giving it to an output-error identification (inputs taken as exact)
    keeps the exact model from being called "not white" because its replay is driven by noisy inputs.
    ``noise_sigma``: the sigmas [SI] of the input and output channels (``[diagnosis.noise_sigma]``, same
    keys and units as ``[objectives.noise_sigma]``); None: from the records' quiet lead-in.
    """
    input_noise: tuple = ()
    noise_sigma: dict | None = None


def _need(d, key, where, types, default=...):
    if key not in d:
        if default is ...:
            raise ConfigError(f"{where}: missing field '{key}'")
        return default
    v = d[key]
    if (isinstance(v, bool) and types is not bool) or not isinstance(v, types):
        names = "/".join(t.__name__ for t in (types if isinstance(types, tuple) else (types,)))
        raise ConfigError(f"{where}: field '{key}' must be {names}, got {v!r}")
    return v


def _only(d: dict, allowed, where: str) -> None:
    """A misspelt key is an error, not a silently ignored setting."""
    unknown = sorted(set(d) - set(allowed))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(unknown)}; use {', '.join(sorted(allowed))}")


def _names(v, where: str, key: str, allow_empty: bool = False) -> list:
    """A list of distinct strings (maneuver, output or channel names)."""
    if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
        raise ConfigError(f"{where}: field '{key}' must be a list of names, got {v!r}")
    if not v and not allow_empty:
        raise ConfigError(f"{where}: field '{key}' is empty")
    dup = sorted({x for x in v if v.count(x) > 1})
    if dup:
        raise ConfigError(f"{where}: field '{key}' names {dup} more than once")
    return v


def _finite(d: dict, key: str, where: str, default=None):
    """An optional finite number (not a bool)."""
    v = d.get(key, default)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ConfigError(f"{where}: field '{key}' must be a finite number, got {v!r}")
    return float(v)


def _unit_factor(spec, unit: str, where: str) -> float:
    if unit in (spec.unit, "SI", ""):
        return 1.0
    if spec.display is not None and unit == spec.display[0]:
        return 1.0 / spec.display[1]
    allowed = [spec.unit] + ([spec.display[0]] if spec.display else [])
    raise ConfigError(f"{where}: unit '{unit}' not recognised for {spec.name}; use {' or '.join(allowed)}")


def load_identification_config(path: str | Path, overrides: dict | None = None,
                               raw: dict | None = None) -> IdentificationConfig:
    """Read and check an identification config. ``overrides`` replace top-level tables (tests, CLI).

    ``raw``: the config's tables as a dict (the parsed TOML) instead of reading ``path``; ``path`` then
    only names the config in messages and is the base of relative paths (its folder).
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
        raw[k] = {**raw.get(k, {}), **v} if isinstance(v, dict) else v
    f = str(path)
    known = {"data", "model", "parameters", "objectives", "discretization", "pareto", "solver", "study", "loop",
             "linear", "diagnosis"}
    unknown = set(raw) - known
    if unknown:
        raise ConfigError(f"{f}: unknown table(s) {sorted(unknown)}; expected {sorted(known)}")
    for k, v in raw.items():
        if not isinstance(v, dict):
            raise ConfigError(f"{f}: '{k}' must be a table [{k}], got {v!r}")

    data = _need(raw, "data", f, dict)
    _only(data, ("dataset", "maneuvers", "validation", "resample_hz", "resample_inputs", "max_duration_s",
                 "input_reference_s"), f"{f} [data]")
    ds = Path(_need(data, "dataset", f"{f} [data]", str))
    if not ds.is_absolute():
        ds = (path.parent / ds).resolve()
    if not ds.is_dir():
        raise ConfigError(f"{f} [data]: field 'dataset': folder {ds} not found")
    if not (ds / "manifest.json").is_file():
        raise ConfigError(f"{f} [data]: field 'dataset': {ds} is not a flight-test folder (no manifest.json; "
                          f"docs/data_format.md)")
    mans = data.get("maneuvers", "identification")
    if mans != "identification":
        if not isinstance(mans, list):
            raise ConfigError(f"{f} [data]: field 'maneuvers' must be \"identification\" or a list of names")
        _names(mans, f"{f} [data]", "maneuvers")
    val = data.get("validation", "validation")
    if val != "validation":
        if not isinstance(val, list):
            raise ConfigError(f"{f} [data]: field 'validation' must be \"validation\" or a list of names")
        _names(val, f"{f} [data]", "validation", allow_empty=True)
        both = [n for n in val if isinstance(mans, list) and n in mans]
        if both:  # a record the fit has seen validates nothing
            raise ConfigError(f"{f} [data]: maneuver(s) {', '.join(both)} listed in both 'maneuvers' (fitted) and "
                              f"'validation'; a validation record must be one the fit has not seen")
    resample = _finite(data, "resample_hz", f"{f} [data]")
    if resample is not None and not resample > 0:
        raise ConfigError(f"{f} [data]: field 'resample_hz' must be a positive number")
    max_dur = _finite(data, "max_duration_s", f"{f} [data]")
    if max_dur is not None and not max_dur > 0:
        raise ConfigError(f"{f} [data]: field 'max_duration_s' must be a positive number")
    res_in = data.get("resample_inputs", "project")
    if res_in not in ("sample", "project"):
        raise ConfigError(f"{f} [data]: field 'resample_inputs' must be \"sample\" or \"project\", got {res_in!r}")
    in_ref = data.get("input_reference_s", 0.0)
    if isinstance(in_ref, bool) or not isinstance(in_ref, (int, float)) or not 0 <= in_ref < float("inf"):
        raise ConfigError(f"{f} [data]: field 'input_reference_s' must be a number >= 0, got {in_ref!r}")

    mdl = raw.get("model", {})
    _only(mdl, ("extensions", "parameters"), f"{f} [model]")
    extensions = []
    ext_names = _names(_need(mdl, "extensions", f"{f} [model]", list, []), f"{f} [model]", "extensions",
                       allow_empty=True)
    if ext_names:
        from .diagnosis.candidates import make_candidate

        for n in ext_names:
            try:
                extensions.append(make_candidate(n))
            except KeyError as exc:
                raise ConfigError(f"{f} [model]: field 'extensions': {exc.args[0]}") from None
    model = HelicopterModel(extensions=extensions)
    fixed = _need(mdl, "parameters", f"{f} [model]", dict, {})
    for k in fixed:
        if k not in model.parameters:
            raise ConfigError(f"{f} [model.parameters]: unknown parameter name '{k}'")
    if fixed:
        try:
            model = model.with_parameters(**fixed)
        except ValueError as exc:
            raise ConfigError(f"{f} [model.parameters]: {exc}") from None

    params = _need(raw, "parameters", f, dict)
    if not params:
        raise ConfigError(f"{f} [parameters]: no free parameter given")
    free = []
    for name, spec_raw in params.items():
        where = f"{f} [parameters.{name}]"
        if name not in model.parameters:
            msg = model.parameters._unknown(name)
            raise ConfigError(f"{where}: {msg}")
        if not isinstance(spec_raw, dict):
            raise ConfigError(f"{where}: must be a table with initial, lower, upper, scale, unit")
        _only(spec_raw, ("initial", "lower", "upper", "scale", "unit"), where)
        spec = model.parameters.spec(name)
        fac = _unit_factor(spec, _need(spec_raw, "unit", where, str, spec.unit), where)
        def num(key, default):
            v = _finite(spec_raw, key, where, default)
            return None if v is None else v * fac
        lo_d, hi_d = spec.bounds or (None, None)
        initial = num("initial", None)
        lower = num("lower", None) if "lower" in spec_raw else lo_d
        upper = num("upper", None) if "upper" in spec_raw else hi_d
        scale = num("scale", None) if "scale" in spec_raw else spec.scale
        if initial is None:
            initial = spec.value
        if lower is None or upper is None:
            raise ConfigError(f"{where}: give 'lower' and 'upper' (no default range for {name})")
        if "scale" in spec_raw and not scale > 0:
            raise ConfigError(f"{where}: field 'scale' must be a number > 0, got {spec_raw['scale']!r}")
        try:
            # both bounds must be values the physics can take (a negative mass, a zero air density, ...)
            spec.check(lower)
            spec.check(upper)
            free.append(FreeParameter(name, initial, lower, upper, scale if scale else max(abs(initial), 1.0)))
        except ValueError as exc:
            raise ConfigError(f"{where}: {exc} (bounds in SI: [{lower:g}, {upper:g}])") from None

    obj = raw.get("objectives", {})
    _only(obj, ("use", "time_outputs", "trim_outputs", "covariance", "input_errors", "noise_sigma"),
          f"{f} [objectives]")
    t_out = tuple(_names(_need(obj, "time_outputs", f"{f} [objectives]", list, list(NLPOptions.time_outputs)),
                         f"{f} [objectives]", "time_outputs"))
    r_out = tuple(_names(_need(obj, "trim_outputs", f"{f} [objectives]", list, list(NLPOptions.trim_outputs)),
                         f"{f} [objectives]", "trim_outputs"))
    for o in t_out:
        if o not in TIME_OUTPUTS:
            raise ConfigError(f"{f} [objectives]: unknown output '{o}' in time_outputs; choose from "
                              f"{', '.join(TIME_OUTPUTS)}")
    for o in r_out:
        if o not in TRIM_OUTPUTS:
            raise ConfigError(f"{f} [objectives]: unknown output '{o}' in trim_outputs; choose from "
                              f"{', '.join(TRIM_OUTPUTS)}")
    cov = _need(obj, "covariance", f"{f} [objectives]", str, "diagonal")
    if cov not in ("diagonal", "full"):
        raise ConfigError(f"{f} [objectives]: field 'covariance' must be diagonal or full")
    in_err, noise_sigma = _input_errors(obj, f, in_ref=raw.get("data", {}).get("input_reference_s", 0.0))
    if noise_sigma is not None:
        lacking = [c for c in t_out + in_err if c not in noise_sigma]
        if lacking:
            raise ConfigError(f"{f} [objectives.noise_sigma]: no sigma for {lacking} (every time output and every "
                              f"channel of input_errors needs one); keys: {', '.join(SENSOR_SIGMA_KEYS)}")
    disc = raw.get("discretization", {})
    _only(disc, ("ncp",), f"{f} [discretization]")
    ncp = _need(disc, "ncp", f"{f} [discretization]", int, 2)
    if not 1 <= ncp <= 5:
        raise ConfigError(f"{f} [discretization]: field 'ncp' must be 1..5")
    nlp = NLPOptions(time_outputs=t_out, trim_outputs=r_out, covariance=cov, ncp=ncp, input_errors=in_err,
                     noise_sigma=noise_sigma)

    par = raw.get("pareto", {})
    _only(par, ("points", "spacing", "warm_start", "cold_check", "predictor", "placement", "max_solves"),
          f"{f} [pareto]")
    sol = raw.get("solver", {})
    unknown = sorted(set(sol) - {"name", "options", "point_rows"})
    if unknown:
        raise ConfigError(f"{f} [solver]: unknown key(s) {', '.join(unknown)}; use name, options, point_rows")
    solver = _need(sol, "name", f"{f} [solver]", str, "casadi-ipopt")
    if solver not in SOLVER_NAMES:
        raise ConfigError(f"{f} [solver]: field 'name': unknown solver '{solver}'; "
                          f"choose from {', '.join(SOLVER_NAMES)}")
    solver_options = dict(_need(sol, "options", f"{f} [solver]", dict, {}))
    if "point_rows" in solver_options:
        raise ConfigError(f"{f} [solver]: point_rows is a [solver] field, not an Ipopt option")
    try:  # a bad option must not reach the solver: a NaN tol hung Ipopt, an absent linear solver crashed it
        validate_solver_options(solver, solver_options)
    except ValueError as exc:
        raise ConfigError(f"{f} [solver] options: {exc}") from None
    if not _need(sol, "point_rows", f"{f} [solver]", bool, True):
        # every row through the NL file (docs/performance.md, "What was done" 8)
        if solver != "casadi-ipopt":
            raise ConfigError(f"{f} [solver]: field 'point_rows' applies to casadi-ipopt only (the AMPL solvers "
                              f"read every row from the NL file anyway)")
        solver_options["point_rows"] = False
    points = _need(par, "points", f"{f} [pareto]", int, 11)
    if not 2 <= points <= 1000:
        raise ConfigError(f"{f} [pareto]: field 'points': the epsilon grid needs 2 (the anchors) to 1000 points, "
                          f"got {points}")
    try:
        pareto = ParetoSettings(points=points, spacing=_need(par, "spacing", f"{f} [pareto]", str, "geometric"),
                                warm_start=_need(par, "warm_start", f"{f} [pareto]", str, "continuation"),
                                cold_check=bool(_need(par, "cold_check", f"{f} [pareto]", bool, False)),
                                predictor=_need(par, "predictor", f"{f} [pareto]", str, "secant"),
                                placement=_need(par, "placement", f"{f} [pareto]", str, "uniform"),
                                max_solves=_need(par, "max_solves", f"{f} [pareto]", int, 14),
                                solver=solver, solver_options=solver_options)
    except ConfigError:
        raise
    except ValueError as exc:
        raise ConfigError(f"{f} [pareto]: {exc}") from None
    use, linear = _objectives_use(raw, f)
    if pareto.placement == "adaptive" and "linear" in use:
        raise ConfigError(f"{f} [pareto]: placement = \"adaptive\" applies to the two-objective front (J_time, "
                          f"J_trim) so far; use placement = \"uniform\" with [objectives] use = [..., \"linear\"]")
    diagnosis = _diagnosis(raw, f, in_ref)
    return IdentificationConfig(path=path, dataset=ds, maneuvers=mans, validation=val,
                                resample_hz=float(resample) if resample else None,
                                max_duration=float(max_dur) if max_dur else None, model=model, free=free,
                                nlp=nlp, pareto=pareto, raw=raw, objectives=use, linear=linear,
                                input_reference_s=float(in_ref), resample_inputs=res_in, diagnosis=diagnosis)


def _input_errors(obj: dict, f, in_ref, table: str = "objectives",
                  key: str = "input_errors") -> tuple[tuple, dict | None]:
    """[objectives] input_errors (errors in variables) and the optional [objectives.noise_sigma] table; the
    same for [diagnosis] input_noise and [diagnosis.noise_sigma] (``table``, ``key``)."""
    chans = tuple(_names(_need(obj, key, f"{f} [{table}]", list, []), f"{f} [{table}]", key, allow_empty=True))
    bad = [c for c in chans if c not in INPUTS]
    if bad:
        raise ConfigError(f"{f} [{table}]: unknown input channel(s) {bad} in {key}; choose from "
                          f"{', '.join(INPUTS)}")
    given = _need(obj, "noise_sigma", f"{f} [{table}]", dict, None)
    if given is not None and not chans:
        raise ConfigError(f"{f} [{table}]: noise_sigma is only used with {key}")
    if chans and given is None and not (isinstance(in_ref, (int, float)) and in_ref > 0):
        raise ConfigError(f"{f} [{table}]: {key} takes the noise sigmas from the records' quiet "
                          f"lead-in; set [data] input_reference_s > 0 or give [{table}.noise_sigma]")
    sigma = None
    if given is not None:
        sigma = {}
        for k, v in given.items():
            if k not in SENSOR_SIGMA_KEYS:
                raise ConfigError(f"{f} [{table}.noise_sigma]: unknown key '{k}'; use {', '.join(SENSOR_SIGMA_KEYS)}")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < math.inf:
                raise ConfigError(f"{f} [{table}.noise_sigma]: '{k}' must be a positive number, got {v!r}")
            ch, factor = SENSOR_SIGMA_KEYS[k]
            if float(v) * factor > SIGMA_MAX_SI:
                raise ConfigError(f"{f} [{table}.noise_sigma]: '{k}' = {v!r} is not a sensor noise sigma (above "
                                  f"{SIGMA_MAX_SI:g} in SI: rad, rad/s, g or m/s); a unit slip?")
            sigma[ch] = float(v) * factor
    return chans, sigma


def _diagnosis(raw: dict, f, in_ref) -> DiagnosisSettings | None:
    """The [diagnosis] table; None when absent (the residual analysis follows the identification)."""
    if "diagnosis" not in raw:
        return None
    d = raw["diagnosis"]
    if not isinstance(d, dict):
        raise ConfigError(f"{f} [diagnosis]: must be a table")
    unknown = sorted(set(d) - {"input_noise", "noise_sigma"})
    if unknown:
        raise ConfigError(f"{f} [diagnosis]: unknown key(s) {', '.join(unknown)}; use input_noise, noise_sigma")
    chans, sigma = _input_errors(d, f, in_ref, table="diagnosis", key="input_noise")
    return DiagnosisSettings(chans, sigma)


#: the objective sets an identification can use ([objectives] use)
OBJECTIVE_SETS = (("time", "trim"), ("time", "trim", "linear"))


def _objectives_use(raw: dict, f: str):
    """[objectives] use and the [linear] table (local linear models, J_linear)."""
    from .linear_settings import LinearSettings

    obj = raw.get("objectives", {})
    use = _names(_need(obj, "use", f"{f} [objectives]", list, ["time", "trim"]), f"{f} [objectives]", "use")
    bad = [u for u in use if u not in ("time", "trim", "linear")]
    if bad:
        raise ConfigError(f"{f} [objectives]: field 'use': unknown objective(s) {bad}; choose from time, trim, linear")
    order = tuple(k for k in ("time", "trim", "linear") if k in use)
    if order not in OBJECTIVE_SETS:
        raise ConfigError(f"{f} [objectives]: field 'use': {list(use)} is not supported; use "
                          + " or ".join(str(list(s)) for s in OBJECTIVE_SETS))
    lin_raw = raw.get("linear", {})
    if "linear" not in order:
        if lin_raw:
            raise ConfigError(f"{f} [linear]: given but [objectives] use does not include \"linear\"")
        return order, None
    if not isinstance(lin_raw, dict):
        raise ConfigError(f"{f} [linear]: must be a table")
    try:
        return order, LinearSettings.from_table(lin_raw)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{f} [linear]: {exc}") from None


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
