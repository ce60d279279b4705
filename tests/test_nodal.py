"""Node-to-matrix scatter of the hooks: 3×3 blocks land where the node numbering says,
duplicates add up, whichever insertion path the matrix takes."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.solvers.nodal import BlockPattern, NodalCoupling, NodalLayout


def empty_matrix(size: int, block_size: int, mat_type: str) -> PETSc.Mat:
    """A ``size`` × ``size`` matrix of ``mat_type`` with room for every entry of its rows."""
    A = PETSc.Mat().create(comm=MPI.COMM_SELF)
    A.setSizes(((size, size), (size, size)), bsize=block_size)
    A.setType(mat_type)
    A.setPreallocationNNZ(size if mat_type == "aij" else size // block_size)
    return A


def add_blocks(coupling: NodalCoupling, A: PETSc.Mat, rows, cols, blocks, scale: float = 1.0):
    """A += the blocks, summed per node pair first (as the contact hook inserts them)."""
    coupling.add_merged_blocks(A, *coupling.merge_blocks(rows, cols, blocks), scale=scale)


@pytest.mark.parametrize("block_size, mat_type", [(3, "aij"), (3, "baij"), (6, "aij")])
def test_blocks_are_added_at_their_nodes(block_size, mat_type):
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
    A = empty_matrix(size, block_size, mat_type)
    add_blocks(coupling, A, rows, cols, blocks, scale=-2.0)
    A.assemble()
    expected = np.zeros((size, size))
    for r, c, b in zip(rows, cols, blocks, strict=True):
        R = block_size * coupling.block_of_node[r] + layout.row_offset
        C = block_size * coupling.block_of_node[c] + layout.col_offset
        expected[R:R + 3, C:C + 3] -= 2.0 * b
    got = A.getValues(range(size), range(size))
    assert np.max(np.abs(got - expected)) < 1e-12 * np.abs(expected).max()


def _coupling_with_block_order(block_of_node: np.ndarray) -> NodalCoupling:
    """A plain (block size 3) coupling whose node -> block map is ``block_of_node``."""
    coupling = NodalCoupling.__new__(NodalCoupling)
    coupling.layout = NodalLayout()
    coupling.block_of_node = np.asarray(block_of_node, dtype=np.int64)
    coupling.num_nodes = len(coupling.block_of_node)
    return coupling


@pytest.mark.parametrize("mat_type", ["aij", "baij"])
def test_summed_blocks_go_in_as_given_and_rows_ascend(mat_type):
    """Blocks already summed per pair (the contact Jacobian's) skip the summation: the matrix
    is the same as for the same blocks split into random parts, the caller's blocks are not
    scaled in place, and every matrix row is handed to PETSc with ascending columns although
    the node -> block map scrambles the order."""
    n = 12
    rng = np.random.default_rng(7)
    coupling = _coupling_with_block_order(rng.permutation(n))
    pairs = np.array(sorted({(int(r), int(c)) for r, c in rng.integers(0, n, (60, 2))}))
    rows, cols = pairs[:, 0], pairs[:, 1]
    blocks = rng.normal(size=(len(rows), 3, 3))
    kept = blocks.copy()

    def assembled(r, c, b):
        A = empty_matrix(3 * n, 3, mat_type)
        add_blocks(coupling, A, r, c, b, scale=-0.5)
        A.assemble()
        return A.getValues(range(3 * n), range(3 * n))

    got = assembled(rows, cols, blocks)
    assert np.array_equal(blocks, kept)
    expected = np.zeros((3 * n, 3 * n))
    for r, c, b in zip(rows, cols, blocks, strict=True):
        R, C = 3 * coupling.block_of_node[r], 3 * coupling.block_of_node[c]
        expected[R:R + 3, C:C + 3] = -0.5 * b
    assert np.array_equal(got, expected)  # one addition per entry: exact
    # the same blocks as two shuffled halves that must be summed first
    part = rng.uniform(size=(len(rows), 1, 1)) * blocks
    order = rng.permutation(2 * len(rows))
    split = (np.concatenate([rows, rows])[order], np.concatenate([cols, cols])[order],
             np.concatenate([part, blocks - part])[order])
    assert np.allclose(assembled(*split), expected, rtol=0.0, atol=1e-14)
    indptr, columns, values, matrix_rows = coupling.block_csr(rows, cols, blocks).scalar
    assert len(np.unique(matrix_rows)) == len(matrix_rows) == 3 * len(np.unique(rows))
    for a, b in zip(indptr[:-1], indptr[1:], strict=True):
        assert np.all(np.diff(columns[a:b]) > 0)


def test_block_pattern_grows_the_pattern_insertion_would_make():
    """A matrix whose pattern is grown by BlockPattern before each assembly ends with the same
    pattern and the same entries, bit for bit, as one that grows as blocks are inserted
    outside its pattern, without any reallocation; a block inserted behind the pattern's back
    is read back before the next growth, so it is kept; an unassembled matrix is left alone."""
    mesh = dolfinx.mesh.create_unit_square(MPI.COMM_SELF, 4, 3)
    V = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (3,)))
    coupling = NodalCoupling(V)
    n, size = coupling.num_nodes, 3 * coupling.num_nodes
    rng = np.random.default_rng(3)
    # a banded starting pattern (each node with its two neighbours), then three assemblies,
    # each adding it and a new random set of blocks (some inside the band, most outside)
    band = [(i, j) for i in range(n) for j in range(max(i - 1, 0), min(i + 2, n))]
    rounds = [(rng.integers(0, n, 25), rng.integers(0, n, 25), rng.normal(size=(25, 3, 3)))
              for _ in range(3)]
    taken = set(band).union(*({*zip(r.tolist(), c.tolist(), strict=True)} for r, c, _ in rounds))
    unannounced = next((i, j) for i in range(n) for j in range(n) if (i, j) not in taken)

    def run(pattern: BlockPattern | None):
        A = PETSc.Mat().createBAIJ(((size, size), (size, size)), bsize=3, nnz=3,
                                   comm=MPI.COMM_SELF)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        rows, cols = np.array(band).T
        assert pattern is None or not pattern.include(A, rows, cols)  # not assembled yet
        add_blocks(coupling, A, rows, cols, np.ones((len(rows), 3, 3)))
        A.assemble()
        mallocs = []  # reallocations while each assembly inserts
        for k, (r, c, b) in enumerate(rounds):
            if pattern is not None:
                grew = pattern.include(A, *coupling.merge_blocks(r, c, b)[:2])
                assert grew
                assert not pattern.include(A, *coupling.merge_blocks(r, c, b)[:2])
            A.zeroEntries()
            before = A.getInfo()["mallocs"]
            add_blocks(coupling, A, rows, cols, np.ones((len(rows), 3, 3)))
            add_blocks(coupling, A, r, c, b)
            if k == 1:  # a block no one announced: outside the pattern and a reallocation
                add_blocks(coupling, A, [unannounced[0]], [unannounced[1]], np.full((1, 3, 3), 2.0))
            A.assemble()
            mallocs.append(A.getInfo()["mallocs"] - before)
        return A.getValuesCSR(), mallocs

    (ip0, j0, v0), mallocs0 = run(None)
    pattern = BlockPattern(coupling)
    (ip1, j1, v1), mallocs1 = run(pattern)
    assert np.array_equal(ip0, ip1) and np.array_equal(j0, j1) and np.array_equal(v0, v1)
    assert pattern.grown == 3
    assert min(mallocs0) > 3 and mallocs1[0] == mallocs1[2] == 0 < mallocs1[1]  # unannounced
    with pytest.raises(ValueError, match="one process"):
        BlockPattern(NodalCoupling(dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (6,))),
                                   NodalLayout(6, 3, 0)))
