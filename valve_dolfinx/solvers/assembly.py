"""The residual and Jacobian of a solve with hooks, as both solver paths assemble them.

The UFL forms go in first (the membrane, pressure and, per path, the mass or inertia
terms), then every hook's nodal forces or 3×3 blocks (contact, bending), then the
Dirichlet conditions.  A hook has ``add_residual(state, b)`` and ``add_jacobian(state,
A)``; its optional ``timing_name`` labels its share of the :class:`Laps`.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Sequence

import numpy as np

from valve_dolfinx._compat import PETSc, dolfinx
from valve_dolfinx.exceptions import DegenerateGeometryError

__all__ = ["Laps", "assemble_jacobian", "assemble_residual", "owned_bc_dofs"]

log = logging.getLogger(__name__)
fem_petsc = dolfinx.fem.petsc


class Laps:
    """Wall-clock seconds per named part of a solve: each call charges the time since the
    previous call (or :meth:`start`) to its name."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._last = time.perf_counter()

    def start(self) -> None:
        """Start the next lap now."""
        self._last = time.perf_counter()

    def __call__(self, name: str) -> None:
        now = time.perf_counter()
        self.seconds[name] = self.seconds.get(name, 0.0) + now - self._last
        self._last = now


def owned_bc_dofs(space: dolfinx.fem.FunctionSpace, bcs: Sequence[dolfinx.fem.DirichletBC]
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The Dirichlet dofs this rank owns: (local indices, global matrix rows in PETSc's
    integer type)."""
    imap, bs = space.dofmap.index_map, space.dofmap.index_map_bs
    local = np.concatenate([bc.dof_indices()[0] for bc in bcs] or [np.empty(0, np.int32)])
    local = local[local < imap.size_local * bs]
    return local, (imap.local_range[0] * bs + local).astype(PETSc.IntType)


def _no_laps(name: str) -> None:
    pass


def _hook_name(hook) -> str:
    return getattr(hook, "timing_name", "hooks")


def assemble_residual(F: PETSc.Vec, form: dolfinx.fem.Form, state: dolfinx.fem.Function,
                      hooks: Sequence, bcs: Sequence[dolfinx.fem.DirichletBC], X: PETSc.Vec,
                      laps: Laps | None = None, *, trial: bool = False) -> None:
    """``F`` = the form's vector plus the hooks' forces at ``state``, and ``-(X - g)`` on
    the Dirichlet dofs (so that Newton's update moves them onto their values ``g``).

    A ``trial`` state (a Newton iterate) at which a hook finds a collapsed triangle
    (:class:`DegenerateGeometryError`) is outside the residual's domain: ``F`` is then NaN,
    which ends the Newton solve as diverged (``DIVERGED_FNORM_NAN``, or a failed line
    search), and the time stepper retries the step with a shorter one, as after any failed
    solve.  (petsc4py has no binding of ``SNESSetFunctionDomainError``.)  Every rank
    evaluates the hooks on all-gathered positions, so every rank finds the collapse.  At any
    other state (an accepted one) the error is raised."""
    lap = _no_laps if laps is None else laps
    with F.localForm() as f_local:
        f_local.set(0.0)
    fem_petsc.assemble_vector(F, form)
    F.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    lap("residual_assembly")
    try:
        for hook in hooks:
            hook.add_residual(state, F)
            lap(_hook_name(hook))
    except DegenerateGeometryError as err:
        if not trial:
            raise
        log.debug("a Newton iterate is outside the residual's domain: %s", err)
        F.assemble()  # the forces the hooks before it added
        F.array[:] = np.nan
        return
    F.assemble()
    fem_petsc.set_bc(F, bcs, x0=X, alpha=-1.0)
    lap("residual_assembly")


def assemble_jacobian(J: PETSc.Mat, form: dolfinx.fem.Form, state: dolfinx.fem.Function,
                      hooks: Sequence, bcs: Sequence[dolfinx.fem.DirichletBC],
                      bc_rows: np.ndarray, laps: Laps | None = None) -> None:
    """``J`` = the form's matrix plus the hooks' blocks at ``state``, with identity rows
    ``bc_rows`` (the Dirichlet dofs this rank owns: the hooks' blocks are cleared from
    them)."""
    lap = _no_laps if laps is None else laps
    J.zeroEntries()
    fem_petsc.assemble_matrix(J, form, bcs=bcs, diag=1.0)
    J.assemble(PETSc.Mat.AssemblyType.FLUSH)
    lap("jacobian_assembly")
    for hook in hooks:
        hook.add_jacobian(state, J)
        lap(_hook_name(hook))
    J.assemble()
    if len(hooks):
        J.zeroRows(bc_rows, diag=1.0)
    lap("jacobian_assembly")
