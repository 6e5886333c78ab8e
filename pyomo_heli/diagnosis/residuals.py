"""Residuals of an identified model: model minus data, for every maneuver and every trim point.

The residuals are computed with the float model (the same physics, trims and
RK4 replay as :mod:`pyomo_heli.simulation.sensitivity`, i.e. the output-error
model of the identification, :mod:`pyomo_heli.simulation.replay`): each maneuver starts from the model's own trim
at the maneuver's trim speed and is driven by the model's trim inputs plus the
measured input increments; a trim point is the model's trim at the measured
speed and flight-path angle.

Sign: **residual = model - data** (SI units, radians). The identification's
objectives and the report's RMS tables use data - model; an RMS does not care.

Identification maneuvers use the config's sample selection (``resample_hz``,
``max_duration_s``, exactly the samples the NLP fits); validation maneuvers are
taken whole at the recorded rate (as the report's validation RMS, which these
numbers reproduce). All
trim points of the dataset enter J_trim, so they count as identification data.

A maneuver whose simulation fails or leaves the plausible range is left out
and named in ``problems``; a speed the model cannot trim gives NaN model values
in the trim table (and is named in ``problems``).
"""
from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from ..channels import OUTPUTS, RESIDUAL_DISPLAY_UNITS, TRIM_CHANNELS
from ..dataset import load_flight_test
from ..nlp.identification import prepare_data
from ..pareto.result import IdentificationResult, write_json
from ..physics.model import HelicopterModel
from ..simulation.replay import model_trims, replay
from ..units import DEG, KT
from .innovations import innovations
from .timeseries import TEST_RATE_HZ

if TYPE_CHECKING:  # the config layer sits above the diagnosis: annotation only
    from ..config import IdentificationConfig

#: time outputs whose residuals are computed (every recorded output the model predicts)
TIME_OUTPUTS = OUTPUTS
#: model quantities kept next to the residuals (regressors for the diagnosis), when the model has them
MODEL_EXTRAS = ("u", "w", "q", "theta", "lambda_i", "beta_1c", "col", "lon")
#: rotor-flow regressors added from the model's states: mu_d (in-plane advance ratio of the disc) and
#: chi (wake skew angle, atan2(mu_d, lambda_d): 0 in hover, -> 90 deg at speed)
FLOW_EXTRAS = ("mu", "chi")
#: display unit and SI -> display factor, for printing only
DISPLAY = RESIDUAL_DISPLAY_UNITS
ROLES = ("identification", "validation")
#: constant input offset of the input-offset sensitivities [rad] (small: the response is linear in it)
OFFSET_STEP = 1e-3 * DEG


def _rms(x) -> float:
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else float("nan")


