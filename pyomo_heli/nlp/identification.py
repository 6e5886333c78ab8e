"""One Pyomo NLP for all the data: maneuvers, trim points, shared parameters.

Layout of the model ``m`` built by :func:`build_identification_nlp`:

- ``m.theta_s[name]``   free parameters (scaled), shared by every block
- ``m.trim[i]``         one trim block per distinct trim speed; a trim data
                        point and a maneuver start at the same speed share it
- ``m.man[name]``       one collocation block per maneuver, started from the
                        trim block at its speed, inputs = model trim + measured increments
- ``m.J_time``, ``m.J_trim``  the objectives (expressions), see :mod:`.objectives`
- ``m.eps_trim``        mutable Param: epsilon bound of ``m.eps_con: J_trim <= eps_trim``
- ``m.objective``       the active objective (swapped by :func:`set_objective`)

Everything the physics sees is in SI units; objectives are scaled only in
``m.objective`` (optimizer level, paper Fig. 4).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pyomo.environ as pyo
from pyomo.common.gc_manager import PauseGC

from ..channels import INPUTS, OUTPUTS, TRIM_CHANNELS
from ..dataset.schema import lead_in
from ..physics.model import FLAPPING, HelicopterModel
from ..simulation.replay import replay
from ..simulation.trim import trim_sweep
from .maneuver_block import build_maneuver_block, initialise_from
from .objectives import (add_known_noise_time_objective, add_time_objective, add_trim_objective, lead_in_ar,
                         noise_sigmas)
from .parameters import FreeParameter, add_parameters
from .trim_block import build_trim_block

TIME_OUTPUTS = OUTPUTS
TRIM_OUTPUTS = TRIM_CHANNELS
#: bound of the estimated input errors, in noise sigmas (NLPOptions.input_errors)
INPUT_ERROR_BOUND = 6.0
#: highest order of the input errors' autoregressive model (NLPOptions.input_error_ar)
MAX_INPUT_ERROR_AR = 8


@dataclass
class NLPOptions:
    """How the data become an NLP."""

    time_outputs: tuple = ("q", "theta", "n_x", "n_z", "TAS")
    trim_outputs: tuple = TRIM_OUTPUTS
    covariance: str = "diagonal"
    ncp: int = 2
    scheme: str = "LAGRANGE-RADAU"
    #: measured outputs and trims as variables pinned by equal bounds (``y_meas``,
    #: ``m.trim_meas``) instead of numbers, so that :func:`set_measurements` can swap
    #: in another data set (a noise realization) and re-solve without a rebuild
    mutable_data: bool = False
    #: input channels whose measurement errors are estimated (errors in variables, see
    #: :mod:`.objectives`); J_time then uses known noise sigmas instead of the estimated R
    input_errors: tuple = ()
    #: channel -> noise sigma [SI] of the outputs and the error inputs when ``input_errors`` is set;
    #: None: estimated from the records' quiet lead-in (``objectives.lead_in_sigma``)
    noise_sigma: dict | None = None
    #: order of the autoregressive model of the input errors, fitted to the records' quiet lead-in
    #: (``objectives.lead_in_ar``); 0: independent errors from sample to sample
    input_error_ar: int = 0
    #: the error of each record's input reference estimated too: the measured increments are referred to the mean of
    #: the quiet lead-in (``input_reference_s``), whose noise offsets every later sample alike. The noise of a sample
    #: is then its increment's error plus the record's reference error ``blk.u_ref``, the errors' mean over the
    #: lead-in is zero by construction (``blk.lead_in_mean``), and the noise model applies to the sum
    input_reference_error: bool = False
    #: order of the autoregressive model of the output noise, fitted to the records' quiet lead-in like the input
    #: errors' (``objectives.lead_in_ar``); J_output then weighs each record's residuals by their one-step prediction
    #: errors. 0: independent residuals. Needs ``input_errors`` (the known-noise J_time)
    output_error_ar: int = 0

    def __post_init__(self):
        bad = [o for o in self.time_outputs if o not in TIME_OUTPUTS]
        if bad:
            raise ValueError(f"unknown time output(s) {bad}; choose from {', '.join(TIME_OUTPUTS)}")
        bad = [o for o in self.trim_outputs if o not in TRIM_OUTPUTS]
        if bad:
            raise ValueError(f"unknown trim output(s) {bad}; choose from {', '.join(TRIM_OUTPUTS)}")
        if not self.time_outputs and not self.trim_outputs:
            raise ValueError("no outputs selected")
        self.input_errors = tuple(self.input_errors)
        bad = [c for c in self.input_errors if c not in INPUTS]
        if bad:
            raise ValueError(f"unknown input channel(s) {bad} in input_errors; choose from {', '.join(INPUTS)}")
        for name in ("input_error_ar", "output_error_ar"):
            order = getattr(self, name)
            if not (isinstance(order, int) and 0 <= order <= MAX_INPUT_ERROR_AR):
                raise ValueError(f"{name} = {order!r}: an integer from 0 to {MAX_INPUT_ERROR_AR}")
        if self.output_error_ar and not self.input_errors:
            raise ValueError("output_error_ar weighs the known-noise J_time: give input_errors too")
        if self.covariance == "full" and self.input_errors:
            raise ValueError("covariance = 'full' is not used with input_errors (their J_time has the known noise "
                             "sigmas, diagonal)")
        if self.noise_sigma is not None:
            bad = [k for k, v in self.noise_sigma.items() if not (isinstance(v, (int, float)) and v > 0)]
            if bad:
                raise ValueError(f"noise_sigma of {bad} must be positive numbers")


@dataclass
class IdentificationData:
    """The data one NLP is built from (SI units), already selected and resampled.

    maneuvers: list of dataset Maneuver objects (data, trim_speed, name).
    trims: DataFrame with V, col, lon, theta (one row per trim point).
    """

    maneuvers: list
    trims: object
    speed_tol: float = 1e-6
    speeds: list = field(default_factory=list)

    def __post_init__(self):
        speeds = sorted({round(float(v), 6) for v in self.trims["V"]} | {round(m.trim_speed, 6)
                                                                          for m in self.maneuvers})
        self.speeds = speeds

    def speed_index(self, V: float) -> int:
        return self.speeds.index(round(float(V), 6))


def _model_at(model: HelicopterModel, free: list[FreeParameter]) -> HelicopterModel:
    return model.with_parameters(**{f.name: f.initial for f in free}) if free else model


def build_identification_nlp(data: IdentificationData, model: HelicopterModel, free: list[FreeParameter],
                             options: NLPOptions | None = None, responses=None) -> pyo.ConcreteModel:
    """Build the full-discretisation NLP, initialised from a simulation at the initial parameters.

    responses: data frequency responses (coherent band only); if given, the model's
    linearisations and ``m.J_linear`` (paper Eq. 9) are added, see :mod:`.linear_model`.
    """
    # Pyomo creates hundreds of thousands of small container objects here; Python's cyclic garbage
    # collector would walk the growing model again and again (Case 1 build 16.2 s with it, 4.4 s
    # without, docs/performance.md). Pyomo's own writers pause it the same way.
    with PauseGC():
        return _build(data, model, free, options or NLPOptions(), responses)


def _build(data: IdentificationData, model: HelicopterModel, free: list[FreeParameter], opts: NLPOptions,
           responses) -> pyo.ConcreteModel:
    m = pyo.ConcreteModel(name="identification")
    pmap = add_parameters(m, model.parameters, free)
    m.extensions = [e.name for e in model.extensions]

    # --- trim blocks, initialised from float trims at the initial guess
    sim_model = _model_at(model, free)
    float_trims, sims = _float_start(sim_model, data)
    m.trim_speeds = pyo.Set(initialize=range(len(data.speeds)), ordered=True)
    m.trim = pyo.Block(m.trim_speeds)
    for i, (V, tp) in enumerate(zip(data.speeds, float_trims)):
        guess = {**tp.to_dict(), **tp.extra_states}
        build_trim_block(m.trim[i], model, pmap, V, guess=guess)

    # --- trim objective
    trim_res = []
    if opts.mutable_data:
        m.trim_meas = pyo.Var(range(len(data.trims)), list(opts.trim_outputs))
    for i, (_, row) in enumerate(data.trims.iterrows()):
        blk = m.trim[data.speed_index(row["V"])]
        if opts.mutable_data:
            trim_res.append([m.trim_meas[i, k] - getattr(blk, k) for k in opts.trim_outputs])
        else:
            trim_res.append([row[k] - getattr(blk, k) for k in opts.trim_outputs])
    if trim_res and opts.trim_outputs:
        add_trim_objective(m, trim_res)
    else:
        m.J_trim = pyo.Expression(expr=0.0)

    # --- maneuvers
    names = [mv.name for mv in data.maneuvers]
    m.maneuver_names = pyo.Set(initialize=names, ordered=True)
    m.man = pyo.Block(m.maneuver_names)
    residuals = {o: [] for o in opts.time_outputs}
    for mv in data.maneuvers:
        blk = m.man[mv.name]
        t_in, increments = mv.input_series()
        build_maneuver_block(blk, model, pmap, mv.data["t"].to_numpy(), increments,
                             m.trim[data.speed_index(mv.trim_speed)], ncp=opts.ncp, scheme=opts.scheme,
                             input_errors=opts.input_errors, input_times=t_in)
        if opts.mutable_data:
            blk.y_meas = pyo.Var(list(opts.time_outputs), blk.samples)
        for o in opts.time_outputs:
            meas = mv.data[o].to_numpy()
            if opts.mutable_data:
                residuals[o].extend(blk.y_meas[o, tt] - blk.y[o, tt] for tt in blk.samples)
            else:
                residuals[o].extend(float(y) - blk.y[o, tt] for y, tt in zip(meas, blk.samples))
    init_res = _start_maneuvers(m, data, sims, sim_model.state_names, opts.time_outputs)
    if opts.input_errors and opts.mutable_data and opts.noise_sigma is None:
        raise ValueError("input_errors with mutable_data needs noise_sigma: sigmas estimated from the lead-in "
                         "of the first data set would be kept for every other one")
    if data.maneuvers and opts.time_outputs and opts.input_errors:
        sigma = noise_sigmas(data.maneuvers, (*opts.time_outputs, *opts.input_errors), opts.noise_sigma,
                             input_record=True)
        m.noise_sigma_source = "given" if opts.noise_sigma is not None else "lead-in"
        errs = {c: [m.man[n].u_err[c, tt] for n in names for tt in m.man[n].input_samples]
                for c in opts.input_errors}
        for c, vs in errs.items():
            # An error beyond INPUT_ERROR_BOUND sigmas has no probability worth the name; the bound keeps
            # the first iterates from a far start (30 % off) from spending the outputs' misfit on the inputs.
            for v in vs:
                v.setlb(-INPUT_ERROR_BOUND * sigma[c])
                v.setub(INPUT_ERROR_BOUND * sigma[c])
        if opts.input_reference_error:
            errs = _with_reference_errors(m, data, names, opts.input_errors, sigma)
        err_sigma = dict(sigma)
        if opts.input_error_ar:
            # the errors' likelihood through their one-step prediction errors (innovations) under an AR model of
            # the lead-in's noise, per maneuver, the samples before each record's first taken as zero
            m.input_error_ar = {}
            for c in opts.input_errors:
                a, ratio = lead_in_ar(data.maneuvers, c, opts.input_error_ar, input_record=True)
                m.input_error_ar[c] = list(a)
                err_sigma[c] = sigma[c] * ratio
                errs[c] = [w for e in _cut(errs[c], [len(m.man[n].input_samples) for n in names])
                           for w in _ar_innovation(e, a)]
        out_sigma = dict(sigma)
        if opts.output_error_ar:
            # the same for the output noise, on each record's residuals at its samples
            m.output_error_ar = {}
            counts = [len(m.man[n].samples) for n in names]
            for o in opts.time_outputs:
                a, ratio = lead_in_ar(data.maneuvers, o, opts.output_error_ar)
                m.output_error_ar[o] = list(a)
                out_sigma[o] = sigma[o] * ratio
                residuals[o] = [w for e in _cut(residuals[o], counts) for w in _ar_innovation(e, a)]
            # MUMPS' pivot tolerance 1e-4 instead of its 1e-6 for these rows, which couple neighbouring samples: at
            # 1e-6 MUMPS reported a wrong inertia on every iteration once mu was small, and the regularised steps
            # crept (point A, the bundled set's ten records, AR(2): still creeping at iteration 60; at 1e-4 optimal
            # in 34 iterations, 51 s). Not a default for every NLP: the noise-free Case 2 exactness fit took 107 s
            # at 1e-4 against 74 s (docs/performance.md).
            m.ipopt_defaults = {"mumps_pivtol": 1e-4}
        add_known_noise_time_objective(m, residuals, list(opts.time_outputs), out_sigma, errs, err_sigma)
    elif data.maneuvers and opts.time_outputs:
        add_time_objective(m, residuals, list(opts.time_outputs), opts.covariance,
                           {o: np.array(v) for o, v in init_res.items()})
    else:
        m.J_time = pyo.Expression(expr=0.0)

    # --- local linear models (third objective), only when asked for
    if responses:
        from .linear_model import add_linear_information

        add_linear_information(m, model, pmap, responses, data.speeds, [m.trim[i] for i in m.trim_speeds])

    # --- epsilon constraint and the active objective
    m.eps_trim = pyo.Param(initialize=1e20, mutable=True)
    m.eps_con = pyo.Constraint(expr=m.J_trim <= m.eps_trim)
    m.objective = pyo.Objective(expr=m.J_time)
    m.options = opts
    if opts.mutable_data:
        set_measurements(m, data)
    return m


def _cut(flat: list, counts: list) -> list:
    """A flat list of every record's entries, cut into one list per record (``counts``: each record's length)."""
    out, i = [], 0
    for k in counts:
        out.append(flat[i:i + k])
        i += k
    return out


def _with_reference_errors(m, data: IdentificationData, names, channels, sigma: dict) -> dict:
    """Channel -> the input noise of every sample of every record, ``u_err + u_ref`` (NLPOptions.input_reference_error).

    Per record: ``blk.u_ref[c]``, the noise mean over the quiet lead-in that the increments were referred to (the
    samples with t <= t0 + ``input_reference_s``, as :meth:`~pyomo_heli.dataset.schema.Maneuver.increments` takes
    them), and ``blk.lead_in_mean[c]``: the increments' errors sum to zero over the lead-in, as the increments do.
    """
    by = {mv.name: mv for mv in data.maneuvers}
    for n in names:
        blk, mv = m.man[n], by[n]
        if mv.input_reference_s <= 0:
            raise ValueError(f"maneuver {n}: input_reference_error needs the inputs referred to a quiet lead-in; "
                             f"give [data] input_reference_s > 0")
        t_in = list(blk.input_samples)
        lead = [t for t, inside in zip(t_in, lead_in(t_in, mv.input_reference_s)) if inside]
        blk.u_ref = pyo.Var(list(channels), initialize=0.0,
                            bounds=lambda _, c: (-INPUT_ERROR_BOUND * sigma[c], INPUT_ERROR_BOUND * sigma[c]))
        blk.lead_in_mean = pyo.Constraint(list(channels),
                                          rule=lambda b, c: sum(b.u_err[c, t] for t in lead) / len(lead) == 0.0)
    return {c: [m.man[n].u_err[c, t] + m.man[n].u_ref[c] for n in names for t in m.man[n].input_samples]
            for c in channels}


def _ar_innovation(errors: list, a) -> list:
    """``w_k = e_k - sum_j a_j e_{k-j}`` of a record's error variables (pre-record errors zero)."""
    return [e - sum(a[j] * errors[k - 1 - j] for j in range(min(len(a), k))) for k, e in enumerate(errors)]


