"""``pyomo-heli check-data DIR``: validate a flight-test dataset folder and summarise it."""
from __future__ import annotations

import sys

from .reader import _Reader


def check_data(path: str) -> int:
    """Print the dataset summary and return 0, or print every problem and return 2.

    Problems go to stderr, one per line, each prefixed with ``error: ``; the summary goes to
    stdout.  Bad data never produces a traceback.
    """
    try:
        reader = _Reader(path)
        ft = reader.run()
        problems = reader.problems
    except Exception as exc:  # a bug in the reader must not look like a crash on bad data
        print(f"error: {path}: could not check the dataset ({type(exc).__name__}: {exc})", file=sys.stderr)
        return 2
    if problems or ft is None:
        for p in problems:
            print(f"error: {p}", file=sys.stderr)
        return 2
    print(ft.summary())
    return 0