@dataclass
class Residuals:
    """Model-minus-data residuals of one parameter set (SI units, radians).

    ``time``: one row per sample of every replayed maneuver, columns
      ``maneuver, role, trim_speed [m/s], t [s], in_col, in_lon`` (measured
      inputs, absolute, rad), then for every output ``o`` in ``outputs``:
      ``res_<o>`` (model - data), ``data_<o>``, ``model_<o>``, and model
      quantities ``model_<x>`` for x in u, w, lambda_i, beta_1c, col, lon (the
      model's applied inputs) as regressors.
    ``trim``: one row per trim point, columns ``V [m/s], gamma_fp [rad], source``
      and for every channel ``c``: ``res_<c>``, ``data_<c>``, ``model_<c>``, plus
      ``model_u, model_w, model_lambda_i, model_mu, model_chi`` of the model trim, and
      ``dres_<c>_d<p>`` (d model_c / d parameter p) for every parameter given.
    ``info["inputs"]``: maneuver -> the input channels it excites (from the dataset).
    ``fitted_outputs`` / ``fitted_trim``: what the identification's objectives used.
    ``innovations``: with ``[objectives] input_errors`` or ``[diagnosis] input_noise`` only (else None),
      the time residuals whitened by
      the covariance the measured inputs' noise gives them, at the test-rate samples (columns
      ``maneuver, role, t, inn_<o>``, dimensionless; :mod:`pyomo_heli.diagnosis.innovations`);
      ``info["innovations"]`` says which outputs, sigmas and rate.
    """

    label: str
    parameters: dict
    time: pd.DataFrame
    trim: pd.DataFrame
    outputs: list = field(default_factory=lambda: list(TIME_OUTPUTS))
    trim_channels: list = field(default_factory=lambda: list(TRIM_CHANNELS))
    fitted_outputs: list = field(default_factory=list)
    fitted_trim: list = field(default_factory=list)
    problems: list = field(default_factory=list)
    info: dict = field(default_factory=dict)
    innovations: pd.DataFrame | None = None

    # ------------------------------------------------------------ access
    def maneuver_names(self, role: str | None = None) -> list[str]:
        df = self.time if role is None else self.time[self.time["role"] == role]
        return list(dict.fromkeys(df["maneuver"]))

    def maneuver(self, name: str) -> pd.DataFrame:
        """The rows of one maneuver (a copy, index reset)."""
        if name not in set(self.time["maneuver"]):
            raise KeyError(f"no maneuver '{name}' in the residuals; have {', '.join(self.maneuver_names())}")
        return self.time[self.time["maneuver"] == name].reset_index(drop=True)

    # ------------------------------------------------------------ summary
    def rms(self) -> pd.DataFrame:
        """RMS of the residuals (SI): rows ``kind`` (time/trim), ``role``, ``channel``, ``rms``, ``n``.

        Time rows: every output, pooled over the maneuvers of each role. Trim
        rows: every channel over all trim points (role identification), and also
        over the ``level`` and ``maneuver_start`` points when the data say so.
        """
        rows = []
        for role in ROLES:
            df = self.time[self.time["role"] == role]
            if df.empty:
                continue
            for o in self.outputs:
                e = df[f"res_{o}"].to_numpy(dtype=float)
                rows.append({"kind": "time", "role": role, "channel": o, "rms": _rms(e),
                             "n": int(np.isfinite(e).sum())})
        groups = [("identification", np.ones(len(self.trim), bool))]
        if "source" in self.trim and len(self.trim):
            level = (self.trim["source"].astype(str) == "level").to_numpy()
            groups += [("level", level), ("maneuver_start", ~level)]
        for group, mask in groups:
            if not mask.any():
                continue
            for c in self.trim_channels:
                e = self.trim[f"res_{c}"].to_numpy(dtype=float)[mask]
                rows.append({"kind": "trim", "role": group, "channel": c, "rms": _rms(e),
                             "n": int(np.isfinite(e).sum())})
        return pd.DataFrame(rows, columns=["kind", "role", "channel", "rms", "n"])

    def rms_dict(self) -> dict:
        """``{"time": {role: {output: rms}}, "trim": {group: {channel: rms}}}`` (SI), for JSON."""
        out = {"time": {}, "trim": {}}
        for _, r in self.rms().iterrows():
            out[r["kind"]].setdefault(r["role"], {})[r["channel"]] = float(r["rms"])
        return out

    def __str__(self) -> str:
        tab = self.rms()
        tab["unit"] = [DISPLAY[c][0] for c in tab["channel"]]
        tab["rms"] = [v * DISPLAY[c][1] for v, c in zip(tab["rms"], tab["channel"])]
        head = (f"Residuals (model - data) of '{self.label}': {len(self.maneuver_names())} maneuvers, "
                f"{len(self.trim)} trim points; RMS in display units")
        lines = [head, tab[["kind", "role", "channel", "rms", "unit", "n"]].to_string(
            index=False, float_format=lambda x: f"{x:.4g}")]
        if self.problems:
            lines += ["problems:"] + [f"  - {p}" for p in self.problems]
        return "\n".join(lines)

    # ------------------------------------------------------------ disk
    def save(self, folder: str | Path) -> Path:
        """Write ``time.csv.gz`` (gzip-compressed CSV), ``trim.csv``, ``meta.json`` and, when there are
        innovations, ``innovations.csv`` into ``folder``."""
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        if (folder / "time.csv").exists():
            (folder / "time.csv").unlink()
        self.time.to_csv(folder / "time.csv.gz", index=False, float_format="%.10g",
                         compression={"method": "gzip", "mtime": 0})
        self.trim.to_csv(folder / "trim.csv", index=False, float_format="%.12g")
        if (folder / "innovations.csv").exists():
            (folder / "innovations.csv").unlink()
        if self.innovations is not None:
            self.innovations.to_csv(folder / "innovations.csv", index=False, float_format="%.10g")
        write_json(folder / "meta.json", {"label": self.label, "parameters": self.parameters, "outputs": self.outputs,
                                          "trim_channels": self.trim_channels, "fitted_outputs": self.fitted_outputs,
                                          "fitted_trim": self.fitted_trim, "problems": self.problems,
                                          "info": self.info, "sign": "model - data", "units": "SI (rad, m/s, g)"})
        return folder

    @classmethod
    def load(cls, folder: str | Path) -> "Residuals":
        folder = Path(folder)
        time_file = folder / "time.csv.gz" if (folder / "time.csv.gz").is_file() else folder / "time.csv"
        for f in (time_file, folder / "trim.csv", folder / "meta.json"):
            if not f.is_file():
                raise FileNotFoundError(f"{folder}: no {f.name}; is this a residuals folder?")
        meta = json.loads((folder / "meta.json").read_text())
        time = pd.read_csv(time_file, dtype={"maneuver": str, "role": str})
        trim = pd.read_csv(folder / "trim.csv", dtype={"source": str})
        inn = folder / "innovations.csv"
        innovations = pd.read_csv(inn, dtype={"maneuver": str, "role": str}) if inn.is_file() else None
        return cls(label=meta["label"], parameters=meta["parameters"], time=time, trim=trim, outputs=meta["outputs"],
                   trim_channels=meta["trim_channels"], fitted_outputs=meta["fitted_outputs"],
                   fitted_trim=meta["fitted_trim"], problems=meta["problems"], info=meta.get("info", {}),
                   innovations=innovations)