def _float_start(sim_model: HelicopterModel, data: IdentificationData) -> tuple[list, dict]:
    """The start of the NLP at ``sim_model``'s parameters: float trims at every trim speed of ``data``
    and the RK4 replay (2 sub-steps per sample, no divergence rule) of every maneuver from its speed's
    trim. Raises TrimError when the model cannot be trimmed. The Python RK4 (``compiled=False``): the start is then
    the same to the bit as before the replays ran compiled, and some small NLPs land elsewhere from a start that
    differs in the 13th digit (tests/test_placement_nd.py's direct Eq. 11 solve did); it is run once per build."""
    float_trims = trim_sweep(sim_model, data.speeds)
    sims = {mv.name: replay(sim_model, mv, float_trims[data.speed_index(mv.trim_speed)], substeps=2, check=False,
                            compiled=False)
            for mv in data.maneuvers}
    return float_trims, sims


def _start_maneuvers(m: pyo.ConcreteModel, data: IdentificationData, sims: dict, states, outputs) -> dict:
    """Set every maneuver block's variables to its replay in ``sims`` (input errors at zero); return
    output -> data - replay at every sample (the start of the covariance estimate)."""
    init_res = {o: [] for o in outputs}
    for mv in data.maneuvers:
        blk, sim = m.man[mv.name], sims[mv.name]
        initialise_from(blk, sim, states)
        for name in ("u_err", "u_ref"):
            if blk.component(name) is not None:
                for v in blk.component(name).values():
                    v.set_value(0.0)
        for o in outputs:
            init_res[o].extend(mv.data[o].to_numpy() - sim[o].to_numpy())
    return init_res


