"""The ``pyomo-heli`` command line.

Every command turns bad input into a one-line error naming the culprit and
exit status 2, never a traceback. Degrees, knots and feet appear only here
and in files, labelled; everything inside is SI and radians.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
from pathlib import Path

from .units import DEG, KT

MAX_SPEED_KT = 150.0  # upper end of the speed range the model is meant for
MAX_INPUT_DEG = 20.0  # largest input increment simulate accepts (control travel is about +-10..15 deg from trim)
MAX_SIM_SAMPLES = 1_000_000  # simulate output samples: more is a typo in --rate or --duration, not a record


class UserError(Exception):
    """Bad input from the user: printed as one line, exit status 2."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, no usage dump
        raise UserError(message)


# ---------------------------------------------------------------- argparse types
# argparse reports a failing ``type=`` as "argument --OPTION: MESSAGE", so these name the option themselves.
def _number(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None


def finite_float(text: str) -> float:
    v = _number(text)
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return v


def positive_float(text: str) -> float:
    v = finite_float(text)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return v


def nonneg_float(text: str) -> float:
    v = finite_float(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text}")
    return v


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None


def nonneg_int(text: str) -> int:
    v = _integer(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {text}")
    return v


def positive_int(text: str) -> int:
    v = _integer(text)
    if v < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {text}")
    return v


def _starts(text: str) -> int:
    from .workflows.multistart import MAX_STARTS

    v = _integer(text)
    if not 1 <= v <= MAX_STARTS:
        raise argparse.ArgumentTypeError(f"must be an integer between 1 and {MAX_STARTS:,}, got {text}")
    return v


def _epsilon(text: str) -> float:
    v = finite_float(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text} is negative; J_trim is a sum of squares (>= 0), so "
                                         f"J_trim <= {text} is infeasible")
    return v


def _check_out_dir(path, option: str = "--out") -> None:
    """A results folder that can be created: nothing on its path may be a file."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise UserError(f"option {option}: {path} is a file, expected a folder")
    for parent in p.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise UserError(f"option {option}: cannot create folder {path}: {parent} is a file, not a folder")
            if not os.access(parent, os.W_OK | os.X_OK):
                raise UserError(f"option {option}: cannot create folder {path}: {parent} is not writable")
            return


def _check_out_file(path, option: str = "--out") -> None:
    """An output file that can be written: its folder exists and it is not itself a folder."""
    p = Path(path)
    if p.is_dir():
        raise UserError(f"option {option}: {path} is a folder, expected a file name")
    parent = p.absolute().parent
    if not parent.exists():
        raise UserError(f"option {option}: cannot write {path}: folder {parent} does not exist")
    if not parent.is_dir():
        raise UserError(f"option {option}: cannot write {path}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise UserError(f"option {option}: cannot write {path}: permission denied")


#: what a run of a command leaves in its folder before the files that name its kind (pareto/store.py KINDS)
_RUN_LEFTOVERS = ("points", "checkpoint.json")


def _visible(folder: Path) -> list[Path]:
    return sorted(c for c in folder.iterdir() if not c.name.startswith(".") and not c.name.endswith((".tmp", ".lock")))


def _names(paths, at_most: int = 5) -> str:
    names = [p.name + ("/" if p.is_dir() else "") for p in paths]
    return ", ".join(names[:at_most]) + (f", ... ({len(names)} in all)" if len(names) > at_most else "")


def _check_out_not_foreign(path, kind: str, option: str = "--out") -> None:
    """Refuse a results folder that holds someone else's files: a flight test, or files that are no results of
    pyomo-heli. ``kind``: ``identification``, ``multi-start`` or ``close-loop`` (pareto/store.py KINDS). A new
    or empty folder is fine; a results folder of any kind passes here (the command's own claim_folder refuses
    another command's results, naming them)."""
    from .pareto.store import StoreMismatchError, folder_kind

    p = Path(path)
    if not p.is_dir():
        return
    present = _visible(p)
    if not present:
        return
    if (p / "manifest.json").is_file():
        raise UserError(f"option {option}: {path} is a flight-test folder (manifest.json); results are never "
                        f"written into data: choose another {option}")
    try:
        if folder_kind(p, strict=False) is not None:
            return
    except StoreMismatchError:
        return  # a damaged checkpoint.json: the command names it
    others = [c for c in present if c.name not in _RUN_LEFTOVERS]
    if others:
        raise UserError(f"option {option}: {path} holds files that are not results of pyomo-heli "
                        f"({_names(others)}); choose a new or empty folder")


def _out_contents(out, results_dir) -> tuple[Path, list]:
    """An ``--out`` of a command that reads ``results_dir``: its visible files (none when it is new, empty or the
    results folder itself); a flight-test folder is refused."""
    p = Path(out)
    if not p.is_dir() or p.resolve() == Path(results_dir).resolve():
        return p, []
    present = _visible(p)
    if present and (p / "manifest.json").is_file():
        raise UserError(f"option --out: {out} is a flight-test folder (manifest.json); choose another --out")
    return p, present


def _check_diagnosis_out(out, results_dir) -> None:
    """``diagnose --out``: a new or empty folder, the results folder itself, or a folder holding a diagnosis (rerun);
    never another results folder (its diagnosis would be replaced by one of other results) or other files."""
    p, present = _out_contents(out, results_dir)
    if not present:
        return
    if (p / "chosen.json").is_file() or (p / "loop.json").is_file() or (p / "starts.csv").is_file():
        raise UserError(f"option --out: {out} is another results folder ({_names(present)}); its own diagnosis "
                        f"would be replaced by one of {results_dir}: choose another --out (default: {results_dir})")
    if not (p / "diagnosis.json").is_file():
        raise UserError(f"option --out: {out} holds files that are no diagnosis ({_names(present)}); choose a new or "
                        f"empty folder")


def _check_copy_out(out, results_dir) -> None:
    """``uncertainty --out``: a new or empty folder, the results folder, or an earlier copy of the same results
    (same anchor A and chosen point); never another results folder or other files."""
    p, present = _out_contents(out, results_dir)
    if not present:
        return

    def key(folder):
        try:
            ch = json.loads((Path(folder) / "chosen.json").read_text())
            td = json.loads((Path(folder) / "time_domain.json").read_text())
            return (td["parameters"], td["J_time"], (ch["chosen"] or {}).get("parameters"))
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            return None

    mine = key(p)
    if mine is not None and mine == key(results_dir):
        return  # an earlier copy of these results: updated in place
    what = "other results" if (p / "chosen.json").is_file() else "other files"
    raise UserError(f"option --out: {out} holds {what} ({_names(present)}), not a copy of {results_dir}; choose a "
                    f"new or empty folder")


def _warning(cmd: str):
    """A one-line warning on stderr, prefixed like the command's errors."""
    return lambda msg: print(f"pyomo-heli {cmd}: warning: {msg}", file=sys.stderr)


def _point_parameters(result, which: str, results_dir) -> dict:
    """The parameters of the chosen point or of A, every value finite (named with file and key otherwise)."""
    point = result.chosen if which == "chosen" else result.time_domain
    file = Path(results_dir) / ("chosen.json" if which == "chosen" else "time_domain.json")
    key = "chosen.parameters" if which == "chosen" else "parameters"
    if point is None:
        raise UserError(f"{file}: no chosen point (no front point converged); nothing to diagnose")
    params = point["parameters"]
    for n in result.parameters:
        v = params.get(n)
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v):
            raise UserError(f"{file}: key {key}.{n} = {v!r} is not a finite number")
    return params


def _solver_status_line(result, which: str) -> str:
    """How the solve of the analysed point ended (``which``: chosen or time_domain), and whether the results
    folder marks the anchors' derived quantities unreliable."""
    point = result.chosen if which == "chosen" else result.time_domain
    label = "chosen point C" if which == "chosen" else "time-domain point A"
    status = point.get("status", "unknown")
    iterations = point.get("iterations")
    line = f"solver status of the {label}: {status}" + (f" ({iterations} iterations)" if iterations is not None
                                                          else "")
    if point.get("success") is False:
        line += " -- WARNING: this solve did not converge; its numbers are an unconverged iterate"
    unreliable = result.info.get("unreliable")
    if unreliable and which == "chosen":
        line += f" -- WARNING: {unreliable.get('reason')}; the Eq. 11 choice of this point is unreliable"
    return line


def _parse_params(items, model):
    values = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"--param {item!r} must read NAME=VALUE")
        name, val = item.split("=", 1)
        if name not in model.parameters:
            raise UserError(model.parameters._unknown(name).replace("unknown parameter name",
                                                                    "unknown parameter name in --param"))
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


