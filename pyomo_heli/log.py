"""Logging, progress with ETA, and the provenance of a results folder.

Every module reports through ``logging.getLogger("pyomo_heli")`` (or a child,
``get_logger("multistart")``), never ``print``, so that a user of the Python
API decides what is shown, as with any library. The functions that take a
``progress`` callable default to :func:`info`, i.e. ``logger.info``.

The command line (:func:`configure_console`) shows INFO messages on stdout
(where ``print`` put them before), warnings and errors on stderr; ``-v``
adds DEBUG, ``-q`` leaves warnings and errors only; ``--log-file FILE``
copies everything to FILE. A console whose reader went away (``pyomo-heli
... | head``) silences the console handler instead of breaking the run.

Every results folder gets ``pyomo_heli.log`` (all INFO messages of the run
that wrote it, UTC times) and ``provenance.json`` (:func:`provenance`):
decorate the function that writes the folder with :func:`results_folder`.

:class:`Progress` counts the finished items of a known total (front points,
loop iterations, multistart starts, Monte Carlo realisations) and appends to
each message how many are done, the elapsed time and an ETA; items read
back from disk count as done but not in the rate.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import inspect
import json
import logging
import math
import os
import subprocess
import sys
import time
from pathlib import Path

LOGGER_NAME = "pyomo_heli"
LOG_FILE = "pyomo_heli.log"
PROVENANCE_FILE = "provenance.json"

logger = logging.getLogger(LOGGER_NAME)
# no NullHandler: with no logging set up, warnings still reach stderr (logging's last resort), INFO stays silent


def get_logger(name: str | None = None) -> logging.Logger:
    """The package logger, or its child ``pyomo_heli.<name>``."""
    return logger if not name else logger.getChild(name)


def info(message: str) -> None:
    """The default ``progress`` callable of the package: ``logger.info(message)``."""
    logger.info(message)


# ---------------------------------------------------------------- console
class _ConsoleHandler(logging.Handler):
    """INFO and below to the current ``sys.stdout``, WARNING and above to ``sys.stderr``.

    The streams are looked up at each record (so redirections made after set-up are followed). A stream
    that is closed or whose reader went away (BrokenPipeError) is not written again; for the process's own
    stdout it is pointed at /dev/null, so the interpreter's final flush does not fail either.
    """

    def __init__(self, level=logging.INFO):
        super().__init__(level)
        self._dead: set[int] = set()

    def emit(self, record: logging.LogRecord) -> None:
        stream = sys.stdout if record.levelno < logging.WARNING else sys.stderr
        if stream is None or id(stream) in self._dead:
            return
        try:
            stream.write(self.format(record) + "\n")
            stream.flush()
        except (BrokenPipeError, ValueError, OSError) as exc:
            if isinstance(exc, OSError) and not isinstance(exc, BrokenPipeError) and exc.errno not in (32, 9):
                self.handleError(record)
                return
            self._dead.add(id(stream))
            _silence(stream)


def _silence(stream) -> None:
    """Point the process's stdout/stderr file descriptor at /dev/null after its reader went away."""
    if stream not in (sys.__stdout__, sys.__stderr__):
        return
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, stream.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


class _UTCFormatter(logging.Formatter):
    converter = time.gmtime

    def formatTime(self, record, datefmt=None):  # noqa: N802 (logging's name)
        return time.strftime("%Y-%m-%dT%H:%M:%S", self.converter(record.created)) + f".{int(record.msecs):03d}Z"


FILE_FORMAT = "%(asctime)s %(levelname)-7s %(name)s: %(message)s"

_cli_handlers: list[logging.Handler] = []


