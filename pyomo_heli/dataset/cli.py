"""``pyomo-heli check-data DIR``: validate a flight-test dataset folder and summarise it."""
from __future__ import annotations

import sys

from .reader import _Reader


def check_data(path: str) -> int:
    """Print the dataset summary and return 0, or print every problem and return 2.

    Problems go to stderr, one per line, each prefixed with ``error: ``; the summary goes to
    stdout.  Bad data never produces a traceback; an exception is a bug of the reader, and the command line
    reports it as an internal error (exit 1), not as a problem of the data.
    """
    reader = _Reader(path)
    ft = reader.run()
    problems = reader.problems
    if problems or ft is None:
        for p in problems:
            print(f"error: {p}", file=sys.stderr)
        return 2
    print(ft.summary())
    return 0
