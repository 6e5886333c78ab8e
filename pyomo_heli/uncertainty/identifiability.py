"""Identifiability: singular values of the scaled sensitivity matrix, per objective and combined.

The scaled sensitivity matrix of an objective has one row per residual,
divided by that residual's estimated noise standard deviation, and one column
per free parameter, multiplied by the parameter's scale (the optimizer's
unit). Its singular values sigma_k are the square roots of the eigenvalues of
the Fisher information in scaled units: along the right singular vector v_k
the Cramer-Rao standard error is 1/sigma_k scale units. A small sigma_k names
a weak direction: a combination of parameters the data hardly see. The
"combined" matrix stacks the time and trim rows, i.e. F_time + F_trim, the
information of both data types with each residual covariance as estimated.

A singular value below ``SV_RTOL`` times the largest of its matrix is a direction
the data do not see at all (Iyy in the trims: a trim is an equilibrium): the
central-difference sensitivities leave only round-off and trim-solve tolerance
there (measured 2.5e-9 and 5.3e-9 against 7.8 for Case 2's trims, changing from
run to run), so it is reported as 0 with an infinite Cramer-Rao bound.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from .cramer_rao import PointInformation

#: components below this share of a unit direction are not named
NAME_THRESHOLD = 0.1
#: singular values below this share of the largest are numerically zero (module docstring)
SV_RTOL = 1e-6


def describe_direction(v: np.ndarray, names) -> str:
    """A unit vector as '+0.97 theta_twist -0.24 CL_alpha_HT' (largest first, tiny parts dropped)."""
    v = np.asarray(v, dtype=float)
    if v[np.argmax(np.abs(v))] < 0:
        v = -v
    order = np.argsort(-np.abs(v))
    parts = [f"{v[i]:+.2f} {names[i]}" for i in order if abs(v[i]) >= NAME_THRESHOLD]
    return " ".join(parts)


@dataclass
class Identifiability:
    """Singular values and directions per objective ("time", "trim", "combined")."""

    names: list
    table: pd.DataFrame  # objective, k, singular_value, se_scaled, direction, v_<name>...

    def weakest(self, objective: str) -> pd.Series:
        t = self.table[self.table.objective == objective]
        return t.loc[t.singular_value.idxmin()]

    def condition(self, objective: str) -> float:
        sv = self.table.loc[self.table.objective == objective, "singular_value"].to_numpy()
        return float(sv.max() / sv.min()) if len(sv) and sv.min() > 0 else float("inf")

    def save(self, path) -> None:
        self.table.to_csv(path, index=False, float_format="%.8g")

    @classmethod
    def load(cls, path) -> "Identifiability":
        t = pd.read_csv(path)
        return cls(names=[c[2:] for c in t.columns if c.startswith("v_")], table=t)

    def summary(self) -> str:
        lines = []
        for obj in dict.fromkeys(self.table.objective):
            w = self.weakest(obj)
            lines.append(f"{obj:>8s}: singular values "
                         + ", ".join(f"{x:.4g}" for x in self.table.loc[self.table.objective == obj,
                                                                         "singular_value"])
                         + f"; condition {self.condition(obj):.3g}; weakest direction {w.direction} "
                         f"(CRB {w.se_scaled:.3g} scale units)")
        return "\n".join(lines)

    def __str__(self) -> str:
        cols = ["objective", "k", "singular_value", "se_scaled", "direction"]
        return self.table[cols].to_string(index=False, float_format=lambda x: f"{x:.4g}")


def _svd_rows(objective: str, A: np.ndarray, names) -> list[dict]:
    if A.shape[0] == 0:
        return []
    # full_matrices: with fewer rows than parameters (a few trims) the directions the rows cannot see are the last
    # rows of vt, singular value 0, not left out
    _, s, vt = np.linalg.svd(A, full_matrices=A.shape[0] < A.shape[1])  # full only where it is small
    s = np.concatenate([s, np.zeros(vt.shape[0] - s.size)])
    s = np.where(s < SV_RTOL * s.max(), 0.0, s) if s.size else s
    rows = []
    for k, (sk, v) in enumerate(zip(s, vt)):
        if v[np.argmax(np.abs(v))] < 0:
            v = -v
        rows.append({"objective": objective, "k": k + 1, "singular_value": float(sk),
                     "se_scaled": float(1 / sk) if sk > 0 else float("inf"),
                     "direction": describe_direction(v, names), **{f"v_{n}": float(x) for n, x in zip(names, v)}})
    return rows


def identifiability(info: PointInformation) -> Identifiability:
    """Singular values of the scaled sensitivity matrices of J_time, J_trim and both at ``info``."""
    names = list(info.names)
    At, Ar = info.scaled_time(), info.scaled_trim()
    rows = _svd_rows("time", At, names) + _svd_rows("trim", Ar, names)
    if At.shape[0] and Ar.shape[0]:
        rows += _svd_rows("combined", np.vstack([At, Ar]), names)
    return Identifiability(names=names, table=pd.DataFrame(rows))
