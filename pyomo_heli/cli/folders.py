"""Results folders on the command line: checks of ``--out`` folders and files before anything is written,
the chosen point's parameters and solver status read back, and the decorator that logs a command into its
results folder."""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

from ..ioerrors import visible_entries
from .options import UserError

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
    """What a folder holds, leaving out a run's temporary and lock files."""
    return visible_entries(folder, ignore_suffixes=(".tmp", ".lock"))


def _names(paths, at_most: int = 5) -> str:
    names = [p.name + ("/" if p.is_dir() else "") for p in paths]
    return ", ".join(names[:at_most]) + (f", ... ({len(names)} in all)" if len(names) > at_most else "")


def _check_out_not_foreign(path, kind: str, option: str = "--out") -> None:
    """Refuse a results folder that holds someone else's files: a flight test, or files that are no results of
    pyomo-heli. ``kind``: ``identification``, ``multi-start`` or ``close-loop`` (pareto/store.py KINDS). A new
    or empty folder is fine; a results folder of any kind passes here (the command's own claim_folder refuses
    another command's results, naming them)."""
    from ..pareto.store import StoreMismatchError, folder_kind

    p = Path(path)
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


def _results_folder(folder_of):
    """Decorate a command that writes into the folder ``folder_of(args)``: its messages go to that folder's
    pyomo_heli.log and its provenance.json is written (pyomo_heli.log.run_in_folder)."""
    import functools

    def wrap(cmd):
        @functools.wraps(cmd)
        def run(args):
            from ..log import run_in_folder

            folder = folder_of(args)
            if folder is None:
                return cmd(args)

            def describe():
                config = getattr(args, "config", None)
                try:
                    from ..config import load_identification_config

                    dataset = load_identification_config(config).dataset if config else None
                except Exception:  # noqa: BLE001 - provenance only; the command reported any bad config
                    dataset = None
                return config, [dataset]

            return run_in_folder(folder, describe, cmd, args)

        return run

    return wrap