def configure_console(verbosity: int = 0, log_file: str | Path | None = None) -> None:
    """Set up the package logger for the command line.

    verbosity: -1 quiet (warnings and errors), 0 INFO (default), 1 and more DEBUG.
    log_file: also append every message (DEBUG with -v, else INFO) to this file, with UTC times.
    Calling it again replaces the handlers of the previous call (commands run in one process, as in tests).
    """
    for h in _cli_handlers:
        logger.removeHandler(h)
        h.close()
    _cli_handlers.clear()
    level = logging.DEBUG if verbosity > 0 else logging.INFO
    logger.setLevel(level)
    logger.propagate = False  # the command line owns the output; no second copy through the root logger
    console = _ConsoleHandler(logging.WARNING if verbosity < 0 else level)
    console.setFormatter(logging.Formatter("%(message)s" if verbosity <= 0 else "%(levelname)s %(name)s: %(message)s"))
    _cli_handlers.append(console)
    if log_file is not None:
        fh = logging.FileHandler(log_file, mode="a", encoding="utf-8")
        fh.setLevel(level)
        fh.setFormatter(_UTCFormatter(FILE_FORMAT))
        _cli_handlers.append(fh)
    for h in _cli_handlers:
        logger.addHandler(h)


class _FolderFileHandler(logging.FileHandler):
    """``FOLDER/pyomo_heli.log``, opened (and the folder created) at the first message only."""

    def __init__(self, folder: Path, level: int):
        super().__init__(Path(folder) / LOG_FILE, mode="a", encoding="utf-8", delay=True)
        self.setLevel(level)
        self.setFormatter(_UTCFormatter(FILE_FORMAT))

    def _open(self):
        Path(self.baseFilename).parent.mkdir(parents=True, exist_ok=True)
        return super()._open()


@contextlib.contextmanager
def log_to_folder(folder: str | Path):
    """Append the package's messages to ``folder/pyomo_heli.log`` while the block runs.

    INFO messages are written even when the console shows fewer (``-q``, or no logging set up by an API
    user); DEBUG ones when the logger is at DEBUG (``-v``).
    """
    before = logger.level
    effective = logger.getEffectiveLevel()
    handler = _FolderFileHandler(Path(folder), logging.DEBUG if effective <= logging.DEBUG else logging.INFO)
    if effective > logging.INFO:
        logger.setLevel(logging.INFO)
    logger.addHandler(handler)
    try:
        yield handler
    finally:
        logger.removeHandler(handler)
        handler.close()
        logger.setLevel(before)


# ---------------------------------------------------------------- progress
def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    seconds = int(round(seconds))
    h, rest = divmod(seconds, 3600)
    m, s = divmod(rest, 60)
    return f"{h}h{m:02d}m" if h else (f"{m}m{s:02d}s" if m else f"{s}s")


class Progress:
    """Progress of ``total`` items of one kind, as a suffix for a log message: done, elapsed and ETA.

    ``tick()`` marks one more item finished and returns e.g. ``" [3/11 front points, 1m02s, ETA 2m40s]"``.
    The ETA is the mean time of the items finished in this run times the items left; an item read back
    from disk (``from_disk=True``) counts as done and not in that mean. ``at_most`` says the total is an
    upper bound (the closed loop stops early when nothing more is accepted).
    """

    def __init__(self, total: int, what: str, at_most: bool = False, clock=time.perf_counter):
        self.total, self.what, self.at_most = int(total), what, at_most
        self.done = 0
        self._ran = 0
        self._clock = clock
        self._t0 = clock()

    def eta(self) -> float:
        """Seconds left at the rate of the items run so far (nan before the first one)."""
        if self._ran == 0:
            return math.nan
        return (self._clock() - self._t0) / self._ran * max(self.total - self.done, 0)

    def tick(self, from_disk: bool = False) -> str:
        self.done += 1
        if not from_disk:
            self._ran += 1
        return self.suffix()

    def suffix(self) -> str:
        elapsed = self._clock() - self._t0
        total = f"{'<=' if self.at_most else ''}{self.total}"
        if self.done >= self.total:
            return f" [{self.done}/{total} {self.what}, {_duration(elapsed)}]"
        eta = self.eta()
        return (f" [{self.done}/{total} {self.what}, {_duration(elapsed)}, ETA "
                f"{'at most ' if self.at_most and math.isfinite(eta) else ''}{_duration(eta)}]")


