"""Residual and Jacobian assembly into PETSc objects, with Dirichlet conditions and hooks.

A *hook* adds contributions that do not come from a UFL form -- the contact
forces of :mod:`valve_dolfinx.contact` -- to the assembled residual vector
and Jacobian matrix.  Hooks are objects with two methods::

    hook.add_residual(u: Function, b: PETSc.Vec) -> None   # b += hook's residual part
    hook.add_jacobian(u: Function, A: PETSc.Mat) -> None   # A += its derivative

called after the finite element assembly and before the boundary rows are
set.  They may add to any global row (off-process entries are communicated by
PETSc), and may create new non-zeros: the matrix allows it.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from valve_dolfinx._compat import PETSc, dolfinx

__all__ = ["Hook", "AssembledSystem"]

log = logging.getLogger(__name__)
fem = dolfinx.fem
fem_petsc = dolfinx.fem.petsc


class Hook(Protocol):
    def add_residual(self, u: fem.Function, b: PETSc.Vec) -> None: ...

    def add_jacobian(self, u: fem.Function, A: PETSc.Mat) -> None: ...


class AssembledSystem:
    """F(u) = 0 with Jacobian J(u): DOLFINx forms + hooks, as SNES callbacks.

    The unknown vector holds the displacement itself (not an increment); on
    Dirichlet dofs the residual is ``u − g``, DOLFINx's convention.
    """

    def __init__(self, residual, jacobian, u: fem.Function, bcs: Sequence = (),
                 hooks: Sequence[Hook] = (), jit_options: dict | None = None):
        self.u = u
        self.bcs = list(bcs)
        self.hooks = list(hooks)
        self.F_form = fem.form(residual, jit_options=jit_options)
        self.J_form = fem.form(jacobian, jit_options=jit_options)
        self.b = fem_petsc.create_vector(u.function_space)
        self.x = fem_petsc.create_vector(u.function_space)
        self.A = fem_petsc.create_matrix(self.J_form)
        self.A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        V = u.function_space
        bs = V.dofmap.index_map_bs
        imap = V.dofmap.index_map
        local_bc = np.unique(np.concatenate(
            [bc.dof_indices()[0] for bc in self.bcs] or [np.empty(0, np.int32)]))
        local_bc = local_bc[local_bc < imap.size_local * bs]
        self._bc_rows = (imap.local_range[0] * bs + local_bc).astype(PETSc.IntType)
        self.n_residual = 0
        self.n_jacobian = 0

    # --- SNES callbacks ---------------------------------------------------------
    def residual(self, snes, x: PETSc.Vec, b: PETSc.Vec) -> None:
        self.n_residual += 1
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        x.copy(self.u.x.petsc_vec)
        self.u.x.scatter_forward()
        with b.localForm() as b_local:
            b_local.set(0.0)
        fem_petsc.assemble_vector(b, self.F_form)
        fem_petsc.apply_lifting(b, [self.J_form], bcs=[self.bcs], x0=[x], alpha=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        for hook in self.hooks:
            hook.add_residual(self.u, b)
        b.assemble()
        fem_petsc.set_bc(b, self.bcs, x0=x, alpha=-1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)

    def jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        self.n_jacobian += 1
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        x.copy(self.u.x.petsc_vec)
        self.u.x.scatter_forward()
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self.J_form, bcs=self.bcs, diag=1.0)
        if self.hooks:
            A.assemble(PETSc.Mat.AssemblyType.FLUSH)
            for hook in self.hooks:
                hook.add_jacobian(self.u, A)
            A.assemble()
            # hooks may have written into Dirichlet rows: restore identity rows there
            A.zeroRows(self._bc_rows, diag=1.0)
        else:
            A.assemble()

    def residual_norm(self) -> float:
        """‖F(u)‖₂ at the current u (assembles the residual)."""
        self.u.x.petsc_vec.copy(self.x)
        self.residual(None, self.x, self.b)
        return self.b.norm()