# ---------------------------------------------------------------- computing
def flow_regressors(model: HelicopterModel, states: dict, inputs: dict) -> dict:
    """Disc advance ratio ``mu`` and wake skew angle ``chi`` [rad] at arrays of states and inputs.

    States missing from ``states`` (extension states) are taken at zero; the
    model is evaluated vectorised, or sample by sample if an extension needs floats.
    """
    n = len(np.atleast_1d(states["u"]))
    x = {k: np.asarray(states.get(k, np.zeros(n)), dtype=float) for k in model.state_names}
    u = {k: np.asarray(inputs[k], dtype=float) for k in ("col", "lon")}
    try:
        with np.errstate(all="ignore"):
            d = model.evaluate(x, u).disc
        mu_d, lam_d = np.broadcast_to(d.mu_d, (n,)), np.broadcast_to(d.lambda_d, (n,))
    except Exception:  # noqa: BLE001 - an extension written for scalars
        mu_d, lam_d = np.empty(n), np.empty(n)
        for i in range(n):
            d = model.evaluate({k: float(v[i]) for k, v in x.items()}, {k: float(v[i]) for k, v in u.items()}).disc
            mu_d[i], lam_d[i] = float(d.mu_d), float(d.lambda_d)
    return {"mu": np.array(mu_d, dtype=float), "chi": np.arctan2(mu_d, lam_d)}


