"""Validate and load a flight-test dataset folder (format ``pyomo_heli-flighttest`` version 1).

One pass over the folder both collects every problem and builds the typed objects; the loader
raises :class:`DatasetError` when anything is wrong, the validator returns the list.  Only
``manifest.json`` and the CSV files named in it are opened: ``truth.json`` (evaluation-only
ground truth) is never opened or required.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import cumulative_trapezoid

from .schema import (
    DEG,
    FORMAT_NAME,
    FORMAT_VERSION,
    G_RANGE_M_S2,
    INPUT_CHANNELS,
    INPUT_DOMINANCE,
    INPUT_NOISE_FACTOR,
    INPUT_STD_FLOOR_DEG,
    KINEMATIC_CORR_MIN,
    KINEMATIC_SLOPE_RANGE,
    KT,
    MANEUVER_QUANTITIES,
    MANIFEST_NAME,
    MASS_RANGE_KG,
    MODEL_MATCH_RTOL,
    NZ_START_MIN_G,
    PITOT_MIN_KT,
    RHO_RANGE_KG_M3,
    SPEED_RANGE_KT,
    TRIM_CHANNELS,
    TRIM_QUANTITIES,
    TrimConventions,
    TRIM_WINDOW_S,
    DatasetError,
    FlightTest,
    Maneuver,
    Problem,
)
from .manifest_checks import ManifestChecks
from .tables import ATMOSPHERE_KEYS, MANIFEST_KEYS, MAX_LISTED
from .tables import _rows, _rows_values, _speed_tol_kt, _plural, _type_name
from .tables import TableChecks





class _Reader(ManifestChecks, TableChecks):
    def __init__(self, path):
        self.root = Path(path)
        self.problems: list[Problem] = []

    def add(self, file: str, field: str | None, message: str) -> None:
        self.problems.append(Problem(file, field, message))

    # ------------------------------------------------------------ manifest
    def run(self):
        man = self.read_manifest()
        if man is None:
            return None
        self.check_keys(man, MANIFEST_KEYS, "")
        if "format" in man and man["format"] != FORMAT_NAME:
            self.add(MANIFEST_NAME, "format", f"must be {FORMAT_NAME!r}, got {man['format']!r}")
        if "format_version" in man:
            v = man["format_version"]
            if not (isinstance(v, int) and not isinstance(v, bool)):
                self.add(MANIFEST_NAME, "format_version", f"must be the integer {FORMAT_VERSION}, got {v!r}")
            elif v != FORMAT_VERSION:
                self.add(MANIFEST_NAME, "format_version",
                         f"unsupported version {v}; this reader supports version {FORMAT_VERSION}")
        aircraft = self.text(man, "aircraft", "aircraft")
        description = self.text(man, "description", "description", required=False)
        rho = g = None
        if "atmosphere" in man:
            atm = man["atmosphere"]
            if isinstance(atm, dict):
                self.check_keys(atm, dict.fromkeys(ATMOSPHERE_KEYS, True), "atmosphere.")
                rho = self.plausible_constant(self.positive(atm, "rho_kg_m3", "atmosphere.rho_kg_m3", "kg/m^3"),
                                              "atmosphere.rho_kg_m3", RHO_RANGE_KG_M3, "kg/m^3", "air density")
                g = self.plausible_constant(self.positive(atm, "g_m_s2", "atmosphere.g_m_s2", "m/s^2"),
                                            "atmosphere.g_m_s2", G_RANGE_M_S2, "m/s^2", "surface gravity")
            else:
                self.add(MANIFEST_NAME, "atmosphere", f"must be an object with keys {', '.join(ATMOSPHERE_KEYS)}, "
                                                      f"got {_type_name(atm)}")
        mass = self.plausible_constant(self.positive(man, "mass_kg", "mass_kg", "kg"), "mass_kg", MASS_RANGE_KG,
                                       "kg", "helicopter mass")

        entries = self.check_maneuver_entries(man)
        # None: the maneuver list is unusable or an entry's name is (missing, invalid, duplicated, or the entry
        # is no object), so the names are incomplete and trim 'source' names cannot be checked against them
        # (the row naming the entry meant would be reported as a second, spurious problem)
        names = {e["name"] for e in entries} if entries and self._names_complete else None
        if man.get("maneuvers") == []:
            names = set()  # trim-only: every trim row is a level-flight point
        conventions = self.check_conventions(man)
        source = self.text(man, "source", "source")
        accuracy = self.check_accuracy(man)
        assumptions = None
        if "assumptions" in man:
            a = man["assumptions"]
            if not isinstance(a, list) or not all(isinstance(x, str) and x.strip() for x in a):
                self.add(MANIFEST_NAME, "assumptions", f"must be a list of non-empty strings (one assumption "
                                                       f"each), got {_type_name(a)} {a!r}")
            else:
                assumptions = list(a)

        maneuvers = {}
        for e in entries:
            if e.get("file") is None:
                continue
            m = self.load_maneuver(e)
            if m is not None and e["name"] is not None:
                maneuvers[e["name"]] = m

        # manifest trim speeds to compare the maneuvers' start trims with (not those already disputed by the record)
        trim_speeds = {e["name"]: e["trim_kt"] for e in entries
                       if e["name"] is not None and e["trim_kt"] is not None and not e.get("speed_disputed")}
        trims = None
        trim_file = None
        if "trim_file" in man:
            trim_file = self.rel_path(man["trim_file"], "trim_file", "trim table")
            if trim_file is not None:
                trims = self.load_trims(trim_file, names, trim_speeds)

        if self.problems:
            return None
        return FlightTest(aircraft=aircraft, mass=mass, rho=rho, g=g, maneuvers=maneuvers, trims=trims,
                          path=self.root, description=description, trim_file=trim_file,
                          conventions=conventions or TrimConventions(), source=source, accuracy=accuracy,
                          assumptions=assumptions)

    def load_maneuver(self, e):
        rel = e["file"]
        n0 = len(self.problems)
        table = self.read_table(rel, MANEUVER_QUANTITIES)
        if table is None:
            return None
        cols, names, n = table
        if "t" in cols and not self.check_time(rel, names["t"], cols["t"]):
            cols.pop("t")
        if "t" in cols and "TAS" in cols and e["trim_kt"] is not None:
            t, tas = cols["t"], cols["TAS"]
            start_kt = float(np.mean(tas[t - t[0] <= TRIM_WINDOW_S])) / KT
            trim_kt = e["trim_kt"]
            tol = _speed_tol_kt(trim_kt)
            # compared where either speed is one the pitot reads (8 kt in the manifest for an 80 kt record too)
            if max(trim_kt, start_kt) >= PITOT_MIN_KT and abs(start_kt - trim_kt) > tol:
                e["speed_disputed"] = True  # reported here; not again against its start trim in trims.csv
                self.add(MANIFEST_NAME, f"maneuvers[{e['index']}].trim_speed_kt",
                         f"{trim_kt:g} kt disagrees with the start of column '{names['TAS']}' in {rel}: "
                         f"{start_kt:.1f} kt (mean over the first {TRIM_WINDOW_S:g} s; tolerance "
                         f"{tol:.1f} kt)")
        if "t" in cols:
            self.check_kinematics(rel, cols, names)
        if e["inputs"] is not None and all(c in cols for c in INPUT_CHANNELS):
            self.check_inputs_move(e, rel, cols, names)
        if len(self.problems) > n0 or None in (e["name"], e["role"], e["trim_kt"], e["inputs"]):
            return None
        order = [q.si for q in MANEUVER_QUANTITIES if q.si in cols]
        data = pd.DataFrame({k: cols[k] for k in order})
        return Maneuver(name=e["name"], role=e["role"], trim_speed=e["trim_kt"] * KT, inputs=e["inputs"],
                        data=data, file=rel, description=e["description"])

    def check_kinematics(self, rel, cols, names) -> None:
        """Units and signs the plausible limits cannot see (schema.py, "Kinematic consistency"): n_z about +1 g
        at the record's start, and theta moving as the time integral of q."""
        t = cols["t"]
        if "n_z" in cols:
            start = float(np.mean(cols["n_z"][t - t[0] <= TRIM_WINDOW_S]))
            if start < NZ_START_MIN_G:
                self.add(rel, names["n_z"], f"starts at {start:.3g} g (mean over the first {TRIM_WINDOW_S:g} s): the "
                                            "format's n_z is positive up, about +1 g at a trim; a record of the "
                                            "opposite sign must be negated")
        if "q" in cols and "theta" in cols:
            integral = cumulative_trapezoid(cols["q"], t, initial=0.0)
            rise = cols["theta"] - cols["theta"][0]
            if np.ptp(integral) > 0 and np.ptp(rise) > 0:
                r = float(np.corrcoef(integral, rise)[0, 1])
                slope = float(np.polyfit(integral, rise, 1)[0])
                lo, hi = KINEMATIC_SLOPE_RANGE
                if abs(r) >= KINEMATIC_CORR_MIN and not lo <= slope <= hi:
                    self.add(rel, names["q"], f"pitch attitude '{names['theta']}' moves {slope:.3g} times the time "
                                              f"integral of this column (correlation {r:.2f}; 1 expected): is "
                                              f"'{names['t']}' in seconds, the rate in the unit its name says, and "
                                              "both nose-up positive?")

    def check_inputs_move(self, e, rel, cols, names) -> None:
        """The manifest's ``inputs`` against the record: no undeclared input channel may clearly move more.

        Problem when an undeclared channel's std over the record exceeds INPUT_DOMINANCE x that of the least
        moving declared channel, INPUT_NOISE_FACTOR x its own noise estimate and INPUT_STD_FLOOR_DEG (schema.py
        explains the rule and the numbers).
        """
        std, noise = {}, {}
        for ch in INPUT_CHANNELS:
            x = cols[ch]
            std[ch] = float(np.std(x))
            noise[ch] = float(np.median(np.abs(np.diff(x)))) / (0.6745 * math.sqrt(2.0)) if x.size > 1 else 0.0
        declared = e["inputs"]

        def moves(ch):
            return std[ch] > max(INPUT_NOISE_FACTOR * noise[ch], INPUT_STD_FLOOR_DEG * DEG)

        n0 = len(self.problems)
        weakest = min(declared, key=lambda c: std[c])
        for ch in INPUT_CHANNELS:
            if ch in declared:
                continue
            if moves(ch) and std[ch] > INPUT_DOMINANCE * std[weakest]:
                if std[weakest] > 0:
                    how = (f"moves {std[ch] / std[weakest]:.3g} times as much as the declared '{names[weakest]}' "
                           f"(std over the record {std[ch] / DEG:.3g} vs {std[weakest] / DEG:.3g} deg, above "
                           f"{INPUT_DOMINANCE:g}x; sensor noise about {noise[ch] / DEG:.2g} deg)")
                else:
                    how = (f"moves (std over the record {std[ch] / DEG:.3g} deg) while the declared "
                           f"'{names[weakest]}' is constant")
                self.add(MANIFEST_NAME, f"maneuvers[{e['index']}].inputs",
                         f"{declared!r}, but in {rel} the undeclared input column '{names[ch]}' {how}: list the "
                         "input(s) the record excites (frequency responses take a maneuver as single-input on "
                         "this field)")
        if len(self.problems) == n0 and not any(moves(ch) for ch in declared):
            # nothing else contradicts the declaration, but the record excites none of what it declares
            self.add(MANIFEST_NAME, f"maneuvers[{e['index']}].inputs",
                     f"{declared!r}, but in {rel} the declared input column{'s' if len(declared) > 1 else ''} "
                     + ", ".join(f"'{names[ch]}' (std over the record {std[ch] / DEG:.3g} deg, noise about "
                                 f"{noise[ch] / DEG:.2g} deg)" for ch in declared)
                     + f" never move{'s' if len(declared) == 1 else ''} beyond noise ({INPUT_NOISE_FACTOR:g}x the "
                       f"noise and {INPUT_STD_FLOOR_DEG:g} deg): a record that excites no input identifies nothing; "
                       "check the file or the role")

    def load_trims(self, rel, maneuver_names, maneuver_speeds_kt=None):
        n0 = len(self.problems)
        table = self.read_table(rel, TRIM_QUANTITIES)
        if table is None:
            return None
        cols, names, n = table
        if "V" in cols:
            kt = cols["V"] / KT
            lo, hi = SPEED_RANGE_KT
            neg = np.flatnonzero(kt < lo)
            over = np.flatnonzero(kt > hi)
            if neg.size:
                self.add(rel, names["V"], f"{_plural(neg.size, 'negative speed')} ({_rows(neg)})")
            if over.size:
                self.add(rel, names["V"], f"{_plural(over.size, 'speed')} outside the model range {lo:g}..{hi:g} kt "
                                          f"(max {kt.max():.6g} kt, {_rows(over)})")
        if "source" in cols:
            if maneuver_names is None:
                bad = [i for i, s in enumerate(cols["source"]) if not s]
            else:
                valid = {"level"} | set(maneuver_names)
                bad = [i for i, s in enumerate(cols["source"]) if s not in valid]
            if bad:
                self.add(rel, "source", f"{_plural(len(bad), 'value')} neither 'level' nor a maneuver name "
                                        f"({_rows_values(bad, cols['source'])})")
            if "V" in cols and maneuver_speeds_kt:
                kt, src = cols["V"] / KT, cols["source"]
                off = [i for i, s in enumerate(src) if s in maneuver_speeds_kt
                       and max(kt[i], maneuver_speeds_kt[s]) >= PITOT_MIN_KT
                       and abs(kt[i] - maneuver_speeds_kt[s]) > _speed_tol_kt(maneuver_speeds_kt[s])]
                if off:
                    shown = ", ".join(f"{i + 1} ({kt[i]:.6g} kt; source {src[i]!r} has {maneuver_speeds_kt[src[i]]:g} "
                                      f"kt, tolerance {_speed_tol_kt(maneuver_speeds_kt[src[i]]):.3g} kt)"
                                      for i in off[:MAX_LISTED])
                    self.add(rel, names["V"], f"{_plural(len(off), 'start trim')} of a maneuver not at the maneuver's "
                                              f"trim_speed_kt in {MANIFEST_NAME}: row{'s' if len(off) > 1 else ''} "
                                              f"{shown}{', ...' if len(off) > MAX_LISTED else ''}")
        present = [c for c in TRIM_CHANNELS if c in cols]
        if len(present) == len(TRIM_CHANNELS):
            none = np.flatnonzero(np.all([np.isnan(cols[c]) for c in present], axis=0))
            if none.size:
                self.add(rel, None, f"{_plural(none.size, 'trim row')} with no measured channel ({_rows(none)}): "
                                    f"columns {', '.join(names[c] for c in present)} are all empty there; a trim row "
                                    "needs at least one of them")
        if len(self.problems) > n0:
            return None
        cols.setdefault("gamma_fp", np.zeros(n))
        order = [q.si for q in TRIM_QUANTITIES if q.si in cols]
        df = pd.DataFrame({k: cols[k] for k in order})
        if "source" in df:
            df["source"] = df["source"].astype(str)
        return df


