"""Innovations of the time residuals when the measured inputs are noisy (errors in variables).

Why: the replay of a maneuver is driven by the *measured* inputs. Their sensor noise (0.02 deg on the
synthetic flight test) moves the model's outputs sample by sample, and at speed the pitch attitude
integrates it into a slow wander. The residual of even the exact model is then coloured, and the
whiteness test of :mod:`.timeseries` calls it "not white" (on the bundled data the truth model itself,
at the true parameters, fails it in theta on three 80 kt maneuvers of ten). When the identification
estimates the input errors (``[objectives] input_errors``) the residual analysis should take that
colour out the same way, or it reports a missing effect that is only the input noise. An output-error
identification (the inputs taken as exact) leaves its residuals with the same colour; ``[diagnosis]
input_noise`` asks for the innovations there too (config.DiagnosisSettings).

What: to first order the residual of a maneuver at the test-rate samples is

    e = n + S_u du,    cov(e) = V = R + S_u Sigma_u S_u^T,

with ``n`` the sensor noise (``R = diag(sigma_o^2)``, white at the test rate: that is why the test
decimates), ``du`` the errors of every input sample at the identification's rate (independent, sigma
as the NLP takes them: ``[objectives.noise_sigma]`` or the records' lead-in,
:func:`pyomo_heli.nlp.objectives.noise_sigmas`) and ``S_u`` the exact output sensitivities of the test
samples to every input sample (:func:`pyomo_heli.simulation.compiled.input_sensitivities`). With the
rows in time order (all outputs of test sample k before those of k+1) the lower Cholesky factor L of V
whitens them as innovations: ``L^-1 e`` is white with unit variance when the model is right, and row
k depends on samples up to k only. The nuisance of the residual analysis (a bias per output, and the
response to a constant offset of each input: the lead-in reference's error) is projected off in the
whitened coordinates.

Every maneuver is taken at the identification's sample rate (``resample_hz``; validation maneuvers too,
so that the input-noise model is the NLP's), identification maneuvers cut to ``max_duration_s``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
from scipy.linalg import cholesky, solve_triangular

from ..nlp.objectives import input_error_covariance, input_error_models, noise_sigmas, times_covariance
from ..physics.model import HelicopterModel
from ..simulation.compiled import input_sensitivities, simulate_outputs
from ..simulation.trim import trim_float
from .input_path import (expected_inputs, histories, input_path_test, parameter_columns, play_widths,
                         record_block, signals_of)
from .timeseries import decimation


def input_noise_factor(model: HelicopterModel, mv, outputs, input_errors, sigma: dict, substeps: int = 2,
                       keep=None, models: dict | None = None) -> tuple[dict, np.ndarray, np.ndarray, np.ndarray]:
    """The covariance the measured inputs' noise gives one maneuver's outputs, factored.

    Rows in time order (every output of kept sample 0, then of kept sample 1, ...; ``keep``: sample
    indices, default all). The input samples are the NLP's (``Maneuver.input_grid``: the recorded-rate ones with
    ``resample_inputs = "record"``). Returns ``(y, Su, L, Sigma_u)``: the model outputs at every sample (the
    replay driven by those inputs), the stacked sensitivities of the kept rows to every input sample
    (:func:`input_sensitivities`), the lower
    Cholesky factor of ``V = R + Su Sigma_u Su^T`` (``sigma``: noise sigma [SI] of every output and
    input channel) and Sigma_u (:func:`~pyomo_heli.nlp.objectives.input_error_covariance`: the errors independent,
    or with ``models`` the AR processes the NLP's ``[objectives] input_error_ar`` takes them for). Shared by the
    innovations here and the score test's whitening (attribution).
    """
    t_in, inc, idx = mv.input_grid()
    n = len(t_in)
    keep = np.arange(len(idx)) if keep is None else np.asarray(keep, dtype=int)
    y, S_u = input_sensitivities(model, trim_float(model, mv.trim_speed), t_in, inc, outputs, input_errors,
                                 substeps, keep=idx[keep])
    y = {o: np.asarray(v, dtype=float)[idx] for o, v in y.items()}
    n_out = len(outputs)
    Su = np.empty((len(keep) * n_out, len(input_errors) * n))
    for j, o in enumerate(outputs):
        Su[j::n_out] = S_u[o]
    cov_u = input_error_covariance(n, list(input_errors), sigma, models)
    V = times_covariance(Su, cov_u) @ Su.T
    V[np.diag_indices_from(V)] += np.tile([float(sigma[o]) ** 2 for o in outputs], len(keep))
    return y, Su, cholesky(V, lower=True), cov_u


def record_rate_outputs(model: HelicopterModel, mv, record, outputs, substeps: int = 2) -> dict:
    """The model outputs at ``mv``'s samples (a resampled record) from the replay driven by ``record``, the same
    maneuver at the record's own rate: the recorded inputs, not the resampled ones (their difference is the
    resampling's, not the model's). The replay is integrated on the record's samples up to ``mv``'s last, each of
    which falls on one of them."""
    t = mv.data["t"].to_numpy(dtype=float)
    data = record.data[record.data["t"] <= t[-1] + 1e-9].reset_index(drop=True)
    rec = dataclasses.replace(record, data=data)
    tf = data["t"].to_numpy(dtype=float)
    idx = np.clip(np.searchsorted(tf, t - 1e-9), 0, len(tf) - 1)
    if not np.allclose(tf[idx], t, atol=1e-9):
        raise ValueError(f"maneuver {mv.name}: its samples are not samples of the record")
    yf = simulate_outputs(model, trim_float(model, mv.trim_speed), tf, rec.increments(), list(outputs), substeps)
    return {o: np.asarray(yf[o], dtype=float)[idx] for o in outputs}


def maneuver_innovations(model: HelicopterModel, mv, outputs, input_errors, sigma: dict, test_rate_hz: float,
                         substeps: int = 2, path: list | None = None, nuisance_parameters=(),
                         record=None, widths: dict | None = None,
                         models: dict | None = None) -> tuple[pd.DataFrame, dict]:
    """Innovations of one prepared maneuver at its test-rate samples (columns ``t`` and ``inn_<o>``), and the
    maneuver's output biases: ``{"bias_<o>": SI, "se_bias_<o>": SI}``, the generalised least-squares estimates
    of the nuisance with their standard errors under the same covariance, scaled by each output's innovation RMS in
    the record (the record's own noise level: the sigmas come from the lead-ins and need not fit every record).

    ``sigma``: the noise sigma [SI] of every output and input channel. The sign follows
    :class:`~pyomo_heli.diagnosis.residuals.Residuals` (model - data); whiteness does not care.
    ``path``: a list to which the record's rows for the input-path regression are appended
    (:func:`.input_path.record_block`), with the output sensitivities to ``nuisance_parameters`` (the identified
    parameters) among its nuisance. ``record``: the same maneuver at the record's own rate; given, the residual is
    taken against the replay its recorded inputs drive (at ``mv``'s samples; :func:`record_rate_outputs`), the
    input-noise model and the sensitivities stay ``mv``'s. ``widths``: the play and dead-zone signals' widths of the
    input-path dictionary (:func:`.input_path.play_widths`; None: the standard dictionary, without them).
    ``models``: the input errors' AR models (:func:`~pyomo_heli.nlp.objectives.input_error_models`; None:
    independent errors).
    """
    t = mv.data["t"].to_numpy(dtype=float)
    n = len(t)
    k = decimation(t, test_rate_hz)
    keep = np.arange(0, n, k)
    y, Su, L, cov_u = input_noise_factor(model, mv, outputs, input_errors, sigma, substeps, keep, models)
    if record is not None:
        y = record_rate_outputs(model, mv, record, outputs, substeps)
    n_out, m = len(outputs), len(keep)
    # rows in time order: (test sample 0: every output), (test sample 1: ...), ...
    e = np.column_stack([y[o][keep] - mv.data[o].to_numpy(dtype=float)[keep] for o in outputs]).ravel()
    # nuisance: one bias per output, and the response to a constant offset of each input (the sum of that
    # channel's columns: the same error on every sample)
    N = np.zeros((m * n_out, n_out + len(input_errors)))
    for j in range(n_out):
        N[j::n_out, j] = 1.0
    n_in = Su.shape[1] // len(input_errors)
    for c in range(len(input_errors)):
        N[:, n_out + c] = Su[:, c * n_in:(c + 1) * n_in].sum(axis=1)
    ew, Nw = solve_triangular(L, e, lower=True), solve_triangular(L, N, lower=True)
    coef, *_ = np.linalg.lstsq(Nw, ew, rcond=None)
    ew = ew - Nw @ coef  # the innovations: whitened, the nuisance projected out
    block = None
    if path is not None:  # the input-path regression also allows a shift of the identified parameters
        quiet = expected_inputs(mv, ew, Su, L, cov_u, input_errors)
        P = parameter_columns(model, quiet, outputs, keep, nuisance_parameters, substeps)
        signals = signals_of(model, mv, y, input_errors, substeps, widths)
        block = record_block(-e, Su, np.column_stack([N, P]), L, signals, input_errors, cov_u, mv.input_grid()[0],
                             mv.name)
    cov = np.linalg.pinv(Nw.T @ Nw)  # the estimates' covariance if the whitened rows have unit variance
    ew = ew.reshape(m, n_out)
    # each output's noise scale in this record: the RMS of its innovations (1 when the sigmas are right; a record
    # noisier than the lead-in's sigma says, e.g. at hover, widens its bias's standard error)
    dof = max(m - N.shape[1] / n_out, 1.0)
    scale = np.sqrt(np.sum(ew**2, axis=0) / dof)
    biases = {**{f"bias_{o}": float(coef[j]) for j, o in enumerate(outputs)},
              **{f"se_bias_{o}": float(np.sqrt(cov[j, j]) * scale[j]) for j, o in enumerate(outputs)}}
    if block is not None:  # appended last: a record that fails is in neither list
        path.append(block)
    return pd.DataFrame({"t": t[keep], **{f"inn_{o}": ew[:, j] for j, o in enumerate(outputs)}}), biases


def innovations(model: HelicopterModel, maneuvers, sigma_from, outputs, input_errors, noise_sigma: dict | None,
                test_rate_hz: float, substeps: int = 2, problems: list | None = None,
                parameters=(), records: dict | None = None,
                input_path_family: str = "standard", input_error_ar: int = 0) -> tuple[pd.DataFrame, dict]:
    """Innovations of every maneuver: ``maneuvers`` is a list of (role, prepared maneuver).

    ``sigma_from``: the maneuvers whose lead-in gives the sigmas when ``noise_sigma`` is None (the
    identification maneuvers, as in the NLP). An output without a known sigma (not in the
    ``noise_sigma`` table, or no noise in the lead-in) is left out and named in ``problems``; a maneuver
    whose computation fails likewise. Returns ``(table, settings)``: columns ``maneuver, role, t,
    inn_<o>``, and the channels and sigmas used, with ``failed``: the maneuvers (and roles) whose innovations
    failed (absent from the table: their whiteness is untested), ``record_biases``: per maneuver its role, trim
    speed and output biases with their standard errors (:func:`maneuver_innovations`), and ``input_path``: the stepwise
    regression of the input errors on the generic dictionary (:mod:`.input_path`), a shift of ``parameters`` (the
    identified ones) allowed. ``records``: maneuver name -> the same maneuver at the record's rate, whose recorded
    inputs drive the replay the residuals are taken against (``[diagnosis] replay = "record"``).
    ``input_path_family``: "extended" adds each input's free play and dead zone to the input path's dictionary.
    ``input_error_ar``: the order of the AR model of the input errors (the NLP's ``[objectives] input_error_ar``),
    fitted to the lead-ins of ``sigma_from`` at their samples; 0: independent errors.
    """
    problems = problems if problems is not None else []
    input_errors = list(input_errors)
    sigma = noise_sigmas(sigma_from, input_errors, noise_sigma, input_record=True)
    outs = []
    for o in outputs:
        missing = [mv.name for _, mv in maneuvers if o not in mv.data]
        if missing:
            problems.append(f"innovations: output {o} left out (not recorded in {', '.join(missing)}): its "
                            "residuals are tested as they are")
            continue
        try:
            sigma.update(noise_sigmas(sigma_from, [o], noise_sigma))
            outs.append(o)
        except ValueError as exc:
            problems.append(f"innovations: output {o} left out ({exc})")
    frames, biases, path, failed = [], [], [], []
    widths = play_widths(sigma) if input_path_family == "extended" else None
    models = input_error_models(sigma_from, input_errors, input_error_ar, input_record=True)
    for role, mv in maneuvers:
        try:
            df, b = maneuver_innovations(model, mv, outs, input_errors, sigma, test_rate_hz, substeps, path, parameters,
                                         (records or {}).get(mv.name), widths, models)
        except Exception as exc:  # noqa: BLE001 - the raw residual tests stay available
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            problems.append(f"maneuver {mv.name}: innovations failed ({why})")
            failed.append({"maneuver": mv.name, "role": role})
            continue
        df.insert(0, "role", role)
        df.insert(0, "maneuver", mv.name)
        frames.append(df)
        biases.append({"maneuver": mv.name, "role": role, "trim_speed": float(mv.trim_speed), **b})
    table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(columns=["maneuver", "role", "t"])
    settings = {"outputs": outs, "input_errors": input_errors, "test_rate_hz": float(test_rate_hz),
                "input_error_ar": {c: [float(x) for x in a] for c, (a, _) in models.items()},
                "replay": "record" if records else "fit",
                "sigma": {c: float(v) for c, v in sigma.items()}, "record_biases": biases,
                "failed": failed}
    if input_errors and path:
        test = input_path_test(path)
        test.play_widths = dict(widths or {})
        test.histories = histories(test, path, input_errors)
        settings["input_path"] = test.to_dict()
    return table, settings
