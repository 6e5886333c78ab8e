"""Interrupt policy: a first Ctrl-C (SIGINT) or SIGTERM stops a run cleanly.

Why this is needed: Ipopt inside casadi polls Python for pending signals; with
Python's default handler the KeyboardInterrupt is swallowed by casadi and the
solve returns ``NonIpopt_Exception_Thrown``, which looks like an ordinary
failed solve. A sweep would then store the interrupted iterate as a point and
go on.

Within :func:`guard` (the command line, :func:`~pyomo_heli.workflows.identify.run_identification`,
:func:`~pyomo_heli.workflows.multistart.run_multistart`, :func:`~pyomo_heli.workflows.close_loop.close_loop`
and every solve of :class:`~pyomo_heli.solvers.casadi_ipopt.CasadiIpoptSolver`),
SIGINT and SIGTERM are recorded and raise :class:`Interrupted` where Python
code runs. A solver that returns after an interrupt raises it as well
(:func:`check`), and :class:`~pyomo_heli.pareto.store.PointStore` refuses to
save while an interrupt is pending, so an interrupted solve is never stored.
The command line ends with exit status 130 and one line saying "interrupted".

Handlers can only be installed in the main thread; elsewhere :func:`guard`
does nothing (the signals keep their current disposition).
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

#: exit status of an interrupted command (128 + SIGINT, the shell's convention)
EXIT_INTERRUPTED = 130
SIGNALS = (signal.SIGINT, signal.SIGTERM)

_received: list[int] = []  # signals received within the outermost guard
_depth = [0]


class Interrupted(KeyboardInterrupt):
    """A run stopped by SIGINT or SIGTERM. ``point``: the point being solved then, if any (it is not stored)."""

    def __init__(self, signum: int = signal.SIGINT, point: str | None = None):
        super().__init__(signum)
        self.signum = signum
        self.point = point

    @property
    def signame(self) -> str:
        try:
            return signal.Signals(self.signum).name
        except ValueError:
            return f"signal {self.signum}"

    def __str__(self) -> str:
        where = f" while solving point {self.point} (not stored)" if self.point else ""
        return f"interrupted by {self.signame}{where}"


def _handler(signum, frame):
    _received.append(signum)
    raise Interrupted(signum)


def requested() -> int | None:
    """The first signal received within the current guard, or None."""
    return _received[0] if _received else None


def check() -> None:
    """Raise :class:`Interrupted` if a signal was received within the current guard."""
    if _received:
        raise Interrupted(_received[0])


@contextmanager
def guard():
    """SIGINT and SIGTERM raise :class:`Interrupted` (and are remembered for :func:`check`) within this block.

    Re-entrant: only the outermost guard installs the handlers, clears and finally forgets the record.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if _depth[0] > 0:
        _depth[0] += 1
        try:
            yield
        finally:
            _depth[0] -= 1
        return
    _received.clear()
    # a signal the process was told to ignore (SIG_IGN, e.g. SIGINT of a background job) stays ignored
    old = {s: h for s in SIGNALS if (h := signal.getsignal(s)) is not signal.SIG_IGN}
    for s in old:
        signal.signal(s, _handler)
    _depth[0] = 1
    try:
        yield
    finally:
        _depth[0] = 0
        for s, h in old.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        _received.clear()
