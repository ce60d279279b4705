"""Broad phase of the contact search: nodes inside padded triangle bounding boxes.

The padded axis-aligned bounding boxes (AABBs) of the triangles are matched
against the nodes with a uniform grid built from a counting sort and prefix sums:

* the two axes along which the boxes are widest are cut into square columns
  of edge ``cell``; the third, the *sweep axis*, into thinner levels;
* each node gets the key of its cell, ``(column, level)`` in lexicographic
  order, and the nodes are sorted by it, so that the nodes of a column are
  contiguous and ordered along the sweep axis; a dense table gives the first
  node of every cell;
* a box covers a few columns, and in each of them the nodes between its two
  faces across the sweep axis form one contiguous run of the sorted nodes,
  read from the table in O(1) (sweep and prune within a column);
* the runs are walked and their nodes filtered with the exact box test, box by
  box (a loop compiled by Numba).

The work is linear in the queried nodes, the grid cells (bounded by a multiple
of the nodes and boxes), the box–column runs and the pairs; there is no Python
loop over nodes or triangles, only over blocks of :data:`BLOCK_SIZE` boxes,
which keeps the temporaries cache-sized.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numba
import numpy as np

from valve_dolfinx.contact.geometry import triangle_normals

__all__ = ["candidate_pairs", "padded_bounds", "CellGrid", "CellIndex", "BLOCK_SIZE"]

log = logging.getLogger(__name__)

#: Column edge as a multiple of the mean box width across the column axes.
#: Smaller columns mean fewer false candidates but more runs; the optimum is
#: flat between 0.75 and 1.5 on the meshes of benchmarks/contact.py.
_CELL_FACTOR = 1.0
#: The column edge is doubled until a box covers at most this many columns on
#: average, so a few large triangles cannot blow up the number of runs.
_MAX_COLUMNS_PER_BOX = 25.0
#: Cell depth along the sweep axis as a multiple of the mean box depth (the
#: runs overshoot the box by less than one cell at each end).
_STEP_FACTOR = 0.25
#: Largest grid, in cells per indexed node or box (a dense start table is kept).
_CELLS_PER_ITEM = 16
#: Boxes processed at once: bounds the temporaries at a few MB (cache-sized).
BLOCK_SIZE = 4096


def padded_bounds(xt: np.ndarray, triangles: np.ndarray, pad: float,
                  normals: np.ndarray | None = None, slack: float = 1e-9
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper corners ``(3, M)`` of padded triangle bounding boxes (mm).

    Without ``normals``: the triangles' AABBs inflated by ``pad`` on every
    side.  With the unit ``normals`` ``(3, M)``: the AABBs of the triangles'
    *contact prisms* :math:`\\{q + s\\,n : q \\in T, |s| \\le pad\\}`, i.e. inflated
    by :math:`pad\\,|n_i|` along axis ``i``, plus ``slack`` times the box size
    (for a projection test that accepts barycentric coordinates down to
    ``-slack/4``) and a rounding margin.  A prism box is much smaller than the
    padded AABB when the mesh is finer than ``pad`` and still contains every
    node whose projection falls in the triangle within ``pad``.

    ``xt`` holds the node coordinates by axis, ``(3, N)``; the result is laid
    out the same way (one contiguous row per axis), which makes the gathers
    of the box test several times faster than on ``(M, 3)`` arrays.
    """
    lo = np.empty((3, len(triangles)))
    hi = np.empty((3, len(triangles)))
    for axis in range(3):
        a, b, c = (xt[axis][triangles[:, j]] for j in range(3))
        np.minimum(np.minimum(a, b, out=lo[axis]), c, out=lo[axis])
        np.maximum(np.maximum(a, b, out=hi[axis]), c, out=hi[axis])
    if normals is None:
        return lo - pad, hi + pad
    size = (hi - lo).max(axis=0) + pad
    rounding = 1e-13 * (1.0 + float(np.abs(xt).max(initial=0.0)))
    margin = pad * np.abs(normals) + (slack * size + rounding)
    return lo - margin, hi + margin


