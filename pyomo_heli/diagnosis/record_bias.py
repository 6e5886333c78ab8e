"""Do the records agree on each output's bias? A data-compatibility check across maneuvers.

Every maneuver's residual is tested for whiteness after a nuisance is taken off: a constant bias per
output and the response to a constant offset of each input (:mod:`.innovations`). Whiteness cannot see
what is constant within a record, so an error that shifts an output by a different amount in each record
(a position error of the airspeed probe that depends on speed, a calibration that drifts with the flight
condition) passes it. Flight-path reconstruction practice compares the bias estimates across records:
a sensor bias is the same in every record; what changes with the flight condition is a model or sensor
error.

For each output o, with the records' generalised least-squares bias estimates ``b_r`` and their standard
errors ``s_r`` (:func:`~.innovations.maneuver_innovations`: the covariance of the sensor noise and of the
measured inputs' noise, scaled by the output's innovation RMS in the record)

    chi2_o = sum_r (b_r - b_o)^2 / s_r^2  ~  chi^2(R - 1)  when every record has the same bias,

``b_o`` the inverse-variance weighted mean. The records disagree when p < alpha / (number of outputs)
(Bonferroni). What they disagree about is shown per trim speed: the weighted mean bias of the records
flown there, minus ``b_o``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd
from scipy import stats

from ..units import KT
from .residuals import DISPLAY


@dataclass
class RecordBiasTest:
    """The records' agreement on one output's bias (SI)."""

    output: str
    chi2: float
    df: int
    p: float
    bound: float  # the Bonferroni level the p is compared with
    common: float  # inverse-variance weighted mean bias
    by_speed: list = field(default_factory=list)  # [{"V": m/s, "shift": SI, "se": SI, "records": n}]

    @property
    def consistent(self) -> bool:
        return not self.p < self.bound

    def to_dict(self) -> dict:
        return {**asdict(self), "consistent": self.consistent}

    def describe(self) -> str:
        unit, fac = DISPLAY[self.output]
        if self.consistent:
            return (f"record biases of {self.output} agree (chi2 = {self.chi2:.3g} on {self.df} df, p = {self.p:.2g}"
                    f" >= {self.bound:.2g})")
        top = sorted(self.by_speed, key=lambda r: -abs(r["shift"] / r["se"]))[:3]
        where = ", ".join(f"{r['shift'] * fac:+.3g} +- {r['se'] * fac:.2g} {unit} at {r['V'] / KT:.0f} kt"
                          for r in sorted(top, key=lambda r: r["V"]))
        return (f"record biases of {self.output} differ between records (chi2 = {self.chi2:.3g} on {self.df} df, "
                f"p = {self.p:.2g} < {self.bound:.2g}): it changes with the flight condition; residual bias (model - "
                f"data) against the records' mean: {where}")


def record_bias_tests(records: list[dict], alpha: float = 0.01) -> dict[str, RecordBiasTest]:
    """One :class:`RecordBiasTest` per output found in ``records`` (rows with ``trim_speed``, ``bias_<o>`` and
    ``se_bias_<o>``; the innovations' ``record_biases``). An output with fewer than two records is left out."""
    tab = pd.DataFrame(records)
    outs = [c[len("bias_"):] for c in tab.columns if c.startswith("bias_") and f"se_{c}" in tab]
    groups = {}
    for o in outs:
        g = tab[["trim_speed", f"bias_{o}", f"se_bias_{o}"]].dropna()
        g = g[g[f"se_bias_{o}"] > 0]
        if len(g) >= 2:
            groups[o] = g
    tests = {}
    for o, g in groups.items():
        b, s = g[f"bias_{o}"].to_numpy(float), g[f"se_bias_{o}"].to_numpy(float)
        w = 1.0 / s**2
        common = float(np.sum(w * b) / np.sum(w))
        chi2 = float(np.sum(w * (b - common) ** 2))
        by_speed = []
        for v, gv in g.groupby("trim_speed"):
            wv = 1.0 / gv[f"se_bias_{o}"].to_numpy(float) ** 2
            mv = float(np.sum(wv * gv[f"bias_{o}"].to_numpy(float)) / np.sum(wv))
            by_speed.append({"V": float(v), "shift": mv - common, "se": float(np.sqrt(1.0 / np.sum(wv))),
                             "records": int(len(gv))})
        tests[o] = RecordBiasTest(o, chi2, len(g) - 1, float(stats.chi2.sf(chi2, len(g) - 1)), alpha / len(groups),
                                  common, by_speed)
    return tests