def _trims(model: HelicopterModel, trims: pd.DataFrame, extra_speeds, problems: list) -> dict:
    """Model trim points keyed by (round(V, 6), round(gamma_fp, 9)); None where trim fails."""
    gammas = trims.get("gamma_fp", 0.0 * trims["V"])
    keys = {(round(float(v), 6), round(float(g), 9)) for v, g in zip(trims["V"], gammas)}
    keys |= {(round(float(v), 6), 0.0) for v in extra_speeds}
    out = {}
    for g in sorted({k[1] for k in keys}):
        tps, failed = model_trims(model, [k[0] for k in keys if k[1] == g], gamma_fp=g)
        out.update({(v, g): tp for v, tp in tps.items()})
        problems.extend(f"model trim failed at {v / KT:.1f} kt, gamma {g / DEG:.1f} deg: {msg}" for v, msg in failed)
    return out


def compute_residuals(cfg: IdentificationConfig, parameters: dict, label: str = "model",
                      roles=ROLES, outputs=TIME_OUTPUTS, input_offsets: bool = True,
                      trim_sensitivities: bool = True, test_rate_hz: float = TEST_RATE_HZ) -> Residuals:
    """Residuals (model - data) of every maneuver of ``roles`` and every trim point at ``parameters`` (SI).

    ``parameters`` override the config model's values (free parameters of an
    identification, extension strengths, ...); the rest stays as configured.
    ``input_offsets``: also compute, per maneuver, the output response to a
    constant offset of each input (columns ``dres_<o>_d<input>``, per rad): the
    replay starts from the first recorded input sample, so that sample's noise
    acts as a constant input error over the whole record (a nuisance the
    diagnosis removes before testing whiteness). Costs two more replays.
    ``trim_sensitivities``: also the trim sensitivities of the parameters given
    (columns ``dres_<c>_d<parameter>`` of ``trim``, central differences of the
    model trims, SI per SI unit), so that a diagnosis can ask what the
    identified parameters could still absorb. Costs two trim sweeps per parameter.
    With ``[objectives] input_errors`` or ``[diagnosis] input_noise`` the residuals' innovations at
    ``test_rate_hz`` are added (:mod:`pyomo_heli.diagnosis.innovations`; every maneuver at the
    identification's sample rate), with the input-path regression (:mod:`pyomo_heli.diagnosis.input_path`), which
    allows a shift of the config's free parameters.
    """
    model = cfg.model.with_parameters(**parameters) if parameters else cfg.model
    ft = load_flight_test(cfg.dataset)
    selection = {"identification": cfg.maneuvers, "validation": cfg.validation}
    mans, inn_mans, id_mans = [], [], []
    for role in roles:
        if role not in selection:
            raise ValueError(f"unknown role '{role}'; choose from {', '.join(ROLES)}")
        sel = selection[role]
        if sel == "validation" and not any(mv.role == "validation" for mv in ft.maneuvers.values()):
            continue
        data = (prepare_data(ft, sel, cfg.resample_hz, cfg.max_duration, cfg.input_reference_s,
                              cfg.resample_inputs)
                if role == "identification" else prepare_data(ft, sel, input_reference_s=cfg.input_reference_s))
        mans += [(role, mv) for mv in data.maneuvers]
        if role == "identification":
            id_mans += list(data.maneuvers)
            inn_mans += [(role, mv) for mv in data.maneuvers]
        else:  # the innovations take every maneuver at the NLP's rate (its input-noise model)
            inn_mans += [(role, mv) for mv in prepare_data(ft, sel, cfg.resample_hz,
                                                           input_reference_s=cfg.input_reference_s,
                                                           resample_inputs=cfg.resample_inputs).maneuvers]
    problems: list[str] = []
    trims = ft.trims.reset_index(drop=True)
    tps = _trims(model, trims, [mv.trim_speed for _, mv in mans], problems)

    frames, not_replayed = [], []
    for role, mv in mans:
        tp = tps.get((round(float(mv.trim_speed), 6), 0.0))
        if tp is None:
            problems.append(f"maneuver {mv.name}: no model trim at {mv.trim_speed / KT:.1f} kt, not replayed")
            not_replayed.append({"maneuver": mv.name, "role": role})
            continue
        try:
            sim = replay(model, mv, tp)
        except Exception as exc:  # noqa: BLE001 - an unstable model must not stop the diagnosis
            problems.append(f"maneuver {mv.name}: replay failed ({str(exc).splitlines()[0] or type(exc).__name__})")
            not_replayed.append({"maneuver": mv.name, "role": role})
            continue
        df = pd.DataFrame({"maneuver": mv.name, "role": role, "trim_speed": float(mv.trim_speed),
                           "t": mv.data["t"].to_numpy(dtype=float)})
        for k in ("col", "lon"):
            df[f"in_{k}"] = mv.data[k].to_numpy(dtype=float) if k in mv.data else np.nan
        for o in outputs:
            data = mv.data[o].to_numpy(dtype=float) if o in mv.data else np.full(len(df), np.nan)
            mod = sim[o].to_numpy(dtype=float)
            df[f"res_{o}"], df[f"data_{o}"], df[f"model_{o}"] = mod - data, data, mod
        for x in MODEL_EXTRAS:
            if x in sim and f"model_{x}" not in df:
                df[f"model_{x}"] = sim[x].to_numpy(dtype=float)
        fl = flow_regressors(model, {k: sim[k].to_numpy() for k in model.state_names if k in sim},
                             {k: sim[k].to_numpy() for k in ("col", "lon")})
        for x in FLOW_EXTRAS:
            df[f"model_{x}"] = fl[x]
        if input_offsets:
            for c in ("col", "lon"):
                try:
                    sim_c = replay(model, mv, tp, offsets={c: OFFSET_STEP})
                except Exception:  # noqa: BLE001 - keep the residuals, drop the sensitivity
                    problems.append(f"maneuver {mv.name}: input-offset replay ({c}) failed")
                    continue
                for o in outputs:
                    df[f"dres_{o}_d{c}"] = (sim_c[o].to_numpy(dtype=float) - sim[o].to_numpy(dtype=float)) / OFFSET_STEP
        frames.append(df)
    time = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame(
        columns=["maneuver", "role", "trim_speed", "t"])

    rows = []
    for _, r in trims.iterrows():
        g = float(r["gamma_fp"]) if "gamma_fp" in r else 0.0
        tp = tps.get((round(float(r["V"]), 6), round(g, 9)))
        row = {"V": float(r["V"]), "gamma_fp": g, "source": str(r["source"]) if "source" in r else "level"}
        for c in TRIM_CHANNELS:
            mod = float(getattr(tp, c)) if tp is not None else math.nan
            row.update({f"res_{c}": mod - float(r[c]), f"data_{c}": float(r[c]), f"model_{c}": mod})
        for x in ("u", "w", "lambda_i"):
            row[f"model_{x}"] = float(getattr(tp, x)) if tp is not None else math.nan
        if tp is not None:
            fl = flow_regressors(model, {**tp.state(), **tp.extra_states}, tp.inputs())
            row.update({f"model_{x}": float(np.ravel(fl[x])[0]) for x in FLOW_EXTRAS})
        else:
            row.update({f"model_{x}": math.nan for x in FLOW_EXTRAS})
        rows.append(row)
    trim = pd.DataFrame(rows)
    if trim_sensitivities and parameters and len(trim):
        _add_trim_sensitivities(model, list(parameters), trim, problems)
    inn, inn_info = None, None
    noise = cfg.diagnosis_settings  # [diagnosis], else the identification's input errors
    if noise.input_noise and inn_mans:
        records = None
        if noise.replay == "record" and cfg.resample_hz:  # the recorded inputs drive the replay (DiagnosisSettings)
            names = [mv.name for _, mv in inn_mans]
            records = {mv.name: mv for mv in prepare_data(ft, names, input_reference_s=cfg.input_reference_s).maneuvers}
        try:
            inn, inn_info = innovations(model, inn_mans, id_mans or [mv for _, mv in inn_mans], outputs,
                                        noise.input_noise, noise.noise_sigma, test_rate_hz, problems=problems,
                                        parameters=[p.name for p in cfg.free], records=records,
                                        input_path_family=noise.input_path_family,
                                        input_error_ar=noise.input_error_ar)
        except ValueError as exc:  # e.g. no input sigma: the raw residual tests stay
            problems.append(f"innovations not computed: {exc}")
    return Residuals(label=label, parameters={k: float(v) for k, v in (parameters or {}).items()}, time=time,
                     trim=trim, outputs=list(outputs), trim_channels=list(TRIM_CHANNELS),
                     fitted_outputs=list(cfg.nlp.time_outputs), fitted_trim=list(cfg.nlp.trim_outputs),
                     problems=problems,
                     info={**({"not_replayed": not_replayed} if not_replayed else {}),
                           "config": _shown_path(cfg.path), "dataset": _shown_path(cfg.dataset),
                           "extensions": [e.name for e in cfg.model.extensions],
                           "inputs": {mv.name: list(mv.inputs) for _, mv in mans},
                           **({"innovations": inn_info} if inn_info else {})},
                     innovations=inn)