# ---------------------------------------------------------------- display units
def format_parameters(values: dict, parameters=None, digits: int = 6, se: dict | None = None,
                      notes: dict | None = None) -> str:
    """``name=value unit`` for each parameter, in the display unit of the config files (deg, deg/m, ...).

    parameters: a :class:`~pyomo_heli.physics.parameters.ParameterSet` giving each name's units; a name it
    does not know is shown as given (SI). se: name -> standard error [SI], shown as ``value+-se unit``. notes:
    name -> a text shown instead of the value where it is not empty (e.g. "at lower bound").
    """
    parts = []
    for name, v in values.items():
        unit, factor = "", 1.0
        if parameters is not None:
            try:
                spec = parameters.spec(name)
            except (KeyError, ValueError):
                spec = None
            if spec is not None:
                unit, factor = spec.display if spec.display is not None else (spec.unit, 1.0)
        if (notes or {}).get(name):
            parts.append(f"{name} {notes[name]}")
            continue
        try:
            shown = f"{float(v) * factor:.{digits}g}"
            if se is not None and name in se:
                shown += f"+-{float(se[name]) * abs(factor):.3g}"
        except (TypeError, ValueError):
            shown = str(v)
        parts.append(f"{name}={shown}" + (f" {unit}" if unit and unit != "-" else ""))
    return " ".join(parts)


