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