@numba.njit(cache=True)
def include_bands(xt, triangles, band, normal, pad, lo, hi):  # pragma: no cover
    """Grow the boxes ``lo``, ``hi`` ``(3, M)`` to hold each triangle's fade band prism.

    The band of triangle ``t`` is the triangle ``{λ_j ≥ -band[t, j]}`` around it (``λ_j``
    its barycentric coordinates), whose corner ``k`` lies at
    ``Y_k = X_k + Σ_{j≠k} b_j (X_k − X_j) = (1 + Σ_j b_j) X_k − Σ_j b_j X_j``; its prism
    is swept ``±pad`` along the unit ``normal``, i.e. ``pad·|n_i|`` along axis ``i``.
    ``xt`` holds the node coordinates by axis, ``(3, N)``."""
    for t in range(triangles.shape[0]):
        b0, b1, b2 = band[t, 0], band[t, 1], band[t, 2]
        scale = 1.0 + b0 + b1 + b2
        for axis in range(3):
            x0 = xt[axis, triangles[t, 0]]
            x1 = xt[axis, triangles[t, 1]]
            x2 = xt[axis, triangles[t, 2]]
            shift = b0 * x0 + b1 * x1 + b2 * x2
            y0, y1, y2 = scale * x0 - shift, scale * x1 - shift, scale * x2 - shift
            margin = pad * abs(normal[axis, t])
            low = min(y0, y1, y2) - margin
            high = max(y0, y1, y2) + margin
            if low < lo[axis, t]:
                lo[axis, t] = low
            if high > hi[axis, t]:
                hi[axis, t] = high


@dataclass(frozen=True)
class CellGrid:
    """A grid of ``cell × cell × step`` cells: square columns along the sweep axis ``axes[2]``.

    Cell ``(i, j, l)`` covers ``[i, i+1)·cell × [j, j+1)·cell × [l, l+1)·step``
    from ``origin`` along ``axes``; its key is ``(i·shape[1] + j)·shape[2] + l``.
    Keys are monotone in each coordinate, so the nodes inside a box have, in
    each column the box covers, keys between those of the box's corners —
    one contiguous run of the nodes sorted by key.  Arrays of points and
    boxes are ``(3, K)``.
    """

    origin: np.ndarray
    cell: float
    step: float
    shape: tuple[int, int, int]
    axes: tuple[int, int, int]

    @classmethod
    def covering(cls, lo: np.ndarray, hi: np.ndarray, max_cells: int) -> CellGrid:
        """Grid over the boxes ``[lo, hi]``, sweeping along their thinnest axis.

        Columns are about ``_CELL_FACTOR`` of the mean box width, levels
        ``_STEP_FACTOR`` of the mean box depth, both coarsened (doubled) until
        a box covers at most ``_MAX_COLUMNS_PER_BOX`` columns on average and
        the grid has at most ``max_cells`` cells.
        """
        origin = lo.min(axis=1)
        span = hi.max(axis=1) - origin
        extent = hi - lo
        mean_extent = extent.mean(axis=1)
        sweep = int(np.argmin(mean_extent))
        a, b = (ax for ax in range(3) if ax != sweep)
        tiny = 1e-9 * max(float(span.max()), 1.0)
        cell = max(_CELL_FACTOR * 0.5 * float(mean_extent[a] + mean_extent[b]), tiny)
        while cell <= max(span[a], span[b]):
            columns = (np.floor(extent[a] / cell) + 2.0) * (np.floor(extent[b] / cell) + 2.0)
            if columns.mean() <= _MAX_COLUMNS_PER_BOX:
                break
            cell *= 2.0
        step = max(_STEP_FACTOR * float(mean_extent[sweep]), tiny)

        def shape_for(cell: float, step: float) -> tuple[int, int, int]:
            # same rounding as _cell_keys (floor of a quotient, not //), so that
            # the upper corner of the widest box falls in the last cell
            return (int(np.floor(span[a] / cell)) + 1, int(np.floor(span[b] / cell)) + 1,
                    int(np.floor(span[sweep] / step)) + 1)

        while np.prod(shape_for(cell, step), dtype=float) > max_cells:
            if step < cell:
                step *= 2.0
            else:
                cell *= 2.0
        return cls(origin=origin, cell=cell, step=step, shape=shape_for(cell, step),
                   axes=(a, b, sweep))

    @property
    def num_cells(self) -> int:
        return self.shape[0] * self.shape[1] * self.shape[2]

    @property
    def kernel_arguments(self) -> tuple:
        """``(origin, cell, step, shape, axes)`` as the compiled loops take them."""
        return (self.origin, self.cell, self.step, np.array(self.shape, dtype=np.int64),
                np.array(self.axes, dtype=np.int64))


