"""The ``pyomo-heli`` command line: the parser and ``main``; the commands live in one module per group
(``model_commands``, ``data_commands``, ``identify_commands``, ``loop_commands``), option types in
``options`` and the checks of results folders in ``folders``.

Every command turns bad input into a one-line error naming the culprit and
exit status 2, never a traceback. Degrees, knots and feet appear only here
and in files, labelled; everything inside is SI and radians.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .data_commands import cmd_check_data, cmd_generate_data, cmd_schema
from .folders import (_check_copy_out, _check_diagnosis_out, _check_out_dir, _check_out_file,  # noqa: F401
                      _check_out_not_foreign, _point_parameters, _solver_status_line)
from .identify_commands import (cmd_demo, cmd_identify, cmd_inspect, cmd_multistart, cmd_report_linear,
                                cmd_uncertainty)
from .loop_commands import cmd_check_effect, cmd_close_loop, cmd_diagnose, cmd_report_loop, cmd_trim_loop
from .model_commands import cmd_linearize, cmd_simulate, cmd_trim
from .options import (MAX_INPUT_DEG, MAX_SIM_SAMPLES, MAX_SPEED_KT, UserError, _epsilon, _Parser,  # noqa: F401
                      _starts, finite_float, nonneg_float, nonneg_int, positive_float, positive_int)


# ---------------------------------------------------------------- parser
def _logging_flags(parser, default) -> None:
    g = parser.add_argument_group("output")
    g.add_argument("-v", "--verbose", action="count", default=0 if default is None else default,
                   help="more messages (-v: DEBUG)")
    g.add_argument("-q", "--quiet", action="store_true", default=False if default is None else default,
                   help="warnings and errors only (results are still printed)")
    g.add_argument("--log-file", metavar="FILE", default=default,
                   help="also append every message, with UTC times, to FILE (each results folder gets its "
                        "own pyomo_heli.log anyway)")


FIGURE_FORMATS = ("png", "pdf", "svg")


def _placement_flag(parser) -> None:
    parser.add_argument("--placement", choices=("uniform", "adaptive"),
                        help="override [pareto] placement: the uniform epsilon grid, or adaptive placement by "
                             "normalised arc length refined around the Eq. 11 choice ([pareto] max_solves)")


def _figure_flag(parser, none: bool = False) -> None:
    parser.add_argument("--figure-format", choices=(*FIGURE_FORMATS, *(("none",) if none else ())), default="png",
                        help="file format of the report's figures (default png)"
                             + ("; none: the report's text and tables only (batch runs), report-loop draws the "
                                "figures later" if none else ""))


def _dask_flags(parser, what: str) -> None:
    parser.add_argument("--workers", type=nonneg_int, default=0,
                        help=f"solve the {what} on a Dask LocalCluster of this many worker processes "
                             f"(default 0: one after the other in this process; same results either way)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help=f"send the {what} to the Dask cluster of this scheduler (e.g. tcp://host:8786)")


def _config_command(sub, name: str, help: str, out_help: str):
    """A command that reads a config (positional) and writes the results folder ``--out`` (required)."""
    parser = sub.add_parser(name, help=help)
    parser.add_argument("config")
    parser.add_argument("--out", required=True, help=out_help)
    return parser


def build_parser() -> argparse.ArgumentParser:
    from .._version import __version__

    # -v/-q/--log-file are accepted before the command and after it (the subcommand's copy must not reset
    # the value given before it: SUPPRESS as its default)
    common = _Parser(add_help=False)
    _logging_flags(common, argparse.SUPPRESS)
    p = _Parser(prog="pyomo-heli", description="Multi-objective parameter identification of helicopter models")
    p.add_argument("--version", action="version", version=f"pyomo-heli {__version__}")
    _logging_flags(p, None)
    sub = p.add_subparsers(dest="command", parser_class=_Parser, metavar="COMMAND")
    _add_parser = sub.add_parser
    sub.add_parser = lambda *a, **k: _add_parser(*a, parents=[common], **k)
    sub.required = True

    t = sub.add_parser("trim", help="trim table of the model over speed (Pyomo trim block)")
    t.add_argument("--speeds-kt", type=finite_float, nargs="+", default=[0, 20, 40, 60, 80, 100, 120])
    t.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter (SI)")
    t.add_argument("--solver", default="casadi-ipopt", help="casadi-ipopt (default), pounce or ipopt")
    t.add_argument("--json", metavar="FILE", help="also write the table as JSON records")
    t.set_defaults(func=cmd_trim)

    s = sub.add_parser("simulate", help="simulate a maneuver from trim (scipy)")
    s.add_argument("--speed-kt", type=finite_float, required=True)
    s.add_argument("--input", action="append", metavar="CH:SHAPE:AMP_DEG:STEP_S",
                   help="input increment, e.g. lon:3211:0.5:0.5 (shapes 3211, doublet, step, pulse); "
                   "a log frequency sweep: CH:sweep:AMP_DEG:LENGTH_S[:WMIN_RAD_S:WMAX_RAD_S[:DWELL_CYCLES]], "
                   "e.g. lon:sweep:0.5:90:0.3:20")
    s.add_argument("--duration", type=positive_float, default=15.0, help="record length [s]")
    s.add_argument("--rate", type=positive_float, default=50.0, help="output sample rate [Hz]")
    s.add_argument("--t-start", type=nonneg_float, default=1.0, help="time the input starts [s], before --duration")
    s.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter (SI)")
    s.add_argument("--out", metavar="FILE.csv", help="write CSV (units in column names)")
    s.set_defaults(func=cmd_simulate)

    g = sub.add_parser("generate-data", help="generate a synthetic flight test from a config")
    g.add_argument("--config", required=True)
    g.add_argument("--out", required=True)
    g.add_argument("--seed", type=int, help="replace the config's [dataset] seed (another noise realisation)")
    g.add_argument("--force", action="store_true",
                   help="replace a flight test already in --out (its old files are deleted), or write beside "
                        "other files there; without it such an --out is refused")
    g.set_defaults(func=cmd_generate_data)

    i = _config_command(sub, "identify", "multi-objective identification from a config (Pareto front)",
                        "results folder")
    i.add_argument("--no-report", action="store_true", help="skip figures and report")
    i.add_argument("--cold-check", action="store_true",
                   help="also solve every interior front point cold ([pareto] cold_check), to measure warm starts")
    i.add_argument("--uncertainty", choices=("all", "chosen", "none"), default="all",
                   help="Cramer-Rao standard errors for every front point (all, default), only for A, the chosen "
                        "point and the direct solve (chosen, faster), or none")
    _placement_flag(i)
    _figure_flag(i)
    i.set_defaults(func=cmd_identify)

    cl = _config_command(sub, "close-loop", "identify, attribute the residual to a candidate effect, add it, "
                                            "re-identify, repeat ([loop] table of the config)",
                         "results folder (loop.json, loop_report.md, iter_*/)")
    cl.add_argument("--max-iterations", type=nonneg_int, help="override [loop] max_iterations")
    cl.add_argument("--dataset", help="flight-test folder replacing the config's [data] dataset (e.g. another noise "
                                      "realisation from generate-data --seed)")
    cl.add_argument("--restart", action="store_true",
                    help="identify every iteration afresh (finished points and shape decisions in --out are "
                         "discarded) instead of resuming")
    _figure_flag(cl, none=True)
    cl.set_defaults(func=cmd_close_loop)

    rp = sub.add_parser("report-loop", help="rewrite loop_report.md and the figures of a finished close-loop "
                                            "folder from its loop.json (no solve)")
    rp.add_argument("loop_dir", help="results folder of pyomo-heli close-loop")
    rp.add_argument("--config", help="the loop's config (default: the one named in loop.json)")
    _figure_flag(rp)
    rp.set_defaults(func=cmd_report_loop)

    ce = sub.add_parser("check-effect", help="test an effect of your own (or a library term) against a finished "
                                             "close-loop: significant? does it explain what the discovered term does?")
    ce.add_argument("loop_dir", help="results folder of pyomo-heli close-loop")
    ce.add_argument("--effect", required=True,
                    help="FILE.py:CLASS or MODULE:CLASS (an extension whose strength has bounds), or a library name")
    ce.add_argument("--iteration", type=nonneg_int,
                    help="test at this iteration's model (default: the model the loop kept)")
    ce.add_argument("--config", help="the loop's config (default: the one named in the iteration's chosen.json)")
    ce.add_argument("--against", default="auto",
                    help="generic term for the encompassing test: 'auto' (default: the one the step at that "
                         "iteration discovered or described), a term's name, or 'none'")
    ce.add_argument("--json", help="also write the whole result to this JSON file")
    ce.set_defaults(func=cmd_check_effect)

    tl = _config_command(sub, "trim-loop", "identify a trim-only flight test (J_trim), test the candidate effects "
                                           "on the trim residuals, add the accepted one, repeat (docs/real_data.md)",
                         "results folder (report.md, trim_loop.json, figures)")
    tl.set_defaults(func=cmd_trim_loop)

    u = sub.add_parser("uncertainty", help="standard errors and identifiability of an existing results folder")
    u.add_argument("config", help="the identification config the results came from")
    u.add_argument("--results", required=True, help="results folder of `identify`")
    u.add_argument("--out", help="write a copy with standard errors here (default: into --results)")
    u.add_argument("--points", choices=("all", "chosen"), default="all",
                   help="every front point, or only A, the chosen point and the direct solve")
    u.set_defaults(func=cmd_uncertainty)


    i.add_argument("--restart", action="store_true",
                   help="discard finished points in --out instead of resuming from them")
    i.set_defaults(func=cmd_identify)

    ms = sub.add_parser("multistart", help="solve from seeded random initial guesses within the bounds")
    ms.add_argument("config")
    ms.add_argument("--starts", type=_starts, default=20, help="number of starts (default 20, at most 10,000)")
    ms.add_argument("--seed", type=nonneg_int, default=0, help="seed of the initial guesses (default 0)")
    ms.add_argument("--epsilon", type=_epsilon, default=None,
                    help="solve min J_time s.t. J_trim <= EPSILON (one front point) instead of min J_time")
    ms.add_argument("--rtol", type=positive_float, default=1e-6,
                    help="relative objective tolerance for 'reached the best optimum' (default 1e-6)")
    ms.add_argument("--out", required=True, help="results folder (resumed if it holds finished starts)")
    ms.add_argument("--restart", action="store_true", help="discard finished starts in --out")
    _dask_flags(ms, "starts")
    ms.set_defaults(func=cmd_multistart)

    d = sub.add_parser("demo", help="run the bundled Case 1 into ./demo_out")
    d.add_argument("--out", default="demo_out")
    d.add_argument("--restart", action="store_true", help="discard finished points in --out instead of resuming")
    _placement_flag(d)
    _figure_flag(d)
    d.set_defaults(func=cmd_demo)

    n = sub.add_parser("inspect", help="print the NLP of a config without solving")
    n.add_argument("config")
    n.add_argument("--no-diagnostics", action="store_true", help="skip the IDAES structural diagnostics")
    n.set_defaults(func=cmd_inspect)

    rl = _config_command(sub, "report-linear", "figures and report of a tri-objective results folder",
                         "results folder written by identify")
    _figure_flag(rl)
    rl.set_defaults(func=cmd_report_linear)

    lz = sub.add_parser("linearize", help="labelled A, B, C, D and the mode table of the float model at trim "
                                          "(central differences)")
    lz.add_argument("--speeds-kt", type=finite_float, nargs="+", default=[0, 80])
    lz.add_argument("--json", metavar="FILE", help="also write matrices (with state/input/output names and units), "
                                                   "trim and modes as JSON")
    lz.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter (SI)")
    lz.set_defaults(func=cmd_linearize)

    c = sub.add_parser("check-data", help="check a flight-test dataset folder and print a summary")
    c.add_argument("directory")
    c.set_defaults(func=cmd_check_data)

    from ..settings import KINDS

    sc = sub.add_parser("schema", help="JSON Schema of a config kind, for editors (docs/settings.md)")
    sc.add_argument("kind", nargs="?", choices=tuple(KINDS), help="the config kind: " + "; ".join(
        f"{k}: {what}" for k, (what, _) in KINDS.items()))
    sc.add_argument("--out-dir", help="write every kind's schema to OUT_DIR/<kind>.schema.json instead")
    sc.set_defaults(func=cmd_schema)

    g = sub.add_parser("diagnose", help="residual analysis of an identification result (diagnosis.json, diagnosis.md)")
    g.add_argument("results_dir", help="results folder of pyomo-heli identify")
    g.add_argument("--config", help="identification config (default: the one named in chosen.json)")
    g.add_argument("--out", help="folder for diagnosis.json, diagnosis.md and figures (default: RESULTS_DIR)")
    g.add_argument("--point", choices=("chosen", "time_domain"), default="chosen",
                   help="diagnose the chosen point C (default) or the time-domain point A")
    g.add_argument("--alpha", type=finite_float, default=0.01, help="significance level of the tests (default 0.01)")
    g.add_argument("--test-rate-hz", type=positive_float, default=5.0,
                   help="sample rate of the whiteness test, at most the data's (default 5)")
    g.add_argument("--seed", type=nonneg_int, default=0, help="seed of the Monte Carlo p-values (default 0)")
    g.add_argument("--no-residuals", action="store_true",
                   help="do not save the residuals folder (residuals_<point>/, about 1 MB per 10 maneuvers)")
    _figure_flag(g)
    g.set_defaults(func=cmd_diagnose)
    trace = "on an error, also print the Python traceback (or set PYOMO_HELI_TRACEBACK=1)"
    p.add_argument("--traceback", action="store_true", help=trace)
    for command in sub.choices.values():
        command.add_argument("--traceback", action="store_true", default=argparse.SUPPRESS, help=trace)
    return p


class _Stdout:
    """sys.stdout for a command: a closed pipe (``| head -1``) silences the rest of the output instead of
    aborting the run; any other failed write (``> /dev/full``) raises OutputError naming standard output."""

    def __init__(self, stream):
        self._stream = stream

    def _failed(self, exc: OSError):
        try:  # the unwritten buffer goes to /dev/null, so that no later flush (at exit) fails again
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self._stream.fileno())
            os.close(devnull)
        except (OSError, ValueError, AttributeError):
            self._stream = open(os.devnull, "w")
        if not isinstance(exc, BrokenPipeError):
            from ..ioerrors import OutputError

            raise OutputError(exc.errno, exc.strerror or str(exc), "<standard output>") from None

    def write(self, text):
        try:
            return self._stream.write(text)
        except OSError as exc:
            self._failed(exc)
            return len(text)

    def flush(self):
        try:
            self._stream.flush()
        except OSError as exc:
            self._failed(exc)

    def __getattr__(self, name):
        return getattr(self._stream, name)


TRACEBACK_HINT = "rerun with --traceback (or PYOMO_HELI_TRACEBACK=1) to see where"
PACKAGE_DIR = Path(__file__).resolve().parents[1]


def _failed_inside(exc: BaseException) -> bool:
    """Did a KeyError or ValueError come from an operation of the package's own code (a dict lookup, a
    conversion, a library call such as a linear solve) rather than from a ``raise`` statement that names the bad
    input? The innermost frame of its traceback in the package is at a line that is no ``raise``: an internal
    error, never reported as bad input."""
    import linecache

    tb, inside = exc.__traceback__, None
    while tb is not None:
        if PACKAGE_DIR in Path(tb.tb_frame.f_code.co_filename).resolve().parents:
            inside = tb
        tb = tb.tb_next
    if inside is None:
        return False
    line = linecache.getline(inside.tb_frame.f_code.co_filename, inside.tb_lineno)
    return not line.lstrip().startswith("raise")


def main(argv=None) -> int:
    """Run one command. Exit status: 0 done; 2 bad input (one line naming the culprit); 1 an internal error or
    a failed output (one line with the path and a hint to use --traceback), or a run whose result is not to be
    trusted (no point converged, an anchor failed); 130 interrupted by SIGINT or SIGTERM (finished points stay
    on disk; the same command resumes)."""
    from .. import interrupts
    from ..dataset import DatasetError
    from ..settings import ConfigError  # every settings file's one error type
    from ..ioerrors import OUTPUT_ERRNOS
    from ..simulation.inputs import InputSpecError
    from ..simulation.trim import TrimError
    from ..solvers.errors import SolverError, SolverUnavailableError
    from ..pareto.store import StoreMismatchError

    argv = sys.argv[1:] if argv is None else argv
    show_traceback = os.environ.get("PYOMO_HELI_TRACEBACK", "").strip() not in ("", "0")
    try:
        args = build_parser().parse_args(argv)
        cmd = args.command
        if args.log_file is not None:
            _check_out_file(args.log_file, "--log-file")
    except UserError as exc:
        print(f"pyomo-heli: error: {exc}", file=sys.stderr)
        return 2
    show_traceback = show_traceback or getattr(args, "traceback", False)
    bad_input = (UserError, InputSpecError, ConfigError, DatasetError, TrimError,
                 SolverUnavailableError, StoreMismatchError, KeyError, ValueError)
    stdout = sys.stdout
    sys.stdout = _Stdout(stdout)
    from ..log import configure_console

    configure_console(-1 if args.quiet else args.verbose, args.log_file)
    try:
        with interrupts.guard():
            code = args.func(args)
            sys.stdout.flush()
        return code
    except KeyboardInterrupt as exc:  # interrupts.Interrupted, or a Ctrl-C before the guard was up
        name = exc.signame if isinstance(exc, interrupts.Interrupted) else "SIGINT"
        point = getattr(exc, "point", None)
        where = f" while solving point {point} (not stored)" if point else ""
        out = getattr(args, "out", None)
        kept = (f"; finished points stay in {out}: run the same command again to resume"
                if out and cmd in ("identify", "multistart", "close-loop", "demo") else "")
        print(f"pyomo-heli {cmd}: interrupted by {name}{where}{kept}", file=sys.stderr)
        return interrupts.EXIT_INTERRUPTED
    except BaseException as exc:  # noqa: BLE001 - every error ends as one line (and a traceback if asked)
        if isinstance(exc, SystemExit):
            raise
        if show_traceback:
            import traceback

            traceback.print_exc()
        if isinstance(exc, OSError) and (exc.errno in OUTPUT_ERRNOS or not isinstance(
                exc, (FileNotFoundError, NotADirectoryError, IsADirectoryError, PermissionError, FileExistsError))):
            path = exc.filename or getattr(args, "out", None) or "?"
            print(f"pyomo-heli {cmd}: I/O error: {path}: {exc.strerror or exc}"
                  + ("" if show_traceback else f"; {TRACEBACK_HINT}"), file=sys.stderr)
            return 1
        internal = ((isinstance(exc, SolverError) and not isinstance(exc, SolverUnavailableError))
                    or (isinstance(exc, (KeyError, ValueError)) and _failed_inside(exc)))
        if not internal and (isinstance(exc, bad_input) or isinstance(exc, OSError)):
            msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
            for line in str(msg).splitlines() or [""]:  # a settings file: one line per error
                print(f"pyomo-heli {cmd}: error: {line}", file=sys.stderr)
            return 2
        print(f"pyomo-heli {cmd}: internal error: {type(exc).__name__}: {exc}"
              + ("" if show_traceback else f"; {TRACEBACK_HINT}"), file=sys.stderr)
        return 1
    finally:
        sys.stdout = stdout
