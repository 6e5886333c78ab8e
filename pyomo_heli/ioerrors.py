"""Output failures named by their path: a full disk is an I/O error of a file, never "bad input"; and what an
output folder already holds.

Python's ``OSError`` from a failed ``write`` (no space left, file too large,
an I/O error) carries no file name. :func:`writing` adds it, so the command
line can say which file could not be written (exit status 1).
"""
from __future__ import annotations

import errno
import os
from contextlib import contextmanager
from pathlib import Path

#: errno values of a failed output (not of a missing or forbidden input path): exit status 1, not 2
OUTPUT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO, errno.EROFS, errno.EPIPE,
                           errno.ENOMEM, errno.ENXIO})


class OutputError(OSError):
    """Writing ``filename`` failed (errno and strerror of the underlying OSError)."""


@contextmanager
def writing(path):
    """Re-raise an OSError without a file name as :class:`OutputError` naming ``path``."""
    try:
        yield
    except OSError as exc:
        if exc.filename is None and not isinstance(exc, OutputError):
            raise OutputError(exc.errno, exc.strerror or str(exc), str(path)) from exc
        raise


def atomic_write(path: Path, write) -> None:
    """Write ``path`` by ``write(binary file)`` through a temporary name unique to this process, then rename it (a kill
    leaves the whole file or none; two processes never share a temporary file)."""
    path = Path(path)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.tmp")
    try:
        with writing(tmp), open(tmp, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def visible_entries(folder, ignore_suffixes: tuple[str, ...] = ()) -> list[Path]:
    """The entries of ``folder`` that count as its contents, sorted: none for a new (missing) folder; hidden
    names (leading dot) and names ending in one of ``ignore_suffixes`` are left out."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(c for c in folder.iterdir() if not c.name.startswith(".") and not c.name.endswith(ignore_suffixes))