# ---------------------------------------------------------------- provenance
def _version(dist: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def ipopt_version() -> str | None:
    """The version of the Ipopt library shipped with casadi (``GetIpoptVersion`` of its C interface)."""
    try:
        import ctypes

        import casadi

        folder = Path(casadi.__file__).parent
        libs = (sorted(folder.glob("libipopt.so*")) + sorted(folder.glob("libipopt*.dylib"))
                + sorted(folder.glob("*ipopt*.dll")))
        for lib in libs:
            try:
                dll = ctypes.CDLL(str(lib))
                a, b, c = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
                dll.GetIpoptVersion(ctypes.byref(a), ctypes.byref(b), ctypes.byref(c))
                return f"{a.value}.{b.value}.{c.value}"
            except (OSError, AttributeError):
                continue
    except ImportError:
        return None
    return None


def git_commit(path: str | Path | None = None) -> dict | None:
    """``{"commit": sha, "dirty": bool}`` of the git checkout holding ``path`` (the package), else None."""
    where = Path(path) if path is not None else Path(__file__).resolve().parent
    try:
        sha = subprocess.run(["git", "-C", str(where), "rev-parse", "HEAD"], capture_output=True, text=True,
                             timeout=10)
        if sha.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(where), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
        return {"commit": sha.stdout.strip(), "dirty": bool(dirty.stdout.strip()) if dirty.returncode == 0 else None}
    except (OSError, subprocess.SubprocessError):
        return None


def _relative(path, start) -> str:
    """``path`` relative to the folder ``start`` (with .. where needed); absolute when on another drive."""
    try:
        return Path(os.path.relpath(Path(path).resolve(), Path(start).resolve())).as_posix()
    except ValueError:
        return str(Path(path).resolve())


def _command_line() -> str:
    prog = Path(sys.argv[0]).name if sys.argv and sys.argv[0] else "python"
    if prog in ("cli.py", "__main__.py") and "pyomo_heli" in sys.argv[0]:
        prog = "pyomo-heli"
    return " ".join([prog] + sys.argv[1:])


def provenance(config=None, datasets=(), command: str | None = None, folder=None) -> dict:
    """What made a results folder: versions, git commit, UTC time, config and datasets.

    config: the config file (path); datasets: flight-test folders, recorded relative to the config's folder
    (absolute when there is no config). folder: the results folder (the config is recorded relative to it).
    """
    from ._version import __version__

    doc = {
        "pyomo_heli": __version__,
        "python": sys.version.split()[0],
        "pyomo": _version("pyomo"),
        "casadi": _version("casadi"),
        "ipopt": ipopt_version(),
        "idaes-pse": _version("idaes-pse"),
        "git": git_commit(),
        "utc_time": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "command": command if command is not None else _command_line(),
    }
    if config is not None:
        config = Path(config)
        doc["config"] = _relative(config, folder) if folder is not None else str(config)
        doc["config_name"] = config.name
    doc["datasets_relative_to_config"] = [_relative(d, config.parent) if config is not None else str(Path(d).resolve())
                                          for d in datasets if d is not None]
    return doc


def write_provenance(folder, config=None, datasets=(), command: str | None = None) -> Path:
    """Write ``folder/provenance.json`` (see :func:`provenance`) and return its path; the records of earlier
    runs into the same folder move to its list ``previous`` (newest first)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / PROVENANCE_FILE
    doc = provenance(config, datasets, command, folder)
    try:  # a folder written to again (resumed, or standard errors added later) keeps the earlier records
        old = json.loads(path.read_text()) if path.is_file() else None
    except (OSError, ValueError):
        old = None
    if isinstance(old, dict):
        earlier = old.pop("previous", [])
        doc["previous"] = [old] + (earlier if isinstance(earlier, list) else [])
    path.write_text(json.dumps(doc, indent=2) + "\n")
    return path


def results_folder(out: str = "out", describe=None):
    """Decorate a function that writes a results folder (its argument ``out``): while it runs, the package's
    messages go to ``OUT/pyomo_heli.log``; when it returns, ``OUT/provenance.json`` is written.

    describe(arguments) -> (config path or None, [dataset folders]) for the provenance; ``arguments`` are the
    call's arguments by name. A call with ``out=None`` writes neither.
    """

    def wrap(fn):
        sig = inspect.signature(fn)

        @functools.wraps(fn)
        def run(*args, **kwargs):
            bound = sig.bind(*args, **kwargs)
            bound.apply_defaults()
            folder = bound.arguments.get(out)
            if folder is None:
                return fn(*args, **kwargs)
            return run_in_folder(folder, lambda: describe(bound.arguments) if describe is not None else (None, ()),
                                 fn, *args, **kwargs)

        return run

    return wrap


@contextlib.contextmanager
def logged_run(folder, describe):
    """While the block runs, the package's messages are appended to ``folder/pyomo_heli.log``; afterwards
    ``folder/provenance.json`` is written (``describe() -> (config, datasets)``): on success, or after a failure
    once the run has written to the folder (its log is open), never into a folder the block refused before
    starting. On success the log's last line (not on the console) says how long the run took."""
    ok = False
    t0 = time.perf_counter()
    with log_to_folder(folder) as handler:
        try:
            yield handler
            ok = True
            if Path(folder).is_dir():  # the last line of the folder's log only (not on the console)
                handler.handle(logger.makeRecord(logger.name, logging.INFO, __file__, 0,
                                                 f"{_command_line()}: finished in {time.perf_counter() - t0:.1f} s",
                                                 None, None))
        finally:
            if Path(folder).is_dir() and (ok or handler.stream is not None):
                config, datasets = describe()
                write_provenance(folder, config, datasets)


def run_in_folder(folder, describe, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` inside :func:`logged_run` of ``folder``."""
    with logged_run(folder, describe):
        return fn(*args, **kwargs)


def config_and_dataset(arguments: dict, name: str = "cfg"):
    """``describe`` for functions taking an IdentificationConfig ``cfg``: its file and its dataset."""
    cfg = arguments.get(name)
    return getattr(cfg, "path", None), [getattr(cfg, "dataset", None)]
