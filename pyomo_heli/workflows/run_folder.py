"""The results folder of one run, shared by the orchestrators (identify, the tri-objective identification,
multistart, close-loop): claim, lock, point store, front table, log, provenance and progress in one place.

A run goes through its folder in two steps::

    with RunFolder(out, "identification", cfg, restart) as run:   # log to the folder; refuse a foreign folder
        ...                                                         # (close-loop loads its data here)
        with run.locked():                                          # lock the folder; SIGINT/SIGTERM -> Interrupted
            store = run.store(fingerprint, progress)                # finished points on disk; resume from them
            front = run.front("front.csv")                          # the table of finished points, rewritten whole
            bar = run.progress_bar(total, "front points")

What each step writes or refuses (unchanged from when every orchestrator did it itself):

- entering: the package's messages are appended to ``OUT/pyomo_heli.log`` while the run lasts, and
  ``OUT/provenance.json`` is written when it ends (:func:`pyomo_heli.log.logged_run`; never into a folder the
  run refused before writing anything). A folder holding another command's results is refused with one line
  naming it and what it holds (:func:`pyomo_heli.pareto.store.claim_folder`, StoreMismatchError), whether or
  not the run restarts;
- :meth:`RunFolder.locked`: an exclusive lock on ``OUT/.pyomo-heli.lock`` (a second run on the folder is refused
  at once with one line naming the holder, FolderBusyError) and the interrupt guard
  (:mod:`pyomo_heli.interrupts`: the point being solved is never stored, finished points stay on disk);
- :meth:`RunFolder.store`: the :class:`~pyomo_heli.pareto.store.PointStore` under ``OUT/points`` guarded by the
  run's fingerprint (another fingerprint is refused unless the run restarts, which discards the points);
- :meth:`RunFolder.front`: a :class:`FrontWriter`, the CSV table of finished points rewritten after each one.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

import pandas as pd

from .. import interrupts
from ..log import Progress, config_and_dataset, get_logger, logged_run
from ..pareto.result import write_csv
from ..pareto.store import FolderLock, PointStore, claim_folder, write_checkpoint

warning = get_logger(__name__).warning


class FrontWriter:
    """The table of a run's finished points in one CSV file, rewritten whole as each point finishes (12
    significant digits, :func:`pyomo_heli.pareto.result.write_csv`), so a killed run leaves every finished
    point readable.

    fresh: remove a table left by an earlier run first (its points are read back from the store and added
    again in order). order: a column the rows are sorted by in the file (default: in the order they finished).
    """

    def __init__(self, path: str | Path, fresh: bool = True, order: str | None = None):
        self.path = Path(path)
        self.order = order
        self.rows: list[dict] = []
        if fresh and self.path.exists():
            self.path.unlink()

    def add(self, row: dict) -> None:
        """One more finished point: kept, and the whole table written."""
        self.rows.append(row)
        self.write()

    def table(self) -> pd.DataFrame:
        rows = self.rows if self.order is None else sorted(self.rows, key=lambda r: r[self.order])
        return pd.DataFrame(rows)

    def write(self, table: pd.DataFrame | None = None) -> None:
        """Write ``table`` (default: the rows so far) to the file."""
        write_csv(self.table() if table is None else table, self.path)


class RunFolder:
    """The results folder ``root`` of one run of the command that writes results of kind ``what`` (a key of
    :data:`pyomo_heli.pareto.store.KINDS`: ``identification``, ``multi-start``, ``close-loop``).

    cfg: the run's identification config (its file and dataset go into ``provenance.json``). restart: the run
    discards its own finished points (never another command's results). See the module docstring.
    """

    def __init__(self, root: str | Path, what: str, cfg=None, restart: bool = False):
        self.root = Path(root)
        self.what = what
        self.cfg = cfg
        self.restart = restart
        self._stack: contextlib.ExitStack | None = None

    def __enter__(self) -> "RunFolder":
        with contextlib.ExitStack() as stack:
            stack.enter_context(logged_run(self.root, lambda: config_and_dataset({"cfg": self.cfg})))
            claim_folder(self.root, self.what, self.restart)  # before anything is loaded or written
            self._stack = stack.pop_all()
        return self

    def __exit__(self, *exc) -> bool:
        stack, self._stack = self._stack, None
        return stack.__exit__(*exc) if stack is not None else False

    @contextlib.contextmanager
    def locked(self):
        """The folder locked for the block (created if needed) and SIGINT/SIGTERM turned into Interrupted."""
        with interrupts.guard(), FolderLock(self.root, self.what):
            yield self

    def store(self, fingerprint: str, progress=None, items: str = "point") -> PointStore:
        """The run's finished points (``OUT/points``); ``progress`` says how many are resumed, if any."""
        from ..provenance import source_sha256

        store = PointStore(self.root, fingerprint, restart=self.restart, what=self.what, source=source_sha256())
        if progress is not None and store.keys():
            progress(f"resuming: {len(store.keys())} finished {items}(s) in {store.dir}")
        if store.other_code and store.keys():
            warning(f"{store.dir}: its finished {items}s were solved by other code (the package changed since); "
                    f"they are resumed as stored: rerun with --restart for results of this code alone")
        return store

    def mark(self) -> None:
        """Write ``OUT/checkpoint.json`` naming the folder's kind (a run without a point store of its own)."""
        write_checkpoint(self.root, self.what)

    def front(self, name: str = "front.csv", fresh: bool = True, order: str | None = None) -> FrontWriter:
        """The CSV table ``OUT/name`` of finished points (:class:`FrontWriter`)."""
        return FrontWriter(self.root / name, fresh=fresh, order=order)

    @staticmethod
    def progress_bar(total: int, what: str, at_most: bool = False) -> Progress:
        """Done, elapsed and ETA of ``total`` items: as a message suffix (:class:`~pyomo_heli.log.Progress`)."""
        return Progress(total, what, at_most=at_most)