def _pin(var, value: float) -> None:
    var.setlb(value)
    var.setub(value)
    var.set_value(value, skip_validation=True)


def set_measurements(m: pyo.ConcreteModel, data: IdentificationData) -> None:
    """Pin the measured outputs and trims of an NLP built with ``mutable_data`` to ``data``.

    ``data`` must have the NLP's maneuvers (same names and sample times) and
    trim speeds in the same order; only the measured values may differ. A
    solver adapter picks the new values up as bounds on the next re-solve.
    """
    if m.component("trim_meas") is None and not any(m.man[n].component("y_meas") is not None
                                                     for n in m.maneuver_names):
        raise ValueError("the NLP was built without NLPOptions(mutable_data=True)")
    opts = m.options
    if [mv.name for mv in data.maneuvers] != list(m.maneuver_names):
        raise ValueError(f"maneuvers {[mv.name for mv in data.maneuvers]} differ from the NLP's "
                         f"{list(m.maneuver_names)}")
    for mv in data.maneuvers:
        blk = m.man[mv.name]
        samples = list(blk.samples)
        if len(samples) != len(mv.data) or not np.allclose(samples, mv.data["t"].to_numpy()):
            raise ValueError(f"maneuver {mv.name}: sample times differ from the NLP's")
        for o in opts.time_outputs:
            for tt, y in zip(samples, mv.data[o].to_numpy()):
                _pin(blk.y_meas[o, tt], float(y))
    if m.component("trim_meas") is not None:
        if len(data.trims) != len({i for i, _ in m.trim_meas}):
            raise ValueError(f"{len(data.trims)} trim points differ from the NLP's")
        for i, (_, row) in enumerate(data.trims.iterrows()):
            for k in opts.trim_outputs:
                _pin(m.trim_meas[i, k], float(row[k]))


