"""The steady force and moment the recorded trims ask for: the equation error of the model at each trim point.

A trim point records the controls and the attitude that balance the aircraft at one speed. Put into a model's
equations of motion, they leave an acceleration wherever the model misses a steady force or moment. The force and
moment that would cancel it are what the trims ask the model to add, in N and N m, with no library of candidate
effects: what SIDPAC calls equation error, here at the trims.

At a trim point (speed V, flight-path angle gamma_fp; recorded col, lon, theta taken to the model's conventions,
:func:`pyomo_heli.physics.conventions.model_trim`): u = V cos(theta - gamma_fp), w = V sin(theta - gamma_fp),
q = 0, the inflow lambda_i and any extension state at rest (solved), and

    dX = -m du/dt,   dZ = -m dw/dt,   dM = -Iyy dq/dt                   [N, N, N m]

(:func:`pyomo_heli.physics.eom.rigid_body_rates`). A missing steady force (dX, dZ, dM) along the trims comes back
exactly (``tests/test_trim_forces.py``, on trims of M0 plus a held-out effect); a missing effect that acts through
the rotor comes back as the forces and moment it causes there.

Standard errors: the recorded channels' noise (``sigma``, rad) through the central-difference Jacobian of
(dX, dZ, dM) with respect to (col, lon, theta). Without ``sigma`` each channel's noise is estimated from the
identified model's trim residual by differences of neighbouring speeds (von Neumann: sigma^2 = mean((e_{k+1} -
e_k)^2) / 2 over the level trims ordered by speed), which a residual that varies smoothly with speed hardly inflates.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats
from scipy.optimize import root

from ..channels import TRIM_CHANNELS
from ..dataset.schema import TrimConventions
from ..physics.conventions import model_trim
from ..physics.model import STATES, HelicopterModel
from ..simulation.recorded_trims import parameter_step, predict
from ..simulation.trim import TrimError, hover_guess
from ..units import KT

#: the forces and moment, with their units
FORCES = {"dX": "N", "dZ": "N", "dM": "N m"}
#: central-difference step of the Jacobian with respect to the recorded channels [rad]
STEP = 1e-5


def forces_at(model: HelicopterModel, V: float, gamma_fp: float, col: float, lon: float, theta: float,
              guess: dict | None = None) -> tuple[np.ndarray, dict]:
    """(dX, dZ, dM) [N, N, N m] that balance ``model`` at speed V [m/s], flight-path angle gamma_fp and the model's
    col, lon, theta [rad], and the solved rest values of lambda_i and the extension states (a guess for the next)."""
    names = ("lambda_i",) + model.state_names[len(STATES):]
    g = guess or {"lambda_i": hover_guess(model)["lambda_i"]}
    a = theta - gamma_fp
    base = {"u": V * math.cos(a), "w": V * math.sin(a), "q": 0.0, "theta": theta}
    inputs = {"col": col, "lon": lon}

    def state(z):
        return {**base, **dict(zip(names, z))}

    def residual(z):
        r = model.rates(state(z), inputs)
        return np.array([r[n] for n in names])

    sol = root(residual, np.array([g.get(n, 0.0) for n in names], dtype=float), method="hybr", tol=1e-13)
    if not np.all(np.isfinite(sol.x)) or np.max(np.abs(residual(sol.x))) > 1e-9:
        raise ValueError(f"trim point at {V / KT:.1f} kt: the inflow and extension states have no rest value at the "
                         f"recorded controls and attitude (col {col:.4f}, lon {lon:.4f}, theta {theta:.4f} rad)")
    r = model.rates(state(sol.x), inputs)
    p = model.parameters
    return np.array([-p["m"] * r["u"], -p["m"] * r["w"], -p["Iyy"] * r["q"]]), dict(zip(names, sol.x))


def neighbour_sigma(V, e) -> float:
    """The noise standard deviation of a residual ``e`` over speeds ``V`` from differences of neighbouring speeds
    (von Neumann): sqrt(mean(diff(e)^2) / 2), the points ordered by speed; NaN with fewer than three."""
    order = np.argsort(np.asarray(V, float), kind="stable")
    e = np.asarray(e, float)[order]
    e = e[np.isfinite(e)]
    return float(np.sqrt(np.mean(np.diff(e) ** 2) / 2.0)) if len(e) >= 3 else math.nan


@dataclass
class ImpliedForces:
    """The steady force and moment a model lacks at each recorded trim point (:func:`implied_forces`).

    ``table``: one row per trim point: ``V [kt]``, ``gamma_fp [deg]``, ``source``, then ``dX [N]``, ``dZ [N]``,
    ``dM [N m]`` and their standard errors ``se dX [N]`` ...; ``sigma``: the recorded channels' noise used [rad];
    ``sigma_source``: where it came from; ``label``: the model's name.
    """

    table: pd.DataFrame
    sigma: dict
    sigma_source: str
    label: str = "model"
    problems: list = field(default_factory=list)
    #: identified parameter -> d(dX, dZ, dM)/d(parameter) at each point of ``table`` (points x 3, SI)
    shift: dict = field(default_factory=dict)

    def to_frame(self) -> pd.DataFrame:
        return self.table.copy()

    def level(self) -> pd.DataFrame:
        """The level trim points (gamma_fp = 0), ordered by speed."""
        t = self.table
        return t[np.isclose(t["gamma_fp [deg]"], 0.0)].sort_values("V [kt]", kind="stable")

    def summary(self) -> pd.DataFrame:
        """Per force: chi2 = sum (value / se)^2 over the trim points, its degrees of freedom (the points) and p,
        the largest value and the speed it is at; with identified parameters (``shift``) also ``chi2 beyond
        parameters``: the same after the weighted least-squares fit of a shift of those parameters is taken out
        (df: points minus the shift's rank), as the trim-shape test does (docs/diagnosis.md). The parameters were
        fitted to the same trims: read p as a pointer."""
        rows = []
        for i, (k, unit) in enumerate(FORCES.items()):
            v, s = self.table[f"{k} [{unit}]"].to_numpy(float), self.table[f"se {k} [{unit}]"].to_numpy(float)
            ok = np.isfinite(v) & np.isfinite(s) & (s > 0)
            chi2 = float(np.sum((v[ok] / s[ok]) ** 2))
            j = int(np.nanargmax(np.abs(v))) if np.isfinite(v).any() else None
            row = {"force": f"{k} [{unit}]", "points": int(ok.sum()), "chi2": chi2,
                   "p": float(stats.chi2.sf(chi2, ok.sum())) if ok.any() else math.nan,
                   "largest": float(v[j]) if j is not None else math.nan,
                   "at V [kt]": float(self.table["V [kt]"].iloc[j]) if j is not None else math.nan}
            if self.shift:
                D = np.column_stack([np.asarray(c, float).reshape(-1, 3)[:, i] for c in self.shift.values()])
                D = D[ok] / s[ok, None]
                y = v[ok] / s[ok]
                rank = np.linalg.matrix_rank(D, tol=1e-9 * max(np.abs(D).max(), 1e-300)) if D.size else 0
                r = y - D @ np.linalg.lstsq(D, y, rcond=None)[0] if rank else y
                df = int(ok.sum()) - rank
                row.update({"chi2 beyond parameters": float(r @ r), "df beyond": df,
                            "p beyond": float(stats.chi2.sf(r @ r, df)) if df > 0 else math.nan})
            rows.append(row)
        return pd.DataFrame(rows)

    def findings(self, alpha: float = 0.01) -> list[str]:
        """One sentence per force whose chi2 against zero has p < ``alpha``: its size, sign and where it peaks."""
        out = []
        for r in self.summary().to_dict("records"):
            test = (f"chi2 {r['chi2']:.3g} on {r['points']} trim points, p = {r['p']:.2g}" if not self.shift else
                    f"beyond a shift of {', '.join(self.shift)}: chi2 {r['chi2 beyond parameters']:.3g} on "
                    f"{r['df beyond']} df, p = {r['p beyond']:.2g}")
            p = r["p beyond"] if self.shift else r["p"]
            if r["points"] and p < alpha:
                out.append(f"the trims ask {self.label} for a steady {r['force'].split()[0]} of up to "
                           f"{r['largest']:+.3g} {r['force'].split('[')[1].rstrip(']')} at {r['at V [kt]']:.0f} kt "
                           f"({test}; equation error at the trims, no library)")
        return out

    def to_dict(self) -> dict:
        return {"label": self.label, "sigma_rad": self.sigma, "sigma_source": self.sigma_source,
                "summary": self.summary().to_dict("records"), "table": self.table.to_dict("records"),
                "problems": self.problems, "shift": self.shift}

    def __str__(self) -> str:
        return (f"steady force and moment the trims ask {self.label} to add (noise: {self.sigma_source})\n"
                + self.table.to_string(index=False, float_format=lambda x: f"{x:.4g}") + "\n\n"
                + self.summary().to_string(index=False, float_format=lambda x: f"{x:.4g}"))

    def save(self, folder) -> Path:
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        self.table.to_csv(folder / "implied_forces.csv", index=False)
        (folder / "implied_forces.json").write_text(json.dumps(
            {"label": self.label, "sigma_rad": self.sigma, "sigma_source": self.sigma_source,
             "problems": self.problems, "shift": self.shift}, indent=1))
        return folder

    @classmethod
    def load(cls, folder) -> "ImpliedForces":
        folder = Path(folder)
        meta = json.loads((folder / "implied_forces.json").read_text())
        table = pd.read_csv(folder / "implied_forces.csv", keep_default_na=False, na_values=[""])
        return cls(table, meta["sigma_rad"], meta["sigma_source"], meta["label"], meta.get("problems", []),
                   meta.get("shift", {}))


def implied_forces(model: HelicopterModel, trims: pd.DataFrame, conventions: TrimConventions | None = None,
                   sigma: dict | None = None, label: str = "model", free=()) -> ImpliedForces:
    """The steady force and moment ``model`` lacks at each recorded trim point of ``trims`` (a flight test's trim
    table: ``V`` [m/s], ``gamma_fp``, ``col``, ``lon``, ``theta`` [rad]; rows without all three channels are left
    out) as :class:`ImpliedForces`. ``conventions``: the flight test's (default: the format's); ``sigma``: the
    recorded channels' noise {col, lon, theta} [rad] (default: from the model's trim residual, module docstring);
    ``free``: the identified parameters, whose shift the summary takes out (:meth:`ImpliedForces.summary`)."""
    conventions = conventions or TrimConventions()
    missing = [c for c in ("V", "gamma_fp") + TRIM_CHANNELS if c not in trims]
    if missing:
        raise ValueError(f"trims: no column {', '.join(missing)} (a flight test's trim table has V, gamma_fp, "
                         f"col, lon, theta)")
    pts = trims[trims[list(TRIM_CHANNELS)].notna().all(axis=1)].reset_index(drop=True)
    p = model.parameters
    rows, jac, problems, guess = [], [], [], None
    shift = {n: [] for n in free}  # d(dX, dZ, dM)/d(parameter) at each point kept
    for _, r in pts.sort_values("V", kind="stable").iterrows():
        V, gam = float(r["V"]), float(r["gamma_fp"])
        rec = np.array([float(r[c]) for c in TRIM_CHANNELS])

        def at(values, guess=None):
            mt = model_trim(*values, p, conventions)
            return forces_at(model, V, gam, mt["col"], mt["lon"], mt["theta"], guess)

        try:
            F, guess = at(rec, guess)
            J = np.column_stack([(at(rec + STEP * d, guess)[0] - at(rec - STEP * d, guess)[0]) / (2 * STEP)
                                 for d in np.eye(3)])
            D = {n: _parameter_column(model, n, V, gam, rec, conventions, guess) for n in free}
        except ValueError as exc:
            problems.append(str(exc))
            continue
        rows.append({"V [kt]": V / KT, "gamma_fp [deg]": math.degrees(gam), "source": r.get("source", ""),
                     **{f"{k} [{u}]": float(v) for (k, u), v in zip(FORCES.items(), F)}})
        jac.append(J)
        for n in free:
            shift[n].append(D[n].tolist())
    source = "given"
    if sigma is None:
        sigma, source = residual_sigma(model, pts, conventions), "the model's trim residual, neighbouring speeds"
    s = np.array([sigma.get(c, math.nan) for c in TRIM_CHANNELS], float)
    for row, J in zip(rows, jac):
        cov = J @ np.diag(s**2) @ J.T
        for i, (k, u) in enumerate(FORCES.items()):
            row[f"se {k} [{u}]"] = float(math.sqrt(cov[i, i])) if np.isfinite(cov[i, i]) else math.nan
    cols = ["V [kt]", "gamma_fp [deg]", "source"] + [f"{k} [{u}]" for k, u in FORCES.items()] + \
        [f"se {k} [{u}]" for k, u in FORCES.items()]
    return ImpliedForces(pd.DataFrame(rows, columns=cols), {c: float(v) for c, v in zip(TRIM_CHANNELS, s)},
                         source, label, problems, shift)


def _parameter_column(model: HelicopterModel, name: str, V: float, gam: float, rec, conventions, guess) -> np.ndarray:
    """d(dX, dZ, dM)/d(parameter ``name``) at one recorded trim point (central difference; one-sided at a bound)."""
    a, b = parameter_step(model, name)
    out = []
    for x in (a, b):
        m = model.with_parameters(**{name: x})
        mt = model_trim(*rec, m.parameters, conventions)
        out.append(forces_at(m, V, gam, mt["col"], mt["lon"], mt["theta"], guess)[0])
    return (out[1] - out[0]) / (b - a)


def residual_sigma(model: HelicopterModel, pts: pd.DataFrame, conventions: TrimConventions) -> dict:
    """Each recorded channel's noise [rad] from ``model``'s residual at the level trim points of ``pts``
    (:func:`neighbour_sigma`); NaN where the model does not trim."""
    level = pts[np.isclose(pts["gamma_fp"].to_numpy(float), 0.0)]
    out = {}
    for c in TRIM_CHANNELS:
        try:
            e = level[c].to_numpy(float) - predict(model, conventions, level["V"], [c] * len(level))
        except (TrimError, ValueError):
            e = np.array([])
        out[c] = neighbour_sigma(level["V"], e)
    return out
