"""Shared fixtures and MPI hygiene (collective PETSc destroys, one printing rank)."""

from __future__ import annotations

import gc

import pytest

from valve_dolfinx._compat import MPI, PETSc


@pytest.fixture(autouse=True)
def _collective_cleanup():
    yield
    gc.collect()
    PETSc.garbage_cleanup()
    MPI.COMM_WORLD.barrier()


@pytest.fixture
def comm():
    return MPI.COMM_WORLD
