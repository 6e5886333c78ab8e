"""The CSV table checks of the flight-test reader: one file read, its columns matched to the format's
quantities, numbers parsed, values and the time column checked for plausibility."""
from __future__ import annotations

import csv
import io
import math
import re

import numpy as np

from .schema import (
    DECIMAL_PATTERN,
    MIN_SAMPLES,
    NAME_PATTERN,
    SAMPLE_RATE_RANGE_HZ,
    SPACING_TOL,
    TRIM_SPEED_TOL_KT,
    TRIM_SPEED_TOL_REL,
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




class TableChecks:
    """Reading and checking one CSV table, mixed into the reader (``self.add`` records a problem)."""

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