def _results_folder(folder_of):
    """Decorate a command that writes into the folder ``folder_of(args)``: its messages go to that folder's
    pyomo_heli.log and its provenance.json is written (pyomo_heli.log.run_in_folder)."""
    import functools

    def wrap(cmd):
        @functools.wraps(cmd)
        def run(args):
            from .log import run_in_folder

            folder = folder_of(args)
            if folder is None:
                return cmd(args)

            def describe():
                config = getattr(args, "config", None)
                try:
                    from .config import load_identification_config

                    dataset = load_identification_config(config).dataset if config else None
                except Exception:  # noqa: BLE001 - provenance only; the command reported any bad config
                    dataset = None
                return config, [dataset]

            return run_in_folder(folder, describe, cmd, args)

        return run

    return wrap


# ---------------------------------------------------------------- commands
def cmd_trim(args) -> int:
    from .nlp.trim_table import trim_table
    from .physics.model import HelicopterModel

    for v in args.speeds_kt:
        _check_speed_kt(v, "--speeds-kt")
    if args.json:
        _check_out_file(args.json, "--json")
    model = _parse_params(args.param, HelicopterModel())
    table = trim_table(model, [v * KT for v in args.speeds_kt], solver=args.solver)
    records = []
    for v_kt, row in zip(args.speeds_kt, table.to_dict("records")):
        records.append({"speed_kt": v_kt, "col_deg": row["col"] / DEG, "lon_deg": row["lon"] / DEG,
                        "theta_deg": row["theta"] / DEG, "lambda_i": row["lambda_i"],
                        "beta_0_deg": row["beta_0"] / DEG, "beta_1c_deg": row["beta_1c"] / DEG})
    head = (f"{'speed kt':>8} {'col deg':>8} {'lon deg':>8} {'theta deg':>9} {'lambda_i':>9} {'beta_0 deg':>10} "
            f"{'beta_1c deg':>11}")
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
    from .simulation.inputs import InputSpecError, parse_input
    from .simulation.integrate import simulate
    from .simulation.trim import trim_float

    _check_speed_kt(args.speed_kt, "--speed-kt")
    # --duration, --rate, --t-start are finite and in range by their argparse types; here what ties them together
    n_samples = math.floor(args.duration * args.rate + 1e-6) + 1
    if n_samples < 2:
        raise UserError(f"--rate {args.rate:g} Hz gives fewer than 2 samples over --duration {args.duration:g} s "
                        f"(need --rate >= {1.0 / args.duration:g} Hz)")
    if n_samples > MAX_SIM_SAMPLES:
        raise UserError(f"--rate {args.rate:g} Hz over --duration {args.duration:g} s gives {n_samples:.3g} samples, "
                        f"more than {MAX_SIM_SAMPLES:,}; lower --rate or --duration")
    if args.input and args.t_start >= args.duration:
        raise UserError(f"--t-start {args.t_start:g} s: the input would start at or after the end of the record "
                        f"(--duration {args.duration:g} s) and never be applied")
    signals = []
    for text in args.input or []:
        try:
            sig = parse_input(text, t_start=args.t_start)
        except InputSpecError as exc:
            raise UserError(f"--input {text!r}: {exc}") from None
        if abs(sig.amplitude) > MAX_INPUT_DEG * DEG:
            raise UserError(f"--input {text!r}: amplitude {sig.amplitude / DEG:g} deg is outside "
                            f"+-{MAX_INPUT_DEG:g} deg (an increment on trim; larger ones leave the control travel and "
                            f"the model's small-angle, attached-flow range)")
        signals.append(sig)
    channels = [s.channel for s in signals]
    if len(set(channels)) != len(channels):
        raise UserError(f"--input: channel given twice ({', '.join(channels)})")
    if args.out:
        _check_out_file(args.out, "--out")
    model = _parse_params(args.param, HelicopterModel())
    trim = trim_float(model, args.speed_kt * KT)
    t = np.arange(n_samples) / args.rate
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
    _check_out_dir(args.out)
    replaced = (Path(args.out) / "manifest.json").is_file()
    out = generate_from_file(args.config, args.out, seed=args.seed, force=args.force)
    print(f"wrote synthetic flight test to {out}" + (" (replacing the flight test that was there)" if replaced else ""))
    return 0


