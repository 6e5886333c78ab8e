"""The local linear model as a flight-test engineer reads it: labelled A, B, C, D with SI units, the mode
table (frequency, damping, period or time to half/double, mode name) and the units of Bode gains
(``pyomo-heli linearize``, the Bode plots of the tri-objective report).
"""
from __future__ import annotations

import numpy as np
import pandas as pd


#: SI unit of every state, input and output of the linear model (the rows and columns of A, B, C, D)
SIGNAL_UNITS = {"u": "m/s", "w": "m/s", "q": "rad/s", "theta": "rad", "lambda_i": "-", "col": "rad", "lon": "rad",
                "n_x": "g", "n_z": "g", "TAS": "m/s", "beta_0": "rad"}


def signal_unit(name: str) -> str:
    """SI unit of a state, input or output ("?" for an extension's state of unknown unit)."""
    return SIGNAL_UNITS.get(name, "?")


def _per(num: str, den: str) -> str:
    """The unit num/den, simplified where it cancels ("-" is dimensionless)."""
    if num == den:
        return "-"
    if den == "-":
        return num
    n = f"({num})" if "/" in num else num
    d = f"({den})" if "/" in den else den
    return f"1/{d}" if num == "-" else f"{n}/{d}"


def gain_unit(output: str, input: str) -> str:
    """Unit of the transfer function output/input, e.g. (rad/s)/rad for q/lon; 0 dB is 1 of it."""
    return _per(signal_unit(output), signal_unit(input))


def labelled_matrices(lin) -> dict[str, pd.DataFrame]:
    """A, B, C, D of a :class:`~pyomo_heli.simulation.linearize.LinearModel` with named rows and columns.

    Rows of A and B: d/dt of each state; rows of C and D: each output; columns: states or inputs. Each
    label carries its SI unit, so the unit of an entry is row unit / column unit (per second for A and B).
    """
    def per_s(unit):
        return "1/s" if unit == "-" else (unit + "^2" if unit.endswith("/s") else unit + "/s")

    def lab(names, rate=False):
        return [f"d{n}/dt [{per_s(signal_unit(n))}]" if rate else f"{n} [{signal_unit(n)}]" for n in names]

    xs, us, ys = list(lin.states), list(lin.inputs), list(lin.outputs)
    return {"A": pd.DataFrame(lin.A, index=lab(xs, True), columns=lab(xs)),
            "B": pd.DataFrame(lin.B, index=lab(xs, True), columns=lab(us)),
            "C": pd.DataFrame(lin.C, index=lab(ys), columns=lab(xs)),
            "D": pd.DataFrame(lin.D, index=lab(ys), columns=lab(us))}


#: mode names by the state that takes the largest part in the mode (participation factor)
_REAL_MODE = {"u": "speed", "w": "heave", "q": "pitch", "theta": "attitude", "lambda_i": "inflow"}
_OSC_MODE = {"u": "phugoid", "theta": "phugoid", "w": "short period", "q": "short period",
             "lambda_i": "inflow oscillation"}


