"""Checks of user solver options (``[solver] options``) before any solve.

Without them a bad option surfaced late and badly: ``tol = nan`` hung
casadi-ipopt, ``linear_solver = "ma97"`` segfaulted it (no HSL in the casadi
wheel), an unknown or out-of-range option printed raw Ipopt text, a
non-integral ``max_iter`` was silently truncated, and pounce turned every bad
option into a per-point solver failure.

:func:`validate_solver_options` raises ``ValueError`` with one line naming the
option; callers prefix where the options came from. How each backend is
checked:

* ``casadi-ipopt``: the Ipopt library shipped in the casadi wheel is loaded
  with ctypes (casadi itself is not imported) and each option is set on a
  throw-away ``IpoptProblem`` through Ipopt's C interface, exactly the
  registered-option checks (name, type, range, valid strings) Ipopt runs when
  casadi hands it the options. Ipopt reports a refusal only as text on the
  process stdout, so file descriptor 1 is pointed at a temporary file for the
  duration (about a millisecond) and that text is parsed for the message.
  ``linear_solver`` must be one Ipopt reports as linked in
  (``IpoptGetAvailableLinearSolvers``; this wheel: mumps, spral), or a
  runtime-loaded one (HSL, Pardiso) whose library can actually be loaded.
* ``pounce``: its bundled executable is run once on its built-in
  ``quadratic`` test problem with the options (about 15 ms), the way
  Pyomo's ASL interface passes them (``key=str(value)``); pounce refuses bad
  options before solving and its message is turned into one line.
* ``ipopt`` (an executable on PATH): types and finite values only.

For every backend, non-finite numbers and values that are neither a string
nor a number (booleans, lists, tables, dates) are refused before any solver
sees them. Keys the adapters consume themselves are allowed: ``verbose``
(all backends), ``point_rows`` and ``scaling`` (casadi-ipopt).
"""

from __future__ import annotations

import ctypes
import glob
import importlib.util
import math
import os
import re
import subprocess
import sys
import tempfile
import threading

__all__ = ["validate_solver_options"]

#: keys consumed by our adapters, never passed to the solver: name -> backends
ADAPTER_KEYS = {
    "verbose": ("casadi-ipopt", "pounce", "ipopt"),  # resolve_options pops it
    "point_rows": ("casadi-ipopt",),  # CasadiIpoptSolver pops it
    "scaling": ("casadi-ipopt",),  # CasadiIpoptSolver pops it (CasadiSettings.scaling)
}

# IpoptGetAvailableLinearSolvers bits (IpLinearSolvers.h, Ipopt 3.14)
_LINEAR_SOLVER_BITS = {
    "ma27": 0x001, "ma57": 0x002, "ma77": 0x004, "ma86": 0x008, "ma97": 0x010,
    "pardiso": 0x040, "pardisomkl": 0x080, "spral": 0x100, "wsmp": 0x200, "mumps": 0x400,
}
_HSL = ("ma27", "ma57", "ma77", "ma86", "ma97")
#: libraries Ipopt 3.14's loader opens when ``hsllib``/``pardisolib`` are not set
_DEFAULT_RUNTIME_LIBS = {"hsl": ("libhsl.so", "libcoinhsl.so"), "pardiso": ("libpardiso.so",)}

_IPOPT_TYPE_WORDS = {"Number": "a number", "Integer": "an integer", "String": "a string"}

_PROBE_TIMEOUT = 10.0  # seconds; the pounce probe takes ~15 ms
_lock = threading.Lock()


def validate_solver_options(name: str, options: dict) -> None:
    """Raise ValueError (one line, naming the option) if ``options`` would fail for solver ``name``.

    ``name`` is one of ``SOLVER_NAMES``; ``options`` maps option names to
    values as read from TOML. Returns None when every option is acceptable.
    Prints nothing, never solves a real problem; a few ms for casadi-ipopt,
    ~15 ms for pounce. When a backend is not installed only the generic
    checks (types, finite numbers) run: ``make_solver`` reports the missing
    backend.
    """
    if name not in ("casadi-ipopt", "pounce", "ipopt"):
        raise ValueError(f"unknown solver {name!r}; valid choices: casadi-ipopt, pounce, ipopt")
    if not isinstance(options, dict):
        raise ValueError(f"options must be a table of option = value, got {type(options).__name__}")
    solver_opts = {}
    for key, value in options.items():
        if not isinstance(key, str) or not key:
            raise ValueError(f"option name {key!r} must be a non-empty string")
        if key in ADAPTER_KEYS:
            if name not in ADAPTER_KEYS[key]:
                raise ValueError(f"option {key!r} applies to {', '.join(ADAPTER_KEYS[key])} only, not {name}")
            if not isinstance(value, bool):
                raise ValueError(f"option {key!r} must be true or false, got {_show(value)}")
            continue
        _check_generic(key, value)
        solver_opts[key] = value
    if not solver_opts:
        return
    if name == "casadi-ipopt":
        _check_casadi_ipopt(solver_opts)
    elif name == "pounce":
        _check_pounce(solver_opts)


