"""The residual diagnosis of an identified model: one call, one plain result.

:func:`diagnose` takes the :class:`~pyomo_heli.diagnosis.residuals.Residuals`
of a parameter set and runs every test:

- trim residual shape per channel against airspeed (:mod:`.trim_shape`);
- per maneuver, the nuisance part of the time residuals (output biases and the
  response to constant input offsets) removed, then whiteness (Ljung-Box at the
  test rate), spectra (Welch), coherence with the excited inputs and the
  correlation with physical regressors (:mod:`.timeseries`); when the
  identification estimated the input errors, whiteness is tested on the
  residuals' innovations instead, which take out the colour the measured
  inputs' noise gives them (:mod:`.innovations`);
- with the innovations, the records' agreement on each output's bias: whiteness
  cannot see an error that is constant within a record and changes from record
  to record (:mod:`.record_bias`);
- with the innovations, whether the input errors follow a signal of the flight
  (a control-path effect: stepwise regression on a generic dictionary,
  :mod:`.input_path`).

The result, :class:`Diagnosis`, is plain data: it saves to and loads from
JSON, prints as readable tables and carries short findings in words. Figures
are functions of it (``pyomo_heli.report.diagnosis``).
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..pareto.result import write_json
from ..units import DEG, KT
from .residuals import DISPLAY, Residuals
from .timeseries import (DYN_BAND, HIGH_BAND, TEST_RATE_HZ, clean_time_residuals, coherence_table,
                         correlation_table, spectra, whiteness_table, with_bound)
from .input_path import InputPathTest
from .record_bias import record_bias_tests
from .trim_shape import ShapeTest, trim_shape_test

#: band ratio above which a residual spectrum counts as dominated by the dynamics band
BAND_RATIO_FLAG = 3.0
#: |r| above which a correlation with a regressor is listed in the findings
CORRELATION_FLAG = 0.3


def _plain(v):
    """A JSON-ready Python value: numpy scalars unwrapped, NaN and missing as None."""
    if isinstance(v, np.generic):
        v = v.item()
    if v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v)):
        return None
    return v


def _records(df: pd.DataFrame) -> list[dict]:
    # not df.to_json: pandas writes a float between about 1e-16 and 5e-11 as 0.0 (10 decimals), which
    # turned small p-values into 0 in diagnosis.json
    return [{k: _plain(v) for k, v in rec.items()} for rec in df.to_dict(orient="records")] if len(df) else []


@dataclass
class Diagnosis:
    """Every residual test of one parameter set (SI inside; findings in display units)."""

    label: str
    parameters: dict
    settings: dict
    rms: list = field(default_factory=list)  # records of Residuals.rms()
    trim_shapes: dict = field(default_factory=dict)  # channel -> ShapeTest as dict
    nuisance: list = field(default_factory=list)  # per maneuver: bias_<o>, offset_<input>
    whiteness: list = field(default_factory=list)  # per maneuver and output
    spectra: dict = field(default_factory=dict)  # role -> {"f", "fs", "psd": {o: [...]}, "band_ratio": {o: r}}
    coherence: list = field(default_factory=list)  # per maneuver, output and input
    coherence_curves: dict = field(default_factory=dict)  # maneuver -> {"f": [...], "<in>:<out>": [...]}
    correlations: list = field(default_factory=list)
    record_biases: dict = field(default_factory=dict)  # output -> RecordBiasTest as dict
    input_path: dict = field(default_factory=dict)  # InputPathTest as dict (with the innovations only)
    verdict: dict = field(default_factory=dict)
    findings: list = field(default_factory=list)
    problems: list = field(default_factory=list)
    info: dict = field(default_factory=dict)

    # ------------------------------------------------------------ tables
    def table(self, name: str) -> pd.DataFrame:
        """One of rms, nuisance, whiteness, coherence, correlations, trim_shapes, record_biases as a DataFrame."""
        if name == "trim_shapes":
            rows = []
            for c, t in self.trim_shapes.items():
                p = t["p_values"]
                rows.append({"channel": c, "shape": t["shape"], "min p": min(p.values()), "n": t["n"],
                             **{f"p {s}": p[s] for s in p}, "rms": t["rms"], "rms after": t["rms_after"],
                             "runs z": t["runs"].get("z")})
            return pd.DataFrame(rows)
        if name == "record_biases":
            return pd.DataFrame([{k: v for k, v in t.items() if k != "by_speed"} for t in self.record_biases.values()])
        return pd.DataFrame(getattr(self, name))

    def shape(self, channel: str) -> ShapeTest:
        return ShapeTest(**self.trim_shapes[channel])

    # ------------------------------------------------------------ disk
    def save(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, asdict(self))
        return path

    @classmethod
    def load(cls, path: str | Path) -> "Diagnosis":
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such diagnosis file")
        return cls(**json.loads(path.read_text()))

    def __str__(self) -> str:
        L = [f"Residual diagnosis of '{self.label}' (residual = model - data)", ""]
        L += ["Findings:"] + [f"  - {f}" for f in self.findings] + [""]
        ts = self.table("trim_shapes")
        if len(ts):
            ts = ts.assign(**{"rms [deg]": ts["rms"] / DEG, "rms after [deg]": ts["rms after"] / DEG})
            L += ["Trim residual shape vs airspeed (Monte Carlo p-values of F against noise only):",
                  ts[["channel", "shape", "p constant", "p V^2", "p bump", "p V^2+bump", "rms [deg]",
                      "rms after [deg]", "runs z"]].to_string(index=False, float_format=lambda x: f"{x:.3g}"), ""]
        w = self.table("whiteness")
        if len(w):
            piv = w.pivot_table(index=["role", "maneuver"], columns="output", values="p", sort=False)
            inn = self.settings.get("innovations")
            how = f"; innovations of {', '.join(inn['outputs'])} (input noise taken out)" if inn else ""
            L += [f"Whiteness: Ljung-Box p-values at {self.settings['test_rate_hz']:g} Hz after removing the nuisance "
                  f"(white if p > alpha / tests{how}):", piv.to_string(float_format=lambda x: f"{x:.2g}"), ""]
        rb = self.table("record_biases")
        if len(rb):
            L += ["Record biases: do the records agree on each output's bias (chi-square across records, SI)?",
                  rb.to_string(index=False, float_format=lambda x: f"{x:.3g}"), ""]
        if self.input_path:
            L += ["Input path (stepwise regression of the input errors on the generic dictionary):",
                  "  " + InputPathTest.from_dict(self.input_path).describe(), ""]
        for role, sp in self.spectra.items():
            br = ", ".join(f"{o} {v:.3g}" for o, v in sp.get("band_ratio", {}).items())
            L.append(f"Spectral band ratio ({role}; PSD {DYN_BAND[0]:g}-{DYN_BAND[1]:g} Hz / "
                     f"{HIGH_BAND[0]:g}-{HIGH_BAND[1]:g} Hz, ~1 for white noise): {br}")
        if self.problems:
            L += ["", "Problems:"] + [f"  - {p}" for p in self.problems]
        return "\n".join(L)


# ---------------------------------------------------------------- findings in words
def _shape_sentence(t: ShapeTest) -> str:
    unit, fac = DISPLAY.get(t.channel, ("SI", 1.0))
    pmin = min(t.p_values.values())
    if not t.structured:
        return (f"trim {t.channel}: noise only (smallest p = {pmin:.2g} >= {t.alpha / len(t.p_values):.2g}"
                + (f", a shift of {', '.join(t.nuisance)} allowed" if t.nuisance else "")
                + f"); RMS {t.rms * fac:.3g} {unit}"
                + (f", {t.rms_after * fac:.3g} {unit} after the parameter shift" if t.nuisance else ""))
    parts = [f"trim {t.channel}: {t.description} (p = {pmin:.2g}"
             + (f", beyond a shift of {', '.join(t.nuisance)})" if t.nuisance else ")")]
    f = t.fit
    if "amplitude" in f:
        parts.append(f"bump centre {f['centre'] / KT:.0f} kt, width {f['width'] / KT:.0f} kt, amplitude "
                     f"{f['amplitude'] * fac:+.3g} {unit}")
    if "V2_at_120kt" in f:
        parts.append(f"V^2 term {f['V2_at_120kt'] * fac:+.3g} {unit} at 120 kt")
    if "offset" in f:
        parts.append(f"offset {f['offset'] * fac:+.3g} {unit}")
    parts.append(f"RMS {t.rms * fac:.3g} -> {t.rms_after * fac:.3g} {unit} after the shape")
    return "; ".join(parts)


def _findings(d: Diagnosis, shapes: dict, white: pd.DataFrame, coh: pd.DataFrame, corr: pd.DataFrame) -> list[str]:
    out = [_shape_sentence(t) for t in shapes.values()]
    for role in ("identification", "validation"):
        w = white[white["role"] == role] if len(white) else white
        if not len(w):
            continue
        untested = int(w["p"].isna().sum())  # a Ljung-Box p of NaN (too few samples, no data): neither verdict
        w = w[w["p"].notna()]
        bad = w[~w["white"].astype(bool)]
        inn = d.settings.get("innovations")
        how = (f" (innovations of {', '.join(inn['outputs'])}: the measured inputs' noise taken out)" if inn else "")
        how += f"; {untested} not tested (no p-value)" if untested else ""
        if not len(w):
            out.append(f"{role} maneuvers: no whiteness test ran{how}")
        elif bad.empty:
            out.append(f"{role} maneuvers: residuals white in all {len(w)} tests (Ljung-Box at "
                       f"{d.settings['test_rate_hz']:g} Hz, family-wise alpha {d.settings['alpha']:g}){how}")
        else:
            items = ", ".join(f"{r.output} in {r.maneuver} (p = {r.p:.1e})" for r in bad.itertuples())
            out.append(f"{role} maneuvers: residuals NOT white in {len(bad)} of {len(w)} tests{how}: {items}")
    for role, sp in d.spectra.items():
        hot = {o: v for o, v in sp.get("band_ratio", {}).items() if v > BAND_RATIO_FLAG}
        if hot:
            out.append(f"{role} residual spectra concentrated in {DYN_BAND[0]:g}-{DYN_BAND[1]:g} Hz (band ratio > "
                       f"{BAND_RATIO_FLAG:g}): " + ", ".join(f"{o} {v:.3g}" for o, v in hot.items()))
    if len(coh):
        sig = coh[coh["significant"].astype(bool)]
        if len(sig):
            out.append("coherence of residual with input above the zero-coherence threshold: "
                       + ", ".join(f"{r.output} with {r.input} in {r.maneuver} ({r.peak:.2f} at {r.f_peak:.2g} Hz)"
                                   for r in sig.itertuples()))
    if len(corr):
        for (kind, role), gr in corr.groupby(["kind", "role"], sort=False):
            bound = d.settings["alpha"] / max(int(gr["p"].notna().sum()), 1)
            for ch, g in gr.groupby("channel", sort=False):
                g = g.dropna(subset=["r"])
                if g.empty:
                    continue
                top = g.loc[g["r"].abs().idxmax()]
                if abs(top["r"]) >= CORRELATION_FLAG and top["p"] < bound:
                    out.append(f"{kind} residual {ch} ({role}) correlates most with {top['regressor']}: "
                               f"r = {top['r']:+.2f} (nominal p = {top['p']:.1e})")
    return out


# ---------------------------------------------------------------- the diagnosis
#: a parameter whose trim sensitivity times its magnitude stays below this [rad] does not act on trims
#: (e.g. a time constant): its column is finite-difference noise and is left out of the nuisance
TRIM_EFFECT_FLOOR = 1e-7


def trim_nuisance(res: Residuals, channel: str) -> tuple[np.ndarray | None, list]:
    """The trim sensitivities of the identified parameters for ``channel`` (columns ``dres_<c>_d<p>``),
    without parameters that do not act on trims."""
    names = []
    for p in res.parameters:
        col = f"dres_{channel}_d{p}"
        if col not in res.trim:
            continue
        ref = abs(res.parameters[p]) or 1.0
        if np.nanmax(np.abs(res.trim[col].to_numpy(dtype=float))) * ref >= TRIM_EFFECT_FLOOR:
            names.append(p)
    if not names:
        return None, []
    return res.trim[[f"dres_{channel}_d{p}" for p in names]].to_numpy(dtype=float), names


def _whiteness(res: Residuals, clean: pd.DataFrame, test_rate_hz: float, alpha: float, settings: dict) -> pd.DataFrame:
    """Whiteness table: the innovations where the residuals have them (input errors estimated, the input
    noise's colour taken out, :mod:`.innovations`), the nuisance-cleaned residuals for every other output."""
    inn = res.innovations
    inn_outs = list(res.info.get("innovations", {}).get("outputs", [])) if inn is not None and len(inn) else []
    raw_outs = [o for o in res.outputs if o not in inn_outs]
    parts = []
    if raw_outs:
        parts.append(whiteness_table(clean, raw_outs, test_rate_hz, alpha).assign(series="residual"))
    if inn_outs:
        rate = float(res.info["innovations"]["test_rate_hz"])
        settings["innovations"] = {"outputs": inn_outs, "test_rate_hz": rate}
        tab = inn.rename(columns={f"inn_{o}": f"res_{o}" for o in inn_outs})
        parts.append(whiteness_table(tab, inn_outs, rate, alpha).assign(series="innovation"))
    parts = [p for p in parts if len(p)]
    return with_bound(pd.concat(parts, ignore_index=True), alpha) if parts else pd.DataFrame()


def verdict_status(verdict: dict) -> str:
    """One word for a :func:`diagnose` verdict: "noise only", "unexplained residual" (a test found structure) or
    "not fully tested" (no test found structure, but a part of the verdict could not be tested: ``untested``)."""
    if verdict.get("noise_only"):
        return "noise only"
    return "not fully tested" if verdict.get("untested") and not structure_found(verdict) else "unexplained residual"


def structure_found(verdict: dict) -> bool:
    """Whether a test of the verdict found structure: a trim shape, identification residuals not white, records
    disagreeing on a bias, or input errors a signal explains (a part not tested counts as none)."""
    return not (all(s == "noise" for s in verdict.get("trim_shape", {}).values())
                and verdict.get("white_identification", True) and verdict.get("record_biases_agree", True)
                and verdict.get("input_path_consistent", True))


def diagnose(res: Residuals, alpha: float = 0.01, test_rate_hz: float = TEST_RATE_HZ, n_mc: int = 4000, seed: int = 0,
             absorb_parameters: bool = True) -> Diagnosis:
    """Run every residual test on ``res`` (see the module docstring).

    ``absorb_parameters``: the trim shape test allows a shift of the identified
    parameters (their trim sensitivities, when ``res`` has them) in every model.
    """
    settings = {"alpha": alpha, "test_rate_hz": test_rate_hz, "n_mc": n_mc, "seed": seed,
                "dynamics_band_hz": list(DYN_BAND), "high_band_hz": list(HIGH_BAND),
                "absorb_parameters": absorb_parameters}
    problems = list(res.problems)
    shapes = {}
    untested = []  # the parts of the verdict whose test could not run: no "noise only" without them
    for c in res.trim_channels:
        S, names = trim_nuisance(res, c) if absorb_parameters else (None, [])
        try:
            shapes[c] = trim_shape_test(res.trim["V"], res.trim[f"res_{c}"], c, alpha=alpha, n_mc=n_mc, seed=seed,
                                        nuisance=S, nuisance_names=names)
        except ValueError as exc:
            problems.append(str(exc))
            untested.append(f"trim shape of {c}")
    time = res.time
    if len(time):
        clean, nuisance = clean_time_residuals(time, res.outputs)
        white = _whiteness(res, clean, test_rate_hz, alpha, settings)
        spec = {role: spectra(clean, res.outputs, role) for role in dict.fromkeys(clean["role"])}
        coh, curves = coherence_table(clean, res.outputs, res.info.get("inputs"), alpha)
        corr = correlation_table(clean, res.trim, res.outputs, res.trim_channels, test_rate_hz)
    else:
        nuisance = white = coh = pd.DataFrame()
        corr = correlation_table(time, res.trim, res.outputs, res.trim_channels, test_rate_hz) if len(res.trim) \
            else pd.DataFrame()
        spec, curves = {}, {}
    d = Diagnosis(label=res.label, parameters=dict(res.parameters), settings=settings, rms=_records(res.rms()),
                  trim_shapes={c: t.to_dict() for c, t in shapes.items()}, nuisance=_records(nuisance),
                  whiteness=_records(white), spectra={r: s for r, s in spec.items() if s}, coherence=_records(coh),
                  coherence_curves=curves, correlations=_records(corr), problems=problems, info=dict(res.info))
    biases = record_bias_tests(res.info["innovations"]["record_biases"], alpha) \
        if res.info.get("innovations", {}).get("record_biases") else {}
    d.record_biases = {o: t.to_dict() for o, t in biases.items()}
    verdict = {"trim_shape": {c: t.shape for c, t in shapes.items()}}
    for role in ("identification", "validation"):
        w = white[white["role"] == role] if len(white) else white
        ran = w[w["p"].notna()] if len(w) else w  # a Ljung-Box p of NaN: too few samples or no data, not white
        if len(ran):
            verdict[f"white_{role}"] = bool(ran["white"].astype(bool).all())
        if role == "identification":
            untested += [f"whiteness of {r['output']} in {r['maneuver']} (n = {r['n']})"
                         for r in w[w["p"].isna()].to_dict(orient="records")] if len(w) else []
            untested += [f"the identification record {r['maneuver']} (not replayed)"
                         for r in res.info.get("not_replayed", []) if r["role"] == "identification"]
            inn_info = res.info.get("innovations", {})
            untested += [f"whiteness of {', '.join(inn_info.get('outputs', []))} in {r['maneuver']} (its innovations "
                         "failed)" for r in inn_info.get("failed", []) if r["role"] == "identification"]
    if biases:
        verdict["record_biases_agree"] = all(t.consistent for t in biases.values())
    path = InputPathTest.from_dict(res.info["innovations"]["input_path"]) \
        if res.info.get("innovations", {}).get("input_path") else None
    if path is not None:
        d.input_path = path.to_dict()
        verdict["input_path_consistent"] = path.consistent
        if path.alpha != alpha:
            d.problems.append(f"input path tested at alpha {path.alpha:g}, not {alpha:g}")
    structure = structure_found(verdict)
    if untested:
        verdict["untested"] = untested
    verdict["noise_only"] = not structure and not untested
    d.verdict = verdict
    d.findings = (_findings(d, shapes, white, coh, corr) + [t.describe() for t in biases.values() if not t.consistent]
                  + ([path.describe()] if path is not None and not path.consistent else []))
    d.findings.insert(0, "verdict: " + ("the residuals look like noise only (no trim shape, identification residuals "
                                        "white" + (", record biases agree" if biases else "")
                                        + (", input errors white" if path is not None else "") + ")"
                                        if verdict["noise_only"] else
                                        "structure left in the residuals: something is missing from the model"
                                        if structure else
                                        "not every test ran, so the residuals are not called noise only; not tested: "
                                        + "; ".join(untested)))
    return d


def diagnose_many(residuals: dict, **kw) -> dict:
    """{key: Diagnosis} for a dict of Residuals (e.g. the chosen and the time-domain point)."""
    return {k: diagnose(r, **kw) for k, r in residuals.items()}


def summary_rows(d: Diagnosis) -> list[dict]:
    """Per trim channel and time output: RMS (display units) and the test verdicts, for report tables."""
    rows = []
    rms = pd.DataFrame(d.rms)
    for c, t in d.trim_shapes.items():
        unit, fac = DISPLAY[c]
        rows.append({"data": "trim", "channel": c, "unit": unit, "RMS": t["rms"] * fac, "verdict": t["description"],
                     "p": min(t["p_values"].values())})
    w = pd.DataFrame(d.whiteness)
    for role in ("identification", "validation"):
        for o in dict.fromkeys(w["output"]) if len(w) else []:
            g = w[(w["role"] == role) & (w["output"] == o)]
            if g.empty:
                continue
            unit, fac = DISPLAY[o]
            r = rms[(rms["kind"] == "time") & (rms["role"] == role) & (rms["channel"] == o)]["rms"]
            ran = g[g["p"].notna()]  # a test without a p-value is neither white nor not
            n_bad = int((~ran["white"].astype(bool)).sum())
            untested = f", {len(g) - len(ran)} not tested" if len(ran) < len(g) else ""
            rows.append({"data": f"time ({role})", "channel": o, "unit": unit,
                         "RMS": float(r.iloc[0]) * fac if len(r) else np.nan,
                         "verdict": "not tested" if ran.empty else
                         (f"white in {len(ran)}/{len(g)} maneuvers{untested}" if untested else "white")
                         if n_bad == 0 else f"not white in {n_bad}/{len(ran)} maneuvers{untested}",
                         "p": float(ran["p"].min()) if len(ran) else np.nan})
    return rows
