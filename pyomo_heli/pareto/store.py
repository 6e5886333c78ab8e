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

State on disk that is damaged or foreign (never the result of a kill):

- a stored point that cannot be read (truncated, empty, not an ``.npz`` of
  this store) is treated as unfinished: a warning on stderr names the file,
  it is renamed to ``<key>.npz.corrupt`` and the point is solved again. Its
  solution was lost with the file, so nothing more is lost, and the rerun
  still resumes from every other finished point (a re-solved point starts
  from the same warm start as before, so the results are those of an
  uninterrupted run);
- a ``checkpoint.json`` that is not a JSON object, or finished points without
  one, cannot tell which run the points belong to: refused with one line
  naming the file (StoreMismatchError) unless the caller restarts;
- a folder that holds the results of another command (``checkpoint.json``'s
  ``what``; for folders without one, their marker files: ``loop.json`` or
  ``iter_*/`` of close-loop, ``front.csv`` or ``chosen.json`` of identify,
  ``starts.csv`` of multistart) is refused with one line naming the folder
  and what it holds, even with restart: restart discards one's own finished
  points, never another command's results (:func:`claim_folder`).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import sys
import zipfile
import zlib
from pathlib import Path

import numpy as np
import pyomo.environ as pyo

from .. import interrupts
from ..ioerrors import atomic_write, writing


class StoreMismatchError(ValueError):
    """The results folder holds points of a different run; the message says how to proceed."""


#: what a results folder holds (``checkpoint.json``'s ``what``) -> the command that writes it and the files that
#: mark such a folder (globs; the first ones identify a folder written before checkpoint.json named its kind)
KINDS = {
    "identification": ("identify", ("front.csv", "chosen.json", "points/")),
    "multi-start": ("multistart", ("starts.csv", "multistart.json", "points/")),
    "close-loop": ("close-loop", ("loop.json", "iter_*/")),
}
_MARKERS = {"close-loop": ("loop.json", "iter_*/"), "identification": ("front.csv", "chosen.json"),
            "multi-start": ("starts.csv", "multistart.json")}
#: what reading a damaged .npz raises (truncated: BadZipFile; empty: EOFError; not an archive: ValueError, ...)
_UNREADABLE = (zipfile.BadZipFile, EOFError, ValueError, KeyError, TypeError, zlib.error, OSError)


class FolderBusyError(StoreMismatchError):
    """The results folder is locked by another run; the message names the holder (pid, command)."""


LOCK_FILE = ".pyomo-heli.lock"


def _command_line() -> str:
    argv = list(sys.argv)
    if argv and ("pyomo_heli" in argv[0] or Path(argv[0]).name == "pyomo-heli"):
        argv[0] = "pyomo-heli"
    return " ".join(argv)


class FolderLock:
    """An exclusive lock on a results folder for the life of a run (``fcntl.flock`` on ``DIR/.pyomo-heli.lock``).

    A second run on the folder is refused at once with :class:`FolderBusyError`, one line naming the holder's
    pid and command (written into the lock file). The kernel releases the lock when the holder exits, however
    it ends (a SIGKILL included), so a stale lock file never blocks a later run. Use as a context manager;
    ``root`` is created if needed. Re-entrant within one process for the same folder.
    """

    _held: dict = {}  # resolved folder -> [FolderLock, depth] held by this process

    def __init__(self, root: str | Path, what: str = "run"):
        self.root = Path(root)
        self.what = what
        self.fd = None

    def __enter__(self) -> "FolderLock":
        import fcntl

        self.root.mkdir(parents=True, exist_ok=True)
        key = str(self.root.resolve())
        if key in FolderLock._held:
            FolderLock._held[key][1] += 1
            self._key = key
            return self
        path = self.root / LOCK_FILE
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _read_holder(fd)
            os.close(fd)
            raise FolderBusyError(f"{self.root}: in use by another run ({holder}); wait for it to end or "
                                  f"choose another --out") from None
        except BaseException:
            os.close(fd)
            raise
        doc = json.dumps({"pid": os.getpid(), "command": _command_line(), "what": self.what}) + "\n"
        os.ftruncate(fd, 0)
        os.pwrite(fd, doc.encode(), 0)
        self.fd, self._key = fd, key
        FolderLock._held[key] = [self, 1]
        return self

    def __exit__(self, *exc) -> None:
        entry = FolderLock._held.get(self._key)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] == 0:
            del FolderLock._held[self._key]
            lock = entry[0]
            os.close(lock.fd)  # releases the flock; the file stays (removing it would race with a new holder)
            lock.fd = None