# ---------------------------------------------------------------- generic
def _show(value) -> str:
    return repr(value) if isinstance(value, str) else str(value).lower() if isinstance(value, bool) else str(value)


#: convergence tolerances outside these ranges are refused for every backend: above, a solve reports success at
#: a point that is no optimum (``tol = 1e300`` "converged" at the initial guess); below, double precision cannot
#: meet the test (Ipopt's defaults: tol 1e-8, acceptable_tol 1e-6, constr_viol_tol and compl_inf_tol 1e-4)
TOLERANCE_RANGES = {"tol": (1e-14, 1e-2), "acceptable_tol": (1e-14, 1e-2), "constr_viol_tol": (1e-14, 1e-2),
                    "compl_inf_tol": (1e-14, 1e-2)}


def _check_generic(key: str, value) -> None:
    if isinstance(value, bool):
        raise ValueError(
            f"option {key!r} must be a number or a string (Ipopt switches take \"yes\"/\"no\"), got {_show(value)}"
        )
    if isinstance(value, float) and not math.isfinite(value):
        hint = "" if math.isnan(value) else "; use a large finite value instead"
        raise ValueError(f"option {key!r} must be a finite number, got {value}{hint}")
    if not isinstance(value, (str, int, float)):
        raise ValueError(f"option {key!r} must be a number or a string, got {type(value).__name__} {value!r}")
    if isinstance(value, str) and ("\0" in value or "\n" in value):
        raise ValueError(f"option {key!r} must be a one-line string, got {value!r}")
    if key == "max_iter" and isinstance(value, (int, float)) and value == 0:  # Ipopt takes 0: no step, "stopped"
        raise ValueError(f"option 'max_iter' = {_show(value)}: a solve needs at least 1 iteration")
    if key in TOLERANCE_RANGES and isinstance(value, (int, float)):
        lo, hi = TOLERANCE_RANGES[key]
        if not lo <= value <= hi:
            why = ("a solve would report success at a point that is no optimum" if value > hi else
                   "double precision cannot meet it")
            raise ValueError(f"option {key!r} = {value:g} is outside the sane range {lo:g}..{hi:g}: {why}")


# ---------------------------------------------------------------- casadi-ipopt
class _Ipopt:
    """ctypes binding of the few Ipopt C-interface calls the checks need."""

    def __init__(self, path: str):
        lib = ctypes.CDLL(path)
        D, I, B, VP = ctypes.c_double, ctypes.c_int, ctypes.c_bool, ctypes.c_void_p  # noqa: E741 (ctypes int)
        DP, IP = ctypes.POINTER(D), ctypes.POINTER(I)
        # callback types of IpStdCInterface.h; never called (nothing is solved)
        self._f_t = ctypes.CFUNCTYPE(B, I, DP, B, DP, VP)
        self._g_t = ctypes.CFUNCTYPE(B, I, DP, B, I, DP, VP)
        self._jac_t = ctypes.CFUNCTYPE(B, I, DP, B, I, I, IP, IP, DP, VP)
        self._h_t = ctypes.CFUNCTYPE(B, I, DP, B, D, I, DP, B, I, IP, IP, DP, VP)
        self._f = self._f_t(lambda *a: False)
        self._grad = self._f_t(lambda *a: False)
        lib.CreateIpoptProblem.restype = VP
        lib.CreateIpoptProblem.argtypes = [I, DP, DP, I, DP, DP, I, I, I,
                                           self._f_t, self._g_t, self._f_t, self._jac_t, self._h_t]
        lib.FreeIpoptProblem.restype = None
        lib.FreeIpoptProblem.argtypes = [VP]
        for kind, ctype in (("Str", ctypes.c_char_p), ("Num", D), ("Int", I)):
            fn = getattr(lib, f"AddIpopt{kind}Option")
            fn.restype = B
            fn.argtypes = [VP, ctypes.c_char_p, ctype]
        lib.IpoptGetAvailableLinearSolvers.restype = ctypes.c_uint
        lib.IpoptGetAvailableLinearSolvers.argtypes = [I]
        self.lib = lib
        self.linked = int(lib.IpoptGetAvailableLinearSolvers(1))
        self.loadable = int(lib.IpoptGetAvailableLinearSolvers(0))
        self._xl = (D * 1)(-1.0)
        self._xu = (D * 1)(1.0)
        self._libc = ctypes.CDLL(None)  # fflush(NULL): Ipopt's messages sit in C stdio buffers

    def create(self):
        p = self.lib.CreateIpoptProblem(1, self._xl, self._xu, 0, None, None, 0, 0, 0,
                                        self._f, self._g_t(), self._grad, self._jac_t(), self._h_t())
        if not p:
            raise OSError("CreateIpoptProblem returned NULL")
        return p

    def set(self, problem, kind: str, key: str, value, sink) -> tuple[bool, str]:
        """Set one option; (accepted, what Ipopt printed about it)."""
        self._libc.fflush(None)
        start = sink.tell()
        arg = value.encode() if kind == "Str" else value
        ok = bool(getattr(self.lib, f"AddIpopt{kind}Option")(problem, key.encode(), arg))
        self._libc.fflush(None)
        sink.seek(start)
        text = sink.read().decode(errors="replace")
        sink.seek(0, os.SEEK_END)
        return ok, text


