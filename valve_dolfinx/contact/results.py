"""Contact rows and their nodal forces, Jacobian blocks and diagnostics (SPEC §5).

A contact model (:class:`~valve_dolfinx.contact.surface.SurfaceContact`,
:class:`~valve_dolfinx.contact.planes.PlaneContact`) finds its contacts as
:class:`ContactRows` -- a node, the nodes taking the reaction, the law's force and
what its derivative needs -- and :meth:`ContactRows.result` turns them into the
:class:`ContactResult` the solver hook adds to the residual and the Jacobian.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numba
import numpy as np

from valve_dolfinx.contact.blocks import NodeBlocks, group_blocks, row_block_sums
from valve_dolfinx.contact.linearisation import row_gradients
from valve_dolfinx.exceptions import MeshError

__all__ = ["ContactResult", "ContactRows", "StepClock", "check_nodes", "check_positions",
           "group_index", "nodal_forces"]


@dataclass
class ContactResult:
    """Contact forces, their Jacobian blocks and diagnostics of one evaluation.

    Attributes
    ----------
    forces
        ``(N, 3)`` nodal contact forces (mN): on the contacting nodes and the
        reactions on the vertices of the triangles they touch.
    jac_rows, jac_cols
        ``(K,)`` node ids of the Jacobian blocks (duplicates allowed: sum them).
    jac_blocks
        ``(K, 3, 3)`` blocks :math:`\\partial\\,\\mathrm{forces}[row] / \\partial x[col]`
        (mN/mm); for a residual ``R = R_int - f_ext - forces`` subtract them from
        the Jacobian.
    n_active
        Number of contacts (node–triangle or node–plane) with ``f > 0``.
    max_penetration
        ``max(-d, 0)`` over the active contacts whose node is over the surface
        (mm; contacts fading out beyond a boundary, presence < 1/2, are not
        counted), 0.0 if none.
    total_force
        Sum of the contact force magnitudes ``f`` (mN).
    max_crossing
        How far the mid-surfaces themselves have passed through each other
        (mm): the penetration without the contact thickness, 0 while the
        contact layers only overlap (see ``ContactParameters.thickness``).
    pairs
        ``(n_active, 2)`` ``[node, triangle]`` of the active contacts;
        ``triangle = -1 - i`` for plane ``i``.
    """

    forces: np.ndarray
    jac_rows: np.ndarray
    jac_cols: np.ndarray
    jac_blocks: np.ndarray
    n_active: int
    max_penetration: float
    total_force: float
    pairs: np.ndarray
    max_crossing: float = 0.0


class StepClock:
    """Wall-clock and CPU (process) laps (s) of the steps of an evaluation, for benchmarks.

    On a loaded machine the wall-clock laps include the time spent waiting for a
    core; the CPU laps do not (they do include the kernel's page-fault work).
    """

    def __init__(self, cpu: bool = False) -> None:
        self.laps: dict[str, float] = {}
        self.cpu_laps: dict[str, float] = {}
        # process_time() is a system call (~0.1-1 ms here): only when asked for
        self._cpu = time.process_time if cpu else (lambda: 0.0)
        self._last = time.perf_counter()
        self._last_cpu = self._cpu()

    def add(self, name: str) -> None:
        """Add the time since the previous call to lap ``name``."""
        now, now_cpu = time.perf_counter(), self._cpu()
        self.laps[name] = self.laps.get(name, 0.0) + now - self._last
        self.cpu_laps[name] = self.cpu_laps.get(name, 0.0) + now_cpu - self._last_cpu
        self._last, self._last_cpu = now, now_cpu



def check_positions(x: np.ndarray, num_nodes: int, name: str) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.shape != (num_nodes, 3):
        raise MeshError(f"{name} has shape {x.shape}; expected ({num_nodes}, 3), "
                        "one row per node of the contact surface")
    if not np.isfinite(x).all():
        raise MeshError(f"{name} has non-finite entries (a diverged solve?)")
    return x


def check_nodes(nodes: np.ndarray | None, num_nodes: int) -> np.ndarray:
    if nodes is None:
        return np.arange(num_nodes, dtype=np.int64)
    nodes = np.asarray(nodes, dtype=np.int64).ravel()
    if nodes.size and (nodes.min() < 0 or nodes.max() >= num_nodes):
        raise MeshError(f"contact nodes must be ids in [0, {num_nodes}); got "
                        f"[{nodes.min()}, {nodes.max()}]")
    return nodes


@numba.njit(cache=True)
def group_index(group):  # pragma: no cover
    """``(inverse, counts)`` of non-negative labels, as ``np.unique(group, return_inverse=True,
    return_counts=True)`` gives them: each label's rank among the distinct labels, and how
    often each distinct label occurs.  Linear in the labels and their largest value (a dense
    table; the labels here are ``node · bodies + body``) instead of a sort."""
    size = 0
    for g in group:
        size = max(size, g + 1)
    rank = np.zeros(size, dtype=np.int64)
    for g in group:
        rank[g] = 1
    distinct = 0
    for g in range(size):
        if rank[g]:
            rank[g] = distinct
            distinct += 1
    inverse = np.empty(len(group), dtype=np.int64)
    counts = np.zeros(distinct, dtype=np.int64)
    for i in range(len(group)):
        inverse[i] = rank[group[i]]
        counts[inverse[i]] += 1
    return inverse, counts


@numba.njit(cache=True)
def nodal_forces(node, support, weights, normal, magnitude, num_nodes):  # pragma: no cover
    """``(N, 3)`` nodal forces of the rows: ``φ n`` on the node and ``-λ_j φ n`` on the
    triangle's vertex ``j`` (``φ`` = ``magnitude``), summed per node in the rows' order
    (as ``np.bincount`` sums)."""
    out = np.zeros((num_nodes, 3))
    m = support.shape[1] + 1
    for s in range(3):
        for i in range(len(node)):
            push = magnitude[i] * normal[i, s]
            for r in range(m):
                if r == 0:
                    out[node[i], s] += 1.0 * push
                else:
                    out[support[i, r - 1], s] += -weights[i, r - 1] * push
    return out


@dataclass(frozen=True)
class ContactRows:
    """Contact rows: a node, the nodes taking the reaction, and everything the Jacobian needs.

    Row ``i`` pushes its node with ``s_i = w_i p_i f_i`` along ``n_i`` and its
    support nodes with ``-λ_j s_i n_i``: ``f`` is the law's force (pairing
    weight included), ``p`` the row's presence (its smooth fade-in/out) and
    ``w`` the softmin blending weight of the rows of one (node, body) group,
    ``w_i ∝ p_i exp(-d_i/ε)``.
    """

    node: np.ndarray        # (A,) contacting node
    support: np.ndarray     # (A, s) nodes taking the reaction (triangle vertices; none for planes)
    weights: np.ndarray     # (A, s) reaction weights λ (barycentric coordinates)
    normal: np.ndarray      # (A, 3) unit force direction on the node
    d: np.ndarray           # (A,) signed distance (mm)
    f: np.ndarray           # (A,) law force (mN), before presence and blending
    dfdd: np.ndarray        # (A,) derivative of f w.r.t. d (mN/mm)
    partner: np.ndarray     # (A,) triangle id, or -1 - plane index
    group: np.ndarray | None = None  # (A,) contact id: blended rows of one contact share it
    blend: np.ndarray | None = None  # (A,) blending weights w (sum to 1 per group)
    blend_scale: float = 1.0         # ε of the softmin (mm)
    blend_cutoff: float = np.inf     # h (with blend): a row of presence p blends at h - p(h - d)
    presence: np.ndarray | None = None         # (A,) p in (0, 1]
    grad_log_presence: np.ndarray | None = None  # (A, 1+s, 3) ∂log p/∂x over [node, support]
    grad_f: np.ndarray | None = None  # (A, 1+s, 3) ∂f/∂x beyond f'·∇d (the driving force turning)
    #: ``(∂n/∂x_m (A, 4, 3, 3), ∂λ_j/∂x_m (A, 3, 4, 3))`` over ``[node, support]``
    #: (:func:`~valve_dolfinx.contact.linearisation.direction_derivatives`): the turning
    #: direction and the sliding contact point, for the geometric Jacobian blocks
    geometric: tuple[np.ndarray, np.ndarray] | None = None
    #: distance of the contact surface from the mid-surface (mm), for all rows or per row:
    #: d + offset is the gap between the mid-surfaces
    surface_offset: float | np.ndarray = 0.0

    def _group_presence(self, inverse: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray]:
        """``G`` of every row's group and ``c_i = Π_{j≠i}(1 - p_j)`` (``∂G/∂p_i``);
        ``inverse``: the rows' group indices, if known (:func:`group_index`'s).

        ``G = 1 - Π_j (1 - p_j)`` over the rows of a group: 1 as soon as one row
        is fully present (a node over the shared edge of two coplanar faces gets
        the full force), ``p`` for a lone row (a node sliding off a free edge
        loses its force smoothly).
        """
        p = np.ones(len(self.node)) if self.presence is None else self.presence
        if self.group is None:
            return p, np.ones(len(p))
        if inverse is None:
            inverse, _ = group_index(self.group)
        exact_one = p >= 1.0
        log_slack = np.where(exact_one, 0.0, np.log(np.maximum(1.0 - p, 1e-300)))
        total = np.bincount(inverse, log_slack)[inverse]       # Σ log(1-p) over p < 1
        ones = np.bincount(inverse, exact_one.astype(float))[inverse]
        G = np.where(ones > 0, 1.0, 1.0 - np.exp(total))
        c = np.where(ones == 0, np.exp(total - log_slack),
                     np.where((ones == 1) & exact_one, np.exp(total), 0.0))
        return G, c

    def result(self, num_nodes: int, clock: StepClock | None = None, jacobian: bool = True
               ) -> ContactResult:
        """Nodal forces and their Jacobian blocks (``clock``: laps "forces" and "jacobian").

        ``jacobian=False``: the forces and diagnostics only (no blocks).
        """
        result = self._forces(num_nodes)
        if clock is not None:
            clock.add("forces")
        if not jacobian:
            return result
        return self.with_jacobian(result, num_nodes, clock)

    def _forces(self, num_nodes: int) -> ContactResult:
        """The nodal forces and the diagnostics, without Jacobian blocks."""
        count = len(self.node)
        w = np.ones(count) if self.blend is None else self.blend
        p = np.ones(count) if self.presence is None else self.presence
        G, _ = self._group_presence()
        magnitude = w * G * self.f
        forces = nodal_forces(node=self.node, support=np.ascontiguousarray(self.support),
                              weights=np.ascontiguousarray(self.weights, dtype=np.float64),
                              normal=np.ascontiguousarray(self.normal, dtype=np.float64),
                              magnitude=magnitude, num_nodes=num_nodes)
        return self._diagnostics(forces, magnitude, p, np.empty(0, dtype=np.int64),
                                 np.empty(0, dtype=np.int64), np.empty((0, 3, 3)))

    def with_jacobian(self, result: ContactResult, num_nodes: int,
                      clock: StepClock | None = None) -> ContactResult:
        """``result`` (these rows' forces) with the Jacobian blocks of the forces added.

        Row ``i`` pushes with ``s_i = w_i G f_i``: ``f`` the law's force,
        ``w_i = p_i e^{-d_i/ε}/Σ_k p_k e^{-d_k/ε}`` the blending weight of the
        rows of its (node, body) group and ``G`` the group's presence
        (:meth:`_group_presence`).  With ``B = [1, -λ...]`` over
        ``ids = [node, support...]``, ``∇d = B⊗n`` (exact: the distance to a
        triangle's plane moves with its vertices as ``-λ_j n``),
        ``∇L = ∇log p - ∇d/ε`` and ``∇f = f'∇d + (∂f/∂F)∇F``:

        * over the row's own nodes: ``G f w(1-w) ∇L + w f c_i ∇p_i + w G ∇f``,
        * over the nodes of another row ``k`` of the group:
          ``-G f_i w_i w_k ∇L_k + w_i f_i c_k ∇p_k``,

        and the force on ``ids[r]`` is ``B_r s n``: its blocks are
        ``B_r n ⊗ ∂s/∂x_m``, plus the turning of ``n`` and the sliding of ``λ``
        (:mod:`~valve_dolfinx.contact.linearisation`, in ``geometric``).  The
        couplings between the rows of a group are summed per group over the
        distinct nodes it touches (:func:`~valve_dolfinx.contact.blocks.group_blocks`),
        not pair by pair, and all blocks summed per (row, col) node pair as they are
        computed (:func:`~valve_dolfinx.contact.blocks.row_block_sums`), from the gradients
        of :func:`~valve_dolfinx.contact.linearisation.row_gradients`.
        """
        count = len(self.node)
        w = np.ones(count) if self.blend is None else self.blend
        p = np.ones(count) if self.presence is None else self.presence
        inverse = None
        if self.group is not None:
            inverse, group_size = group_index(self.group)
        G, c = self._group_presence(inverse)
        f = self.f
        magnitude = w * G * f
        ids = np.concatenate([self.node[:, None], self.support], axis=1)         # (A, m)
        B = np.concatenate([np.ones((count, 1)), -self.weights], axis=1)
        zeros = np.zeros((count, ids.shape[1], 3))
        multi = np.empty(0, dtype=np.int64)
        if self.blend is not None and inverse is not None:
            multi = np.flatnonzero(group_size[inverse] > 1)
        in_multi = np.zeros(count, dtype=bool)
        in_multi[multi] = True
        # log w_i = log p_i + p_i (h - d_i)/ε + const (see SurfaceContact._blend_weights)
        depth = (self.blend_cutoff - self.d) / self.blend_scale if self.blend is not None \
            else np.zeros(count)
        own, Bn, wgrad_L, cgrad_p = row_gradients(
            B=B, normal=np.ascontiguousarray(self.normal),
            grad_logp=zeros if self.grad_log_presence is None else self.grad_log_presence,
            p=p, dfdd=np.ascontiguousarray(self.dfdd),
            grad_f=zeros if self.grad_f is None else self.grad_f,
            turning=self.grad_f is not None, w=w, G=G, f=f, c=c,
            blended=self.blend is not None, depth=depth, scale=self.blend_scale,
            multi=in_multi)
        m = ids.shape[1]
        coupling = NodeBlocks.empty()
        if len(multi):
            coupling = group_blocks(group=inverse[multi], ids=ids[multi], Bn=Bn[multi],
                                    alpha=-(G * f * w)[multi], beta=(w * f)[multi],
                                    U=wgrad_L[multi], V=cgrad_p[multi], num_nodes=num_nodes)
        # a row without force, force slope or driving-force turning has no blocks of its own
        # (in range of the search, out of reach of the law); it may still take part in its
        # group's coupling above
        acting = (f != 0.0) | (self.dfdd != 0.0)
        if self.grad_f is not None:
            acting |= np.any(self.grad_f != 0.0, axis=(1, 2))
        # block (r, m) = n ⊗ (B_r own_m - [r ≥ 1] φ ∂λ_{r-1}/∂x_m) + B_r φ ∂n/∂x_m, with the
        # turning direction and the sliding point (linearisation module); B_r n ⊗ own_m without
        if self.geometric is None:
            dn, dlam = np.empty((0, m, 3, 3)), np.empty((0, m - 1, m, 3))
        else:
            dn, dlam = self.geometric
        rows, cols, blocks = row_block_sums(
            live=np.flatnonzero(acting), ids=ids, B=B, normal=np.ascontiguousarray(self.normal),
            own=own, magnitude=np.ascontiguousarray(magnitude),
            geometric=self.geometric is not None, dn=np.ascontiguousarray(dn),
            dlam=np.ascontiguousarray(dlam), extra=coupling, num_nodes=num_nodes)
        if clock is not None:
            clock.add("jacobian")
        return replace(result, jac_rows=rows, jac_cols=cols, jac_blocks=blocks)

    def _diagnostics(self, forces: np.ndarray, magnitude: np.ndarray, p: np.ndarray,
                     rows: np.ndarray, cols: np.ndarray, blocks: np.ndarray) -> ContactResult:
        """The result: forces, blocks and the counts and depths of the active contacts."""
        active = magnitude > 0.0
        groups = self.group[active] if self.group is not None else None
        # a penetration is measured where the node is over the surface: rows fading out
        # beyond a boundary (presence p < 1/2, e.g. a node that has slid past a
        # neighbour's free edge) push a little but are not a crossing of that surface
        over = active & (p >= 0.5)
        return ContactResult(
            forces=forces, jac_rows=rows, jac_cols=cols, jac_blocks=blocks,
            n_active=int(active.sum()) if groups is None
            else int(np.count_nonzero(np.bincount(groups))),
            max_penetration=float(np.max(-self.d[over], initial=0.0)),
            total_force=float(magnitude.sum()),
            pairs=np.stack([self.node[active], self.partner[active]], axis=1),
            max_crossing=float(np.max(-(self.d + self.surface_offset)[over], initial=0.0)),
        )