#: manifest constant -> (manifest field, model parameter name, unit)
_MODEL_CONSTANTS = (("mass", "mass_kg", "m", "kg"), ("rho", "atmosphere.rho_kg_m3", "rho", "kg/m^3"),
                    ("g", "atmosphere.g_m_s2", "g", "m/s^2"))


def check_model_matches_manifest(flight_test: FlightTest, parameters: Mapping[str, float], where: str,
                                 skip=()) -> None:
    """Raise ValueError unless the model's ``m``, ``rho`` and ``g`` match the manifest.

    ``flight_test`` is the loaded dataset; its manifest fields ``mass_kg``, ``atmosphere.rho_kg_m3``
    and ``atmosphere.g_m_s2`` are compared with ``parameters["m"]``, ``["rho"]`` and ``["g"]`` (the
    model's full parameter values in SI, e.g. ``HelicopterModel.parameters``).  A relative difference
    above ``MODEL_MATCH_RTOL`` (0.5 %) raises one ValueError, a single line naming the manifest
    file, every differing field and model parameter, and ``where`` (the config being used, e.g.
    ``"case1.toml [model]"``), and telling the user to set ``[model] parameters`` accordingly.
    A parameter missing from ``parameters`` raises ValueError too. ``skip``: names not compared (free
    parameters of an identification, whose model value is only the initial guess).
    """
    manifest = (Path(flight_test.path) / MANIFEST_NAME).as_posix() if flight_test.path is not None \
        else MANIFEST_NAME
    missing = [name for _, _, name, _ in _MODEL_CONSTANTS if name not in parameters and name not in skip]
    if missing:
        raise ValueError(f"{where}: model parameter{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                         f"missing, cannot compare with {manifest}")
    diffs, fix = [], []
    for attr, field, name, unit in _MODEL_CONSTANTS:
        if name in skip:
            continue
        data, model = float(getattr(flight_test, attr)), float(parameters[name])
        if not abs(model - data) <= MODEL_MATCH_RTOL * abs(data):
            diffs.append(f"field '{field}' = {data:g} {unit} but model parameter {name} = {model:g} {unit}")
            fix.append(f"{name} = {data:g}")
    if diffs:
        raise ValueError(f"{manifest}: {'; '.join(diffs)} (more than {MODEL_MATCH_RTOL:.1%} apart, model from "
                         f"{where}): set [model] parameters = {{ {', '.join(fix)} }} to fly the flight test's "
                         "aircraft and atmosphere")


def validate_flight_test(path) -> list[Problem]:
    """Every problem with the dataset folder ``path`` (empty list: the dataset is valid)."""
    r = _Reader(path)
    r.run()
    return r.problems


def load_flight_test(path) -> FlightTest:
    """Load a dataset folder into a :class:`FlightTest` (SI units, radians).

    Raises :class:`DatasetError` listing every problem, one per line, if the dataset is invalid.
    """
    r = _Reader(path)
    ft = r.run()
    if r.problems or ft is None:
        raise DatasetError(r.problems, path)
    return ft