def cmd_schema(args) -> int:
    from .settings import write_schemas, schema_text

    if args.out_dir:
        for path in write_schemas(args.out_dir):
            print(path)
    elif args.kind:
        print(schema_text(args.kind), end="")
    else:
        raise UserError("schema: give a config kind or --out-dir")
    return 0


def cmd_check_data(args) -> int:
    from .dataset.cli import check_data

    d = Path(args.directory)
    if d.exists() and not d.is_dir():
        raise UserError(f"{args.directory} is a file, expected a dataset folder")
    if (d / "manifest.json").is_dir():
        raise UserError(f"{d / 'manifest.json'} is a directory, expected a file")
    return check_data(args.directory)


def cmd_close_loop(args) -> int:
    from .workflows.close_loop import close_loop, loop_settings
    from .config import load_identification_config
    from .report.loop import write_loop_report

    from pathlib import Path

    overrides = None
    if args.dataset is not None:
        d = Path(args.dataset)
        if not d.is_dir():
            raise UserError(f"option --dataset: folder {args.dataset} not found")
        if not (d / "manifest.json").is_file():  # checked before --out is created
            held = [n for n in ("loop.json", "front.csv", "chosen.json", "starts.csv") if (d / n).is_file()]
            what = f"it holds results ({', '.join(held)}) and" if held else "it"
            raise UserError(f"option --dataset: {args.dataset} is not a flight-test folder: {what} has no "
                            f"manifest.json (a flight test as written by generate-data)")
        overrides = {"data": {"dataset": str(Path(args.dataset).resolve())}}
    _check_out_dir(args.out)
    _check_out_not_foreign(args.out, "close-loop")
    cfg = load_identification_config(args.config, overrides)
    settings = loop_settings(cfg)
    if args.max_iterations is not None:
        if args.max_iterations < 0:
            raise UserError("option --max-iterations must be >= 0")
        settings.max_iterations = args.max_iterations
    from .workflows.close_loop import IdentificationFailed

    try:
        doc = close_loop(cfg, args.out, settings, restart=args.restart)
    except IdentificationFailed as exc:  # a failed solve, not bad input: exit 1 as identify
        print(f"pyomo-heli close-loop: {exc}", file=sys.stderr)
        return 1
    path = write_loop_report(args.out, cfg, figure_format=args.figure_format)
    print(f"{len(doc['iterations'])} identification(s); stopped: {doc['stopped']}")
    print(f"loop.json and {path} written")
    return 0