_ipopt_cache: list = []  # [] not tried yet, [None] unavailable, [_Ipopt]


def _ipopt():
    if not _ipopt_cache:
        binding = None
        try:
            spec = importlib.util.find_spec("casadi")
            dirs = list(spec.submodule_search_locations or []) if spec else []
            pattern = {"win32": "ipopt*.dll", "darwin": "libipopt*.dylib"}.get(sys.platform, "libipopt.so*")
            paths = sorted(glob.glob(os.path.join(dirs[0], pattern)), key=len) if dirs else []
            if paths:
                binding = _Ipopt(paths[0])
        except Exception:  # noqa: BLE001 - any failure to bind Ipopt leaves the generic checks
            binding = None
        _ipopt_cache.append(binding)
    return _ipopt_cache[0]


class _StdoutToFile:
    """Point file descriptor 1 at a temporary file (Ipopt prints its refusals there)."""

    def __enter__(self):
        sys.stdout.flush()
        self.file = tempfile.TemporaryFile()
        self.saved = os.dup(1)
        os.dup2(self.file.fileno(), 1)
        return self.file

    def __exit__(self, *exc):
        try:
            ctypes.CDLL(None).fflush(None)
        finally:
            os.dup2(self.saved, 1)
            os.close(self.saved)
            self.file.close()
        return False


_TYPE_RE = re.compile(r"It is a valid option, but it is of type\s+(\w+)")
_RANGE_RE = re.compile(r"^\s*(\S+)\s*(<=?)\s*\(.*\)\s*(<=?)\s*(\S+)\s*$", re.M)


def _valid_settings(text: str) -> list[str]:
    block = text.split("Valid Settings:", 1)
    if len(block) < 2:
        return []
    names = []
    for line in block[1].splitlines()[1:] if block[1].startswith("\n") else block[1].splitlines():
        m = re.match(r"^\t(\S+)", line)
        if m:
            names.append(m.group(1))
        elif line.strip().startswith("Default") or (line.strip() and not line.startswith("\t")):
            break
    return names


def _ipopt_refusal(key: str, value, text: str) -> str:
    """One line from Ipopt's text about a refused option."""
    if "It is not a valid option" in text:
        return f"unknown Ipopt option {key!r}"
    m = _TYPE_RE.search(text)
    if m:
        return f"option {key!r} must be {_IPOPT_TYPE_WORDS.get(m.group(1), m.group(1))}, got {_show(value)}"
    if "is not a valid setting" in text:
        settings = _valid_settings(text)
        if settings:
            return f"option {key!r} = {_show(value)} is not a valid setting; valid: {', '.join(settings)}"
        r = _RANGE_RE.search(text)
        if r:
            lo, op1, op2, hi = r.groups()
            bounds = " ".join(p for p in (lo, op1, key, op2, hi))
            return f"option {key!r} = {_show(value)} is out of range; Ipopt requires {bounds}"
        return f"option {key!r} = {_show(value)} is not a valid setting"
    return f"option {key!r} = {_show(value)} was refused by Ipopt"


def _check_one_ipopt(ip: _Ipopt, problem, sink, key: str, value) -> str | None:
    """None if casadi would hand ``key = value`` to Ipopt successfully, else the message.

    casadi converts a number to the option's registered type, so an int is
    fine for a real option and an integral float for an integer one.
    """
    kind = "Str" if isinstance(value, str) else "Int" if isinstance(value, int) else "Num"
    ok, text = ip.set(problem, kind, key, value if kind != "Num" else float(value), sink)
    if ok:
        return None
    m = _TYPE_RE.search(text)
    if m and kind == "Int" and m.group(1) == "Number":
        ok, text = ip.set(problem, "Num", key, float(value), sink)
    elif m and kind == "Num" and m.group(1) == "Integer":
        if not float(value).is_integer():
            return f"option {key!r} must be an integer, got {value}"
        ok, text = ip.set(problem, "Int", key, int(value), sink)
    return None if ok else _ipopt_refusal(key, value, text)


