"""Checks of the study scripts' command-line arguments: a bad one is one argparse error line (exit 2)
before any work, as for ``pyomo-heli`` itself (docs/robustness.md, "Bad input")."""
from __future__ import annotations

import argparse
from pathlib import Path

from pyomo_heli.cli import UserError, _check_out_dir
from pyomo_heli.cli import finite_float, nonneg_int, positive_float, positive_int  # noqa: F401 (re-exported)


def out_folder(ap: argparse.ArgumentParser, path, option: str = "--out") -> Path:
    """``path`` as a results folder that can be created (the command line's own check)."""
    try:
        _check_out_dir(path, option)
    except UserError as exc:
        ap.error(str(exc))
    return Path(path)


def out_file(ap: argparse.ArgumentParser, path, option: str = "--out") -> Path:
    """``path`` as a file to write: not a folder, and nothing on the way to its folder is a file."""
    p = Path(path)
    if p.is_dir():
        ap.error(f"{option} {path}: is a folder, expected a file name")
    out_folder(ap, p.parent, option)
    return p


def in_file(ap: argparse.ArgumentParser, path, option: str) -> Path:
    """An input file that exists (a config)."""
    p = Path(path)
    if not p.is_file():
        ap.error(f"{option} {path}: {'is a folder, expected a file' if p.is_dir() else 'file not found'}")
    return p


def flight_test_folder(ap: argparse.ArgumentParser, path, option: str) -> Path:
    """An input flight-test folder (one holding manifest.json)."""
    p = Path(path)
    if not (p / "manifest.json").is_file():
        ap.error(f"{option} {path}: no manifest.json there; give a flight-test folder")
    return p


#: the record of what a study's results folder was made from (:func:`claim_inputs`)
INPUTS_FILE = "study_inputs.json"


def claim_inputs(ap: argparse.ArgumentParser, out: Path, **inputs) -> None:
    """Refuse ``out`` when its finished work (seeds, generated flight tests, realizations) was made from other
    inputs: the SHA-256 of each named input file (``--config=path`` as ``config=path``; None: not given) and each
    plain value (a flag's setting; ``study``: the study's name) are kept in ``OUT/study_inputs.json`` on the first
    run and compared on every rerun, which resumes only on equal inputs. One argparse error line names the option at
    fault, or the other study."""
    import json

    from pyomo_heli.provenance import config_sha256

    now = {k: config_sha256(v) if isinstance(v, Path) else v for k, v in inputs.items()}
    f = Path(out) / INPUTS_FILE
    if f.is_file():
        try:
            old = json.loads(f.read_text())
        except ValueError:
            old = None
        if isinstance(old, dict):
            diff = [k for k in now if k in old and old[k] != now[k]]
            if "study" in diff:
                ap.error(f"--out {out}: its finished results are another study's ({old['study']}); give another "
                         f"--out or remove it")
            if diff:
                k = diff[0]
                what = f"the content of --{k.replace('_', '-')} {inputs[k]}" if isinstance(inputs[k], Path) \
                    else f"--{k.replace('_', '-')} {inputs[k]!r} (it has {old[k]!r})"
                ap.error(f"--out {out}: its finished results were made from other inputs than {what}; give another "
                         f"--out or remove it")
            now = {**old, **now}
    Path(out).mkdir(parents=True, exist_ok=True)
    f.write_text(json.dumps(now, indent=1))
