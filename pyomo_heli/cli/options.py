"""Option values of the command line: argparse types that name the option at fault, the one-line
``UserError`` (exit status 2), and the checks of model parameters and speeds shared by the commands."""
from __future__ import annotations

import argparse
import math

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
def _read(text: str, convert, what: str):
    try:
        return convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}") from None


def _number(text: str) -> float:
    return _read(text, float, "a number")


def finite_float(text: str) -> float:
    v = _number(text)
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
    return v


def _must(value, ok: bool, rule: str, text: str):
    """``value`` when ``ok``, else the argparse error "must be RULE, got TEXT"."""
    if not ok:
        raise argparse.ArgumentTypeError(f"must be {rule}, got {text}")
    return value


def positive_float(text: str) -> float:
    v = finite_float(text)
    return _must(v, v > 0, "a finite number > 0", text)


def nonneg_float(text: str) -> float:
    v = finite_float(text)
    return _must(v, v >= 0, "a finite number >= 0", text)


def _integer(text: str) -> int:
    return _read(text, int, "an integer")


def nonneg_int(text: str) -> int:
    v = _integer(text)
    return _must(v, v >= 0, "an integer >= 0", text)


def positive_int(text: str) -> int:
    v = _integer(text)
    return _must(v, v >= 1, "an integer >= 1", text)


def _starts(text: str) -> int:
    from ..workflows.multistart import MAX_STARTS

    v = _integer(text)
    return _must(v, 1 <= v <= MAX_STARTS, f"an integer between 1 and {MAX_STARTS:,}", text)


def _epsilon(text: str) -> float:
    v = finite_float(text)
    if v < 0:
        raise argparse.ArgumentTypeError(f"{text} is negative; J_trim is a sum of squares (>= 0), so "
                                         f"J_trim <= {text} is infeasible")
    return v



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

