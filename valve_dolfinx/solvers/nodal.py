"""Nodal data across MPI ranks: gather surface positions, scatter nodal forces and blocks.

Contact is detected over the whole surface, so every rank needs every node's
position.  At valve sizes (10^3-10^5 nodes) an ``allgather`` of the owned
positions costs N·3·8 bytes per rank (240 kB at 10^4 nodes) and one
collective per evaluation -- cheaper and simpler than a ghosted halo wide
enough for contact.  Each rank then evaluates the contacts of the nodes it
*owns* and adds the resulting forces, including reactions on nodes owned by
other ranks, into the global PETSc vector/matrix; PETSc communicates the
off-process entries at assembly.  Summed over ranks this is exactly the serial
computation.

Nodes are numbered by the mesh's input order (``geometry.input_global_indices``),
i.e. like the serial arrays the mesh was built from.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from valve_dolfinx._compat import MPI, PETSc, dolfinx
from valve_dolfinx.contact.blocks import sum_blocks, summed_already
from valve_dolfinx.geometry.distributed import node_to_dof
from valve_dolfinx.solvers.matrix_rows import scalar_rows

__all__ = ["BlockPattern", "BlockRows", "NodalLayout", "NodalCoupling", "pressure_nodal_forces"]


@dataclass(frozen=True)
class NodalLayout:
    """Where a node's 3 force rows / 3 position columns sit inside a dof block.

    For a plain displacement space: block size 3, offsets 0.  For a
    displacement–velocity state (u, v) of block size 6: forces enter the
    momentum rows (offset 3) and depend on the displacement columns (offset 0).
    """

    block_size: int = 3
    row_offset: int = 0
    col_offset: int = 0


#: PETSc matrix types that store 3×3 blocks (with the plain layout's block size 3)
_BLOCK_MATRICES = (PETSc.Mat.Type.SEQBAIJ, PETSc.Mat.Type.MPIBAIJ)


class BlockRows:
    """``scale``·3×3 node blocks, sorted by row node (the blocks of a row consecutive),
    ready for insertion into a matrix (:meth:`NodalCoupling.add_csr`) as either of two
    compressed-row arrays, each made when first asked for and kept."""

    def __init__(self, coupling: NodalCoupling, rows: np.ndarray, cols: np.ndarray,
                 blocks: np.ndarray, scale: float = 1.0):
        self._coupling = coupling
        self.rows, self.cols = rows, cols
        self.blocks = np.ascontiguousarray(blocks, dtype=np.float64)
        self.scale = float(scale)

    @cached_property
    def scalar(self) -> tuple[np.ndarray, ...]:
        """One row per matrix row (:func:`~valve_dolfinx.solvers.matrix_rows.scalar_rows` at
        the coupling's global indices): (row pointer, columns, values, matrix rows), the
        columns of a row ascending."""
        row_base, col_base = self._coupling._matrix_bases
        indptr, columns, values, matrix_rows = scalar_rows(
            self.rows, self.cols, self.blocks, self.scale, row_base, col_base)
        return (indptr.astype(PETSc.IntType), columns.astype(PETSc.IntType), values,
                matrix_rows.astype(PETSc.IntType))

    @cached_property
    def blocked(self) -> tuple[np.ndarray, ...]:
        """One row per block row of a block matrix of the plain layout: (block row
        pointer, block columns, values block after block, block rows)."""
        block = self._coupling.block_of_node
        starts = np.flatnonzero(np.concatenate([[True], self.rows[1:] != self.rows[:-1]]))
        indptr = np.append(starts, len(self.rows))
        return (indptr.astype(PETSc.IntType), block[self.cols].astype(PETSc.IntType),
                (self.scale * self.blocks).ravel(), block[self.rows[starts]].astype(
                    PETSc.IntType))


class NodalCoupling:
    """Map between the mesh's nodes and a (blocked) P1 space's global PETSc indices.

    Parameters
    ----------
    space
        The P1 space of the assembled system (block size 3 or 6).
    layout
        Row/column offsets of the 3 displacement-like components in a block.
    """

    def __init__(self, space: dolfinx.fem.FunctionSpace, layout: NodalLayout = NodalLayout()):
        mesh = space.mesh
        self.comm: MPI.Comm = mesh.comm
        self.layout = layout
        bs = space.dofmap.index_map_bs
        if bs != layout.block_size:
            raise ValueError(f"space has block size {bs}, layout expects {layout.block_size}")
        imap = space.dofmap.index_map
        local_block = node_to_dof(space)  # per local geometry node
        node_id = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
        owned = local_block < imap.size_local
        global_block = imap.local_to_global(local_block.astype(np.int32))
        self.owned_nodes = node_id[owned]
        self._owned_local_block = local_block[owned]
        ids = np.concatenate(self.comm.allgather(self.owned_nodes))
        blocks = np.concatenate(self.comm.allgather(global_block[owned]))
        self.num_nodes = int(ids.max()) + 1 if len(ids) else 0
        if len(ids) != self.num_nodes or len(np.unique(ids)) != len(ids):
            raise RuntimeError("mesh nodes are not numbered 0..N-1 once each")
        self.block_of_node = np.empty(self.num_nodes, dtype=np.int64)
        self.block_of_node[ids] = blocks
        self._gather_order = ids
        x0 = mesh.geometry.x[owned]
        self.reference_positions = self._allgather_nodal(x0)

    def _allgather_nodal(self, owned_values: np.ndarray) -> np.ndarray:
        """(N, 3) array of per-node values on every rank from each rank's owned values."""
        out = np.empty((self.num_nodes, owned_values.shape[1]))
        parts = self.comm.allgather(np.ascontiguousarray(owned_values))
        out[self._gather_order] = np.concatenate(parts)
        return out

    def displacements(self, state: dolfinx.fem.Function) -> np.ndarray:
        """(N, 3) nodal displacement (the layout's column components) on every rank."""
        bs, off = self.layout.block_size, self.layout.col_offset
        blocks = state.x.array.reshape(-1, bs)
        if self.comm.size == 1:  # one gather, node by node
            return blocks[self._local_block_of_node, off:off + 3]
        return self._allgather_nodal(blocks[self._owned_local_block, off:off + 3])

    @cached_property
    def _local_block_of_node(self) -> np.ndarray:
        """``(N,)`` local dof block of every node (one process: every node is owned)."""
        out = np.empty(self.num_nodes, dtype=np.int64)
        out[self._gather_order] = self._owned_local_block
        return out

    def positions(self, state: dolfinx.fem.Function) -> np.ndarray:
        """(N, 3) current nodal positions x₀ + u on every rank."""
        return self.reference_positions + self.displacements(state)

    def vector_displacements(self, vec: PETSc.Vec) -> np.ndarray:
        """(N, 3) nodal values (the layout's column components) of a PETSc vector of the
        state space, such as a Newton update, on every rank."""
        bs, off = self.layout.block_size, self.layout.col_offset
        blocks = vec.array_r.reshape(-1, bs)
        return self._allgather_nodal(blocks[self._owned_local_block, off:off + 3])

    # --- scatter ----------------------------------------------------------------
    def add_forces(self, b: PETSc.Vec, forces: np.ndarray, scale: float = 1.0) -> None:
        """b[row(node, i)] += scale·forces[node, i] for the non-zero rows of ``forces`` (N, 3).

        Call ``b.assemble()`` afterwards (the assembly routines here do).
        """
        nodes = np.flatnonzero(np.any(forces != 0.0, axis=1))
        if len(nodes) == 0:
            return
        rows = self.row_indices(nodes)
        b.setValues(rows.ravel(), (scale * forces[nodes]).ravel(), addv=PETSc.InsertMode.ADD)

    def add_merged_blocks(self, A: PETSc.Mat, row_nodes: np.ndarray, col_nodes: np.ndarray,
                          blocks: np.ndarray, scale: float = 1.0) -> None:
        """A[rows(row_node), cols(col_node)] += scale·block for 3×3 blocks that
        :meth:`merge_blocks` has summed per (row, column) pair (:meth:`add_csr`): every
        matrix entry receives one addition, so the sums do not depend on the order of
        insertion."""
        if len(row_nodes):
            self.add_csr(A, BlockRows(self, row_nodes, col_nodes, blocks, scale))

    def merge_blocks(self, row_nodes: np.ndarray, col_nodes: np.ndarray, blocks: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The blocks summed per (row node, column node) pair, sorted by row then column,
        all-zero blocks left out (:func:`~valve_dolfinx.contact.blocks.sum_blocks`: each
        sum in the blocks' order); blocks that are so already (the contact Jacobian's,
        summed as they are computed) are returned as they are."""
        rows = np.asarray(row_nodes, dtype=np.int64)
        cols = np.asarray(col_nodes, dtype=np.int64)
        blocks = np.ascontiguousarray(blocks, dtype=np.float64).reshape(-1, 3, 3)
        if summed_already(rows, cols, blocks):
            return rows, cols, blocks
        return sum_blocks(rows, cols, blocks, self.num_nodes)

    def block_csr(self, row_nodes: np.ndarray, col_nodes: np.ndarray, blocks: np.ndarray
                  ) -> BlockRows:
        """3×3 blocks with distinct (row, column) pairs sorted by row node, to be inserted
        (:meth:`add_csr`) more than once."""
        order = np.argsort(row_nodes, kind="stable")
        return BlockRows(self, np.asarray(row_nodes, dtype=np.int64)[order],
                         np.asarray(col_nodes, dtype=np.int64)[order],
                         np.asarray(blocks, dtype=np.float64)[order])

    @cached_property
    def _matrix_bases(self) -> tuple[np.ndarray, np.ndarray]:
        """Global matrix row and column of component 0 of each node (``(N,)`` each)."""
        base = self.block_of_node * self.layout.block_size
        return base + self.layout.row_offset, base + self.layout.col_offset

    def add_csr(self, A: PETSc.Mat, blocks: BlockRows) -> None:
        """A += the blocks, one insertion per block row of a block matrix of the plain
        layout, else per matrix row (inserting block by block costs a call per block:
        ~50 ms for the valve's bending matrix)."""
        if self.layout == NodalLayout() and A.getType() in _BLOCK_MATRICES:
            indptr, columns, values, rows = blocks.blocked
            A.setValuesBlockedIJV(indptr, columns, values, addv=PETSc.InsertMode.ADD,
                                  rowmap=rows)
        else:
            indptr, columns, values, rows = blocks.scalar
            A.setValuesIJV(indptr, columns, values, addv=PETSc.InsertMode.ADD, rowmap=rows)

    def row_indices(self, nodes: np.ndarray) -> np.ndarray:
        """``(K, 3)`` global matrix rows of the nodes' three force components."""
        return (self._matrix_bases[0][nodes][:, None] + np.arange(3)).astype(PETSc.IntType)

    def col_indices(self, nodes: np.ndarray) -> np.ndarray:
        """``(K, 3)`` global matrix columns of the nodes' three position components."""
        return (self._matrix_bases[1][nodes][:, None] + np.arange(3)).astype(PETSc.IntType)


class BlockPattern:
    """The 3×3 node blocks of a one-process block matrix's sparsity pattern, grown once
    per assembly.

    A block matrix (``seqbaij``) of a plain displacement space (block size 3) whose
    assembly adds blocks outside its pattern (contact pairs that have just come close)
    reallocates its storage for each new row segment: tens of copies of the whole matrix
    per assembly on the valve.  :meth:`include`, called before an assembly with the blocks
    it will add, sets the pattern to its present one plus those blocks in one
    preallocation instead.  The pattern, and so every factorisation, is the one the
    insertions would have produced.  PETSc does not count that preallocation as a change
    of the matrix's nonzero pattern: a factorisation of the matrix must be set up anew
    after :meth:`include` has grown it.  (A matrix distributed over several processes
    grows at insertion, as PETSc does it.)

    Parameters
    ----------
    coupling
        The node ↔ index map of the matrix (one process, block size 3, offsets 0).
    """

    def __init__(self, coupling: NodalCoupling):
        if coupling.layout != NodalLayout() or coupling.comm.size != 1:
            raise ValueError("a block pattern needs one process and the plain displacement "
                             "layout")
        self.coupling = coupling
        #: sorted keys ``row block · B + column block`` of the matrix's blocks (None: not
        #: read yet)
        self.keys: np.ndarray | None = None
        #: preallocations made by :meth:`include`
        self.grown = 0

    def _read(self, A: PETSc.Mat) -> None:
        """The blocks of the (assembled) matrix's present pattern: the columns ``3c`` of its
        rows ``3b`` (the entries of a block row are its blocks')."""
        self._num_blocks = A.getSize()[1] // 3
        indptr, cols, _ = A.getValuesCSR()
        rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        first = (rows % 3 == 0) & (cols % 3 == 0)
        self.keys = rows[first] // 3 * self._num_blocks + cols[first] // 3

    def include(self, A: PETSc.Mat, row_nodes: np.ndarray, col_nodes: np.ndarray) -> bool:
        """Extend ``A``'s pattern by the blocks ``(row node, column node)`` that it lacks;
        True if it did.  The entries stay, their values do not: call it before assembling
        ``A``.  A matrix not assembled yet is left alone (its first assembly makes its
        pattern)."""
        if A.getType() != PETSc.Mat.Type.SEQBAIJ:
            raise TypeError(f"a block pattern grows a 'seqbaij' matrix, not {A.getType()!r}")
        if not A.assembled:
            return False
        if self.keys is None or A.getInfo()["nz_used"] != 9 * len(self.keys):
            self._read(A)  # first call, or blocks inserted since the last one
        block = self.coupling.block_of_node
        keys = (block[np.asarray(row_nodes, dtype=np.int64)] * self._num_blocks
                + block[np.asarray(col_nodes, dtype=np.int64)])
        found = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        new = keys[self.keys[found] != keys]
        if not len(new):
            return False
        new = np.unique(new)  # into the sorted keys (a merge, not a sort of them all)
        self.keys = np.insert(self.keys, np.searchsorted(self.keys, new), new)
        A.setPreallocationCSR(self._block_pattern())
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        self.grown += 1
        return True

    def _block_pattern(self) -> tuple[np.ndarray, np.ndarray]:
        """(block row pointer, block columns) of the blocks."""
        row_block, col_block = np.divmod(self.keys, self._num_blocks)
        indptr = np.searchsorted(row_block, np.arange(self._num_blocks + 1))
        return indptr.astype(PETSc.IntType), col_block.astype(PETSc.IntType)


def pressure_nodal_forces(x: np.ndarray, triangles: np.ndarray, pressure: float,
                          side: float = -1.0) -> np.ndarray:
    """Consistent nodal forces of a uniform follower pressure on linear triangles, (N, 3).

    ``∫ s·p·n N_i da = s·p·(a_T n_T)/3`` on each triangle (a_T its area): exact
    for P1.  ``side = -1`` pushes against the triangle normal (x1−x0)×(x2−x0),
    as the aortic pressure on the valve does.
    """
    p = x[triangles]
    area_vectors = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    f = np.zeros_like(x)
    share = (side * pressure / 3.0) * area_vectors
    for k in range(3):
        np.add.at(f, triangles[:, k], share)
    return f
