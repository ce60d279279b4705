"""Logging set-up of the command line: rank 0 reports, the other ranks only their errors.

Library modules log through ``logging.getLogger(__name__)`` and never add
handlers; ``valve-dolfinx`` runs each command inside :class:`configure_logging`, and a
script that wants the same output calls it once.  Lines read::

    YYYY-MM-DD hh:mm:ss INFO    root: d0 = 17.391 mm -> d = 20.089 mm at 10.666 kPa
    YYYY-MM-DD hh:mm:ss ERROR   [rank 1/2] error: ...

the ``[rank r/n]`` tag only under MPI with more than one process.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from pathlib import Path

__all__ = ["configure_logging", "world_rank_size"]

PACKAGE = "valve_dolfinx"
FORMAT = "%(asctime)s %(levelname)-7s %(rank_tag)s%(message)s"
DATE_FORMAT = "%Y-%m-%d %H:%M:%S"

# rank and size as set by the MPI launchers (Open MPI, MPICH/Hydra, PMIx, Slurm)
_RANK_VARS = ("OMPI_COMM_WORLD_RANK", "PMIX_RANK", "PMI_RANK", "SLURM_PROCID")
_SIZE_VARS = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "SLURM_NTASKS")


def world_rank_size() -> tuple[int, int]:
    """This process's rank in ``COMM_WORLD`` and its size, without initialising MPI.

    From mpi4py once the package has loaded it; before that from the launcher's
    environment (importing mpi4py here would load MPI ahead of DOLFINx's wheel,
    see :mod:`valve_dolfinx._compat`).
    """
    mpi = sys.modules.get("mpi4py.MPI")
    if mpi is not None and mpi.Is_initialized() and not mpi.Is_finalized():
        return mpi.COMM_WORLD.rank, mpi.COMM_WORLD.size
    rank = next((os.environ[v] for v in _RANK_VARS if v in os.environ), "0")
    size = next((os.environ[v] for v in _SIZE_VARS if v in os.environ), "1")
    try:
        return int(rank), int(size)
    except ValueError:
        return 0, 1


class _RankFilter(logging.Filter):
    """Passes everything on rank 0 and only errors on the other ranks."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.levelno >= logging.ERROR or world_rank_size()[0] == 0


class _Formatter(logging.Formatter):
    """Time, level, ``[rank r/n]`` under MPI with more than one process, message."""

    def format(self, record: logging.LogRecord) -> str:
        rank, size = world_rank_size()
        record.rank_tag = f"[rank {rank}/{size}] " if size > 1 else ""
        return super().format(record)


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is when a record arrives (pytest and tqdm swap it)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


class configure_logging(contextlib.AbstractContextManager):  # noqa: N801 (used as a function)
    """Send the package's log to stderr (and append it to ``log_file``) with time and level.

    ``verbosity``: -1 warnings and errors only (``-q``), 0 progress (INFO, the
    default), 1 debug (``-v``).  Other libraries log their warnings and errors.
    Takes effect at the call and replaces an earlier call's handlers (a script
    calls it once); used as a context manager (the CLI), its handlers and levels
    are removed again on the way out.
    """

    def __init__(self, verbosity: int = 0, log_file: str | Path | None = None) -> None:
        level = {-1: logging.WARNING, 0: logging.INFO}.get(verbosity, logging.DEBUG)
        root, package = logging.getLogger(), logging.getLogger(PACKAGE)
        self._saved = root.level, package.level
        for handler in [h for h in root.handlers if getattr(h, "valve_dolfinx", False)]:
            root.removeHandler(handler)  # an earlier call's: one set of handlers at a time
            handler.close()
        self._handlers: list[logging.Handler] = [_StderrHandler()]
        if log_file is not None:
            Path(log_file).parent.mkdir(parents=True, exist_ok=True)
            self._handlers.append(logging.FileHandler(log_file, mode="a", encoding="utf-8"))
        for handler in self._handlers:
            handler.valve_dolfinx = True
            handler.setFormatter(_Formatter(FORMAT, DATE_FORMAT))
            handler.addFilter(_RankFilter())
            root.addHandler(handler)
        root.setLevel(min(logging.WARNING, root.level or logging.WARNING))
        package.setLevel(level)

    def __exit__(self, *exc) -> None:
        root = logging.getLogger()
        for handler in self._handlers:
            handler.flush()
            root.removeHandler(handler)
            handler.close()
        root.setLevel(self._saved[0])
        logging.getLogger(PACKAGE).setLevel(self._saved[1])
