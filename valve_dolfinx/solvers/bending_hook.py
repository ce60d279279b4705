"""The bending stiffness as a solver hook: adds ``K x`` to the residual and ``K`` to the
Jacobian of a solve (:mod:`valve_dolfinx.mechanics.bending` builds ``K``)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from valve_dolfinx._compat import PETSc, dolfinx
from valve_dolfinx.solvers.nodal import BlockRows, NodalCoupling

__all__ = ["BendingHook"]


class BendingHook:
    """Adds the bending force ``−K x`` (to the residual: ``+K x``) and ``K`` to a solve.

    Same interface as :class:`~valve_dolfinx.solvers.contact_hook.ContactHook`;
    each rank adds the rows of the nodes it owns.
    """

    #: name of this hook's share in a solver's timings
    timing_name = "bending"

    def __init__(self, coupling: NodalCoupling, stiffness: sp.csr_matrix):
        self.coupling = coupling
        K = sp.csr_matrix(stiffness)
        owned = np.zeros(K.shape[0], dtype=bool)
        owned[coupling.owned_nodes] = True
        self.K_owned = sp.diags(owned.astype(float)) @ K  # rows of the owned nodes
        coo = self.K_owned.tocoo()
        keep = coo.data != 0.0
        self._rows, self._cols = coo.row[keep], coo.col[keep]
        self._values = coo.data[keep]  # the 3×3 blocks are value·I
        self._csr: BlockRows | None = None  # made on first use

    def add_residual(self, state: dolfinx.fem.Function, b: PETSc.Vec) -> None:
        x = self.coupling.positions(state)
        self.coupling.add_forces(b, self.K_owned @ x, scale=1.0)

    def coupled_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """(row nodes, column nodes) of K's blocks, for the Jacobian's sparsity pattern."""
        return self._rows, self._cols

    def add_jacobian(self, state: dolfinx.fem.Function, A: PETSc.Mat) -> None:
        """``A += K``, row by row from a CSR copy of K's 3×3 blocks made once
        (:meth:`NodalCoupling.block_csr`); the blocks are K_ij·I."""
        if self._csr is None:
            blocks = self._values[:, None, None] * np.eye(3)
            self._csr = self.coupling.block_csr(self._rows, self._cols, blocks)
        self.coupling.add_csr(A, self._csr)