def _runtime_library_loads(options: dict, kind: str) -> bool:
    names = [options[f"{kind}lib"]] if isinstance(options.get(f"{kind}lib"), str) else _DEFAULT_RUNTIME_LIBS[kind]
    for lib in names:
        try:
            ctypes.CDLL(lib)
            return True
        except OSError:
            continue
    return False


def _available_linear_solvers(ip: _Ipopt, options: dict) -> list[str]:
    names = []
    for solver, bit in _LINEAR_SOLVER_BITS.items():
        if ip.linked & bit:
            names.append(solver)
        elif ip.loadable & bit and solver in _HSL + ("pardiso",):
            if _runtime_library_loads(options, "hsl" if solver in _HSL else "pardiso"):
                names.append(solver)
    return names


def _check_casadi_ipopt(options: dict) -> None:
    ip = _ipopt()
    if ip is None:
        return  # no casadi/Ipopt here: make_solver raises SolverUnavailableError
    solver = options.get("linear_solver")
    if isinstance(solver, str):
        # before Ipopt sees it: a registered but missing solver (HSL in the casadi wheel) segfaults
        available = _available_linear_solvers(ip, options)
        if solver.lower() not in available:
            raise ValueError(
                f"option 'linear_solver' = {solver!r} is not available in this Ipopt build; "
                f"available: {', '.join(available)}"
            )
    message = None
    with _lock:
        try:
            with _StdoutToFile() as sink:
                problem = ip.create()
                try:
                    for key, value in options.items():
                        message = _check_one_ipopt(ip, problem, sink, key, value)
                        if message:
                            break
                finally:
                    ip.lib.FreeIpoptProblem(problem)
        except OSError:
            return  # stdout cannot be redirected (closed fd 1, ...): keep the generic checks only
    if message:
        raise ValueError(message)


# ---------------------------------------------------------------- pounce
def _pounce_executable() -> str | None:
    try:
        spec = importlib.util.find_spec("pounce")  # locates, does not import (import costs 0.25 s)
    except (ImportError, ValueError):
        spec = None
    for d in (spec.submodule_search_locations or []) if spec else []:
        exe = os.path.join(d, "bin", "pounce.exe" if os.name == "nt" else "pounce")
        if os.access(exe, os.X_OK):
            return exe
    return None


_POUNCE_SET_RE = re.compile(r"failed to set ([^=\s]+)=")
_POUNCE_MSG_RE = re.compile(r"Exception message:\s*(.+)")
_POUNCE_NOT_IMPL_RE = re.compile(r"(\w+)=(\S+) is not implemented\. pounce provides `(\w+)`")


def _pounce_refusal(options: dict, text: str) -> str:
    m = _POUNCE_NOT_IMPL_RE.search(text)
    if m:
        key = m.group(1)
        value = options.get(key, m.group(2))
        return (f"option {key!r} = {_show(value)} is not available in pounce; available: feral "
                "(and ma57 in a pounce build with HSL)")
    key_m = _POUNCE_SET_RE.search(text)
    msg_m = _POUNCE_MSG_RE.search(text)
    if key_m:
        key = key_m.group(1)
        detail = msg_m.group(1).strip() if msg_m else ""
        if "not a valid option" in detail:
            return f"unknown pounce option {key!r}"
        if "Integer value expected" in detail:
            return f"option {key!r} must be an integer, got {_show(options.get(key, '?'))}"
        if "for string option" in detail:
            value = options.get(key, "?")
            if not isinstance(value, str):
                return f"option {key!r} must be a string, got {_show(value)}"
            return f"option {key!r} = {_show(value)} is not a valid setting for pounce"
        if "out of range" in detail:
            return f"option {key!r} = {_show(options.get(key, '?'))} is out of range for pounce"
        return f"option {key!r} = {_show(options.get(key, '?'))} refused by pounce: {detail}".rstrip(": ")
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return f"options refused by pounce: {lines[-1] if lines else 'no message'}"


def _check_pounce(options: dict) -> None:
    exe = _pounce_executable()
    if exe is None:
        return  # not installed: make_solver raises SolverUnavailableError
    args = [f"{k}={v}" for k, v in options.items()]  # as pyomo's ASL interface formats them
    with tempfile.TemporaryDirectory(prefix="pyomo_heli_pounce_opts_") as tmp:
        try:
            run = subprocess.run(
                [exe, "--problem", "quadratic", "--no-options-file", "--no-sol", *args],
                cwd=tmp, stdin=subprocess.DEVNULL, capture_output=True, text=True, errors="replace",
                timeout=_PROBE_TIMEOUT,
            )
        except (OSError, subprocess.SubprocessError):
            return  # cannot probe; the solve will report
    text = run.stdout + "\n" + run.stderr
    if run.returncode == 2 or "failed to set" in text or "is not implemented" in text:
        raise ValueError(_pounce_refusal(options, text))