@numba.njit(cache=True)
def _cell_keys(pt, origin, cell, step, shape, axes):  # pragma: no cover
    """:class:`CellGrid` key of each point ``(3, K)``, -1 for a point outside the grid.

    Cell ``i`` along an axis is ``floor((p - origin) / cell)``: the rounding of
    :func:`_box_pairs`, so that the upper corner of the widest box falls in the last cell."""
    a, b, c = axes[0], axes[1], axes[2]
    keys = np.empty(pt.shape[1], dtype=np.int64)
    for k in range(pt.shape[1]):
        qi = (pt[a, k] - origin[a]) / cell
        qj = (pt[b, k] - origin[b]) / cell
        ql = (pt[c, k] - origin[c]) / step
        if not (0.0 <= qi < shape[0] and 0.0 <= qj < shape[1] and 0.0 <= ql < shape[2]):
            keys[k] = -1  # (NaN too)
            continue
        keys[k] = ((np.int64(math.floor(qi)) * shape[1] + np.int64(math.floor(qj))) * shape[2]
                   + np.int64(math.floor(ql)))
    return keys


@numba.njit(cache=True)
def _sorted_by_cell(xt, nodes, origin, cell, step, shape, axes, num_cells):  # pragma: no cover
    """The ``nodes`` inside the grid sorted by key (a stable counting sort), their
    coordinates ``(3, S)`` in that order, and ``first`` ``(num_cells + 1,)``: the position
    of the first node of each cell or later (:class:`CellIndex`)."""
    pt = np.empty((3, len(nodes)))
    for k in range(len(nodes)):
        for axis in range(3):
            pt[axis, k] = xt[axis, nodes[k]]
    keys = _cell_keys(pt, origin, cell, step, shape, axes)
    first = np.zeros(num_cells + 1, dtype=np.int64)
    for key in keys:
        if key >= 0:
            first[key + 1] += 1
    for key in range(num_cells):
        first[key + 1] += first[key]
    fill = first[:-1].copy()
    sorted_nodes = np.empty(first[num_cells], dtype=np.int64)
    sorted_xt = np.empty((3, first[num_cells]))
    for k in range(len(nodes)):
        key = keys[k]
        if key < 0:
            continue
        position = fill[key]
        sorted_nodes[position] = nodes[k]
        for axis in range(3):
            sorted_xt[axis, position] = pt[axis, k]
        fill[key] += 1
    return sorted_nodes, sorted_xt, first


@numba.njit(cache=True)
def _box_pairs(lo, hi, origin, cell, step, shape, axes, first, sorted_nodes,
               sorted_xt):  # pragma: no cover
    """The indexed nodes inside each closed box ``[lo[:, b], hi[:, b]]`` (``(3, M)``):
    ``(node, box)`` pairs, box by box, and within a box column by column (the
    :class:`CellGrid` ``cell``/``step``/``shape``/``axes`` at ``origin``), each column's
    run of nodes between the box's two levels tested against the box.

    Every node of a run is written to the next free slot and the slot kept only if the node
    is inside the box: about two in three nodes of a run are not, at random, and a branch
    on the test would be mispredicted as often."""
    ax, bx, cx = axes[0], axes[1], axes[2]
    total = 0
    for phase in range(2):  # 0: count the run lengths, 1: test and write the pairs
        if phase == 1:
            node = np.empty(total + 1, dtype=np.int64)  # + the slot of a last rejected node
            owner = np.empty(total + 1, dtype=np.int64)
        kept = 0
        for b in range(lo.shape[1]):
            lo0, lo1, lo2 = lo[0, b], lo[1, b], lo[2, b]
            hi0, hi1, hi2 = hi[0, b], hi[1, b], hi[2, b]
            # the cell index of a corner, rounded as _cell_keys rounds
            i0 = np.int64(math.floor((lo[ax, b] - origin[ax]) / cell))
            i1 = np.int64(math.floor((hi[ax, b] - origin[ax]) / cell))
            j0 = np.int64(math.floor((lo[bx, b] - origin[bx]) / cell))
            j1 = np.int64(math.floor((hi[bx, b] - origin[bx]) / cell))
            level_lo = np.int64(math.floor((lo[cx, b] - origin[cx]) / step))
            level_hi = np.int64(math.floor((hi[cx, b] - origin[cx]) / step))
            for i in range(i0, i1 + 1):
                for j in range(j0, j1 + 1):
                    base = (i * shape[1] + j) * shape[2]
                    start, stop = first[base + level_lo], first[base + level_hi + 1]
                    if phase == 0:
                        total += stop - start
                        continue
                    for position in range(start, stop):
                        x0, x1, x2 = (sorted_xt[0, position], sorted_xt[1, position],
                                      sorted_xt[2, position])
                        inside = ((lo0 <= x0) & (x0 <= hi0) & (lo1 <= x1) & (x1 <= hi1)
                                  & (lo2 <= x2) & (x2 <= hi2))
                        node[kept], owner[kept] = sorted_nodes[position], b
                        kept += np.int64(inside)
    return node[:kept], owner[:kept]


