"""Shared fixtures and MPI hygiene (collective PETSc destroys, one printing rank)."""

from __future__ import annotations

import gc
import logging
import signal

import pytest

from valve_dolfinx._compat import MPI, PETSc


@pytest.fixture(autouse=True)
def _collective_cleanup():
    """Under mpirun, after each test: collect the Python garbage and destroy the PETSc
    objects it held on every rank together, so no rank waits in another's destroy.  One
    process has no collective destroys to line up, and a full collection after each of
    the suite's tests costs about 0.15 s (two minutes of CPU over the serial run): Python's own
    collector is left to it there."""
    yield
    if MPI.COMM_WORLD.size > 1:
        gc.collect()
        PETSc.garbage_cleanup()
        MPI.COMM_WORLD.barrier()


@pytest.fixture
def comm():
    return MPI.COMM_WORLD


@pytest.fixture
def parallel_world():
    """COMM_WORLD for a test that compares a run on its ranks with a serial one: skipped on
    one rank, where both sides would be the same serial run (``mpirun -n 2`` runs it)."""
    if MPI.COMM_WORLD.size == 1:
        pytest.skip("compares two ranks with one: runs under mpirun -n 2")
    return MPI.COMM_WORLD


@pytest.fixture
def quiet_cli():
    """Undo what the CLI does to logging levels and SIGTERM in this process."""
    saved = {n: logging.getLogger(n).level for n in ("valve_dolfinx", "valve_dolfinx.study")}
    handler = signal.getsignal(signal.SIGTERM)
    yield
    for name, level in saved.items():
        logging.getLogger(name).setLevel(level)
    signal.signal(signal.SIGTERM, handler)