def cmd_trim_loop(args) -> int:
    """Trim-only closed loop (pyomo_heli.workflows.trim_loop): report, figures and trim_loop.json in --out."""
    from .workflows.trim_loop import TrimIdentificationFailed, load_trim_loop_config, run_trim_loop, write_trim_report

    _check_out_dir(args.out)
    cfg = load_trim_loop_config(args.config)
    try:
        doc = run_trim_loop(cfg, args.out)
    except TrimIdentificationFailed as exc:  # a failed solve, not bad input: exit 1 as identify
        print(f"pyomo-heli trim-loop: {exc}", file=sys.stderr)
        return 1
    path = write_trim_report(cfg, doc, args.out)
    print(f"{len(doc['iterations'])} identification(s); stopped: {doc['stopped']}")
    print(f"{path}, trim_curves.png, trim_residuals.png and trim_loop.json written")
    return 0


def _data_rate_hz(cfg) -> tuple[float, str]:
    """Sample rate [Hz] of the residuals a diagnosis of ``cfg`` tests: [data] resample_hz, else the slowest maneuver."""
    if cfg.resample_hz:
        return float(cfg.resample_hz), f"[data] resample_hz of config {cfg.path}"
    from .dataset import load_flight_test

    ft = load_flight_test(cfg.dataset)
    sel = cfg.maneuvers
    names = set(sel) if not isinstance(sel, str) else {n for n, mv in ft.maneuvers.items() if mv.role == sel}
    if not isinstance(cfg.validation, str) and cfg.validation:
        names |= set(cfg.validation)
    rates = [ft.maneuvers[n].sample_rate for n in names if n in ft.maneuvers]
    rates = [r for r in rates if math.isfinite(r)]
    return (min(rates) if rates else math.inf), f"dataset {cfg.dataset} of config {cfg.path}"


