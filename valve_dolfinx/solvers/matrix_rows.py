"""3×3 node blocks as the rows of a compressed-row matrix: the arrays
:meth:`~valve_dolfinx.solvers.nodal.NodalCoupling.add_csr` inserts into a PETSc matrix
with one call, made by a loop compiled by Numba (a block row's few blocks put in column
order as they are written out).
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["scalar_rows"]


@numba.njit(cache=True)
def scalar_rows(rows, cols, blocks, scale, row_base, col_base):  # pragma: no cover
    """``scale``·3×3 blocks as matrix rows: ``(indptr, columns, values, rows)`` of a CSR
    with three rows per block row.

    ``rows``/``cols`` are block row/column ids, the blocks of a row consecutive;
    ``row_base[r] + p`` is the matrix row of component ``p`` of block row ``r`` and
    ``col_base[c] + q`` the column of component ``q`` of block column ``c``.  Within a
    matrix row the columns ascend (the blocks of a row put in order of ``col_base``, an
    insertion sort of the row's few blocks), which is the order a compressed-row matrix
    finds them fastest in.  Every entry of every block is written, zeros included.
    """
    n = len(rows)
    runs = 0
    for k in range(n):
        if k == 0 or rows[k] != rows[k - 1]:
            runs += 1
    indptr = np.empty(3 * runs + 1, dtype=np.int64)
    out_rows = np.empty(3 * runs, dtype=np.int64)
    columns = np.empty(9 * n, dtype=np.int64)
    values = np.empty(9 * n)
    order = np.empty(n, dtype=np.int64)
    position, r, start = 0, 0, 0
    while start < n:
        stop = start
        while stop < n and rows[stop] == rows[start]:
            key = col_base[cols[stop]]
            a = stop
            while a > start and col_base[cols[order[a - 1]]] > key:
                order[a] = order[a - 1]
                a -= 1
            order[a] = stop
            stop += 1
        for p in range(3):
            out_rows[r] = row_base[rows[start]] + p
            indptr[r] = position
            for a in range(start, stop):
                m = order[a]
                for q in range(3):
                    columns[position] = col_base[cols[m]] + q
                    values[position] = scale * blocks[m, p, q]
                    position += 1
            r += 1
        start = stop
    indptr[r] = position
    return indptr, columns, values, out_rows