def set_objective(m: pyo.ConcreteModel, expr) -> None:
    """Replace the active objective (the solver adapter must then be rebuilt)."""
    m.del_component("objective")
    m.objective = pyo.Objective(expr=expr)


RESAMPLE_INPUTS = ("sample", "project", "record")


def project_inputs(t_fine: np.ndarray, u_fine: np.ndarray, t_coarse: np.ndarray) -> np.ndarray:
    """Coarse-grid values of an input whose piecewise-linear interpolant is closest to the fine record.

    Least squares over the fine samples: ``min ||H u_c - u_f||``, H the linear-interpolation weights of
    the coarse grid at the fine times. Picking every k-th sample instead moves every input edge that
    falls between coarse samples, and the model integrates that error (the noise-free Case 2 anchor A:
    twist +8.1 % off at 25 Hz with picked inputs, 0.00 % with projected ones; docs/close_loop.md). The
    projection keeps the sum of the input over the fine samples (the constants lie in the span of H)
    and returns the coarse samples unchanged when the fine record is linear between them.
    """
    from scipy.linalg import solveh_banded

    t_fine, u_fine, t_coarse = (np.asarray(x, dtype=float) for x in (t_fine, u_fine, t_coarse))
    n = len(t_coarse)
    if n < 2:
        return np.interp(t_coarse, t_fine, u_fine)
    j = np.clip(np.searchsorted(t_coarse, t_fine, side="right") - 1, 0, n - 2)
    w = np.clip((t_fine - t_coarse[j]) / (t_coarse[j + 1] - t_coarse[j]), 0.0, 1.0)
    a, b = 1.0 - w, w  # weights of coarse samples j and j + 1
    diag = np.bincount(j, a * a, n) + np.bincount(j + 1, b * b, n)
    off = np.bincount(j, a * b, n - 1)
    rhs = np.bincount(j, a * u_fine, n) + np.bincount(j + 1, b * u_fine, n)
    ab = np.zeros((2, n))
    ab[0, 1:], ab[1] = off, diag  # upper form of the tridiagonal normal matrix
    return solveh_banded(ab, rhs)


