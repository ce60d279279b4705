"""Version and import differences of the FEniCSx stack, kept in one place.

The PyPI wheel ``dolfinx-solver-real`` must be imported before ``dolfinx`` and
``petsc4py`` (it loads MPI first and guards against a foreign petsc4py).  A
Debian, Spack or conda DOLFINx >= 0.10 has no such module; we then import the
stack directly.  Every module of the package imports DOLFINx/PETSc through
this one, so the ordering holds no matter which module a user imports first.

PETSc starts without its signal handlers (``-no_signal_handler``): its handler of SIGTERM
aborts the process, past Python's, where the command line ends cleanly with status 143
and records nothing unfinished (:mod:`valve_dolfinx.interrupts`).
"""

from __future__ import annotations

import importlib.metadata as _metadata
import sys

try:  # pragma: no cover - depends on how DOLFINx was installed
    import dolfinx_solver  # noqa: F401  (orders mpi4py ahead of the bindings)
except ImportError:  # pragma: no cover
    dolfinx_solver = None

from mpi4py import MPI  # noqa: E402

if "petsc4py.PETSc" not in sys.modules:  # not initialised yet by the caller
    import petsc4py

    petsc4py.init(["-no_signal_handler"])
from petsc4py import PETSc  # noqa: E402

import dolfinx  # noqa: E402
import dolfinx.fem.petsc  # noqa: E402,F401  (PETSc assembly API)

__all__ = ["MPI", "PETSc", "dolfinx", "package_versions", "MIN_DOLFINX"]

MIN_DOLFINX = (0, 10)

_version = tuple(int(p) for p in dolfinx.__version__.split(".")[:2])
if _version < MIN_DOLFINX:  # pragma: no cover
    raise ImportError(
        f"valve_dolfinx needs DOLFINx >= {MIN_DOLFINX[0]}.{MIN_DOLFINX[1]}, found "
        f"{dolfinx.__version__}. Install the wheel with `pip install dolfinx-solver-real`."
    )


def package_versions() -> dict[str, str]:
    """Versions of the packages that produced a result (written beside every result)."""
    names = [
        "valve_dolfinx",
        "dolfinx-solver-real",
        "fenics-dolfinx",
        "fenics-basix",
        "fenics-ffcx",
        "fenics-ufl",
        "petsc4py",
        "mpi4py",
        "numpy",
        "scipy",
        "gmsh",
        "pyvista",
    ]
    out = {"dolfinx": dolfinx.__version__, "petsc": ".".join(map(str, PETSc.Sys.getVersion()))}
    for name in names:
        try:
            out[name] = _metadata.version(name)
        except _metadata.PackageNotFoundError:
            continue
    return out