def _read_holder(fd: int) -> str:
    """'pid N: COMMAND' of the lock's holder (it writes them right after locking: retried briefly)."""
    import time

    for _ in range(50):
        try:
            doc = json.loads(os.pread(fd, 65536, 0).decode() or "null")
        except (ValueError, UnicodeDecodeError):
            doc = None
        if isinstance(doc, dict) and "pid" in doc:
            return f"pid {doc['pid']}: {doc.get('command', '?')}"
        time.sleep(0.02)
    return "holder unknown"


def read_checkpoint(meta: str | Path) -> dict:
    """The content of a ``checkpoint.json``; StoreMismatchError naming the file if it is not a JSON object."""
    meta = Path(meta)
    try:
        doc = json.loads(meta.read_text())
    except UnicodeDecodeError:
        doc = None
    except ValueError as exc:
        raise StoreMismatchError(f"{meta}: not valid JSON ({exc}); cannot tell which run the finished points in "
                                 f"{meta.parent} belong to: rerun with --restart to discard them, or choose "
                                 f"another --out") from None
    if not isinstance(doc, dict):
        raise StoreMismatchError(f"{meta}: expected a JSON object with the run's fingerprint, got "
                                 f"{type(doc).__name__ if doc is not None else 'non-UTF-8 bytes'}; cannot tell "
                                 f"which run the finished points in {meta.parent} belong to: rerun with --restart "
                                 f"to discard them, or choose another --out")
    return doc


def _present(root: Path, patterns) -> list[str]:
    found = []
    for pat in patterns:
        is_dir = pat.endswith("/")
        hits = sorted(p for p in root.glob(pat.rstrip("/")) if (p.is_dir() if is_dir else p.is_file()))
        found += [p.name + ("/" if is_dir else "") for p in hits]
    return found


def folder_kind(root: str | Path, strict: bool = True) -> str | None:
    """What the results folder ``root`` holds: ``checkpoint.json``'s ``what``, else guessed from its marker files
    (folders written before checkpoint.json named the kind, or close-loop folders of older versions); None for a
    new or empty folder. A damaged ``checkpoint.json`` raises StoreMismatchError naming it (``strict``) or is
    ignored (a restart, which rewrites it)."""
    root = Path(root)
    meta = root / "checkpoint.json"
    if meta.is_file():
        try:
            what = read_checkpoint(meta).get("what")
        except StoreMismatchError:
            if strict:
                raise
            what = None
        if what in KINDS:
            return what
    for kind, markers in _MARKERS.items():
        if _present(root, markers):
            return kind
    return None


def claim_folder(root: str | Path, what: str, restart: bool = False) -> None:
    """Refuse (StoreMismatchError, one line naming the folder and what it holds) a results folder of another
    command, whether or not the caller restarts. ``what`` is a key of KINDS. Writes nothing: the caller creates
    the folder and its checkpoint."""
    root = Path(root)
    if not root.is_dir():
        return
    kind = folder_kind(root, strict=not restart)
    if kind is None or kind == what:
        return
    command, files = KINDS[kind]
    held = ", ".join(_present(root, files)[:6]) or "its checkpoint.json"
    mine = KINDS.get(what, (what,))[0]
    raise StoreMismatchError(f"{root}: holds the results of `pyomo-heli {command}` ({held}), not of `{mine}`; "
                             f"choose another --out" + (" (--restart discards a run's own finished points, never "
                                                        "another command's results)" if restart else ""))


def write_checkpoint(root: str | Path, what: str, fingerprint: str | None = None, source: str | None = None) -> None:
    """Write ``root/checkpoint.json``: what the folder holds (see KINDS) and, for a point store, its fingerprint and
    the code that solved its points (``source``: the package sources' hash, or "mixed")."""
    doc = {"fingerprint": fingerprint, "what": what} if fingerprint is not None else {"what": what}
    if source is not None:
        doc["source"] = source
    path = Path(root) / "checkpoint.json"
    with writing(path):
        path.write_text(json.dumps(doc, indent=2) + "\n")


def _canonical(obj) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def fingerprint(raw_config: dict, dataset: str | Path | None = None, **settings) -> str:
    """SHA-256 over the config table, the dataset files' contents and extra settings.

    The dataset enters by content, not by path: given ``dataset``, the config's
    ``[data] dataset`` (a path, absolute after a ``--dataset`` override) is left
    out, so moving a checkout or a run folder keeps the fingerprint, while
    editing a data file changes it.
    """
    from .._version import __version__

    data = raw_config.get("data")
    if dataset is not None and isinstance(data, dict) and "dataset" in data:
        raw_config = {**raw_config, "data": {k: v for k, v in data.items() if k != "dataset"}}
    h = hashlib.sha256()
    h.update(_canonical({"config": raw_config, "settings": settings, "version": __version__}).encode())
    if dataset is not None:
        root = Path(dataset)
        for f in sorted(p for p in root.rglob("*") if p.is_file()):
            h.update(str(f.relative_to(root)).encode())
            h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