def _shown_path(p) -> str:
    """A path relative to the current folder when it lies inside it (machine-independent records)."""
    p = Path(p)
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(p)


def _add_trim_sensitivities(model: HelicopterModel, names: list, trim: pd.DataFrame, problems: list) -> None:
    from ..simulation.sensitivity import sensitivities

    if "gamma_fp" in trim and np.any(np.abs(trim["gamma_fp"].to_numpy(dtype=float)) > 1e-9):
        problems.append("trim sensitivities skipped: the data have climbing/descending trims")
        return
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            sens = sensitivities(model, names, trim_speeds=trim["V"].to_numpy(dtype=float),
                                 trim_out=list(TRIM_CHANNELS))
    except Exception as exc:  # noqa: BLE001 - the residuals stay usable without them
        problems.append(f"trim sensitivities failed ({str(exc).splitlines()[0] if str(exc) else type(exc).__name__})")
        return
    for c in TRIM_CHANNELS:
        for j, n in enumerate(names):
            trim[f"dres_{c}_d{n}"] = sens.trim[c][:, j]


# ---------------------------------------------------------------- from a results folder
def find_config(results_dir: str | Path, result: IdentificationResult | None = None) -> Path:
    """The config a results folder was made from (``chosen.json`` info["config"]).

    A relative path is tried from the current directory, then from the results
    folder and each of its parents (a committed results folder inside a checkout).
    """
    results_dir = Path(results_dir)
    result = result or IdentificationResult.load(results_dir)
    name = result.info.get("config")
    if not name:
        raise FileNotFoundError(f"{results_dir / 'chosen.json'}: field info.config is missing; pass the config "
                                f"explicitly")
    p = Path(name)
    here = results_dir.resolve()
    candidates = [p] if p.is_absolute() else [p] + [d / p for d in [here, *here.parents]]
    for c in candidates:
        if c.is_file():
            return c
    raise FileNotFoundError(f"{results_dir / 'chosen.json'}: field info.config: config '{name}' not found "
                            f"(tried the current folder and the parents of {results_dir}); pass it explicitly")


def result_residuals(results_dir: str | Path, cfg: IdentificationConfig, roles=ROLES) -> dict[str, Residuals]:
    """Residuals of a results folder at the chosen point (Eq. 11) and at the time-domain point (A).

    ``cfg``: the folder's identification config (``pyomo_heli.config.load_result_config``).
    Returns ``{"chosen": Residuals, "time_domain": Residuals}``.
    """
    res = IdentificationResult.load(results_dir)
    return {"chosen": compute_residuals(cfg, res.chosen["parameters"], "multi-objective (C)", roles),
            "time_domain": compute_residuals(cfg, res.time_domain["parameters"], "time-domain (A)", roles)}
