"""Replay of measured maneuvers with the float model: model trims, and each maneuver from the model's trim.

The output-error model of the identification, in one place for everyone who needs it (the report's
validation, the residual diagnosis, the sensitivities, the NLP's initialisation, single shooting):

- :func:`model_trims`: the model's trims at a set of speeds [m/s] by continuation from hover, with a
  per-speed fallback, so that one speed the model cannot trim costs only itself;
- :func:`replay`: one maneuver started at the model's trim at the maneuver's trim speed, driven by the
  model's trim inputs plus the measured input increments (linearly interpolated samples), integrated
  by classic RK4 with ``substeps`` steps per sample interval (or an adaptive scipy method);
- one divergence rule: a replay has diverged when a recorded output is not finite or its magnitude
  exceeds the plausibility limit the dataset reader applies to measurements
  (:data:`DIVERGENCE_LIMITS`, SI). The compiled RK4 (casadi, the default) integrates the whole record
  at once; the Python one integrates it in pieces of about :data:`CHUNK_S` seconds, each starting
  from the state at the end of the previous one (the same arithmetic as one piece), so that a
  diverging model is stopped early. Either way :class:`Diverged` carries the record up to the
  first implausible sample.
- :func:`predict`: trims and replays of one parameter set as a plain :class:`Prediction`, every
  failure recorded in its ``problems`` (what the report formats and the closed loop scores);
- :func:`maneuver_outputs`: the outputs of a list of maneuvers concatenated per output, by the
  compiled (casadi) RK4 or the Python one (they agree to rounding).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..channels import OUTPUTS, TRIM_CHANNELS
from ..dataset.schema import MANEUVER_QUANTITIES
from ..physics.model import INPUTS, HelicopterModel
from ..units import KT
from .compiled import simulate_outputs, simulate_states
from .integrate import frame, sampled, simulate, stable_substeps
from .trim import TrimPoint, trim_float, trim_sweep

#: |value| beyond which a replayed output counts as diverged: the dataset's plausibility limits (SI)
DIVERGENCE_LIMITS = {q.si: q.limit for q in MANEUVER_QUANTITIES if q.si in OUTPUTS and q.limit}
#: a checked replay is integrated in pieces of this length [s], so that a diverging model is stopped early
CHUNK_S = 1.0


class Diverged(RuntimeError):
    """The replayed response left the plausible range; ``partial`` holds the record up to there."""

    def __init__(self, message: str, partial: pd.DataFrame):
        super().__init__(message)
        self.partial = partial


def speed_key(v: float) -> float:
    """A trim speed [m/s] as a dictionary key (rounded to 1e-6 m/s)."""
    return round(float(v), 6)


def _first_line(exc: Exception) -> str:
    return str(exc).splitlines()[0] if str(exc) else type(exc).__name__


def model_trims(model: HelicopterModel, speeds, gamma_fp: float = 0.0) -> tuple[dict, list]:
    """Trim ``model`` at ``speeds`` [m/s] (flight-path angle ``gamma_fp`` [rad]) by continuation from hover.

    Returns (speed key -> TrimPoint or None, failures), failures a list of (speed key, first line of
    the error) in speed order. One sweep through every speed first; if it breaks, each speed is tried
    on its own. Floating-point warnings of failing trims are silenced: a failure is returned, not raised.
    """
    speeds = sorted({speed_key(v) for v in speeds})
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return dict(zip(speeds, trim_sweep(model, speeds, gamma_fp=gamma_fp))), []
    except Exception:  # noqa: BLE001 - any failure of the physics is returned, not raised
        pass
    out, failed = {}, []
    for v in speeds:
        try:
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore")
                out[v] = trim_sweep(model, [v], gamma_fp=gamma_fp)[0]
        except Exception as exc:  # noqa: BLE001
            out[v] = None
            failed.append((v, _first_line(exc)))
    return out, failed


def maneuver_increments(maneuver, offsets: dict | None = None) -> dict:
    """Channel -> measured input increment [rad] at the maneuver's samples (+ a constant ``offsets``); a
    maneuver with inputs at a finer rate (``inputs_record``) is replayed from those (:func:`replay`)."""
    offsets = offsets or {}
    return {k: v + offsets.get(k, 0.0) for k, v in maneuver.increments().items()}


def replay(model: HelicopterModel, maneuver, trim: TrimPoint, substeps: int = 4, offsets: dict | None = None,
           check: bool = True, method: str = "rk4", compiled: bool = True, **integrator) -> pd.DataFrame:
    """Replay a measured maneuver: start at ``trim``, inputs = trim inputs + measured increments.

    ``substeps`` RK4 steps per sample interval (``method="rk4"``; more where a lag state is faster,
    :func:`stable_substeps`), or ``method`` / ``integrator``
    options of :func:`~.integrate.simulate` for scipy's adaptive integrators. RK4 runs compiled (casadi,
    :func:`~.compiled.simulate_states`) unless ``compiled=False`` (the Python RK4: the same arithmetic, the
    same record to rounding). ``offsets``: constant
    input offsets [rad] added to the increments. ``check``: apply the divergence rule (see the module
    docstring) and raise :class:`Diverged` with the record up to the first implausible sample;
    without it the record is integrated in one piece and returned as it is. Raises RuntimeError if
    the integration itself fails (a non-finite state).
    """
    t = maneuver.data["t"].to_numpy(dtype=float)
    if getattr(maneuver, "inputs_record", None) is not None and len(maneuver.inputs_record) != len(t):
        return _replay_at_input_rate(model, maneuver, trim, substeps, offsets, check, method, compiled, integrator)
    inc = {k: sampled(t, v) for k, v in maneuver_increments(maneuver, offsets).items()}
    if method == "rk4" and len(t) > 1:
        substeps = stable_substeps(model, trim, float(np.max(np.diff(t))), substeps)
    kw = dict(method=method, substeps=substeps, **integrator)
    if method == "rk4" and compiled and len(t) > 1:
        return _replay_compiled(model, trim, t, inc, substeps, check)
    if not check:
        return simulate(model, trim, t, inc, **kw)
    names = model.state_names
    per = max(int(round(CHUNK_S * (len(t) - 1) / max(t[-1] - t[0], 1e-12))), 1) if len(t) > 1 else 1
    pieces, x0, i0 = [], None, 0
    while True:
        i1 = min(i0 + per, len(t) - 1)
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sim = simulate(model, trim, t[i0:i1 + 1], inc, x0=x0, **kw)
        if len(sim) != i1 + 1 - i0:
            raise RuntimeError(f"simulation stopped after {i0 + len(sim)} of {len(t)} samples")
        pieces.append(sim if not pieces else sim.iloc[1:])
        first = _first_implausible(sim)
        if first:
            partial = pd.concat(pieces, ignore_index=True)
            partial = partial[partial["t"] <= sim["t"].iloc[first[0]]].reset_index(drop=True)
            raise Diverged(first[1], partial)
        if i1 >= len(t) - 1:
            break
        x0 = {n: float(sim[n].iloc[-1]) for n in names}
        i0 = i1
    return pd.concat(pieces, ignore_index=True)


def _first_implausible(sim: pd.DataFrame) -> tuple[int, str] | None:
    """The first sample of ``sim`` where a recorded output is not finite or beyond :data:`DIVERGENCE_LIMITS`, and
    the divergence message; None when there is none."""
    vals = sim[[c for c in OUTPUTS if c in sim]]
    bad = ~np.isfinite(vals.to_numpy(dtype=float))
    for c, lim in DIVERGENCE_LIMITS.items():
        if c in vals:
            bad[:, list(vals.columns).index(c)] |= np.abs(vals[c].to_numpy(dtype=float)) > lim
    if not bad.any():
        return None
    k = int(np.argmax(bad.any(axis=1)))
    col = vals.columns[int(np.argmax(bad[k]))]
    return k, f"diverged: {col} left its plausible range at t = {sim['t'].iloc[k]:.2f} s"


def _replay_at_input_rate(model, maneuver, trim, substeps, offsets, check, method, compiled, integrator):
    """:func:`replay` of a maneuver whose inputs are recorded at a finer rate than its outputs
    (``Maneuver.inputs_record``): integrated on the input samples (the same RK4 step length), then taken at
    the output samples."""
    import dataclasses
    import math

    t = maneuver.data["t"].to_numpy(dtype=float)
    t_in = maneuver.inputs_record["t"].to_numpy(dtype=float)
    idx = np.searchsorted(t_in, t - 1e-9)
    if np.any(idx >= len(t_in)) or not np.allclose(t_in[np.minimum(idx, len(t_in) - 1)], t, atol=1e-9):
        raise ValueError(f"maneuver {maneuver.name}: the output samples are not among the input samples")
    fine = dataclasses.replace(maneuver, data=maneuver.inputs_record, inputs_record=None)
    k = (len(t_in) - 1) / max(len(t) - 1, 1)
    try:
        sim = replay(model, fine, trim, max(1, math.ceil(substeps / k)), offsets, check, method, compiled,
                     **integrator)
    except Diverged as exc:
        keep = idx[idx < len(exc.partial)]
        raise Diverged(str(exc), exc.partial.iloc[keep].reset_index(drop=True)) from None
    return sim.iloc[idx].reset_index(drop=True)


def _replay_compiled(model, trim, t, inc, substeps, check) -> pd.DataFrame:
    """:func:`replay` by the compiled RK4: the whole record at once, then the same divergence rule."""
    arrays = {k: np.asarray(f(t), dtype=float) for k, f in inc.items()}
    xs, _ = simulate_states(model, trim, t, arrays, substeps)
    finite = np.all(np.isfinite(xs), axis=0)
    n_ok = len(t) if finite.all() else int(np.argmin(finite))
    base = trim.inputs()

    def inputs_at(tt, _y):
        return {k: base[k] + (float(inc[k](tt)) if k in inc else 0.0) for k in INPUTS}

    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = frame(model, t[:n_ok], xs[:, :n_ok], inputs_at)
    first = _first_implausible(sim) if check and n_ok else None
    if first:
        raise Diverged(first[1], sim.iloc[:first[0] + 1].reset_index(drop=True))
    if n_ok < len(t):
        raise RuntimeError(f"simulation diverged at t = {t[n_ok]:.3f} s")
    return sim


def maneuver_outputs(model: HelicopterModel, maneuvers, outputs, substeps: int = 4,
                     compiled: bool = True) -> dict[str, np.ndarray]:
    """Model outputs at the samples of every maneuver, concatenated per output (SI).

    Each maneuver from the model's trim at its trim speed (:func:`~.trim.trim_float`). RK4 with
    ``substeps`` steps per sample interval, evaluated by casadi (:mod:`.compiled`, about 20x faster:
    ``python studies/benchmark.py --replay``) or, with ``compiled=False``, by the Python integrator of
    :mod:`.integrate`; the two agree to rounding. No divergence rule: a non-finite state raises.
    """
    out = {o: [] for o in outputs}
    for mv in maneuvers:
        tp = trim_float(model, mv.trim_speed)
        if compiled and getattr(mv, "inputs_record", None) is None:
            y = simulate_outputs(model, tp, mv.data["t"].to_numpy(), maneuver_increments(mv), outputs, substeps)
        else:
            df = replay(model, mv, tp, substeps=substeps, check=False, compiled=compiled)
            y = {o: df[o].to_numpy() for o in outputs}
        for o in outputs:
            out[o].append(y[o])
    return {o: np.concatenate(v) if v else np.zeros(0) for o, v in out.items()}


# ---------------------------------------------------------------- model predictions
@dataclass
class Prediction:
    """What one parameter set predicts for the data, computed with the float model (SI units).

    ``trims``: speed (rounded key, see :func:`speed_key`) -> TrimPoint or None
    (failed). ``maneuvers``: name -> replayed DataFrame or None (failed or
    diverged). ``partial``: name -> the record of a diverged replay up to
    where it left the plausible range. ``problems``: one readable line per
    failed trim or replay.
    """

    label: str
    parameters: dict
    trims: dict = field(default_factory=dict)
    maneuvers: dict = field(default_factory=dict)
    partial: dict = field(default_factory=dict)
    problems: list = field(default_factory=list)

    def shown_runs(self) -> dict:
        """name -> record to plot: the full simulation, the diverged part, or None."""
        return {n: (sim if sim is not None else self.partial.get(n)) for n, sim in self.maneuvers.items()}

    def trim_table(self, speeds) -> pd.DataFrame:
        """V and the trim channels at ``speeds`` [m/s], NaN where the model could not be trimmed."""
        rows = []
        for v in speeds:
            tp = self.trims.get(speed_key(v))
            rows.append({"V": float(v), **{c: (getattr(tp, c) if tp is not None else np.nan) for c in TRIM_CHANNELS}})
        return pd.DataFrame(rows, columns=["V", *TRIM_CHANNELS])


def predict(label: str, model: HelicopterModel, parameters: dict, trim_speeds, maneuvers) -> Prediction:
    """Trims at ``trim_speeds`` [m/s] and replays of ``maneuvers`` for ``model`` at ``parameters`` (SI).

    A trim or replay that fails or diverges is recorded in ``problems``, never raised.
    """
    mdl = model.with_parameters(**parameters) if parameters else model
    speeds = set(speed_key(v) for v in trim_speeds) | {speed_key(mv.trim_speed) for mv in maneuvers}
    trims, failed = model_trims(mdl, speeds)
    pred = Prediction(label=label, parameters=dict(parameters), trims=trims)
    if failed:
        kts = ", ".join(f"{v / KT:.1f}" for v, _ in failed)
        pred.problems.append(f"trim failed at {len(failed)} speed(s) [kt]: {kts} (first: {failed[0][1]})")
    for mv in maneuvers:
        tp = trims.get(speed_key(mv.trim_speed))
        if tp is None:
            pred.maneuvers[mv.name] = None
            pred.problems.append(f"maneuver {mv.name}: no model trim at {mv.trim_speed / KT:.1f} kt, not simulated")
            continue
        try:
            pred.maneuvers[mv.name] = replay(mdl, mv, tp)
        except Diverged as exc:
            pred.maneuvers[mv.name] = None
            pred.partial[mv.name] = exc.partial
            pred.problems.append(f"maneuver {mv.name}: simulation {exc} (shown up to there, no RMS)")
        except Exception as exc:  # noqa: BLE001 - an unstable model must not stop the report
            pred.maneuvers[mv.name] = None
            pred.problems.append(f"maneuver {mv.name}: simulation failed ({_first_line(exc)})")
    return pred