def _variables(m):
    return list(m.component_data_objects(pyo.Var, descend_into=True))


def variable_values(m) -> list:
    """The values of every variable of ``m`` in the store's order (nan where unset)."""
    return [math.nan if v.value is None else float(v.value) for v in _variables(m)]


class PointStore:
    """Finished points of one run in ``root/points``, guarded by a fingerprint.

    ``restart=True`` deletes points stored under any fingerprint; otherwise a
    folder with points of another fingerprint raises StoreMismatchError.
    """

    def __init__(self, root: str | Path, fingerprint: str, restart: bool = False, what: str = "run",
                 source: str | None = None):
        self.root = Path(root)
        self.dir = self.root / "points"
        self.fingerprint = fingerprint
        #: the stored points were solved by other code than ``source`` (the package's sources changed since): they are
        #: resumed as stored, and the caller says so (the fingerprint covers config, data and settings, not the code)
        self.other_code = False
        meta = self.root / "checkpoint.json"
        if what in KINDS:
            claim_folder(self.root, what, restart)
        self.root.mkdir(parents=True, exist_ok=True)
        if restart and self.dir.exists():
            shutil.rmtree(self.dir)
        if self.dir.exists() and any(self.dir.glob("*.npz")):
            if not meta.is_file():
                raise StoreMismatchError(
                    f"{self.dir}: holds finished points but {meta} is missing, so nothing tells which {what} "
                    f"they belong to; rerun with --restart to discard them, or choose another --out")
            stored = read_checkpoint(meta)
            old = stored.get("fingerprint")
            self.other_code = source is not None and stored.get("source", source) != source
            if old != fingerprint:
                raise StoreMismatchError(
                    f"{self.root}: holds finished points of a different {what} (config, data or settings changed: "
                    f"fingerprint {str(old)[:12]} here, {fingerprint[:12]} now); rerun with --restart to "
                    f"discard them, or choose another --out")
        self.dir.mkdir(exist_ok=True)
        write_checkpoint(self.root, what, fingerprint, "mixed" if self.other_code else source)

    def _path(self, key: str) -> Path:
        return self.dir / f"{key}.npz"

    def has(self, key: str) -> bool:
        """Whether ``key`` is finished on disk. A stored point that cannot be read is not finished: it is
        renamed to ``<key>.npz.corrupt``, a warning names it, and the caller solves the point again."""
        path = self._path(key)
        if not path.is_file():
            return False
        problem = _unreadable(path)
        if problem is None:
            return True
        aside = path.with_name(path.name + ".corrupt")
        os.replace(path, aside)
        print(f"warning: {path}: unreadable stored point ({problem}); solving it again (the file is kept as "
              f"{aside.name})", file=sys.stderr, flush=True)
        return False

    def keys(self) -> list[str]:
        return sorted(p.stem for p in self.dir.glob("*.npz"))

    def save(self, key: str, record: dict, m=None, duals: bool = False, values=None) -> None:
        """Write one finished point: its record and (with ``m``) the model's variable values, or ``values``
        as :func:`variable_values` gave them (e.g. on a worker that solved the point).

        Refused (:class:`~pyomo_heli.interrupts.Interrupted`) once SIGINT or SIGTERM was received: whatever
        was computed after the signal may be an interrupted solve, and is never stored as a result."""
        interrupts.check()
        arrays = {"record": np.array(json.dumps(record, default=_json_default))}
        if m is not None:
            arrays["values"] = np.array(variable_values(m))
            if duals:
                arrays.update(_duals(m))
        elif values is not None:
            arrays["values"] = np.asarray(values, dtype=float)
        atomic_write(self._path(key), lambda fh: np.savez(fh, **arrays))

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


def _unreadable(path: Path) -> str | None:
    """Why the stored point ``path`` cannot be read (None if it can): every array is read (CRC-checked) and the
    record must be a JSON object."""
    try:
        z = np.load(path)
        if not isinstance(z, np.lib.npyio.NpzFile):
            return "not an .npz archive"
        with z:
            if "record" not in z.files:
                return "no record in the archive"
            for name in z.files:
                z[name]
            if not isinstance(json.loads(str(z["record"])), dict):
                return "its record is not a JSON object"
    except PermissionError:
        raise
    except _UNREADABLE as exc:
        return f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
    return None


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
