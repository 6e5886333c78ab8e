"""Write a flight-test dataset folder from SI data (degrees and knots only in the files).

Output is deterministic: fixed column order, floats formatted with ``%.10g``, ``\\n`` line
endings, UTF-8, JSON with sorted keys and 2-space indentation, so that writing the same data twice
gives byte-identical files.
"""
from __future__ import annotations

import io
import json
from collections.abc import Mapping
from pathlib import Path, PurePosixPath

import numpy as np
import pandas as pd

from .reader import validate_flight_test
from .schema import (
    DEG,
    FORMAT_NAME,
    FORMAT_VERSION,
    KT,
    MANEUVER_QUANTITIES,
    MANEUVER_WRITE_COLUMNS,
    MANIFEST_NAME,
    TRIM_QUANTITIES,
    TRIM_WRITE_COLUMNS,
    TRUTH_NAME,
    DatasetError,
    FlightTest,
    Maneuver,
    Problem,
)

FLOAT_FORMAT = "%.10g"
#: SI -> file-unit divisor for the columns the writer produces
_TO_FILE = {"t": 1.0, "col": DEG, "lon": DEG, "q": DEG, "theta": DEG, "n_x": 1.0, "n_z": 1.0, "TAS": KT,
            "beta_0": DEG, "V": KT, "gamma_fp": DEG}


def _num(x) -> float:
    """A manifest float rounded to 10 significant digits (so kt -> m/s -> kt is stable).

    Anything that is not a number is passed through for the validator to report."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.number)):
        return x
    return float(FLOAT_FORMAT % float(x)) + 0.0


def _from_manifest(manifest: Mapping, maneuvers, trims) -> FlightTest:
    """Build a FlightTest from a (partial) manifest dict, SI maneuver tables and an SI trim table."""
    problems = []
    if manifest.get("format", FORMAT_NAME) != FORMAT_NAME:
        problems.append(Problem(MANIFEST_NAME, "format", f"must be {FORMAT_NAME!r}"))
    if manifest.get("format_version", FORMAT_VERSION) != FORMAT_VERSION:
        problems.append(Problem(MANIFEST_NAME, "format_version", f"must be {FORMAT_VERSION}"))
    tables = dict(maneuvers or {})
    entries = manifest.get("maneuvers")
    out = {}
    if entries is None:  # everything is in Maneuver objects
        for name, m in tables.items():
            if isinstance(m, Maneuver):
                out[name] = m
            else:
                problems.append(Problem(MANIFEST_NAME, "maneuvers", f"no manifest entry for maneuver {name!r}"))
    else:
        for i, e in enumerate(entries):
            name = e.get("name")
            if name not in tables:
                problems.append(Problem(MANIFEST_NAME, f"maneuvers[{i}].name",
                                        f"no data table given for maneuver {name!r}"))
                continue
            d = tables[name]
            v = _num(e.get("trim_speed_kt"))
            out[name] = Maneuver(name=name, role=e.get("role"), trim_speed=v * KT if isinstance(v, float) else v,
                                 inputs=list(e.get("inputs", [])), data=d.data if isinstance(d, Maneuver) else d,
                                 file=e.get("file", ""), description=e.get("description"))
        listed = {e.get("name") for e in entries}
        for name in tables:
            if name not in listed:
                problems.append(Problem(MANIFEST_NAME, "maneuvers", f"maneuver table {name!r} has no manifest entry"))
    if problems:
        raise DatasetError(problems)
    atm = manifest.get("atmosphere", {})
    return FlightTest(aircraft=manifest.get("aircraft"), mass=manifest.get("mass_kg"), rho=atm.get("rho_kg_m3"),
                      g=atm.get("g_m_s2"), maneuvers=out, trims=trims, description=manifest.get("description"),
                      trim_file=manifest.get("trim_file", "trims.csv"), **_extra_fields(manifest))


def _extra_fields(manifest: Mapping) -> dict:
    """FlightTest fields from a manifest's optional conventions, source, accuracy and assumptions."""
    from .schema import ESTIMATE, TrimConventions

    out = {k: manifest[k] for k in ("source", "accuracy", "assumptions") if k in manifest}
    c = manifest.get("conventions")
    if isinstance(c, Mapping):
        datum = c.get("theta_datum_deg", 0.0)
        out["conventions"] = TrimConventions(collective_station=c.get("collective_station"),
                                             lon_sign=c.get("lon_sign", 1),
                                             theta_datum=None if datum == ESTIMATE else datum * DEG)
    return out