def mode_table(lin) -> pd.DataFrame:
    """The modes of A: one row per real eigenvalue and per complex pair (the one with Im > 0).

    For an eigenvalue lambda [1/s]:

        natural frequency omega_n = |lambda| [rad/s],   damping ratio zeta = -Re(lambda) / |lambda| [-]
        oscillatory (Im != 0): period T = 2 pi / |Im(lambda)| [s]
        real: time to half amplitude ln 2 / |lambda| (stable) or to double it (unstable) [s]

    The mode is named after the state with the largest participation factor
    p_k = |v_k w_k| / sum_k |v_k w_k| (v right, w left eigenvector of lambda; unit-free, so the SI units of
    the states do not bias it): an oscillation in u or theta is the phugoid, one in q or w the short period; a
    real mode is the subsidence (stable) or divergence (unstable) of its state.
    """
    ev, right = np.linalg.eig(lin.A)
    left = np.linalg.inv(right).T  # columns: left eigenvectors, normalised so that w_k^T v_k = 1
    rows = []
    names = list(lin.states)
    for k in np.lexsort((ev.imag, ev.real)):
        lam = ev[k]
        if lam.imag < -1e-12 * max(abs(lam), 1.0):
            continue  # the conjugate of a pair: listed once
        part = np.abs(right[:, k] * left[:, k])
        part = part / part.sum()
        dom = names[int(np.argmax(part))]
        wn = abs(lam)
        oscillatory = abs(lam.imag) > 1e-12 * max(wn, 1.0)
        unstable = lam.real > 0
        if oscillatory:
            name = _OSC_MODE.get(dom, f"{dom} oscillation")
        else:
            name = f"{_REAL_MODE.get(dom, dom)} {'divergence' if unstable else 'subsidence'}"
        if unstable and oscillatory:
            name += " (unstable)"
        rows.append({"mode": name, "real [1/s]": float(lam.real), "imag [rad/s]": float(abs(lam.imag)),
                     "frequency [rad/s]": float(wn), "damping [-]": float(-lam.real / wn) if wn > 0 else float("nan"),
                     "period [s]": float(2 * np.pi / abs(lam.imag)) if oscillatory else float("nan"),
                     "time to half [s]": float(np.log(2) / abs(lam.real)) if lam.real < 0 else float("nan"),
                     "time to double [s]": float(np.log(2) / lam.real) if unstable else float("nan"),
                     "dominant state": dom, "participation": float(part.max())})
    return pd.DataFrame(rows)


def linearization_text(lin, speed_kt: float) -> str:
    """Labelled A, B, C, D and the mode table, as printed by ``pyomo-heli linearize``."""
    fmt = lambda x: f"{x:.5g}"  # noqa: E731
    parts = [f"{speed_kt:g} kt: finite-difference linearisation of the float model at its trim "
             f"(SI units, angles in rad; entry unit = row unit / column unit)"]
    for key, df in labelled_matrices(lin).items():
        what = {"A": "dx/dt = A x + B u", "B": "dx/dt = A x + B u", "C": "y = C x + D u", "D": "y = C x + D u"}[key]
        parts += [f"{key} ({what}):", df.to_string(float_format=fmt), ""]
    modes = mode_table(lin)
    cols = ["mode", "frequency [rad/s]", "damping [-]", "period [s]", "time to half [s]", "time to double [s]",
            "real [1/s]", "imag [rad/s]"]
    parts += ["modes (eigenvalues of A):", modes[cols].to_string(index=False, float_format=fmt, na_rep="-"),
              "poles [1/s]: " + ", ".join(f"{z.real:.4f}{z.imag:+.4f}j" if abs(z.imag) > 0 else f"{z.real:.4f}"
                                          for z in lin.poles())]
    return "\n".join(parts)


def linearization_dict(lin, speed_kt: float) -> dict:
    """The JSON record of ``pyomo-heli linearize --json``: matrices with names and units, trim, modes."""
    def nan_none(v):
        return None if isinstance(v, float) and not np.isfinite(v) else v

    return {"speed_kt": speed_kt, "speed_m_s": lin.V, "units": "SI, angles in rad",
            "states": [{"name": n, "unit": signal_unit(n)} for n in lin.states],
            "inputs": [{"name": n, "unit": signal_unit(n)} for n in lin.inputs],
            "outputs": [{"name": n, "unit": signal_unit(n)} for n in lin.outputs],
            "A": lin.A.tolist(), "B": lin.B.tolist(), "C": lin.C.tolist(), "D": lin.D.tolist(),
            "trim": {k: float(v) for k, v in lin.trim.items() if isinstance(v, (int, float))},
            "modes": [{k: nan_none(v) for k, v in r.items()} for r in mode_table(lin).to_dict("records")]}