def prepare_data(ft, maneuvers="identification", resample_hz: float | None = None,
                 max_duration: float | None = None, input_reference_s: float = 0.0,
                 resample_inputs: str = "project") -> IdentificationData:
    """Select maneuvers of a loaded FlightTest, keep every k-th sample and crop the record.

    Keeping every k-th sample (k = rate / resample_hz, an integer) leaves the
    measurement times on the element boundaries: nothing is snapped.
    ``resample_inputs``: how the measured inputs (col, lon) reach the coarse samples: ``sample``
    keeps every k-th sample like the outputs; ``project`` (the default since 2026-11-25; it removes the
    picked inputs' bias, docs/model_nlp.md 10.3) takes the coarse values whose linear interpolant is closest to
    the whole record (:func:`project_inputs`); ``record`` projects them too and keeps the inputs at the
    recorded rate in ``Maneuver.inputs_record``: the NLP is then driven by (and estimates input errors at)
    every recorded sample.
    ``input_reference_s``: the input increments are referred to the mean over the first
    ``input_reference_s`` seconds of each record (0: its first sample), see ``Maneuver.increments``.
    """
    import dataclasses

    if resample_inputs not in RESAMPLE_INPUTS:
        raise ValueError(f"resample_inputs = {resample_inputs!r}: choose one of {', '.join(RESAMPLE_INPUTS)}")

    if maneuvers in ("identification", "validation"):
        chosen = [mv for mv in ft.maneuvers.values() if mv.role == maneuvers]
    else:
        missing = [n for n in maneuvers if n not in ft.maneuvers]
        if missing:
            raise KeyError(f"maneuver(s) {missing} not in the dataset; it has {', '.join(ft.maneuvers)}")
        chosen = [ft.maneuvers[n] for n in maneuvers]
    out = []
    for mv in chosen:
        df, record = mv.data, None
        if resample_hz:
            k = mv.sample_rate / resample_hz
            if abs(k - round(k)) > 1e-6 or round(k) < 1:
                raise ValueError(f"resample_hz {resample_hz} must divide the sample rate {mv.sample_rate:g} Hz "
                                 f"of maneuver {mv.name}")
            full = df
            df = df.iloc[:: int(round(k))].copy()
            if resample_inputs != "sample" and int(round(k)) > 1:
                t_f, t_c = full["t"].to_numpy(dtype=float), df["t"].to_numpy(dtype=float)
                inside = t_f <= t_c[-1] + 1e-9  # the tail beyond the last coarse sample has no element
                for ch in INPUTS:
                    if ch in df:
                        df[ch] = project_inputs(t_f[inside], full[ch].to_numpy(dtype=float)[inside], t_c)
                if resample_inputs == "record":
                    record = full.loc[inside, ["t", *[ch for ch in INPUTS if ch in full]]].reset_index(drop=True)
        if max_duration is not None:
            df = df[df["t"] <= df["t"].iloc[0] + max_duration + 1e-9]
            if len(df) < 2:
                raise ValueError(f"max_duration_s = {max_duration:g} leaves fewer than 2 samples of maneuver "
                                 f"{mv.name}")
        if record is not None:
            record = record[record["t"] <= df["t"].iloc[-1] + 1e-9].reset_index(drop=True)
        span = float(df["t"].iloc[-1] - df["t"].iloc[0])
        if input_reference_s and input_reference_s >= span:
            raise ValueError(f"input_reference_s = {input_reference_s:g} s is not shorter than maneuver {mv.name} "
                             f"({span:g} s): the input reference is the mean over its quiet lead-in")
        out.append(dataclasses.replace(mv, data=df.reset_index(drop=True), input_reference_s=float(input_reference_s),
                                       inputs_record=record))
    return IdentificationData(maneuvers=out, trims=ft.trims)


