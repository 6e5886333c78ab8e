"""The ``pyomo-heli`` command line.

Every command turns bad input into a one-line error naming the culprit and
exit status 2, never a traceback. Degrees, knots and feet appear only here
and in files, labelled; everything inside is SI and radians.
"""
from __future__ import annotations

import argparse
import json
import math
import sys

from .units import DEG, KT

MAX_SPEED_KT = 150.0  # upper end of the speed range the model is meant for


class UserError(Exception):
    """Bad input from the user: printed as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage dump
        raise UserError(message)


def _parse_params(items, model):
    values = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"--param {item!r} must read NAME=VALUE")
        name, val = item.split("=", 1)
        if name not in model.parameters:
            raise UserError(model.parameters._unknown(name).replace("unknown parameter name", "unknown parameter name in --param"))
        try:
            values[name] = float(val)
        except ValueError:
            raise UserError(f"--param {name}: value {val!r} is not a number") from None
    return model.with_parameters(**values) if values else model


def _check_speed_kt(v, option):
    if not math.isfinite(v):
        raise UserError(f"{option}: speed {v} is not a finite number")
    if v < 0:
        raise UserError(f"{option}: speed {v:g} kt is negative")
    if v > MAX_SPEED_KT:
        raise UserError(f"{option}: speed {v:g} kt is outside the model's range 0..{MAX_SPEED_KT:g} kt")


# ---------------------------------------------------------------- commands
def cmd_trim(args) -> int:
    from .nlp.trim_table import trim_table
    from .physics.model import HelicopterModel

    for v in args.speeds_kt:
        _check_speed_kt(v, "--speeds-kt")
    model = _parse_params(args.param, HelicopterModel())
    table = trim_table(model, [v * KT for v in args.speeds_kt], solver=args.solver)
    records = []
    for v_kt, row in zip(args.speeds_kt, table.to_dict("records")):
        records.append({"speed_kt": v_kt, "col_deg": row["col"] / DEG, "lon_deg": row["lon"] / DEG,
                        "theta_deg": row["theta"] / DEG, "lambda_i": row["lambda_i"],
                        "beta_0_deg": row["beta_0"] / DEG, "beta_1c_deg": row["beta_1c"] / DEG})
    head = f"{'speed kt':>8} {'col deg':>8} {'lon deg':>8} {'theta deg':>9} {'lambda_i':>9} {'beta_0 deg':>10} {'beta_1c deg':>11}"
    print(head)
    for r in records:
        print(f"{r['speed_kt']:8.1f} {r['col_deg']:8.3f} {r['lon_deg']:8.3f} {r['theta_deg']:9.3f} "
              f"{r['lambda_i']:9.5f} {r['beta_0_deg']:10.3f} {r['beta_1c_deg']:11.3f}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(records, fh, indent=2)
            fh.write("\n")
    return 0


def cmd_simulate(args) -> int:
    import numpy as np

    from .physics.model import HelicopterModel
    from .simulation.inputs import parse_input
    from .simulation.integrate import simulate
    from .simulation.trim import trim_float

    _check_speed_kt(args.speed_kt, "--speed-kt")
    if not (args.duration > 0 and math.isfinite(args.duration)):
        raise UserError(f"--duration must be positive, got {args.duration}")
    if not args.rate > 0:
        raise UserError(f"--rate must be positive, got {args.rate}")
    signals = [parse_input(s, t_start=args.t_start) for s in args.input or []]
    channels = [s.channel for s in signals]
    if len(set(channels)) != len(channels):
        raise UserError(f"--input: channel given twice ({', '.join(channels)})")
    model = _parse_params(args.param, HelicopterModel())
    trim = trim_float(model, args.speed_kt * KT)
    t = np.arange(0.0, args.duration + 1e-9, 1.0 / args.rate)
    df = simulate(model, trim, t, {s.channel: s for s in signals}, max_step=0.05)
    out = df.assign(t_s=df.t, col_deg=df.col / DEG, lon_deg=df.lon / DEG, q_deg_s=df.q / DEG,
                    theta_deg=df.theta / DEG, nx_g=df.n_x, nz_g=df.n_z, tas_m_s=df.TAS,
                    beta0_deg=df.beta_0 / DEG, u_m_s=df.u, w_m_s=df.w, lambda_i=df.lambda_i,
                    beta1c_deg=df.beta_1c / DEG)
    cols = ["t_s", "col_deg", "lon_deg", "q_deg_s", "theta_deg", "nx_g", "nz_g", "tas_m_s", "beta0_deg",
            "u_m_s", "w_m_s", "lambda_i", "beta1c_deg"]
    if args.out:
        out[cols].to_csv(args.out, index=False, float_format="%.10g")
        print(f"wrote {len(out)} samples of {', '.join(channels) or 'no input'} at {args.speed_kt:g} kt to {args.out}")
    else:
        print(out[cols].to_string(index=False, float_format=lambda x: f"{x:.4f}"))
    return 0


def cmd_generate_data(args) -> int:
    from .flighttest.generate import generate_from_file

    if args.seed is not None and args.seed < 0:
        raise UserError(f"option --seed must be an integer >= 0, got {args.seed}")
    out = generate_from_file(args.config, args.out, seed=args.seed)
    print(f"wrote synthetic flight test to {out}")
    return 0


def cmd_check_data(args) -> int:
    from .dataset.cli import check_data

    return check_data(args.directory)


def cmd_close_loop(args) -> int:
    from .close_loop import close_loop, loop_settings
    from .config import load_identification_config
    from .report.loop import write_loop_report

    from pathlib import Path

    overrides = None
    if args.dataset is not None:
        if not Path(args.dataset).is_dir():
            raise UserError(f"option --dataset: folder {args.dataset} not found")
        overrides = {"data": {"dataset": str(Path(args.dataset).resolve())}}
    cfg = load_identification_config(args.config, overrides)
    settings = loop_settings(cfg)
    if args.max_iterations is not None:
        if args.max_iterations < 0:
            raise UserError("option --max-iterations must be >= 0")
        settings.max_iterations = args.max_iterations
    doc = close_loop(cfg, args.out, settings, restart=args.restart)
    path = write_loop_report(args.out, cfg)
    print(f"{len(doc['iterations'])} identification(s); stopped: {doc['stopped']}")
    print(f"loop.json and {path} written")
    return 0


def cmd_diagnose(args) -> int:
    from pathlib import Path

    from .diagnosis.analysis import diagnose
    from .diagnosis.residuals import load_result_config, compute_residuals
    from .pareto.result import IdentificationResult
    from .report.diagnosis import write_diagnosis_report

    if not 0 < args.alpha < 1:
        raise UserError(f"--alpha must lie in (0, 1), got {args.alpha}")
    if not args.test_rate_hz > 0:
        raise UserError(f"--test-rate-hz must be positive, got {args.test_rate_hz}")
    res = IdentificationResult.load(args.results_dir)
    cfg = load_result_config(args.results_dir, args.config)
    if res.info.get("extensions"):  # an iteration of close-loop: the config plus the effects the loop added
        from .close_loop import config_of_result

        cfg = config_of_result(cfg, res)
    point = res.chosen if args.point == "chosen" else res.time_domain
    label = "multi-objective (C)" if args.point == "chosen" else "time-domain (A)"
    out = Path(args.out or args.results_dir)
    print(f"diagnosing {label} of {args.results_dir} (config {cfg.path})")
    r = compute_residuals(cfg, point["parameters"], label, test_rate_hz=args.test_rate_hz)
    if not args.no_residuals:
        r.save(out / f"residuals_{args.point}")
    d = diagnose(r, alpha=args.alpha, test_rate_hz=args.test_rate_hz, seed=args.seed)
    d.save(out / "diagnosis.json")
    cmd = "pyomo-heli diagnose " + " ".join(sys.argv[1:][1:]) if sys.argv[1:2] == ["diagnose"] else None
    write_diagnosis_report(out, r, d, results_dir=args.results_dir, command=cmd)
    print(d)
    print(f"wrote {out / 'diagnosis.json'}, {out / 'diagnosis.md'} and figures")
    return 0


def cmd_identify(args) -> int:
    from .config import load_identification_config
    from .identify import run_identification

    overrides = {"pareto": {"cold_check": True}} if getattr(args, "cold_check", False) else None
    cfg = load_identification_config(args.config, overrides)
    print(f"identifying {', '.join(f.name for f in cfg.free)} from {cfg.dataset} "
          f"({cfg.pareto.points} front points, solver {cfg.pareto.solver})")
    result = run_identification(cfg, args.out, uncertainty=getattr(args, "uncertainty", "all"),
                                restart=getattr(args, "restart", False))
    if result.chosen is None:
        print(result)
        print(f"no front point converged; every status is in {args.out}/front.csv", file=sys.stderr)
        return 1
    if not args.no_report and "linear" in cfg.objectives:
        from .report.linear import write_linear_report

        print(f"report: {write_linear_report(args.out, cfg)}")
    elif not args.no_report:
        from .report.identification import write_report

        write_report(args.out, cfg)
    print(result)
    print(f"results in {args.out}")
    return 0


def cmd_uncertainty(args) -> int:
    import shutil
    from pathlib import Path

    from .config import load_identification_config
    from .dataset import load_flight_test
    from .nlp.identification import identification_data
    from .pareto.result import IdentificationResult
    from .uncertainty.front import add_uncertainty

    cfg = load_identification_config(args.config)
    result = IdentificationResult.load(args.results)
    if result.info.get("extensions"):  # an iteration of close-loop: the config plus the effects the loop added
        from .close_loop import config_of_result

        cfg = config_of_result(cfg, result)
    if args.out and Path(args.out).resolve() != Path(args.results).resolve():
        shutil.copytree(args.results, args.out, dirs_exist_ok=True)
    data = identification_data(cfg)
    add_uncertainty(result, cfg, data, args.out or args.results, points=args.points)
    print(f"standard errors in {args.out or args.results} (front.csv, chosen.json, identifiability.csv)")
    return 0


def cmd_multistart(args) -> int:
    from .config import load_identification_config
    from .multistart import run_multistart

    cfg = load_identification_config(args.config)
    problem = "time" if args.epsilon is None else "epsilon"
    print(f"multi-start of {', '.join(f.name for f in cfg.free)} from {args.starts} random initial guesses "
          f"(seed {args.seed}) on {cfg.dataset}")
    result = run_multistart(cfg, args.out, starts=args.starts, seed=args.seed, problem=problem, epsilon=args.epsilon,
                            rtol=args.rtol, restart=args.restart)
    print(result)
    print(f"results in {args.out}")
    return 0 if result.best is not None else 1


def cmd_demo(args) -> int:
    from pathlib import Path

    config = Path(__file__).resolve().parent.parent / "studies" / "case1.toml"
    if not config.is_file():
        raise UserError(f"demo config {config} not found (the demo runs from a source checkout)")
    args.config, args.no_report = str(config), False
    args.uncertainty = "chosen"  # standard errors of A, C and the direct solve: keeps the demo's duration
    return cmd_identify(args)


def cmd_inspect(args) -> int:
    from .config import load_identification_config
    from .nlp.inspect import inspect_problem

    cfg = load_identification_config(args.config)
    print(inspect_problem(cfg, diagnostics=not args.no_diagnostics))
    return 0


def cmd_report_linear(args) -> int:
    from .config import load_identification_config
    from .report.linear import write_linear_report

    cfg = load_identification_config(args.config)
    print(f"report: {write_linear_report(args.out, cfg)}")
    return 0


def cmd_linearize(args) -> int:
    import numpy as np

    from .physics.model import HelicopterModel
    from .simulation.linearize import linearize_float

    for v in args.speeds_kt:
        _check_speed_kt(v, "--speeds-kt")
    model = _parse_params(args.param, HelicopterModel())
    np.set_printoptions(precision=5, linewidth=140, suppress=False)
    for v in args.speeds_kt:
        lin = linearize_float(model, v * KT)
        print(f"{v:g} kt: finite-difference linearisation of the float model at its trim "
              f"(states {', '.join(lin.states)}; inputs col, lon [rad])")
        print("A =\n" + str(lin.A))
        print("B =\n" + str(lin.B))
        print("poles [1/s]: " + ", ".join(f"{z.real:.4f}{z.imag:+.4f}j" if abs(z.imag) > 0 else f"{z.real:.4f}"
                                          for z in lin.poles()))
    return 0


# ---------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="pyomo-heli", description="Multi-objective parameter identification of helicopter models")
    sub = p.add_subparsers(dest="command", parser_class=_Parser, metavar="COMMAND")
    sub.required = True

    t = sub.add_parser("trim", help="trim table of the model over speed (Pyomo trim block)")
    t.add_argument("--speeds-kt", type=float, nargs="+", default=[0, 20, 40, 60, 80, 100, 120])
    t.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter (SI)")
    t.add_argument("--solver", default="casadi-ipopt", help="casadi-ipopt (default), pounce or ipopt")
    t.add_argument("--json", metavar="FILE", help="also write the table as JSON records")
    t.set_defaults(func=cmd_trim)

    s = sub.add_parser("simulate", help="simulate a maneuver from trim (scipy)")
    s.add_argument("--speed-kt", type=float, required=True)
    s.add_argument("--input", action="append", metavar="CH:SHAPE:AMP_DEG:STEP_S",
                   help="input increment, e.g. lon:3211:0.5:0.5 (shapes 3211, doublet, step, pulse)")
    s.add_argument("--duration", type=float, default=15.0, help="record length [s]")
    s.add_argument("--rate", type=float, default=50.0, help="output sample rate [Hz]")
    s.add_argument("--t-start", type=float, default=1.0, help="time the input starts [s]")
    s.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter (SI)")
    s.add_argument("--out", metavar="FILE.csv", help="write CSV (units in column names)")
    s.set_defaults(func=cmd_simulate)

    g = sub.add_parser("generate-data", help="generate a synthetic flight test from a config")
    g.add_argument("--config", required=True)
    g.add_argument("--out", required=True)
    g.add_argument("--seed", type=int, help="replace the config's [dataset] seed (another noise realisation)")
    g.set_defaults(func=cmd_generate_data)

    i = sub.add_parser("identify", help="multi-objective identification from a config (Pareto front)")
    i.add_argument("config")
    i.add_argument("--out", required=True, help="results folder")
    i.add_argument("--no-report", action="store_true", help="skip figures and report")
    i.add_argument("--cold-check", action="store_true",
                   help="also solve every interior front point cold ([pareto] cold_check), to measure warm starts")
    i.add_argument("--uncertainty", choices=("all", "chosen", "none"), default="all",
                   help="Cramer-Rao standard errors for every front point (all, default), only for A, the chosen "
                        "point and the direct solve (chosen, faster), or none")
    i.set_defaults(func=cmd_identify)

    cl = sub.add_parser("close-loop", help="identify, attribute the residual to a candidate effect, add it, "
                                           "re-identify, repeat ([loop] table of the config)")
    cl.add_argument("config")
    cl.add_argument("--out", required=True, help="results folder (loop.json, loop_report.md, iter_*/)")
    cl.add_argument("--max-iterations", type=int, help="override [loop] max_iterations")
    cl.add_argument("--dataset", help="flight-test folder replacing the config's [data] dataset (e.g. another noise "
                                      "realisation from generate-data --seed)")
    cl.add_argument("--restart", action="store_true",
                    help="identify every iteration afresh (finished points and shape decisions in --out are "
                         "discarded) instead of resuming")
    cl.set_defaults(func=cmd_close_loop)

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
    ms.add_argument("--starts", type=int, default=20, help="number of starts (default 20)")
    ms.add_argument("--seed", type=int, default=0, help="seed of the initial guesses (default 0)")
    ms.add_argument("--epsilon", type=float, default=None,
                    help="solve min J_time s.t. J_trim <= EPSILON (one front point) instead of min J_time")
    ms.add_argument("--rtol", type=float, default=1e-6,
                    help="relative objective tolerance for 'reached the best optimum' (default 1e-6)")
    ms.add_argument("--out", required=True, help="results folder (resumed if it holds finished starts)")
    ms.add_argument("--restart", action="store_true", help="discard finished starts in --out")
    ms.set_defaults(func=cmd_multistart)

    d = sub.add_parser("demo", help="run the bundled Case 1 into ./demo_out")
    d.add_argument("--out", default="demo_out")
    d.add_argument("--restart", action="store_true", help="discard finished points in --out instead of resuming")
    d.set_defaults(func=cmd_demo)

    n = sub.add_parser("inspect", help="print the NLP of a config without solving")
    n.add_argument("config")
    n.add_argument("--no-diagnostics", action="store_true", help="skip the IDAES structural diagnostics")
    n.set_defaults(func=cmd_inspect)

    rl = sub.add_parser("report-linear", help="figures and report of a tri-objective results folder")
    rl.add_argument("config")
    rl.add_argument("--out", required=True, help="results folder written by identify")
    rl.set_defaults(func=cmd_report_linear)

    lz = sub.add_parser("linearize", help="A, B and poles of the float model at trim (central differences)")
    lz.add_argument("--speeds-kt", type=float, nargs="+", default=[0, 80])
    lz.add_argument("--param", action="append", metavar="NAME=VALUE", help="override a model parameter (SI)")
    lz.set_defaults(func=cmd_linearize)

    c = sub.add_parser("check-data", help="check a flight-test dataset folder and print a summary")
    c.add_argument("directory")
    c.set_defaults(func=cmd_check_data)

    g = sub.add_parser("diagnose", help="residual analysis of an identification result (diagnosis.json, diagnosis.md)")
    g.add_argument("results_dir", help="results folder of pyomo-heli identify")
    g.add_argument("--config", help="identification config (default: the one named in chosen.json)")
    g.add_argument("--out", help="folder for diagnosis.json, diagnosis.md and figures (default: RESULTS_DIR)")
    g.add_argument("--point", choices=("chosen", "time_domain"), default="chosen",
                   help="diagnose the chosen point C (default) or the time-domain point A")
    g.add_argument("--alpha", type=float, default=0.01, help="significance level of the tests (default 0.01)")
    g.add_argument("--test-rate-hz", type=float, default=5.0, help="sample rate of the whiteness test (default 5)")
    g.add_argument("--seed", type=int, default=0, help="seed of the Monte Carlo p-values (default 0)")
    g.add_argument("--no-residuals", action="store_true",
                   help="do not save the residuals folder (residuals_<point>/, about 1 MB per 10 maneuvers)")
    g.set_defaults(func=cmd_diagnose)
    return p


def main(argv=None) -> int:
    from .config import ConfigError as IdentificationConfigError
    from .dataset import DatasetError
    from .flighttest.config import ConfigError
    from .simulation.inputs import InputSpecError
    from .simulation.trim import TrimError
    from .solvers.errors import SolverError
    from .pareto.store import StoreMismatchError

    argv = sys.argv[1:] if argv is None else argv
    try:
        args = build_parser().parse_args(argv)
        cmd = args.command
    except UserError as exc:
        print(f"pyomo-heli: error: {exc}", file=sys.stderr)
        return 2
    try:
        return args.func(args)
    except (UserError, InputSpecError, ConfigError, IdentificationConfigError, DatasetError, TrimError, SolverError,
            StoreMismatchError, FileNotFoundError, KeyError, ValueError, RuntimeError) as exc:
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        print(f"pyomo-heli {cmd}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