class CellIndex:
    """The query nodes sorted by their :class:`CellGrid` keys, with a start table per cell.

    Parameters
    ----------
    xt
        ``(3, N)`` node coordinates by axis (mm).
    lo, hi
        ``(3, M)`` corners of the boxes that will be queried (they set the grid).
    nodes
        Ids of the nodes to index, distinct.
    """

    def __init__(self, xt: np.ndarray, lo: np.ndarray, hi: np.ndarray, nodes: np.ndarray) -> None:
        self.xt = xt
        self.grid = None
        self.sorted_nodes = np.empty(0, dtype=np.int64)
        if lo.shape[1] == 0 or len(nodes) == 0:
            return
        max_cells = _CELLS_PER_ITEM * (len(nodes) + lo.shape[1]) + (1 << 16)
        self.grid = CellGrid.covering(lo, hi, max_cells)
        #: the nodes sorted by key; their coordinates by axis, which the box test reads
        #: run by run; ``first[k]``: position of the first node of cell ``k`` or later
        self.sorted_nodes, self.sorted_xt, self.first = _sorted_by_cell(
            xt, np.asarray(nodes, dtype=np.int64), *self.grid.kernel_arguments,
            self.grid.num_cells)

    def box_pairs(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pairs ``(node, box)`` of indexed nodes inside the closed boxes ``[lo, hi]``, ``(3, K)``.

        Box ids are local to ``lo``/``hi``; pairs come grouped by box.
        """
        empty = np.empty(0, dtype=np.int64)
        if self.grid is None or len(self.sorted_nodes) == 0 or lo.shape[1] == 0:
            return empty, empty.copy()
        grid = self.grid
        return _box_pairs(np.ascontiguousarray(lo), np.ascontiguousarray(hi),
                          *grid.kernel_arguments, self.first, self.sorted_nodes, self.sorted_xt)

    def blocks(self, lo: np.ndarray, hi: np.ndarray) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """:meth:`box_pairs` for consecutive blocks of boxes; box ids are global.

        Blocking bounds the temporaries at ``O(BLOCK_SIZE)`` whatever the mesh
        size, which keeps them in cache and avoids page faults on large meshes.
        """
        for first in range(0, lo.shape[1], BLOCK_SIZE):
            block = slice(first, first + BLOCK_SIZE)
            node, box = self.box_pairs(lo[:, block], hi[:, block])
            yield node, box + first


def candidate_pairs(x: np.ndarray, triangles: np.ndarray, nodes: np.ndarray | None, pad: float,
                    *, prism: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Every ``(node, triangle)`` pair whose node lies in the triangle's padded AABB.

    A node at :math:`x_p` is paired with triangle ``t`` iff
    :math:`\\min_j x_{t_j} - pad \\le x_p \\le \\max_j x_{t_j} + pad` in all three
    coordinates (closed boxes; the vertices of ``t`` are paired with ``t``).

    Parameters
    ----------
    x
        ``(N, 3)`` node positions (mm).
    triangles
        ``(M, 3)`` node ids of the triangles.
    nodes
        Ids of the nodes to query (default: all), distinct.
    pad
        Inflation of the boxes (mm), ``>= 0``.
    prism
        Use the tighter boxes of the triangles' contact prisms instead (see
        :func:`padded_bounds`; the normal is :math:`(x_1 - x_0)\\times(x_2 - x_0)`).

    Returns
    -------
    node_ids, tri_ids
        Two ``(P,)`` integer arrays; each pair appears once, grouped by
        triangle (ascending), the nodes of a triangle in no particular order.
        The pairs of a node do not depend on which other nodes are queried.
    """
    x = np.asarray(x, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    nodes = np.arange(len(x)) if nodes is None else np.asarray(nodes, dtype=np.int64).ravel()
    xt = np.ascontiguousarray(x.T)
    normals = None
    if prism:
        normals, _ = triangle_normals(*(x[triangles[:, j]] for j in range(3)))
        normals = np.ascontiguousarray(normals.T)
    lo, hi = padded_bounds(xt, triangles, pad, normals)
    index = CellIndex(xt, lo, hi, nodes)
    node, tri = zip(*index.blocks(lo, hi), strict=True) if len(triangles) else ((), ())
    empty = [np.empty(0, dtype=np.int64)]
    node_ids, tri_ids = np.concatenate([*node, *empty]), np.concatenate([*tri, *empty])
    log.debug("broad phase: %d triangles, %d nodes queried, %d pairs",
              len(triangles), len(nodes), len(node_ids))
    return node_ids, tri_ids