@_results_folder(lambda a: a.out or a.results_dir)
def cmd_diagnose(args) -> int:
    from pathlib import Path

    from .diagnosis.analysis import diagnose
    from .config import load_result_config
    from .diagnosis.residuals import compute_residuals
    from .pareto.result import IdentificationResult
    from .report.diagnosis import write_diagnosis_report

    if not 0 < args.alpha < 1:
        raise UserError(f"--alpha must lie in (0, 1), got {args.alpha}")
    if args.out is not None:
        _check_out_dir(args.out)
        _check_diagnosis_out(args.out, args.results_dir)
    res = IdentificationResult.load(args.results_dir)
    # the config (given, or named in chosen.json) plus a close-loop iteration's effects, checked against the folder
    notes = []  # records the folder lacks: said once the command has checked everything else
    cfg = load_result_config(args.results_dir, args.config, res, warn=notes.append)
    parameters = _point_parameters(res, args.point, args.results_dir)
    rate, source = _data_rate_hz(cfg)
    if args.test_rate_hz > rate * (1 + 1e-9):
        raise UserError(f"option --test-rate-hz: {args.test_rate_hz:g} Hz is above the sample rate of the data "
                        f"({rate:g} Hz, {source}); the whiteness test cannot sample faster than the data")
    for note in notes:
        _warning("diagnose")(note)
    label = "multi-objective (C)" if args.point == "chosen" else "time-domain (A)"
    out = Path(args.out or args.results_dir)
    print(f"diagnosing {label} of {args.results_dir} (config {cfg.path})")
    print(_solver_status_line(res, args.point))
    r = compute_residuals(cfg, parameters, label, test_rate_hz=args.test_rate_hz)
    if not args.no_residuals:
        r.save(out / f"residuals_{args.point}")
    d = diagnose(r, alpha=args.alpha, test_rate_hz=args.test_rate_hz, seed=args.seed)
    d.save(out / "diagnosis.json")
    cmd = "pyomo-heli diagnose " + " ".join(sys.argv[1:][1:]) if sys.argv[1:2] == ["diagnose"] else None
    write_diagnosis_report(out, r, d, results_dir=args.results_dir, command=cmd, figure_format=args.figure_format)
    print(d)
    print(f"wrote {out / 'diagnosis.json'}, {out / 'diagnosis.md'} and figures")
    return 0


def cmd_identify(args) -> int:
    from .config import load_identification_config
    from .workflows.identify import run_identification

    pareto = {"cold_check": True} if getattr(args, "cold_check", False) else {}
    if getattr(args, "placement", None):  # [pareto] placement ("adaptive": pareto/placement.py)
        pareto["placement"] = args.placement
    overrides = {"pareto": pareto} if pareto else None
    _check_out_dir(args.out)
    _check_out_not_foreign(args.out, "identification")
    cfg = load_identification_config(args.config, overrides)
    from .log import info

    points = (cfg.pareto.points if cfg.pareto.placement == "uniform"
              else f"adaptive placement, at most {cfg.pareto.max_solves}")
    info(f"identifying {', '.join(f.name for f in cfg.free)} from {cfg.dataset} "
         f"({points} front points, solver {cfg.pareto.solver})")
    result = run_identification(cfg, args.out, uncertainty=getattr(args, "uncertainty", "all"),
                                restart=getattr(args, "restart", False))
    if result.chosen is None:
        print(result)
        print(f"no front point converged; every status is in {args.out}/front.csv", file=sys.stderr)
        return 1
    if not args.no_report and "linear" in cfg.objectives:
        from .report.linear import write_linear_report

        print(f"report: {write_linear_report(args.out, cfg, figure_format=args.figure_format)}")
    elif not args.no_report:
        from .report.identification import write_report

        write_report(args.out, cfg, figure_format=args.figure_format)
    print(result)
    print(f"results in {args.out}")
    unreliable = result.info.get("unreliable")
    if unreliable:  # the files are written, marked (chosen.json info.unreliable, report.md); the status says so
        print(f"pyomo-heli identify: {unreliable['reason']}: the utopia point, nadir, epsilon grid and Eq. 11 "
              f"choice are unreliable (marked in {args.out}/chosen.json and the report)", file=sys.stderr)
        return 1
    return 0