def validation_maneuvers(cfg, ft) -> list:
    """The validation records of a config as the reports and the closed loop replay them: its ``validation``
    selection of the loaded FlightTest ``ft`` at the recorded rate, inputs referred as the identification refers
    them (``input_reference_s``); [] when the config names none."""
    if not cfg.validation:
        return []
    return list(prepare_data(ft, cfg.validation, input_reference_s=cfg.input_reference_s).maneuvers)


def _record_samples_between_collocation_points(data: IdentificationData, ncp: int):
    """(maneuver, how many, of how many) of the first maneuver whose recorded input samples
    (``resample_inputs = "record"``) include some that no collocation point's interpolant reads (both neighbours of
    the sample beyond every point: more record samples per element than Radau points); None if every one is read.
    The NLP takes the record's interpolant at the collocation points only (``maneuver_block``)."""
    from pyomo.dae.utilities import radau_tau_dict

    tau = np.asarray(radau_tau_dict[ncp], dtype=float)
    for mv in data.maneuvers:
        if mv.inputs_record is None:
            continue
        t_r = mv.inputs_record["t"].to_numpy(dtype=float)
        t_c = mv.data["t"].to_numpy(dtype=float)
        points = (t_c[:-1, None] + np.diff(t_c)[:, None] * tau[None, :]).ravel()
        k = np.clip(np.searchsorted(t_r, points, side="right") - 1, 0, len(t_r) - 1)
        read = np.zeros(len(t_r), dtype=bool)
        read[k] = True  # the sample at or before the point, and the one after unless the point is on a sample
        on_sample = np.isclose(t_r[k], points, rtol=0.0, atol=1e-9)
        read[np.minimum(k[~on_sample] + 1, len(t_r) - 1)] = True
        if not read.all():
            return mv.name, int((~read).sum()), len(t_r)
    return None


