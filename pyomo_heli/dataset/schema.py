"""Typed objects of a loaded flight-test dataset and the column vocabulary of the files.

Inside the package everything is SI with angles in radians.  Degrees and knots appear only in
the files, where every column name carries its unit (``<quantity>_<unit>``); see
``docs/data_format.md``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..channels import INPUTS, TRIM_CHANNELS
from ..units import DEG, KT

FORMAT_NAME = "pyomo_heli-flighttest"
FORMAT_VERSION = 1
MANIFEST_NAME = "manifest.json"
TRUTH_NAME = "truth.json"  # evaluation-only ground truth; never opened by this package
#: "frequency": records for frequency responses only (sweeps), used by no time-domain fit or validation
ROLES = ("identification", "validation", "frequency")
INPUT_CHANNELS = INPUTS
NAME_PATTERN = r"[A-Za-z0-9_-]+"


#: model speed range of trim speeds [kt]
SPEED_RANGE_KT = (0.0, 150.0)
#: below this speed [kt] the pitot is unreliable: no manifest-vs-TAS consistency check where both the manifest's
#: trim speed and the measured one are below it
PITOT_MIN_KT = 15.0
#: length of the record start [s] averaged for the manifest-vs-TAS consistency check
TRIM_WINDOW_S = 1.0
#: allowed relative spread of the sample spacing around its median
SPACING_TOL = 0.01
MIN_SAMPLES = 3
#: plausible sample rates of a maneuver record [Hz]: flight-test data systems record at 10-1000 Hz; outside
#: 1..10,000 Hz the time column is in another unit (ms, or minutes above 166 Hz) or corrupt (time stamps 1e300 s
#: apart). Minutes of a slower record read 600-10,000 Hz: the kinematic check below names those
SAMPLE_RATE_RANGE_HZ = (1.0, 10_000.0)
#: a numeric CSV cell: plain ASCII decimal number with optional sign, point and exponent (no '_' digit
#: separators, no non-ASCII digits such as '٥', which Python's float() would accept)
DECIMAL_PATTERN = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?"

# Plausible ranges of the manifest's physical constants (check-data rejects values outside; they catch
# unit slips and typos, they are not model limits):
#: mass_kg [kg]: the lightest manned helicopters have a take-off mass of a few hundred kg, the heaviest
#: in service (Mi-26) 56 000 kg (Jane's All the World's Aircraft); the range leaves margin both ways
MASS_RANGE_KG = (100.0, 100_000.0)
#: atmosphere.rho_kg_m3 [kg/m^3]: ISA (ISO 2533:1975) density is 0.312 at 12 km, above any helicopter
#: ceiling, and 1.225 at sea level; 1013 hPa at -50 degC gives 1.58 (cold-weather trials)
RHO_RANGE_KG_M3 = (0.3, 1.6)
#: atmosphere.g_m_s2 [m/s^2]: surface gravity on Earth lies within 9.76 (equatorial mountains) .. 9.834
#: (poles) (WGS 84 normal gravity; standard gravity 9.80665)
G_RANGE_M_S2 = (9.7, 9.9)
#: a manifest trim_speed_kt and a measured airspeed of the same trim (the record's start, see TRIM_WINDOW_S, or
#: the trims.csv row whose ``source`` is the maneuver) agree within max(TRIM_SPEED_TOL_KT, TRIM_SPEED_TOL_REL x
#: trim_speed_kt); below PITOT_MIN_KT (both speeds) airspeeds are not compared.  The
#: bundled datasets agree exactly (the generator writes both from one number); a start trim tagged with the
#: wrong maneuver (e.g. 20 kt for an 80 kt maneuver) is far outside.
TRIM_SPEED_TOL_KT = 5.0
TRIM_SPEED_TOL_REL = 0.2
#: trims.csv flight-path angle limit |gamma_fp| [deg] (a plausible range, not a model limit).  Steady
#: helicopter climbs stay near 10-15 deg (a Bo-105 climbs at about 8 m/s at its best-climb speed of about
#: 30-35 m/s); steep approaches are flown at under 15 deg and autorotative descents at about 15-25 deg
#: (8-10 m/s sink at 50-70 kt, steeper only at low speed).  30 deg leaves margin; beyond it the row is
#: near-vertical flight, which the speed-indexed trim table does not describe, or a slip such as 90 for a
#: vertical climb.
GAMMA_FP_LIMIT_DEG = 30.0
# The manifest's "inputs" of a maneuver must match its record: the frequency responses of J_linear take a
# maneuver as single-input for "col" or "lon" on the manifest's word (frequency_response.single_input_maneuvers).
# A record contradicts it when an undeclared input channel clearly moves more than a declared one: its standard
# deviation over the record is more than INPUT_DOMINANCE times the declared channel's, and it is movement, not
# sensor noise: above INPUT_NOISE_FACTOR x the channel's noise and above INPUT_STD_FLOOR_DEG.  The noise is
# estimated from the sample-to-sample differences, median|diff| / (0.6745 sqrt 2), which steps and doublets
# leave unchanged except at their few edges; for anti-alias-filtered noise it underestimates (the bundled
# records: 0.01 deg for a recorded 0.02 deg), hence the factor 3 and the ratio test, which two channels holding
# only noise of similar level never pass.  The bundled records have 0.02 deg input noise (std 0.02 deg on the
# quiet channel) and 0.5-1 deg excitations (std 0.18-0.36 deg, 8.5x the quiet channel or more); a swapped
# declaration gives a ratio near 10.  Ratios 1-2 are let through: off-axis pilot corrections or sensors of
# different noise can give them without the record being a two-input maneuver.
#: an undeclared input channel whose std exceeds this many times a declared channel's contradicts "inputs"
INPUT_DOMINANCE = 2.0
#: ... provided it moves: its std exceeds this many times its noise estimate
INPUT_NOISE_FACTOR = 3.0
#: ... and this [deg] (a noise-free record's round-off is far below)
INPUT_STD_FLOOR_DEG = 0.01
# Kinematic consistency of a record (check-data): the pitch attitude is the time integral of the pitch rate
# (longitudinal motion), so theta - theta(t0) regressed on the integral of q dt has slope 1. Time in minutes, q in
# rad/s under a deg/s name (or the reverse) or q of the opposite sign give slopes near 60, 57 (1/57) or -1. Tested
# only where the two are clearly related (|correlation| >= KINEMATIC_CORR_MIN): a collective record at hover
# hardly pitches. On the bundled records (noisy and clean) the related ones give 0.94-1.05, correlation >= 0.93.
#: |correlation| of theta - theta(t0) with the integral of q dt from which the slope is tested
KINEMATIC_CORR_MIN = 0.9
#: accepted slope of theta - theta(t0) on the integral of q dt
KINEMATIC_SLOPE_RANGE = (0.5, 2.0)
#: least mean n_z [g] over the first TRIM_WINDOW_S of a record (a trim): the format's n_z is positive up, about
#: cos(gamma) >= 0.87 in steady flight; a record of the opposite sign (about -1 g) is caught
NZ_START_MIN_G = 0.5
#: relative difference allowed between a manifest constant and the model parameter it stands for
#: (mass_kg / m, rho_kg_m3 / rho, g_m_s2 / g), see ``check_model_matches_manifest``
MODEL_MATCH_RTOL = 0.005
#: the trim channels (TRIM_CHANNELS, from channels.py) may be left empty in a row of trims.csv (each
#: quantity measured at its own speeds); every row must carry at least one of them
#: conventions.lon_sign values: +1 the format's own (positive aft), -1 the recorded lon is positive forward
LON_SIGNS = (1, -1)
#: conventions.theta_datum_deg given as this word: the datum is unknown and estimated by the identification
ESTIMATE = "estimate"
#: plausible |conventions.theta_datum_deg| [deg]: fuselage reference lines differ from body axes by a few degrees
THETA_DATUM_LIMIT_DEG = 15.0


@dataclass(frozen=True)
class TrimConventions:
    """How a flight test's recorded trim channels relate to the model's (manifest ``conventions``).

    ``collective_station``: r/R of the blade station the recorded collective is the pitch of (0: root,
    theta_0); None: the model's own reference station ``r_ref`` (the format's default, section 4).
    ``lon_sign``: +1 when the recorded longitudinal cyclic is positive aft (the format's convention), -1
    when it is positive forward. ``theta_datum``: recorded pitch attitude minus the model's body-axis
    attitude [rad] (a fuselage reference line at an angle to the body x axis); None when it is not known
    (``"estimate"`` in the manifest): the identification estimates it. The model's output side applies
    them (:mod:`pyomo_heli.physics.conventions`).
    """

    collective_station: float | None = None
    lon_sign: int = 1
    theta_datum: float | None = 0.0

    @property
    def default(self) -> bool:
        return self == TrimConventions()

    @property
    def estimate_theta_datum(self) -> bool:
        return self.theta_datum is None

    def to_manifest(self) -> dict:
        out = {}
        if self.collective_station is not None:
            out["collective_station"] = float(self.collective_station)
        if self.lon_sign != 1:
            out["lon_sign"] = int(self.lon_sign)
        if self.theta_datum is None:
            out["theta_datum_deg"] = ESTIMATE
        elif self.theta_datum != 0.0:
            out["theta_datum_deg"] = float("%.10g" % (self.theta_datum / DEG))
        return out


@dataclass(frozen=True)
class Quantity:
    """One physical quantity of a table and the unit variants accepted for it in files."""

    name: str  # file prefix, e.g. "q"
    si: str  # column name in the loaded (SI) DataFrame, e.g. "q"
    label: str  # human description
    units: dict  # unit suffix -> factor to SI
    required: bool = True
    limit: float | None = None  # plausible |value| in SI (None: no check)
    limit_text: str = ""  # the limit in file units for messages, e.g. "90 deg"
    kind: str = "number"  # "number" or "text"
    #: an empty cell is a measurement not taken (NaN when loaded), not an error (trim channels)
    may_be_empty: bool = False


_ANGLE = {"deg": DEG, "rad": 1.0}

MANEUVER_QUANTITIES: tuple[Quantity, ...] = (
    Quantity("t", "t", "time", {"s": 1.0}),
    Quantity("col", "col", "collective pitch at 0.7 R", _ANGLE, limit=45 * DEG, limit_text="45 deg"),
    Quantity("lon", "lon", "longitudinal cyclic theta_1s, positive aft", _ANGLE,
             limit=45 * DEG, limit_text="45 deg"),
    Quantity("q", "q", "pitch rate", {"deg_s": DEG, "rad_s": 1.0}, limit=360 * DEG, limit_text="360 deg/s"),
    Quantity("theta", "theta", "pitch attitude", _ANGLE, limit=90 * DEG, limit_text="90 deg"),
    Quantity("nx", "n_x", "specific force n_x", {"g": 1.0}, limit=5.0, limit_text="5 g"),
    Quantity("nz", "n_z", "specific force n_z", {"g": 1.0},
             limit=5.0, limit_text="5 g"),
    Quantity("tas", "TAS", "true airspeed", {"m_s": 1.0, "kt": KT}, limit=250 * KT, limit_text="250 kt"),
    Quantity("beta0", "beta_0", "rotor coning angle", _ANGLE, required=False, limit=30 * DEG,
             limit_text="30 deg"),
)

TRIM_QUANTITIES: tuple[Quantity, ...] = (
    Quantity("speed", "V", "trim airspeed", {"kt": KT, "m_s": 1.0}),
    Quantity("gamma_fp", "gamma_fp", "flight-path angle (default 0)", _ANGLE, required=False,
             limit=GAMMA_FP_LIMIT_DEG * DEG, limit_text=f"{GAMMA_FP_LIMIT_DEG:g} deg"),
    Quantity("col", "col", "collective pitch at 0.7 R", _ANGLE, limit=45 * DEG, limit_text="45 deg",
             may_be_empty=True),
    Quantity("lon", "lon", "longitudinal cyclic theta_1s, positive aft", _ANGLE,
             limit=45 * DEG, limit_text="45 deg", may_be_empty=True),
    Quantity("theta", "theta", "pitch attitude", _ANGLE, limit=90 * DEG, limit_text="90 deg", may_be_empty=True),
    Quantity("beta0", "beta_0", "rotor coning angle", _ANGLE, required=False, limit=30 * DEG,
             limit_text="30 deg", may_be_empty=True),
    Quantity("source", "source", "'level' or the name of the maneuver whose start trim this is", {},
             required=False, kind="text"),
)

#: file column names written by :func:`write_flight_test` (fixed order)
MANEUVER_WRITE_COLUMNS = {"t": "t_s", "col": "col_deg", "lon": "lon_deg", "q": "q_deg_s",
                          "theta": "theta_deg", "n_x": "nx_g", "n_z": "nz_g", "TAS": "tas_kt",
                          "beta_0": "beta0_deg"}
TRIM_WRITE_COLUMNS = {"V": "speed_kt", "gamma_fp": "gamma_fp_deg", "col": "col_deg", "lon": "lon_deg",
                      "theta": "theta_deg", "beta_0": "beta0_deg", "source": "source"}


def column_names(quantities: tuple[Quantity, ...]) -> list[str]:
    """Every file column name recognised for a table, in canonical order."""
    out = []
    for qty in quantities:
        out.extend([qty.name] if qty.kind == "text" else [f"{qty.name}_{u}" for u in qty.units])
    return out


# ---------------------------------------------------------------- problems
@dataclass(frozen=True)
class Problem:
    """One thing wrong with a dataset.

    ``file`` is relative to the dataset folder (posix separators), or the folder itself for
    folder-level problems; ``field`` is a CSV column name (for ``.csv`` files) or a manifest key
    path such as ``maneuvers[3].role`` (for ``manifest.json``), or ``None`` when the problem
    concerns the whole file.
    """

    file: str
    field: str | None
    message: str

    @property
    def kind(self) -> str:
        return "column" if self.file.endswith(".csv") else "field"

    def __str__(self) -> str:
        if self.field is None:
            return f"{self.file}: {self.message}"
        return f"{self.file}: {self.kind} '{self.field}': {self.message}"


class DatasetError(ValueError):
    """A dataset could not be loaded or written; ``problems`` lists every problem found."""

    def __init__(self, problems: list[Problem], path: str | Path | None = None):
        self.problems = list(problems)
        self.path = path
        n = len(self.problems)
        head = f"{n} problem{'s' if n != 1 else ''} in flight-test dataset"
        head += f" {str(path)!r}:" if path is not None else ":"
        super().__init__("\n".join([head] + [str(p) for p in self.problems]))


# ---------------------------------------------------------------- loaded objects
@dataclass(eq=False)
class Maneuver:
    """One maneuver time history, SI units, angles in radians.

    ``data`` columns: ``t`` [s], ``col``, ``lon`` [rad], ``q`` [rad/s], ``theta`` [rad],
    ``n_x``, ``n_z`` [g], ``TAS`` [m/s] and optionally ``beta_0`` [rad].
    ``trim_speed`` is in m/s; ``file`` is the CSV path relative to the dataset folder
    (empty: the writer uses ``maneuvers/<name>.csv``).
    """

    name: str
    role: str
    trim_speed: float
    inputs: list[str]
    data: pd.DataFrame
    file: str = ""
    description: str | None = None
    #: inputs are referred to their mean over the first ``input_reference_s`` seconds of the record
    #: (0: to the first sample); set by :func:`pyomo_heli.nlp.identification.prepare_data`
    input_reference_s: float = 0.0
    #: ``t`` and the input columns at the recorded rate when ``data`` holds fewer samples (``[data]
    #: resample_inputs = "record"``, set by :func:`pyomo_heli.nlp.identification.prepare_data`); None: the
    #: inputs are ``data``'s
    inputs_record: pd.DataFrame | None = None

    @property
    def t(self) -> np.ndarray:
        return self.data["t"].to_numpy(dtype=float)

    @property
    def n_samples(self) -> int:
        return len(self.data)

    @property
    def duration(self) -> float:
        """Record length t[-1] - t[0] in s."""
        t = self.t
        return float(t[-1] - t[0]) if t.size else 0.0

    @property
    def sample_rate(self) -> float:
        """Samples per second, 1 / median spacing of ``t`` (nan with fewer than 2 samples)."""
        t = self.t
        return float(1.0 / np.median(np.diff(t))) if t.size > 1 else float("nan")

    @property
    def channels(self) -> list[str]:
        """SI column names present in ``data`` other than time."""
        return [c for c in self.data.columns if c != "t"]

    def increments(self, channels=INPUT_CHANNELS) -> dict[str, np.ndarray]:
        """Input increments on trim: channel -> input minus its reference (rad).

        The reference is the first sample, or, with ``input_reference_s`` > 0, the mean over the
        samples with t <= t[0] + input_reference_s (the quiet lead-in before the first input): the
        noise of one sample would otherwise act as a constant input offset over the whole record.
        """
        return _increments(self.data, channels, self.input_reference_s)

    def input_series(self, channels=INPUT_CHANNELS) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """(times [s], channel -> input increment [rad]) of the inputs the model is driven by: the
        recorded-rate inputs (``inputs_record``) when there are any, else ``data``'s (:meth:`increments`)."""
        src = self.data if self.inputs_record is None else self.inputs_record
        return src["t"].to_numpy(dtype=float), _increments(src, channels, self.input_reference_s)

    def input_grid(self, channels=INPUT_CHANNELS) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
        """:meth:`input_series` and, for each of ``data``'s samples, its index among the input samples: where an
        errors-in-variables fit has its input errors (one per input sample) and where its outputs are."""
        t = self.t
        t_in, inc = self.input_series(channels)
        if len(t_in) == len(t):
            return t_in, inc, np.arange(len(t))
        idx = np.clip(np.searchsorted(t_in, t - 1e-9), 0, len(t_in) - 1)
        if not np.allclose(t_in[idx], t, atol=1e-9):
            raise ValueError(f"maneuver {self.name}: its samples are not samples of its recorded inputs")
        return t_in, inc, idx


def lead_in(t, reference_s: float) -> np.ndarray:
    """Mask of the samples of times ``t`` [s] in a record's quiet lead-in: t <= t[0] + ``reference_s``."""
    t = np.asarray(t, dtype=float)
    return t <= t[0] + reference_s


def _increments(df: pd.DataFrame, channels, reference_s: float) -> dict[str, np.ndarray]:
    """Channel -> the column of ``df`` minus its first value, or its mean over t <= t[0] + ``reference_s``."""
    t = df["t"].to_numpy(dtype=float)
    lead = lead_in(t, reference_s) if reference_s > 0 else slice(0, 1)
    out = {}
    for ch in channels:
        x = df[ch].to_numpy(dtype=float)
        out[ch] = x - float(np.mean(x[lead]))
    return out


@dataclass(eq=False)
class FlightTest:
    """A loaded flight-test dataset (SI units, radians).

    ``trims`` columns: ``V`` [m/s], ``gamma_fp``, ``col``, ``lon``, ``theta`` [rad] and, when the
    file has them, ``beta_0`` [rad] and ``source`` (``"level"`` or a maneuver name).
    """

    aircraft: str
    mass: float
    rho: float
    g: float
    maneuvers: dict[str, Maneuver]
    trims: pd.DataFrame
    path: Path | None = None
    description: str | None = None
    trim_file: str = "trims.csv"
    #: how the recorded trim channels relate to the model's (manifest ``conventions``)
    conventions: TrimConventions = field(default_factory=TrimConventions)
    #: where the data come from (manifest ``source``), free text
    source: str | None = None
    #: measurement or digitising accuracy (manifest ``accuracy``): ``angle_deg``, ``speed_kt``[, ``description``]
    accuracy: dict | None = None
    #: assumptions about the test conditions (manifest ``assumptions``), one sentence each
    assumptions: list | None = None

    @property
    def trim_only(self) -> bool:
        """True for a flight test of trim points without maneuvers."""
        return not self.maneuvers

    def trim_counts(self) -> dict:
        """Trim channel -> number of rows that measured it (a row may leave a channel empty)."""
        if self.trims is None:
            return {}
        return {c: int(self.trims[c].notna().sum()) for c in TRIM_CHANNELS if c in self.trims}

    @classmethod
    def from_frames(cls, manifest, maneuvers, trims) -> "FlightTest":
        """A flight test from in-memory data, checked exactly as a dataset folder is.

        Arguments as the second form of :func:`~pyomo_heli.dataset.write_flight_test`: a manifest dict in
        file form, a mapping maneuver name -> SI DataFrame (or :class:`Maneuver`) and an SI trim DataFrame.
        The data go through the folder format's writer and reader in a temporary folder, which is deleted,
        so every check of ``check-data`` applies; :class:`DatasetError` lists the problems. ``path`` of the
        result is None.
        """
        import tempfile

        from .reader import load_flight_test
        from .writer import write_flight_test

        with tempfile.TemporaryDirectory(prefix="pyomo_heli_ft_") as tmp:
            try:
                folder = write_flight_test(Path(tmp) / "flight_test", manifest, maneuvers, trims, check=False)
                ft = load_flight_test(folder)
            except DatasetError as exc:  # name the in-memory data, not the temporary folder
                raise DatasetError(exc.problems, "<FlightTest.from_frames>") from None
        ft.path = None
        return ft

    def identification(self) -> list[Maneuver]:
        return [m for m in self.maneuvers.values() if m.role == "identification"]

    def validation(self) -> list[Maneuver]:
        return [m for m in self.maneuvers.values() if m.role == "validation"]

    def frequency(self) -> list[Maneuver]:
        """The records of role "frequency" (frequency sweeps for the local linear models)."""
        return [m for m in self.maneuvers.values() if m.role == "frequency"]

    def summary(self) -> str:
        """A readable table of the maneuvers and trim points."""
        n_id, n_val = len(self.identification()), len(self.validation())
        where = f" ({self.path})" if self.path is not None else ""
        lines = [f"Flight test '{self.aircraft}'{where}"]
        if self.description:
            lines.append(f"  {self.description}")
        lines.append(f"  mass {self.mass:g} kg, rho {self.rho:g} kg/m^3, g {self.g:g} m/s^2")
        if self.trim_only:
            lines.append("  trim-only flight test: no maneuvers")
        else:
            n_fr = len(self.frequency())
            lines.append(f"  {len(self.maneuvers)} maneuvers ({n_id} identification, {n_val} validation"
                         + (f", {n_fr} frequency" if n_fr else "") + "):")
        header = ["name", "role", "trim kt", "duration s", "rate Hz", "samples", "inputs", "channels"]
        rows = []
        for m in self.maneuvers.values():
            rows.append([m.name, m.role, f"{m.trim_speed / KT:.1f}", f"{m.duration:.2f}",
                         f"{m.sample_rate:.1f}", str(m.n_samples), ",".join(m.inputs), " ".join(m.channels)])
        right = {2, 3, 4, 5}
        widths = [max(len(r[i]) for r in rows + [header]) for i in range(len(header))]

        def fmt(r):
            cells = [c.rjust(w) if i in right else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths))]
            return ("    " + "  ".join(cells)).rstrip()

        if rows:
            lines.append(fmt(header))
            lines.extend(fmt(r) for r in rows)
        n = len(self.trims)
        if n:
            v = self.trims["V"].to_numpy(dtype=float) / KT
            text = f"  {n} trim points, speed {v.min():.1f} .. {v.max():.1f} kt"
            if "source" in self.trims:
                n_level = int((self.trims["source"] == "level").sum())
                text += f" ({n_level} level, {n - n_level} maneuver start trims)"
            lines.append(text)
        else:
            lines.append("  0 trim points")
        counts = self.trim_counts()
        if n and any(k < n for k in counts.values()):
            lines.append("  measured per channel: " + ", ".join(f"{c} {k}" for c, k in counts.items()))
        if not self.conventions.default:
            c = self.conventions
            parts = []
            if c.collective_station is not None:
                parts.append(f"collective at r/R = {c.collective_station:g}" + (" (root)" if c.collective_station == 0
                                                                                 else ""))
            if c.lon_sign != 1:
                parts.append("lon positive forward")
            if c.theta_datum is None:
                parts.append("pitch-attitude datum unknown (estimated)")
            elif c.theta_datum != 0:
                parts.append(f"pitch-attitude datum {c.theta_datum / DEG:+g} deg")
            lines.append("  conventions: " + "; ".join(parts))
        if self.source:
            lines.append(f"  source: {self.source}")
        return "\n".join(lines)