@_results_folder(lambda a: a.out or a.results)
def cmd_uncertainty(args) -> int:
    import shutil
    from pathlib import Path

    from .config import load_identification_config
    from .nlp.identification import identification_data
    from .pareto.result import IdentificationResult
    from .pareto.store import LOCK_FILE, FolderLock
    from .uncertainty.front import add_uncertainty

    if args.out:
        _check_out_dir(args.out)
        _check_copy_out(args.out, args.results)
    cfg = load_identification_config(args.config)
    result = IdentificationResult.load(args.results)
    if result.info.get("extensions"):  # an iteration of close-loop: the config plus the effects the loop added
        from .config import config_of_result

        cfg = config_of_result(cfg, result)
    from .provenance import check_results_match

    notes = []  # records the folder lacks: said once the command has checked everything else
    check_results_match(cfg, result, args.results, warn=notes.append)
    if result.chosen is None:
        raise UserError(f"{Path(args.results) / 'chosen.json'}: no chosen point (no front point converged); "
                        f"no standard errors to compute")
    data = identification_data(cfg)
    for note in notes:
        _warning("uncertainty")(note)
    for which in ("time_domain", "chosen"):
        print(_solver_status_line(result, which))
    with FolderLock(args.out or args.results, "uncertainty"):  # no identify may write there meanwhile
        if args.out and Path(args.out).resolve() != Path(args.results).resolve():
            shutil.copytree(args.results, args.out, dirs_exist_ok=True,
                            ignore=shutil.ignore_patterns(LOCK_FILE))
        add_uncertainty(result, cfg, data, args.out or args.results, points=args.points)
    print(f"standard errors in {args.out or args.results} (front.csv, chosen.json, identifiability.csv)")
    return 0


def cmd_multistart(args) -> int:
    from .config import load_identification_config
    from .workflows.multistart import run_multistart

    _check_out_dir(args.out)
    _check_out_not_foreign(args.out, "multi-start")
    cfg = load_identification_config(args.config)
    problem = "time" if args.epsilon is None else "epsilon"
    from .log import info
    from .parallel import dask_executor

    info(f"multi-start of {', '.join(f.name for f in cfg.free)} from {args.starts} random initial guesses "
         f"(seed {args.seed}) on {cfg.dataset}")
    with dask_executor(args.workers, args.scheduler) as executor:
        result = run_multistart(cfg, args.out, starts=args.starts, seed=args.seed, problem=problem,
                                epsilon=args.epsilon, rtol=args.rtol, restart=args.restart, executor=executor)
    print(result)
    print(f"results in {args.out}")
    if result.best is None and args.epsilon is not None:
        print(f"no start converged: the bound J_trim <= {args.epsilon:g} (--epsilon) may be infeasible; "
              f"try an epsilon between the front's J_trim values (front.csv of identify)", file=sys.stderr)
    return 0 if result.best is not None else 1


def cmd_demo(args) -> int:
    from .resources import demo_config

    config = demo_config()  # package data: works from an installed wheel in any directory
    args.config, args.no_report = str(config), False
    _check_out_dir(args.out)
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
    notes = []  # records the folder lacks (checked against the config before anything is written)
    print(f"report: {write_linear_report(args.out, cfg, warn=notes.append, figure_format=args.figure_format)}")
    for note in notes:
        _warning("report-linear")(note)
    return 0


