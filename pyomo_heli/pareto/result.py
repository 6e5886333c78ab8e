"""The result of an identification: plain data that saves to and loads from a folder.

Files (written as each point finishes, so nothing finished is lost):
- ``front.csv``: one row per front point: index, kind (A, eps, B), epsilon,
  J_time, J_trim, every free parameter (SI), success, status, iterations,
  wall_time, setup_time, warm_start.
- ``time_domain.json``: point A (classic time-domain output error).
- ``chosen.json``: the utopia-closest front point (Eq. 11, post hoc), the
  direct Eq. 11 solve, the utopia and nadir points and the distances.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..ioerrors import writing


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


class ResultFileError(ValueError):
    """A malformed file of a results folder (the message names the file and the key)."""


def is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _read_json_object(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except UnicodeDecodeError as exc:
        raise ResultFileError(f"{path}: not a text file ({exc.reason})") from None
    except json.JSONDecodeError as exc:
        raise ResultFileError(f"{path}: invalid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    if not isinstance(data, dict):
        raise ResultFileError(f"{path}: expected a JSON object at the top level, got {type(data).__name__}")
    return data


def check_point_record(point, params: list, path: Path, key: str | None, may_be_null: bool = False,
                 finite: bool = False) -> None:
    """A point record: an object whose 'parameters' hold a number for every free parameter and nothing else.

    ``finite``: every value finite; otherwise only a point that does not say it failed (``success``) must be.
    """
    where = f"key '{key}'" if key else "the top level"
    if point is None and may_be_null:
        return
    if not isinstance(point, dict):
        raise ResultFileError(f"{path}: {where} must be an object{' or null' if may_be_null else ''}, "
                              f"got {type(point).__name__}")
    pk = f"{key}.parameters" if key else "parameters"
    values = point.get("parameters")
    if not isinstance(values, dict):
        raise ResultFileError(f"{path}: key '{pk}' must be an object (name -> value), got {values!r}")
    extra = [n for n in values if n not in params]
    if extra:  # applied to the model, such a value would change it silently
        raise ResultFileError(f"{path}: key '{pk}' holds {', '.join(map(repr, extra))}, which "
                              f"{'is' if len(extra) == 1 else 'are'} not among the free parameters of the results "
                              f"(key 'parameters': {', '.join(params) or 'none'})")
    must_be_finite = finite or point.get("success", True) is not False
    for n in params:
        if n not in values:
            raise ResultFileError(f"{path}: key '{pk}' has no value for the free parameter {n!r}")
        v = values[n]
        if not is_number(v) or (must_be_finite and not math.isfinite(v)):
            raise ResultFileError(f"{path}: key '{pk}.{n}' = {v!r} is not a finite number")


def _read_front(path: Path, params: list) -> pd.DataFrame:
    try:
        front = pd.read_csv(path)
    except pd.errors.EmptyDataError:
        raise ResultFileError(f"{path}: empty file, expected a CSV table of front points") from None
    except (pd.errors.ParserError, UnicodeDecodeError) as exc:
        raise ResultFileError(f"{path}: not a readable CSV table: {str(exc).strip().splitlines()[0]}") from None
    missing = [c for c in ["index", "kind", *params] if c not in front.columns]
    if missing:
        raise ResultFileError(f"{path}: column(s) {', '.join(missing)} missing")
    return front


def write_json(path: Path, data: dict) -> None:
    text = json.dumps(data, indent=2, sort_keys=True, default=_json_default) + "\n"
    with writing(path):
        Path(path).write_text(text)


def write_csv(table: pd.DataFrame, path: Path) -> None:
    """A table as CSV, 12 significant digits (a failed write names ``path``)."""
    with writing(path):
        table.to_csv(path, index=False, float_format="%.12g")


@dataclass
class IdentificationResult:
    """Front, anchors, choices and units of one identification run."""

    front: pd.DataFrame
    parameters: list  # free parameter names
    units: dict  # name -> SI unit
    utopia: tuple
    nadir: tuple
    chosen: dict
    direct: dict | None
    time_domain: dict
    info: dict = field(default_factory=dict)

    def save(self, out: str | Path) -> None:
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        write_csv(self.front, out / "front.csv")
        write_json(out / "time_domain.json", self.time_domain)
        write_json(out / "chosen.json", {"chosen": self.chosen, "direct": self.direct, "utopia": list(self.utopia),
                                         "nadir": list(self.nadir), "parameters": self.parameters,
                                         "units": self.units, "info": self.info})

    @classmethod
    def load(cls, out: str | Path) -> "IdentificationResult":
        """Load a results folder; ResultFileError (a ValueError naming the file and key) if a file is malformed."""
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise ResultFileError(f"{out} is a file, expected an identification results folder")
        for name in ("front.csv", "chosen.json", "time_domain.json"):
            if (out / name).is_dir():
                raise ResultFileError(f"{out / name} is a directory, expected a file")
            if not (out / name).is_file():
                raise FileNotFoundError(f"{out}: no {name}; is this an identification results folder?")
        ch_path, td_path = out / "chosen.json", out / "time_domain.json"
        ch = _read_json_object(ch_path)
        for key in ("parameters", "units", "utopia", "nadir", "chosen", "direct"):
            if key not in ch:
                raise ResultFileError(f"{ch_path}: key '{key}' is missing")
        params = ch["parameters"]
        if not isinstance(params, list) or not all(isinstance(n, str) for n in params):
            raise ResultFileError(f"{ch_path}: key 'parameters' must be a list of parameter names, got {params!r}")
        if not isinstance(ch["units"], dict):
            raise ResultFileError(f"{ch_path}: key 'units' must be an object (name -> unit), got {ch['units']!r}")
        for key in ("utopia", "nadir"):
            v = ch[key]
            if not isinstance(v, list) or not all(is_number(x) for x in v):
                raise ResultFileError(f"{ch_path}: key '{key}' must be a list of numbers, got {v!r}")
        info = ch.get("info", {})
        if not isinstance(info, dict):
            raise ResultFileError(f"{ch_path}: key 'info' must be an object, got {info!r}")
        # what a close-loop iteration records about its model (read back by config_of_result)
        for key, ok, what in (("extensions", lambda v: isinstance(v, list) and all(isinstance(x, str) for x in v),
                               "a list of candidate names"),
                              ("shape_parameters", lambda v: isinstance(v, dict) and all(is_number(x) for x in
                                                                                         v.values()),
                               "an object name -> number"),
                              ("config", lambda v: isinstance(v, str), "a path (string)")):
            if key in info and info[key] is not None and not ok(info[key]):
                raise ResultFileError(f"{ch_path}: key 'info.{key}' must be {what}, got {info[key]!r}")
        check_point_record(ch["chosen"], params, ch_path, "chosen", may_be_null=True, finite=True)
        check_point_record(ch["direct"], params, ch_path, "direct", may_be_null=True)
        time_domain = _read_json_object(td_path)
        check_point_record(time_domain, params, td_path, None)
        return cls(front=_read_front(out / "front.csv", params), parameters=params, units=ch["units"],
                   utopia=tuple(ch["utopia"]), nadir=tuple(ch["nadir"]), chosen=ch["chosen"], direct=ch["direct"],
                   time_domain=time_domain, info=info)

    def __str__(self) -> str:
        from ..units import display_unit

        shown = {p: display_unit(self.units.get(p, "")) for p in self.parameters}  # as in the configs
        head = {p: f"{p} [{shown[p][0]}]" if shown[p][0] not in ("", "-") else p for p in self.parameters}
        table = self.front[["index", "kind", "epsilon", "J_time", "J_trim"] + self.parameters
                           + ["status", "iterations", "wall_time"]].copy()
        for p in self.parameters:
            table[p] = pd.to_numeric(table[p], errors="coerce") * shown[p][1]
        lines = ["Pareto front (parameters in the units of the configs):",
                 table.rename(columns=head).to_string(index=False, float_format=lambda x: f"{x:.6g}"), "",
                 f"utopia (J_time, J_trim) = ({self.utopia[0]:.6g}, {self.utopia[1]:.6g}); "
                 f"nadir = ({self.nadir[0]:.6g}, {self.nadir[1]:.6g})"]
        unreliable = self.info.get("unreliable")
        if unreliable:
            lines.append(f"UNRELIABLE: {unreliable.get('reason')}: {', '.join(unreliable.get('quantities', []))} "
                         f"depend on the anchors and are not to be trusted")
        if self.chosen is None:  # a sweep in which no point converged still ends with its statuses on disk
            lines.append("no front point converged: nothing chosen")
            return "\n".join(lines)
        lines.append(f"chosen (Eq. 11, post hoc): front point {self.chosen['index']}")
        rows = [("time domain (A)", self.time_domain), ("multi-objective (chosen)", self.chosen)]
        if self.direct:
            rows.append(("Eq. 11 direct", self.direct))
        width = max([16] + [len(head[p]) + 2 for p in self.parameters])
        lines.append(f"{'':26s}" + "".join(f"{head[p]:>{width}s}" for p in self.parameters)
                     + f"{'J_time':>14s}{'J_trim':>12s}")
        for label, d in rows:
            lines.append(f"{label:26s}" + "".join(f"{d['parameters'][p] * shown[p][1]:{width}.6g}"
                                                  for p in self.parameters)
                         + f"{d['J_time']:14.6g}{d['J_trim']:12.6g}"
                         + ("" if d.get("success", True) else f"  NOT CONVERGED ({d.get('status', '?')}): "
                                                               "its last iterate, not an estimate"))
        return "\n".join(lines)
