"""Node-to-matrix scatter of the hooks: 3×3 blocks land where the node numbering says,
duplicates add up, whichever insertion path the matrix takes."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.solvers.nodal import NodalCoupling, NodalLayout


@pytest.mark.parametrize("block_size", [3, 6])
def test_blocks_are_added_at_their_nodes(block_size):
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 3, 4)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (block_size,)))
    layout = NodalLayout() if block_size == 3 else NodalLayout(6, 3, 0)
    coupling = NodalCoupling(V, layout)
    # the node -> block map itself, against DOLFINx's own dof coordinates: the block of
    # node i holds node i's position once x is interpolated into the space
    where = dolfinx.fem.Function(V)
    where.interpolate(lambda x: np.vstack([x] * (block_size // 3)))
    positions = where.x.array.reshape(-1, block_size)[coupling.block_of_node, :3]
    assert np.allclose(positions, coupling.reference_positions, atol=1e-14)
    assert len(np.unique(positions[:, :2], axis=0)) == coupling.num_nodes
    n, size = coupling.num_nodes, block_size * coupling.num_nodes
    rng = np.random.default_rng(1)
    rows, cols = rng.integers(0, n, 300), rng.integers(0, n, 300)  # many duplicates
    blocks = rng.normal(size=(300, 3, 3))
    A = PETSc.Mat().createAIJ(((size, size), (size, size)), bsize=block_size,
                              comm=MPI.COMM_SELF)
    A.setPreallocationNNZ(size)
    coupling.add_blocks(A, rows, cols, blocks, scale=-2.0)
    A.assemble()
    expected = np.zeros((size, size))
    for r, c, b in zip(rows, cols, blocks, strict=True):
        R = block_size * coupling.block_of_node[r] + layout.row_offset
        C = block_size * coupling.block_of_node[c] + layout.col_offset
        expected[R:R + 3, C:C + 3] -= 2.0 * b
    got = A.getValues(range(size), range(size))
    assert np.max(np.abs(got - expected)) < 1e-12 * np.abs(expected).max()