def cmd_linearize(args) -> int:
    from .physics.model import HelicopterModel
    from .report.linear import linearization_dict, linearization_text
    from .simulation.linearize import linearize_float

    for v in args.speeds_kt:
        _check_speed_kt(v, "--speeds-kt")
    if args.json:
        _check_out_file(args.json, "--json")
    model = _parse_params(args.param, HelicopterModel())
    records = []
    for v in args.speeds_kt:
        lin = linearize_float(model, v * KT)
        print(linearization_text(lin, v))
        print()
        records.append(linearization_dict(lin, v))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(records, fh, indent=2)
            fh.write("\n")
        print(f"wrote {args.json}")
    return 0


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


def _figure_flag(parser) -> None:
    parser.add_argument("--figure-format", choices=FIGURE_FORMATS, default="png",
                        help="file format of the report's figures (default png)")


def _dask_flags(parser, what: str) -> None:
    parser.add_argument("--workers", type=nonneg_int, default=0,
                        help=f"solve the {what} on a Dask LocalCluster of this many worker processes "
                             f"(default 0: one after the other in this process; same results either way)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help=f"send the {what} to the Dask cluster of this scheduler (e.g. tcp://host:8786)")


def build_parser() -> argparse.ArgumentParser:
    from ._version import __version__

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

    i = sub.add_parser("identify", help="multi-objective identification from a config (Pareto front)")
    i.add_argument("config")
    i.add_argument("--out", required=True, help="results folder")
    i.add_argument("--no-report", action="store_true", help="skip figures and report")
    i.add_argument("--cold-check", action="store_true",
                   help="also solve every interior front point cold ([pareto] cold_check), to measure warm starts")
    i.add_argument("--uncertainty", choices=("all", "chosen", "none"), default="all",
                   help="Cramer-Rao standard errors for every front point (all, default), only for A, the chosen "
                        "point and the direct solve (chosen, faster), or none")
    _placement_flag(i)
    _figure_flag(i)
    i.set_defaults(func=cmd_identify)

    cl = sub.add_parser("close-loop", help="identify, attribute the residual to a candidate effect, add it, "
                                           "re-identify, repeat ([loop] table of the config)")
    cl.add_argument("config")
    cl.add_argument("--out", required=True, help="results folder (loop.json, loop_report.md, iter_*/)")
    cl.add_argument("--max-iterations", type=nonneg_int, help="override [loop] max_iterations")
    cl.add_argument("--dataset", help="flight-test folder replacing the config's [data] dataset (e.g. another noise "
                                      "realisation from generate-data --seed)")
    cl.add_argument("--restart", action="store_true",
                    help="identify every iteration afresh (finished points and shape decisions in --out are "
                         "discarded) instead of resuming")
    _figure_flag(cl)
    cl.set_defaults(func=cmd_close_loop)

    tl = sub.add_parser("trim-loop", help="identify a trim-only flight test (J_trim), test the candidate effects on "
                                          "the trim residuals, add the accepted one, repeat (docs/real_data.md)")
    tl.add_argument("config")
    tl.add_argument("--out", required=True, help="results folder (report.md, trim_loop.json, figures)")
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

    rl = sub.add_parser("report-linear", help="figures and report of a tri-objective results folder")
    rl.add_argument("config")
    rl.add_argument("--out", required=True, help="results folder written by identify")
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

    from .settings import KINDS

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
            from .ioerrors import OutputError

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


def main(argv=None) -> int:
    """Run one command. Exit status: 0 done; 2 bad input (one line naming the culprit); 1 an internal error or
    a failed output (one line with the path and a hint to use --traceback), or a run whose result is not to be
    trusted (no point converged, an anchor failed); 130 interrupted by SIGINT or SIGTERM (finished points stay
    on disk; the same command resumes)."""
    from . import interrupts
    from .dataset import DatasetError
    from .settings import ConfigError  # every settings file's one error type
    from .ioerrors import OUTPUT_ERRNOS
    from .simulation.inputs import InputSpecError
    from .simulation.trim import TrimError
    from .solvers.errors import SolverError, SolverUnavailableError
    from .pareto.store import StoreMismatchError

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
    from .log import configure_console

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
        internal = isinstance(exc, SolverError) and not isinstance(exc, SolverUnavailableError)
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


if __name__ == "__main__":
    sys.exit(main())