def _csv_text(df: pd.DataFrame, columns: dict[str, str], rel: str, required, problems) -> str | None:
    known = [c for c in columns if c in df.columns]
    for c in required:
        if c not in df.columns:
            problems.append(Problem(rel, c, f"SI data frame lacks required column '{c}'"))
    for c in df.columns:
        if c not in columns:
            problems.append(Problem(rel, str(c), f"SI data frame has an unknown column; known: {', '.join(columns)}"))
    if problems:
        return None
    out = pd.DataFrame(index=range(len(df)))
    for c in known:
        if c == "source":
            out[columns[c]] = df[c].astype(str).to_numpy()
        else:
            out[columns[c]] = np.asarray(df[c], dtype=float) / _TO_FILE[c] + 0.0
    buf = io.StringIO()
    out.to_csv(buf, index=False, float_format=FLOAT_FORMAT, lineterminator="\n")
    return buf.getvalue()


def _safe_rel(rel: str, field: str, problems) -> bool:
    pp = PurePosixPath(rel)
    if not rel or pp.is_absolute() or ".." in pp.parts or "\\" in rel or pp.suffix != ".csv" or pp.name == TRUTH_NAME:
        problems.append(Problem(MANIFEST_NAME, field, f"{rel!r} is not a relative .csv path inside the folder"))
        return False
    return True


def write_flight_test(path, flight_test_or_manifest, maneuvers=None, trims=None, *, check: bool = True) -> Path:
    """Write a dataset folder; return its path.

    Two call forms:

    * ``write_flight_test(path, flight_test)`` with a :class:`FlightTest`;
    * ``write_flight_test(path, manifest, maneuvers, trims)`` with a manifest dict in file form
      (``aircraft``, ``atmosphere``, ``mass_kg``, optional ``description``/``trim_file``, and a
      ``maneuvers`` list of entries with ``name``, ``role``, ``trim_speed_kt``, ``inputs``,
      optional ``description``/``file``; ``format``/``format_version`` are filled in), a mapping
      maneuver name -> SI DataFrame (or :class:`Maneuver`), and an SI trim DataFrame.

    SI columns are converted to the file units (``*_deg``, ``*_deg_s``, ``tas_kt``, ``speed_kt``).
    Maneuver files default to ``maneuvers/<name>.csv``.  Existing files of the same names are
    overwritten; nothing else in the folder (e.g. ``truth.json``) is touched.  With ``check`` the
    written folder is validated and :class:`DatasetError` raised if it has problems.
    """
    if isinstance(flight_test_or_manifest, FlightTest):
        if maneuvers is not None or trims is not None:
            raise TypeError("give either a FlightTest or (manifest, maneuvers, trims), not both")
        ft = flight_test_or_manifest
    elif isinstance(flight_test_or_manifest, Mapping):
        ft = _from_manifest(flight_test_or_manifest, maneuvers, trims)
    else:
        raise TypeError(f"expected a FlightTest or a manifest dict, got {type(flight_test_or_manifest).__name__}")

    root = Path(path)
    problems: list[Problem] = []
    files: dict[str, str] = {}
    entries = []
    for i, m in enumerate(ft.maneuvers.values()):
        rel = m.file or f"maneuvers/{m.name}.csv"
        if not _safe_rel(rel, f"maneuvers[{i}].file", problems):
            continue
        required = [q.si for q in MANEUVER_QUANTITIES if q.required]
        text = _csv_text(m.data, MANEUVER_WRITE_COLUMNS, rel, required, problems)
        if text is not None:
            files[rel] = text
        v = m.trim_speed
        entry = {"name": m.name, "file": rel, "role": m.role,
                 "trim_speed_kt": _num(float(v) / KT if isinstance(v, (int, float, np.number))
                                       and not isinstance(v, (bool, np.bool_)) else v),  # numpy scalars too
                 "inputs": list(m.inputs)}
        if m.description:
            entry["description"] = m.description
        entries.append(entry)
    trim_rel = ft.trim_file or "trims.csv"
    if ft.trims is None:
        problems.append(Problem(trim_rel, None, "no trim table given"))
    elif _safe_rel(trim_rel, "trim_file", problems):
        required = [q.si for q in TRIM_QUANTITIES if q.required]
        text = _csv_text(ft.trims, TRIM_WRITE_COLUMNS, trim_rel, required, problems)
        if text is not None:
            files[trim_rel] = text
    if problems:
        raise DatasetError(problems, root)

    manifest = {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "aircraft": ft.aircraft,
                "atmosphere": {"rho_kg_m3": _num(ft.rho), "g_m_s2": _num(ft.g)}, "mass_kg": _num(ft.mass),
                "trim_file": trim_rel, "maneuvers": entries}
    if ft.description:
        manifest["description"] = ft.description
    if not ft.conventions.default:
        manifest["conventions"] = ft.conventions.to_manifest()
    for key in ("source", "accuracy", "assumptions"):
        if getattr(ft, key):
            manifest[key] = getattr(ft, key)
    files[MANIFEST_NAME] = json.dumps(manifest, indent=2, sort_keys=True, ensure_ascii=False) + "\n"

    root.mkdir(parents=True, exist_ok=True)
    for rel, text in files.items():
        target = root / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(text.encode("utf-8"))
    if check:
        found = validate_flight_test(root)
        if found:
            raise DatasetError(found, root)
    return root
