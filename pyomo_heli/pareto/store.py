"""Finished points on disk, so that a killed sweep resumes where it stopped.

Each finished solve is written at once to ``DIR/points/<key>.npz``: the
point's record (a JSON text, floats round-trip exactly) and the value of
every variable of the model after the solve (the full primal solution; the
multipliers too when the sweep warm-starts with them). A resumed run loads a
stored point instead of solving it and puts its solution back into the model,
so the next solve starts from bit-identical values and the warm-start chain
gives the same numbers as an uninterrupted run.

``DIR/checkpoint.json`` holds the fingerprint of what produced the points
(config, dataset files, package version, command-specific settings). A
different fingerprint is refused with a one-line message unless the caller
asked to restart, which deletes the stored points.

Files are written to a temporary name and renamed, so a kill during a write
leaves either the whole file or none.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pyomo.environ as pyo


class StoreMismatchError(ValueError):
    """The results folder holds points of a different run; the message says how to proceed."""


def _canonical(obj) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def fingerprint(raw_config: dict, dataset: str | Path | None = None, **settings) -> str:
    """SHA-256 over the config table, the dataset files' contents and extra settings.

    The dataset enters by content (not path), so moving a checkout keeps the
    fingerprint, while editing a data file changes it.
    """
    from .. import __version__

    h = hashlib.sha256()
    h.update(_canonical({"config": raw_config, "settings": settings, "version": __version__}).encode())
    if dataset is not None:
        root = Path(dataset)
        for f in sorted(p for p in root.rglob("*") if p.is_file()):
            h.update(str(f.relative_to(root)).encode())
            h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


def _atomic_write(path: Path, write) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        write(fh)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def _variables(m):
    return list(m.component_data_objects(pyo.Var, descend_into=True))


class PointStore:
    """Finished points of one run in ``root/points``, guarded by a fingerprint.

    ``restart=True`` deletes points stored under any fingerprint; otherwise a
    folder with points of another fingerprint raises StoreMismatchError.
    """

    def __init__(self, root: str | Path, fingerprint: str, restart: bool = False, what: str = "run"):
        self.root = Path(root)
        self.dir = self.root / "points"
        self.fingerprint = fingerprint
        meta = self.root / "checkpoint.json"
        self.root.mkdir(parents=True, exist_ok=True)
        if restart and self.dir.exists():
            shutil.rmtree(self.dir)
        if meta.is_file() and self.dir.exists() and any(self.dir.glob("*.npz")):
            old = json.loads(meta.read_text()).get("fingerprint")
            if old != fingerprint:
                raise StoreMismatchError(
                    f"{self.root}: holds finished points of a different {what} (config, data or settings changed: "
                    f"fingerprint {str(old)[:12]} here, {fingerprint[:12]} now); rerun with --restart to "
                    f"discard them, or choose another --out")
        self.dir.mkdir(exist_ok=True)
        meta.write_text(json.dumps({"fingerprint": fingerprint, "what": what}, indent=2) + "\n")

    def _path(self, key: str) -> Path:
        return self.dir / f"{key}.npz"

    def has(self, key: str) -> bool:
        return self._path(key).is_file()

    def keys(self) -> list[str]:
        return sorted(p.stem for p in self.dir.glob("*.npz"))

    def save(self, key: str, record: dict, m=None, duals: bool = False) -> None:
        """Write one finished point: its record and (with ``m``) the model's variable values."""
        arrays = {"record": np.array(json.dumps(record, default=_json_default))}
        if m is not None:
            arrays["values"] = np.array([np.nan if v.value is None else float(v.value) for v in _variables(m)])
            if duals:
                arrays.update(_duals(m))
        _atomic_write(self._path(key), lambda fh: np.savez(fh, **arrays))

    def record(self, key: str) -> dict:
        with np.load(self._path(key)) as z:
            return json.loads(str(z["record"]))

    def restore(self, key: str, m) -> None:
        """Put the stored solution of ``key`` back into the model (free variables; multipliers if stored)."""
        with np.load(self._path(key)) as z:
            values = z["values"]
            variables = _variables(m)
            if len(values) != len(variables):
                raise StoreMismatchError(f"{self._path(key)}: stored {len(values)} variable values, the model has "
                                         f"{len(variables)}; rerun with --restart")
            for v, val in zip(variables, values):
                if not v.fixed:
                    v.set_value(None if math.isnan(val) else float(val), skip_validation=True)
            if "dual" in z:
                _restore_duals(m, z)


def _json_default(o):
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        return o.item()
    raise TypeError(type(o))


def _duals(m) -> dict:
    """Constraint multipliers and bound multipliers as arrays in model order (for a full warm start)."""
    out = {}
    dual = m.component("dual")
    if isinstance(dual, pyo.Suffix):
        cons = m.component_data_objects(pyo.Constraint, active=True, descend_into=True)
        out["dual"] = np.array([dual.get(c, 0.0) for c in cons], float)
    for name in ("ipopt_zL_out", "ipopt_zU_out"):
        s = m.component(name)
        if isinstance(s, pyo.Suffix):
            out[name] = np.array([s.get(v, 0.0) for v in _variables(m)], float)
    return out


def _restore_duals(m, z) -> None:
    from ..solvers.casadi_ipopt import ensure_suffix

    dual = ensure_suffix(m, "dual", pyo.Suffix.IMPORT)
    for c, val in zip(m.component_data_objects(pyo.Constraint, active=True, descend_into=True), z["dual"]):
        dual[c] = float(val)
    for name in ("ipopt_zL_out", "ipopt_zU_out"):
        if name in z:
            s = ensure_suffix(m, name, pyo.Suffix.IMPORT)
            for v, val in zip(_variables(m), z[name]):
                s[v] = float(val)