def identification_data(cfg, ft=None) -> IdentificationData:
    """The identification maneuvers of a config as the NLP fits them (its maneuvers, ``resample_hz``,
    ``resample_inputs``, ``max_duration_s``, ``input_reference_s``); ``ft`` a loaded FlightTest, else the
    config's dataset is loaded."""
    from ..dataset.reader import check_model_matches_manifest

    if ft is None:
        from ..dataset import load_flight_test

        ft = load_flight_test(cfg.dataset)
    # the flight test's mass and air density are the aircraft the model must fly
    check_model_matches_manifest(ft, cfg.model.parameters, f"{cfg.path} [model]", skip=[f.name for f in cfg.free])
    try:
        data = prepare_data(ft, cfg.maneuvers, cfg.resample_hz, cfg.max_duration, cfg.input_reference_s,
                            cfg.resample_inputs)
        if not data.maneuvers:
            if ft.trim_only:
                raise ValueError(f"{cfg.dataset} is a trim-only flight test (no maneuvers): identify its trims "
                                 f"with `pyomo-heli trim-loop` (docs/real_data.md)")
            raise ValueError(f"no identification maneuver in {cfg.dataset} (field 'maneuvers')")
        # the output-error route compares every trim channel of every row; rows that measured only some
        # channels (each quantity at its own speeds) are for the trim identification (pyomo-heli trim-loop)
        gaps = [i for i in range(len(data.trims))
                if data.trims[[c for c in TRIM_OUTPUTS if c in data.trims]].iloc[i].isna().any()]
        if gaps:
            raise ValueError(f"{cfg.dataset}/{ft.trim_file}: rows {[i + 1 for i in gaps][:5]} leave a trim channel "
                             f"empty; the maneuver identification needs col, lon and theta in every trim row "
                             f"(trim-only data: `pyomo-heli trim-loop`)")
        if not ft.conventions.default:
            raise ValueError(f"{cfg.dataset}/manifest.json: field 'conventions' declares recorded trim conventions "
                             f"that only `pyomo-heli trim-loop` applies so far")
        # the NLP's trim blocks are level (one per speed, build_trim_block's gamma_fp = 0): a climbing or
        # descending trim point would be compared with a level trim, so it is refused, not silently misread
        if "gamma_fp" in data.trims:
            climb = data.trims.index[abs(data.trims["gamma_fp"].to_numpy(dtype=float)) > 1e-9].tolist()
            if climb:
                raise ValueError(f"{cfg.dataset}/trims.csv: rows {[int(i) + 1 for i in climb][:5]} have a flight-path "
                                 f"angle gamma_fp != 0; the identification trims in level flight only")
        unused = _record_samples_between_collocation_points(data, cfg.nlp.ncp)
        if unused:
            name, n, total = unused
            raise ValueError(f"resample_inputs = 'record': {n} of the {total} recorded input samples of maneuver "
                             f"{name} fall between collocation points and would not reach the model; give at most "
                             f"{cfg.nlp.ncp} record samples per output sample (field 'resample_hz') or more "
                             f"collocation points ([discretization] ncp)")
        # the validation maneuvers are replayed only after the solve: a wrong name must fail now
        if isinstance(cfg.validation, list):
            missing = [n for n in cfg.validation if n not in ft.maneuvers]
            if missing:
                raise ValueError(f"field 'validation': maneuver(s) {missing} not in the dataset; it has "
                                 f"{', '.join(ft.maneuvers)}")
        # a record used for both fitting and validation validates nothing (by name or by the manifest's roles)
        validation = (set(cfg.validation) if isinstance(cfg.validation, list) else
                      {n for n, mv in ft.maneuvers.items() if mv.role == cfg.validation})
        both = [mv.name for mv in data.maneuvers if mv.name in validation]
        if both:
            raise ValueError(f"maneuver(s) {', '.join(both)} both fitted (field 'maneuvers') and validation records "
                             f"(field 'validation'); a validation record must be one the fit has not seen")
    except np.linalg.LinAlgError:  # a ValueError, but of the numerics (the inputs' projection), not of the input
        raise
    except (KeyError, ValueError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        raise ValueError(f"{cfg.path} [data]: {msg}") from None
    return data


def build_problem(cfg, responses=None):
    """Load the data and build the NLP of a config (no solve). Returns (nlp, data, flight_test). ``responses``: the
    frequency responses' coherent bands of a three-objective config (J_linear), None for none."""
    from ..dataset import load_flight_test

    ft = load_flight_test(cfg.dataset)
    data = identification_data(cfg, ft)
    m = build_identification_nlp(data, cfg.model, cfg.free, cfg.nlp, responses=responses)
    return m, data, ft


def maneuver_outputs(m: pyo.ConcreteModel, name: str, outputs) -> dict[str, np.ndarray]:
    blk = m.man[name]
    return {o: np.array([pyo.value(blk.y[o, t]) for t in blk.samples]) for o in outputs}


def initialise_at(m: pyo.ConcreteModel, data: IdentificationData, model: HelicopterModel,
                  free: list[FreeParameter], values: dict) -> None:
    """Move the start of a built NLP to other parameter values, without rebuilding it.

    Sets the free parameters to ``values`` (SI) and every state, flapping,
    output and Cholesky variable to what float trims and simulations at those
    values give, exactly as :func:`build_identification_nlp` initialises at
    the configured initial guess (used by multi-start). Raises TrimError when
    the model cannot be trimmed at ``values``.
    """
    from .objectives import R_FLOOR

    by_name = {f.name: f for f in free}
    for n in m.free_parameters:
        m.theta_s[n].set_value(float(values[n]) / by_name[n].scale)
    sim_model = model.with_parameters(**{n: float(values[n]) for n in m.free_parameters})
    float_trims, sims = _float_start(sim_model, data)
    for i, tp in enumerate(float_trims):
        blk = m.trim[i]
        guess = {**tp.to_dict(), **tp.extra_states}
        for name in ("col", "lon", "theta", "lambda_i", *FLAPPING, *(s for e in model.extensions for s in e.states)):
            if name in guess:
                getattr(blk, name).set_value(float(guess[name]), skip_validation=True)
        blk.V.set_value(float(data.speeds[i]), skip_validation=True)
    outputs = list(m.time_outputs) if m.component("time_outputs") is not None else []
    init_res = _start_maneuvers(m, data, sims, sim_model.state_names, outputs)
    if m.component("mean_square") is not None:  # known-noise J_time (input errors): its mean squares
        for c in m.mean_square:
            m.mean_square[c].set_value(pyo.value(m.sum_square[c]) / pyo.value(m.square_count[c]))
    if outputs and m.component("L") is not None:
        E = np.array([init_res[o] for o in outputs])
        R0 = E @ E.T / E.shape[1] + np.diag([R_FLOOR[o] ** 2 for o in outputs])
        if m.options.covariance == "diagonal":
            R0 = np.diag(np.diag(R0))
        L0 = np.linalg.cholesky(R0 + 1e-14 * np.eye(len(outputs)))
        idx = {o: k for k, o in enumerate(outputs)}
        for a, b in m.cov_pairs:
            m.L[a, b].set_value(float(L0[idx[a], idx[b]]), skip_validation=True)
