"""The manifest checks of the flight-test reader: keys against the declaration (settings/manifest.py),
constants, paths, conventions, accuracy and the maneuver entries."""
from __future__ import annotations

import json
import re
from pathlib import PurePosixPath


from .schema import (
    DEG,
    INPUT_CHANNELS,
    MANIFEST_NAME,
    ROLES,
    SPEED_RANGE_KT,
    ESTIMATE,
    LON_SIGNS,
    THETA_DATUM_LIMIT_DEG,
    TrimConventions,
    TRUTH_NAME,
)
from .tables import CONVENTION_KEYS, ACCURACY_KEYS, MANEUVER_KEYS, _NAME_RE
from .tables import _is_number, _type_name







class ManifestChecks:
    """Reading and checking manifest.json, mixed into the reader (``self.add`` records a problem)."""

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
        try:
            target = (self.root / value).resolve()
            target.exists()
        except (OSError, ValueError) as exc:  # a NUL byte, a name too long for the file system
            self.add(MANIFEST_NAME, field, f"path {value!r} cannot be used as a file name "
                                           f"({getattr(exc, 'strerror', None) or exc})")
            return None
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

    # ------------------------------------------------------------ manifest objects

    def optional_object(self, man, field: str, keys) -> dict | None:
        """The manifest's optional object ``field``, its keys checked against ``keys`` (key -> required; each
        missing or unknown key recorded as a problem); None when absent or not an object (that recorded)."""
        if field not in man:
            return None
        obj = man[field]
        if not isinstance(obj, dict):
            self.add(MANIFEST_NAME, field, f"must be an object with keys {', '.join(keys)}, got {_type_name(obj)}")
            return None
        self.check_keys(obj, keys, f"{field}.")
        return obj

    def check_conventions(self, man):
        """The manifest's ``conventions`` object as TrimConventions (None after a problem or when absent)."""
        n0 = len(self.problems)
        c = self.optional_object(man, "conventions", CONVENTION_KEYS)
        if c is None:
            return None
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
        n0 = len(self.problems)
        a = self.optional_object(man, "accuracy", ACCURACY_KEYS)
        if a is None:
            return None
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
                    same = (self.root / f).resolve()  # by target: "a/../a/x.csv" or a link is the same record
                    if same in seen_files:
                        self.add(MANIFEST_NAME, p + "file", f"same file {f!r} as maneuvers[{seen_files[same]}].file")
                    else:
                        seen_files[same] = i
                        e["file"] = f
            if e["name"] is None:
                self._names_complete = False
            entries.append(e)
        roles = [e["role"] for e in entries]
        if "identification" not in roles:
            self.add(MANIFEST_NAME, "maneuvers", "no maneuver has role 'identification'; at least one is needed")
        return entries

