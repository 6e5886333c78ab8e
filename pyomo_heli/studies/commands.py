"""A study's run of a ``pyomo-heli`` command, and how an interrupt ends the study.

A study loops over cases (seeds, effects) and runs a command for each. A command that fails is that case's
failure, and the study goes on with the next case. A command that was interrupted (Ctrl-C or SIGTERM: the
command ends with exit status 130, :mod:`pyomo_heli.interrupts`) is the user's stop: it must end the study, not
only the case it was in.
"""
from __future__ import annotations

import signal
import sys
from typing import Callable

from ..interrupts import EXIT_INTERRUPTED, Interrupted, guard, requested


def run_command(argv: list[str]) -> None:
    """``pyomo-heli ARGV`` in this process. Exit status 0: returns. Interrupted (130): raises :class:`Interrupted`
    (with the signal received). Any other failure (the command has printed why): raises ``SystemExit(status)``."""
    from ..cli import main as cli_main

    with guard():  # the outer guard keeps the signal the command's own guard received
        code = cli_main(argv)
        if code == EXIT_INTERRUPTED:
            raise Interrupted(requested() or signal.SIGINT)
    if code != 0:
        raise SystemExit(code)


def exit_status(main: Callable[[], int], name: str) -> int:
    """``main()``'s exit status; an interrupt ends it with one line on stderr and status 130 (no traceback)."""
    try:
        return main()
    except KeyboardInterrupt as exc:
        what = str(exc) if isinstance(exc, Interrupted) else "interrupted by SIGINT"
        print(f"{name}: {what}; rerun the same command to resume (finished cases are on disk)", file=sys.stderr)
        return EXIT_INTERRUPTED
