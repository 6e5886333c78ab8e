"""Validate and load a flight-test dataset folder (format ``pyomo_heli-flighttest`` version 1).

One pass over the folder both collects every problem and builds the typed objects; the loader
raises :class:`DatasetError` when anything is wrong, the validator returns the list.  Only
``manifest.json`` and the CSV files named in it are opened: ``truth.json`` (evaluation-only
ground truth) is never opened or required.
"""
from __future__ import annotations

import csv
import io
import json
import math
import re
from collections.abc import Mapping
from pathlib import Path, PurePosixPath

import numpy as np
import pandas as pd

from .schema import (
    DECIMAL_PATTERN,
    DEG,
    FORMAT_NAME,
    FORMAT_VERSION,
    G_RANGE_M_S2,
    INPUT_CHANNELS,
    INPUT_DOMINANCE,
    INPUT_NOISE_FACTOR,
    INPUT_STD_FLOOR_DEG,
    KT,
    MANEUVER_QUANTITIES,
    MANIFEST_NAME,
    MASS_RANGE_KG,
    MIN_SAMPLES,
    MODEL_MATCH_RTOL,
    NAME_PATTERN,
    PITOT_MIN_KT,
    RHO_RANGE_KG_M3,
    ROLES,
    SAMPLE_RATE_RANGE_HZ,
    SPACING_TOL,
    SPEED_RANGE_KT,
    ESTIMATE,
    LON_SIGNS,
    THETA_DATUM_LIMIT_DEG,
    TRIM_CHANNELS,
    TRIM_QUANTITIES,
    TrimConventions,
    TRIM_SPEED_TOL_KT,
    TRIM_SPEED_TOL_REL,
    TRIM_WINDOW_S,
    TRUTH_NAME,
    DatasetError,
    FlightTest,
    Maneuver,
    Problem,
    Quantity,
    column_names,
)
from ..settings.manifest import Accuracy, Atmosphere, Conventions, ManeuverEntry, Manifest, key_table

# the manifest's keys (key -> required), declared in pyomo_heli.settings.manifest
MANIFEST_KEYS = key_table(Manifest)
CONVENTION_KEYS = key_table(Conventions)
ACCURACY_KEYS = key_table(Accuracy)
ATMOSPHERE_KEYS = tuple(key_table(Atmosphere))
MANEUVER_KEYS = key_table(ManeuverEntry)
MISSING_TOKENS = {"", "nan", "-nan", "na", "n/a", "nat", "null", "none"}
MAX_LISTED = 5
_NAME_RE = re.compile(NAME_PATTERN)
_DECIMAL_RE = re.compile(DECIMAL_PATTERN)
#: airspeed below this [m/s] is not sensor noise around hover
_TAS_MIN = -10.0


def _rows(idx) -> str:
    """'row 5' / 'rows 5, 6, 7, ...' from 0-based data-row indices (reported 1-based)."""
    idx = [int(i) + 1 for i in idx]
    text = ", ".join(str(i) for i in idx[:MAX_LISTED]) + (", ..." if len(idx) > MAX_LISTED else "")
    return f"row{'s' if len(idx) > 1 else ''} {text}"


def _rows_values(idx, values) -> str:
    """'row 8 ('1,5')' / 'rows 3 ('a'), 9 ('b'), ...' from 0-based indices and the offending cells."""
    shown = ", ".join(f"{i + 1} ({values[i]!r})" for i in idx[:MAX_LISTED])
    return f"row{'s' if len(idx) > 1 else ''} {shown}{', ...' if len(idx) > MAX_LISTED else ''}"


def _speed_tol_kt(trim_kt: float) -> float:
    """Allowed difference [kt] between a manifest trim speed and a measured airspeed of that trim."""
    return max(TRIM_SPEED_TOL_KT, TRIM_SPEED_TOL_REL * trim_kt)


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _type_name(x) -> str:
    return {dict: "object", list: "array", str: "string", bool: "boolean", type(None): "null",
            int: "number", float: "number"}.get(type(x), type(x).__name__)


class _Reader:
    def __init__(self, path):
        self.root = Path(path)
        self.problems: list[Problem] = []

    def add(self, file: str, field: str | None, message: str) -> None:
        self.problems.append(Problem(file, field, message))

    # ------------------------------------------------------------ manifest
    def read_manifest(self):
        if not self.root.exists():
            self.add(str(self.root), None, "dataset folder does not exist")
            return None
        if not self.root.is_dir():
            self.add(str(self.root), None, "is not a folder (a dataset is a folder holding manifest.json)")
            return None
        mpath = self.root / MANIFEST_NAME
        if not mpath.is_file():
            self.add(MANIFEST_NAME, None, f"manifest file not found in {str(self.root)!r}")
            return None
        try:
            text = mpath.read_bytes().decode("utf-8-sig")
        except (OSError, UnicodeDecodeError) as exc:
            self.add(MANIFEST_NAME, None, f"cannot read manifest: {exc}")
            return None
        duplicates = []

        def hook(pairs):
            seen = set()
            for k, _ in pairs:
                if k in seen:
                    duplicates.append(k)
                seen.add(k)
            return dict(pairs)

        try:
            man = json.loads(text, object_pairs_hook=hook)
        except json.JSONDecodeError as exc:
            self.add(MANIFEST_NAME, None, f"not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}")
            return None
        for k in duplicates:
            self.add(MANIFEST_NAME, k, "key appears more than once in a JSON object")
        if not isinstance(man, dict):
            self.add(MANIFEST_NAME, None, f"top level must be a JSON object, got {_type_name(man)}")
            return None
        return man

    def check_keys(self, obj: dict, spec: dict, prefix: str) -> None:
        for key, required in spec.items():
            if required and key not in obj:
                self.add(MANIFEST_NAME, prefix + key, "required key is missing")
        for key in obj:
            if key not in spec:
                self.add(MANIFEST_NAME, prefix + key,
                         f"unknown key; recognised keys: {', '.join(spec)}")

    def positive(self, obj: dict, key: str, field: str, unit: str):
        if key not in obj:
            return None
        v = obj[key]
        if not _is_number(v) or v <= 0:
            got = repr(v) if not isinstance(v, (dict, list)) else _type_name(v)
            self.add(MANIFEST_NAME, field, f"must be a positive number [{unit}], got {got}")
            return None
        return float(v)

    def plausible_constant(self, value, field: str, limits: tuple[float, float], unit: str, what: str):
        """``value`` if within ``limits`` (schema.py gives their sources), else a problem and None."""
        if value is None:
            return None
        lo, hi = limits
        if not lo <= value <= hi:
            self.add(MANIFEST_NAME, field, f"{value:g} {unit} is outside the plausible range {lo:g}..{hi:g} {unit} "
                                           f"for the {what}: wrong unit or typo?")
            return None
        return value

    def text(self, obj: dict, key: str, field: str, required: bool = True):
        if key not in obj:
            return None
        v = obj[key]
        if not isinstance(v, str) or (required and not v.strip()):
            self.add(MANIFEST_NAME, field, f"must be a{' non-empty' if required else ''} string, "
                                           f"got {_type_name(v)} {v!r}")
            return None
        return v

    def rel_path(self, value, field: str, what: str):
        """Check a file path listed in the manifest; return its posix text if usable."""
        if not isinstance(value, str) or not value.strip():
            self.add(MANIFEST_NAME, field, f"must be a non-empty relative path to the {what}, got {value!r}")
            return None
        if "\\" in value:
            self.add(MANIFEST_NAME, field, f"path {value!r} must use '/' as separator")
            return None
        pp = PurePosixPath(value)
        if pp.is_absolute() or re.match(r"^[A-Za-z]:", value):
            self.add(MANIFEST_NAME, field, f"path {value!r} must be relative to the dataset folder")
            return None
        target = (self.root / value).resolve()
        root = self.root.resolve()
        if target != root and root not in target.parents:
            self.add(MANIFEST_NAME, field, f"path {value!r} is outside the dataset folder")
            return None
        if target == root / TRUTH_NAME or pp.name == TRUTH_NAME:
            self.add(MANIFEST_NAME, field, f"{TRUTH_NAME} is evaluation-only ground truth and cannot be "
                                           "part of the dataset")
            return None
        if pp.suffix != ".csv":
            self.add(MANIFEST_NAME, field, f"path {value!r} must name a .csv file")
            return None
        if not target.exists():
            self.add(MANIFEST_NAME, field, f"the {what} {value!r} does not exist")
            return None
        if not target.is_file():
            self.add(MANIFEST_NAME, field, f"the {what} {value!r} is not a file")
            return None
        return pp.as_posix()

    # ------------------------------------------------------------ tables
    def read_table(self, rel: str, quantities: tuple[Quantity, ...]):
        """Parse a CSV table into SI arrays.

        Returns ``(columns, source_names, n_rows)`` where ``columns`` maps the SI name to a numpy
        array (only for columns without problems) and ``source_names`` maps the SI name to the file
        column name; ``None`` when the table is unusable.
        """
        try:
            text = (self.root / rel).read_bytes().decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            self.add(rel, None, f"not UTF-8 text ({exc.reason} at byte {exc.start})")
            return None
        except OSError as exc:
            self.add(rel, None, f"cannot read file: {exc}")
            return None
        try:
            rows = [r for r in csv.reader(io.StringIO(text, newline="")) if r]
        except csv.Error as exc:
            self.add(rel, None, f"not a valid CSV file: {exc}")
            return None
        if not rows:
            self.add(rel, None, "file is empty (no header line)")
            return None
        if len(rows[0]) == 1:  # one field: the header is not comma-separated (every column would be "missing")
            for sep, what in ((";", "semicolons (;)"), ("\t", "tabs"), ("|", "vertical bars (|)")):
                if sep in rows[0][0]:
                    self.add(rel, None, f"fields are separated by {what}, not commas: the format is comma-separated "
                                        f"with '.' as decimal point (docs/data_format.md); save the file as "
                                        f"comma-separated CSV")
                    return None
        header = [h.strip() for h in rows[0]]
        data = rows[1:]
        recognised = column_names(quantities)
        by_qty: dict[str, tuple[Quantity, str, int]] = {}
        counts: dict[str, int] = {}
        for h in header:
            counts[h] = counts.get(h, 0) + 1
        reported_dups = set()
        self._claimed = set()  # quantities whose column already has a naming problem
        for j, name in enumerate(header):
            if name == "":
                self.add(rel, None, f"column {j + 1} of the header has an empty name (a trailing comma?)")
                continue
            if counts[name] > 1:
                self._claimed.update(q.name for q in quantities if name == q.name or name.startswith(q.name + "_"))
                if name not in reported_dups:
                    self.add(rel, name, f"column appears {counts[name]} times in the header")
                    reported_dups.add(name)
                continue
            qty, unit = self.match_column(rel, name, quantities, recognised)
            if qty is None:
                continue
            if qty.name in by_qty:
                other = by_qty[qty.name][1]
                self.add(rel, name, f"second unit variant of {qty.label} '{qty.name}' (already given by column "
                                    f"'{other}'): keep exactly one of them")
                continue
            by_qty[qty.name] = (qty, name, j)
        for qty in quantities:
            if qty.required and qty.name not in by_qty and qty.name not in self._claimed:
                variants = [f"'{qty.name}_{u}'" for u in qty.units]
                what = "one of " + ", ".join(variants) if len(variants) > 1 else variants[0]
                self.add(rel, qty.name, f"missing required column ({qty.label}): add {what}")
        ragged = [i for i, r in enumerate(data) if len(r) != len(header)]
        if ragged:
            lens = sorted({len(data[i]) for i in ragged})
            self.add(rel, None, f"{_plural(len(ragged), 'data row')} ({_rows(ragged)}) "
                                f"{'has' if len(ragged) == 1 else 'have'} {'/'.join(map(str, lens))} fields "
                                f"but the header has {len(header)}")
        n = len(data)
        if n == 0:
            self.add(rel, None, "table has no data rows (header only)")
            return None
        columns, names = {}, {}
        for qty, name, j in by_qty.values():
            raw = [r[j].strip() if j < len(r) else "" for r in data]
            names[qty.si] = name
            if qty.kind == "text":
                columns[qty.si] = np.array(raw, dtype=object)
                continue
            values = self.parse_numbers(rel, name, raw, qty.may_be_empty)
            if values is not None and self.plausible(rel, name, qty, values):
                columns[qty.si] = values * qty.units[name[len(qty.name) + 1:]]
        return columns, names, n

    def match_column(self, rel, name, quantities, recognised):
        for qty in sorted(quantities, key=lambda q: -len(q.name)):
            if qty.kind == "text":
                if name == qty.name:
                    return qty, None
                continue
            variants = " or ".join(f"'{qty.name}_{u}'" for u in qty.units)
            if name == qty.name:
                self._claimed.add(qty.name)
                self.add(rel, name, f"column name has no unit suffix: use {variants}")
                return None, None
            if name.startswith(qty.name + "_"):
                unit = name[len(qty.name) + 1:]
                if unit in qty.units:
                    return qty, unit
                self._claimed.add(qty.name)
                self.add(rel, name, f"unit '{unit}' not recognised for {qty.label} '{qty.name}': "
                                    f"use {variants}")
                return None, None
        hint = [r for r in recognised if r.lower() == name.lower()]
        extra = f" (did you mean '{hint[0]}'?)" if hint else ""
        for qty in quantities:
            if hint and (hint[0] == qty.name or hint[0].startswith(qty.name + "_")):
                self._claimed.add(qty.name)
        self.add(rel, name, f"unknown column{extra}; recognised columns: {', '.join(recognised)}")
        return None, None

    def parse_numbers(self, rel, name, raw, may_be_empty: bool = False):
        """Cells as floats; problems for non-numbers, NaN, infinities and (unless ``may_be_empty``: an empty
        cell is a measurement not taken, NaN) empty cells."""
        values = np.empty(len(raw))
        bad, empty, nan = [], [], []
        for i, s in enumerate(raw):
            if s.lower() in MISSING_TOKENS:
                values[i] = np.nan
                if s == "" and may_be_empty:
                    continue
                (empty if s == "" else nan).append(i)
                continue
            try:
                values[i] = float(s)
            except ValueError:
                values[i] = np.nan
                bad.append(i)
                continue
            if math.isnan(values[i]):
                nan.append(i)
        # float() also reads '1_0' as 10 and non-ASCII digits ('٥' as 5): the format allows only plain
        # ASCII decimals (DECIMAL_PATTERN).  Fast path: on ASCII text without '_', float()'s grammar
        # is exactly DECIMAL_PATTERN plus inf/nan (reported below), so the cell-by-cell regex match
        # runs only for columns holding a non-ASCII character or '_'.
        odd = []
        joined = "".join(raw)
        if not joined.isascii() or "_" in joined:
            skip = set(bad) | set(empty) | set(nan)
            odd = [i for i, s in enumerate(raw)
                   if i not in skip and not _DECIMAL_RE.fullmatch(s) and not math.isinf(values[i])]
            values[odd] = np.nan
        inf = np.flatnonzero(np.isinf(values))
        ok = True
        if bad:
            self.add(rel, name, f"{_plural(len(bad), 'non-numeric value')} ({_rows_values(bad, raw)})")
            ok = False
        if odd:
            self.add(rel, name, f"{_plural(len(odd), 'value')} not written as a plain decimal number "
                                f"({_rows_values(odd, raw)}): use ASCII digits 0-9 with an optional sign, "
                                "decimal point and exponent, e.g. -1.25e-3 (no '_' separators, no non-ASCII "
                                "digits)")
            ok = False
        if nan:
            self.add(rel, name, f"{_plural(len(nan), 'NaN value')} ({_rows(nan)})")
            ok = False
        if empty:
            self.add(rel, name, f"{_plural(len(empty), 'empty value')} ({_rows(empty)})")
            ok = False
        if inf.size:
            self.add(rel, name, f"{_plural(inf.size, 'infinite value')} ({_rows(inf)})")
            ok = False
        return values if ok else None

    def plausible(self, rel, name, qty: Quantity, values) -> bool:
        unit = name[len(qty.name) + 1:]
        si = values * qty.units[unit]
        ok = True
        if qty.limit is not None:
            over = np.flatnonzero(np.abs(si) > qty.limit)
            if over.size:
                peak = float(np.max(np.abs(values)))
                msg = (f"{_plural(over.size, 'value')} beyond the plausible limit {qty.limit_text} for "
                       f"{qty.label} (max |value| {peak:.6g} {unit.replace('_', '/')}, {_rows(over)}): ")
                if qty.si == "gamma_fp":
                    msg += ("steady climbs, approaches and autorotative descents stay within it (schema.py): a "
                            "trim row is steady forward flight, not a vertical climb or descent"
                            + (" (or the values are degrees: the column would be 'gamma_fp_deg')"
                               if unit == "rad" else ""))
                elif unit in ("rad", "rad_s"):
                    msg += f"the values look like degrees, wrong unit? (the column would be '{qty.name}_deg" \
                           f"{'_s' if unit == 'rad_s' else ''}')"
                elif unit == "g":
                    msg += "the values look like m/s^2, wrong unit? (the column must be in g)"
                elif qty.si == "TAS":
                    msg += "wrong unit? (tas_kt is knots, tas_m_s is m/s)"
                else:
                    msg += "wrong unit?"
                self.add(rel, name, msg)
                ok = False
        if qty.si == "TAS":
            neg = np.flatnonzero(si < _TAS_MIN)
            if neg.size:
                self.add(rel, name, f"{_plural(neg.size, 'value')} of airspeed below {_TAS_MIN:g} m/s "
                                    f"({_rows(neg)}): airspeed cannot be negative beyond sensor noise")
                ok = False
        return ok

    def check_time(self, rel, name, t) -> bool:
        n = t.size
        if n < MIN_SAMPLES:
            self.add(rel, None, f"only {_plural(n, 'sample')}; at least {MIN_SAMPLES} are required")
            return False
        dt = np.diff(t)
        dup = np.flatnonzero(dt == 0) + 1
        dec = np.flatnonzero(dt < 0) + 1
        if dup.size:
            self.add(rel, name, f"time is not strictly increasing: {_plural(dup.size, 'duplicated time stamp')} "
                                f"(same time as the previous row at {_rows(dup)})")
        if dec.size:
            self.add(rel, name, f"time is not strictly increasing: it decreases at {_rows(dec)}")
        if dup.size or dec.size:
            return False
        med = float(np.median(dt))
        lo, hi = SAMPLE_RATE_RANGE_HZ
        if not lo <= 1.0 / med <= hi:
            self.add(rel, name, f"sample rate {1 / med:.6g} Hz (median spacing {med:.6g} s) is outside the plausible "
                                f"{lo:g}..{hi:,.0f} Hz: is the time column in seconds?")
            return False
        irregular = np.flatnonzero(np.abs(dt - med) > SPACING_TOL * med) + 1
        if irregular.size:
            self.add(rel, name, f"inconsistent sample rate: spacing varies by more than {SPACING_TOL:.0%} around "
                                f"the median {med:.6g} s ({1 / med:.6g} Hz); spacing {dt.min():.6g} .. "
                                f"{dt.max():.6g} s; {_plural(irregular.size, 'irregular interval')} ending at "
                                f"{_rows(irregular)}")
            return False
        return True

    # ------------------------------------------------------------ whole dataset
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

    def check_conventions(self, man):
        """The manifest's ``conventions`` object as TrimConventions (None after a problem or when absent)."""
        if "conventions" not in man:
            return None
        c = man["conventions"]
        if not isinstance(c, dict):
            self.add(MANIFEST_NAME, "conventions", f"must be an object with keys {', '.join(CONVENTION_KEYS)}, "
                                                   f"got {_type_name(c)}")
            return None
        n0 = len(self.problems)
        self.check_keys(c, CONVENTION_KEYS, "conventions.")
        station, sign, datum = None, 1, 0.0
        if "collective_station" in c:
            v = c["collective_station"]
            if not _is_number(v) or not 0.0 <= v <= 1.0:
                self.add(MANIFEST_NAME, "conventions.collective_station",
                         f"must be a number in 0..1 (r/R of the blade station the recorded collective is the pitch "
                         f"of; 0 = blade root), got {v!r}")
            else:
                station = float(v)
        if "lon_sign" in c:
            v = c["lon_sign"]
            if isinstance(v, bool) or v not in LON_SIGNS:
                self.add(MANIFEST_NAME, "conventions.lon_sign",
                         f"must be 1 (recorded lon positive aft) or -1 (positive forward), got {v!r}")
            else:
                sign = int(v)
        if "theta_datum_deg" in c:
            v = c["theta_datum_deg"]
            if v == ESTIMATE:
                datum = None
            elif not _is_number(v) or abs(v) > THETA_DATUM_LIMIT_DEG:
                self.add(MANIFEST_NAME, "conventions.theta_datum_deg",
                         f"must be a number within +-{THETA_DATUM_LIMIT_DEG:g} deg (recorded pitch attitude minus "
                         f"body-axis attitude) or {ESTIMATE!r} when unknown, got {v!r}")
            else:
                datum = float(v) * DEG
        if len(self.problems) > n0:
            return None
        return TrimConventions(collective_station=station, lon_sign=sign, theta_datum=datum)

    def check_accuracy(self, man):
        if "accuracy" not in man:
            return None
        a = man["accuracy"]
        if not isinstance(a, dict):
            self.add(MANIFEST_NAME, "accuracy", f"must be an object with keys {', '.join(ACCURACY_KEYS)}, "
                                                f"got {_type_name(a)}")
            return None
        n0 = len(self.problems)
        self.check_keys(a, ACCURACY_KEYS, "accuracy.")
        for key, unit in (("angle_deg", "deg"), ("speed_kt", "kt")):
            if key in a and (not _is_number(a[key]) or a[key] < 0):
                self.add(MANIFEST_NAME, f"accuracy.{key}", f"must be a number >= 0 [{unit}], got {a[key]!r}")
        self.text(a, "description", "accuracy.description", required=False)
        return dict(a) if len(self.problems) == n0 else None

    def check_maneuver_entries(self, man) -> list[dict]:
        self._names_complete = True  # every entry is an object with a valid, unique name
        if "maneuvers" not in man:
            return []
        lst = man["maneuvers"]
        if not isinstance(lst, list):
            self.add(MANIFEST_NAME, "maneuvers", f"must be a list of maneuver objects, got {_type_name(lst)}")
            return []
        if not lst:  # a trim-only flight test (its trim table must then hold the data)
            return []
        entries, seen_names, seen_files = [], {}, {}
        for i, item in enumerate(lst):
            p = f"maneuvers[{i}]."
            if not isinstance(item, dict):
                self.add(MANIFEST_NAME, f"maneuvers[{i}]", f"must be an object, got {_type_name(item)}")
                self._names_complete = False
                continue
            self.check_keys(item, MANEUVER_KEYS, p)
            e = {"index": i, "name": None, "file": None, "role": None, "trim_kt": None, "inputs": None,
                 "description": self.text(item, "description", p + "description", required=False)}
            if "name" in item:
                name = item["name"]
                if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
                    self.add(MANIFEST_NAME, p + "name", f"{name!r} is not a valid name: use only letters, digits, "
                                                        "'_' and '-' (at least one character)")
                elif name in seen_names:
                    self.add(MANIFEST_NAME, p + "name", f"duplicate maneuver name {name!r} (also "
                                                        f"maneuvers[{seen_names[name]}].name)")
                else:
                    seen_names[name] = i
                    e["name"] = name
            if "role" in item:
                role = item["role"]
                if role not in ROLES:
                    self.add(MANIFEST_NAME, p + "role", f"{role!r} is not a role: use one of "
                                                        f"{', '.join(repr(r) for r in ROLES)}")
                else:
                    e["role"] = role
            if "trim_speed_kt" in item:
                v = item["trim_speed_kt"]
                lo, hi = SPEED_RANGE_KT
                if not _is_number(v):
                    self.add(MANIFEST_NAME, p + "trim_speed_kt", f"must be a number [kt], got {v!r}")
                elif v < 0:
                    self.add(MANIFEST_NAME, p + "trim_speed_kt", f"trim speed {v:g} kt is negative")
                elif v > hi:
                    self.add(MANIFEST_NAME, p + "trim_speed_kt", f"trim speed {v:g} kt is outside the model "
                                                                 f"range {lo:g}..{hi:g} kt")
                else:
                    e["trim_kt"] = float(v)
            if "inputs" in item:
                inp = item["inputs"]
                if (not isinstance(inp, list) or not inp or any(c not in INPUT_CHANNELS for c in inp)
                        or len(set(inp)) != len(inp)):
                    self.add(MANIFEST_NAME, p + "inputs", f"must be a non-empty list of distinct input channels "
                                                          f"from {list(INPUT_CHANNELS)}, got {inp!r}")
                else:
                    e["inputs"] = list(inp)
            if "file" in item:
                f = self.rel_path(item["file"], p + "file", "maneuver file")
                if f is not None:
                    if f in seen_files:
                        self.add(MANIFEST_NAME, p + "file", f"same file {f!r} as maneuvers[{seen_files[f]}].file")
                    else:
                        seen_files[f] = i
                        e["file"] = f
            if e["name"] is None:
                self._names_complete = False
            entries.append(e)
        roles = [e["role"] for e in entries]
        if "identification" not in roles:
            self.add(MANIFEST_NAME, "maneuvers", "no maneuver has role 'identification'; at least one is needed")
        return entries

    def load_maneuver(self, e):
        rel = e["file"]
        n0 = len(self.problems)
        table = self.read_table(rel, MANEUVER_QUANTITIES)
        if table is None:
            return None
        cols, names, n = table
        if "t" in cols and not self.check_time(rel, names["t"], cols["t"]):
            cols.pop("t")
        if "t" in cols and "TAS" in cols and e["trim_kt"] is not None and e["trim_kt"] >= PITOT_MIN_KT:
            t, tas = cols["t"], cols["TAS"]
            start_kt = float(np.mean(tas[t - t[0] <= TRIM_WINDOW_S])) / KT
            trim_kt = e["trim_kt"]
            tol = _speed_tol_kt(trim_kt)
            if abs(start_kt - trim_kt) > tol:
                e["speed_disputed"] = True  # reported here; not again against its start trim in trims.csv
                self.add(MANIFEST_NAME, f"maneuvers[{e['index']}].trim_speed_kt",
                         f"{trim_kt:g} kt disagrees with the start of column '{names['TAS']}' in {rel}: "
                         f"{start_kt:.1f} kt (mean over the first {TRIM_WINDOW_S:g} s; tolerance "
                         f"{tol:.1f} kt)")
        if e["inputs"] is not None and all(c in cols for c in INPUT_CHANNELS):
            self.check_inputs_move(e, rel, cols, names)
        if len(self.problems) > n0 or None in (e["name"], e["role"], e["trim_kt"], e["inputs"]):
            return None
        order = [q.si for q in MANEUVER_QUANTITIES if q.si in cols]
        data = pd.DataFrame({k: cols[k] for k in order})
        return Maneuver(name=e["name"], role=e["role"], trim_speed=e["trim_kt"] * KT, inputs=e["inputs"],
                        data=data, file=rel, description=e["description"])

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
