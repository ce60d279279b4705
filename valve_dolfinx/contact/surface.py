"""Node-to-surface penalty contact between membrane triangles (SPEC §5).

Every call to :meth:`SurfaceContact.evaluate` searches the whole surface:

1. broad phase — nodes inside the bounding boxes of the triangles' contact
   prisms (the triangle swept ``±max(h, penetration_depth)`` along its
   normal; :func:`~valve_dolfinx.contact.broadphase.padded_bounds`), found
   with a uniform grid (:class:`~valve_dolfinx.contact.broadphase.CellIndex`);
2. narrow phase — the closest point of the triangle to the node (on its face,
   or on an edge or vertex where the node's projection falls outside it) is
   within reach, the triangle is not in the node's own neighbourhood, and the
   signed distance ``d`` w.r.t. the *sided* normal satisfies
   ``-penetration_depth < d < h``;
3. one contact per (node, body): the rows of the triangles a node meets on one
   body are blended by softmin weights of their distances, each row fading in
   and out smoothly (:meth:`SurfaceContact._blend_weights`);
4. the SPEC §5 law :func:`~valve_dolfinx.contact.law.contact_force` gives the
   magnitude ``f``; the node receives ``+f n``, the triangle's vertices
   ``-λ_j f n`` (``λ`` the barycentric coordinates of the closest point), so
   that forces and moments balance.

All of it works on all candidate pairs at once -- NumPy expressions, and loops
compiled by Numba where a pair's work is a few dozen flops (the narrow phase,
:mod:`~valve_dolfinx.contact.narrowphase`; the rows' presence,
:mod:`~valve_dolfinx.contact.presence`) -- processed in blocks of triangles so
that temporaries stay cache-sized.  The work of one call is
linear in the number of candidate pairs (plus an ``S log S`` sort of the
queried nodes), and the pairs of a node depend only on that node, so the sum
of the results for disjoint node sets (one per MPI rank) is the result for
their union.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from valve_dolfinx.contact.broadphase import (
    BLOCK_SIZE,
    CellIndex,
    include_bands,
    padded_bounds,
)
from valve_dolfinx.contact.exclusions import (
    adjacent_triangles,
    merge_exclusions,
    reference_neighbours,
    seam_distances,
    triangle_halo,
)
from valve_dolfinx.contact.law import (
    DEFAULT_PARAMETERS,
    ContactParameters,
    contact_force_slope_in_F,
    law_force_from_load,
)
from valve_dolfinx.contact.linearisation import direction_derivatives, turning_load
from valve_dolfinx.contact.narrowphase import NearPairs, TriangleFrames, narrow_rows, near_pairs
from valve_dolfinx.contact.presence import RowPlanes, presence_gradients, row_presence
from valve_dolfinx.contact.results import (
    ContactResult,
    ContactRows,
    StepClock,
    check_nodes,
    check_positions,
    group_index,
)
from valve_dolfinx.contact.sides import SideMemory, nearest_inside, present_side
from valve_dolfinx.exceptions import DegenerateGeometryError, MeshError

__all__ = ["FACE_BAND", "SurfaceContact"]

log = logging.getLogger(__name__)

#: A projection counts as inside a triangle when all its barycentric
#: coordinates are >= -INSIDE_TOLERANCE.  Rounding of λ is ~1e-16·|x|/edge
#: (< 1e-13 for a 25 mm valve meshed at 0.05 mm), so 1e-10 guarantees that a
#: node right above a shared edge or vertex is caught by at least one of the
#: triangles around it, while enlarging each triangle by only 1e-10 of its size.
INSIDE_TOLERANCE = 1e-10
#: Face rows extend this far outside their triangle, in barycentric coordinates, and fade
#: out across the band: a node pressed through a sheet near its boundary then loses its
#: contact force smoothly instead of at once (a jump that makes Newton's method cycle).
FACE_BAND = 0.1
#: Slack of the contact-prism boxes of the broad phase: a point accepted with
#: barycentric coordinates >= -INSIDE_TOLERANCE lies within 2·√3·INSIDE_TOLERANCE
#: times the box size of the triangle, so 10·INSIDE_TOLERANCE keeps it in the box.
PRISM_SLACK = 10.0 * INSIDE_TOLERANCE
#: Safety margin (mm) of the lower bound on a node's distance to a triangle used to skip
#: the exact closest-point computation; far above the bound's rounding error.
_BOUND_MARGIN = 1e-6
#: A (node, triangle) pair keeps its side while the node stays over the triangle within this
#: many search distances of its plane at the accepted states (see
#: :mod:`~valve_dolfinx.contact.sides`): farther than a pseudo-time step moves a node
TRACKING_FACTOR = 2.0


def _rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.einsum("ij,ij->i", a, b)


@dataclass(frozen=True)
class _RowGeometry:
    """Per contact row, what its Jacobian terms need beyond :class:`ContactRows`: the row's
    triangle plane (:class:`~valve_dolfinx.contact.presence.RowPlanes`) and the triangle's
    barycentric gradients."""

    planes: RowPlanes
    plane_gradients: np.ndarray  # (A, 3, 3): g_j of the row's triangle, [j, axis]


class SurfaceContact:
    """Penalty contact of the nodes of a triangulated surface with its own triangles.

    Covers self-contact of one body and contact between bodies (leaflets):
    each node is tested against every triangle of the mesh except those in
    its closed edge neighbourhood (the triangles containing the node or one
    of the nodes it shares an edge with).

    **Sidedness.**  Contact only makes sense on one side of a triangle: the
    side the node comes from, remembered while the pair stays close
    (:mod:`~valve_dolfinx.contact.sides`).  Each accepted state
    (:meth:`update_history`) records the side of every pair close in it
    (the node over the triangle within ``TRACKING_FACTOR`` search distances of
    its plane, or within the law's reach of its boundary): a pair that was
    remembered keeps its side, however far the node has been pushed or pulled
    through the triangle since; a new pair takes the side its node has on an
    adjacent triangle of the same body, else the side it is on.  Between two
    records a pair that is not remembered takes the same rule at the current
    positions.  Before the first record the node comes from the side opposite
    to where its pressure force pushes it,
    :math:`s = -\\operatorname{sign}(f_{ext,p}\\cdot n_t)` (its current side
    where that is zero).  The sided normal is :math:`n = s\\,n_t` and
    :math:`d = (x_p - x_{t_0})\\cdot n`.
    The rule is the same within a leaflet and between leaflets, on either face
    of a triangle (a graft sliding below its neighbours meets their aortic
    faces): the force acts along :math:`s\\,n_t` with a non-negative
    magnitude, so a node that has not passed through a triangle is only ever
    pushed away from it, and one that has passed through is pushed back.

    **Jacobian.**  The blocks are the exact derivative of the forces for given
    external forces ``f_ext``: with :math:`B = [1, -λ_0, -λ_1, -λ_2]` over
    ``[node, t0, t1, t2]`` the distance term is
    :math:`\\partial f_p/\\partial x_q = B_p B_q\\,(\\partial f/\\partial d)\\,n\\otimes n`;
    the blocks also hold the rotation of ``n`` and the sliding of the contact
    point (``∂n/∂x``, ``∂λ/∂x``, of order ``f/ℓ`` with ``ℓ`` the edge length;
    :mod:`~valve_dolfinx.contact.linearisation`), the driving force
    ``F = -f_ext·n`` turning with ``n``, the blending weights and the presence
    fades (checked against finite differences in ``tests/test_contact_model.py``).
    Only ``∂f_ext/∂x`` is not included: the solver hook freezes ``f_ext`` within
    a step (:mod:`~valve_dolfinx.solvers.contact_hook`).  Without the geometric
    terms the Jacobian would be exact only for flat, normally loaded contact, and
    Newton's method would converge linearly on curved contact.

    Parameters
    ----------
    triangles
        ``(M, 3)`` node ids; the normal is :math:`(x_1 - x_0)\\times(x_2 - x_0)`.
    num_nodes
        Number of nodes ``N`` of the positions passed to :meth:`evaluate`.
    params
        Contact law and search parameters.
    triangle_body
        ``(M,)`` body label (leaflet tag) of each triangle (default: one body).
        A node keeps at most one contact per body, so it touches a neighbour
        leaflet once even above a shared edge, but can touch two leaflets at
        once.  Nodes shared by bodies (commissures) need no special care: the
        exclusion is topological and the grouping is by the triangle's body.
    reference, self_exclusion_radius
        ``(M, 3, D)`` vertex coordinates of every triangle in the stress-free
        state, and a radius (mm): a node never contacts the triangles of its
        own body that lie within that radius of it in the reference state.
        A sheet folded back on itself with a fold radius ρ meets itself at
        distance 2ρ across material that is πρ long, so nodes closer than
        about 1.5× the contact reach in the reference state cannot be in
        genuine self-contact; near a crease (a leaflet's V-shaped tip at the
        valve centre) they are within reach across the crease, and treating
        them as contacts makes the two sides of the crease fight.
    attached_reference, seam_taper_length
        ``(N, 3)`` node positions of the assembled, unloaded structure (the
        leaflets wrapped on the root) and a length (mm).  Bodies sewn together
        (leaflets sharing the nodes of a commissure) close next to their seam like
        the pages of a book, closer than the contact thickness: a node's contact
        thickness against another body grows linearly with its distance from
        their seam in that state, from 0 at the seam to the full thickness at
        ``seam_taper_length`` (:func:`~valve_dolfinx.contact.exclusions.seam_distances`),
        so that the layers neither fight the suture line nor let the pages pass
        through each other beside it.
    boundary_band
        Width (barycentric, i.e. in triangle heights) of the band beyond the
        surface's boundary edges over which face contacts with *other* bodies
        fade out (``FACE_BAND`` = 0.1 elsewhere).  Two leaflets coapt up to
        their free edges, which lie level with each other: with a narrow band
        a node at one free edge slides on and off the edge of its neighbour's
        surface as the edges move by a few hundredths of a millimetre, and the
        force appears and vanishes within that distance.  A band of about one
        triangle continues the neighbour's last row of faces as a plane (as
        the symmetry planes of the reference do).
    body_names
        Name of each body label, for messages (``"leaflet left_coronary"``; default
        ``"body <label>"``).

    **Collapsed triangles.**  Positions at which a triangle has collapsed
    (:data:`~valve_dolfinx.contact.geometry.COLLAPSE_TOLERANCE`) are outside the domain of
    the contact forces: :meth:`evaluate` and :meth:`update_history` raise
    :class:`~valve_dolfinx.exceptions.DegenerateGeometryError` naming the triangles and
    their bodies.
    """

    def __init__(self, triangles: np.ndarray, num_nodes: int,
                 params: ContactParameters = DEFAULT_PARAMETERS, *,
                 triangle_body: np.ndarray | None = None,
                 reference: np.ndarray | None = None,
                 self_exclusion_radius: float = 0.0,
                 attached_reference: np.ndarray | None = None,
                 seam_taper_length: float = 0.0,
                 boundary_band: float = FACE_BAND,
                 body_names: Mapping[int, str] | None = None) -> None:
        triangles = np.asarray(triangles, dtype=np.int64)
        if triangles.ndim != 2 or triangles.shape[1] != 3:
            raise MeshError(f"triangles must be an (M, 3) array of node ids, got {triangles.shape}")
        if triangles.size and (triangles.min() < 0 or triangles.max() >= num_nodes):
            raise MeshError(f"triangle node ids must lie in [0, {num_nodes}); got "
                            f"[{triangles.min()}, {triangles.max()}]")
        body = np.zeros(len(triangles), dtype=np.int64) if triangle_body is None \
            else np.asarray(triangle_body).ravel()
        if body.shape != (len(triangles),):
            raise MeshError(f"triangle_body has {body.size} labels for {len(triangles)} triangles")
        self.triangles = triangles
        self.num_nodes = int(num_nodes)
        self.params = params
        #: padding of the search: the penetration window plus the contact thickness
        self.search_distance = max(params.search_distance,
                                   params.thickness + params.penetration_depth)
        self.body_labels, self.triangle_body = np.unique(body, return_inverse=True)
        self.body_names = dict(body_names or {})
        #: body of each node: the lowest body among its triangles (commissure nodes are shared)
        self.node_body = np.full(self.num_nodes, np.iinfo(np.int64).max, dtype=np.int64)
        for k in range(3):
            np.minimum.at(self.node_body, triangles[:, k], self.triangle_body)
        #: ``(M, U)`` nodes that never contact triangle ``t``
        #: (:func:`~valve_dolfinx.contact.exclusions.triangle_halo`).
        self.excluded_nodes = triangle_halo(triangles, self.num_nodes)
        if reference is not None and self_exclusion_radius > 0.0:
            reference = np.asarray(reference, dtype=float)
            if reference.shape[:2] != (len(triangles), 3):
                raise MeshError(f"reference has shape {reference.shape}; expected "
                                f"({len(triangles)}, 3, D), the vertices of every triangle")
            extra = reference_neighbours(triangles, reference, self.triangle_body,
                                         self_exclusion_radius)
            self.excluded_nodes = merge_exclusions(self.excluded_nodes, extra)
        #: ``(N, B)`` factor on the contact thickness of each node against each body: its
        #: distance from their seam over ``seam_taper_length``, at most 1 (1 against its own)
        self.thickness_scale = np.ones((self.num_nodes, len(self.body_labels)))
        if attached_reference is not None and seam_taper_length > 0.0:
            placed = check_positions(attached_reference, self.num_nodes, "attached_reference")
            seam = seam_distances(triangles, self.triangle_body, placed, len(self.body_labels))
            self.thickness_scale = np.minimum(seam / seam_taper_length, 1.0)
        #: ``(M, 3)`` band (barycentric) beyond the side opposite each vertex over which face
        #: rows of *other* bodies fade out: ``boundary_band`` on the surface's boundary
        #: (free edges), ``FACE_BAND`` on interior sides (the neighbour takes over there)
        self.side_band = np.full((len(triangles), 3), FACE_BAND)
        if boundary_band != FACE_BAND:
            sides = np.stack([triangles[:, [1, 2]], triangles[:, [2, 0]], triangles[:, [0, 1]]],
                             axis=1).reshape(-1, 2)
            _, inverse, counts = np.unique(np.sort(sides, axis=1), axis=0, return_inverse=True,
                                           return_counts=True)
            boundary = (counts[inverse.ravel()] == 1).reshape(-1, 3)
            self.side_band[boundary] = float(boundary_band)
        #: same-body triangles around each triangle, which pass a node's side on
        self.adjacent = adjacent_triangles(triangles, self.triangle_body)
        #: sides of the pairs close at the last accepted state (None: no state recorded)
        self.memory: SideMemory | None = None
        #: ``(x, f_ext, nodes, rows, geometry, result)`` of the last forces-only evaluation
        #: (see :meth:`evaluate`)
        self._last_rows: tuple | None = None
        #: ``(x, nodes, candidates)`` of the last search (see :meth:`_candidates`)
        self._last_candidates: tuple | None = None
        #: Wall-clock seconds of the steps of the last evaluation: "broad" (grid and box
        #: queries), "narrow" (exact geometric tests, sides, windows), "forces" (blending,
        #: the law, nodal forces) and "jacobian" (all derivative blocks).
        self.timings: dict[str, float] = {}
        #: The same steps in CPU (process) time, s.
        self.cpu_timings: dict[str, float] = {}
        log.debug("surface contact: %d triangles, %d nodes, %d bodies, halo width %d",
                  len(triangles), self.num_nodes, len(self.body_labels),
                  self.excluded_nodes.shape[1])

    def update_history(self, x: np.ndarray) -> None:
        """Record an accepted state: remember the side of every pair close in it.

        A node keeps its remembered sides with a body only while it lies over that body's
        surface: where the nearest of its pairs with the body is not a face whose plane
        it projects into (beyond a free edge, or off a convex ridge), it has nothing it
        could have passed through, and its pairs with that body take the sides it is on
        now -- it may go round the free edge and meet the other face.  (They are still
        recorded, so that within the next step no side flips as the node moves.)"""
        x = check_positions(x, self.num_nodes, "x")
        xt = np.ascontiguousarray(x.T)
        frames = self._frames(xt)
        # faces within the tracking distance; edges and vertices within the law's reach (a
        # node beyond it of a triangle's boundary feels no force from it, and takes its side
        # from the adjacent faces when it slides over them)
        near = self._search(xt, frames, np.arange(self.num_nodes), StepClock(),
                            distance=TRACKING_FACTOR * self.search_distance)
        node, tri, d0, gap, _, _, plane_lam = self._narrow(xt, frames, near)
        face = np.isnan(gap)
        inside = face & (plane_lam.min(axis=1, initial=np.inf) >= -INSIDE_TOLERANCE)
        # the distance to the triangle: the plane's where the node projects into it, the
        # closest boundary point's otherwise (a face row in its band does not measure it)
        distance = np.where(inside, np.abs(d0), np.where(face, np.inf, gap))
        group = node * len(self.body_labels) + self.triangle_body[tri]
        over = nearest_inside(group, distance, inside)
        side = np.where(over, self._remembered_side(node, tri, d0), present_side(d0))
        self.memory = SideMemory.of(node, tri, side, len(self.triangles))
        self._last_rows = None

    def forget_search(self) -> None:
        """Forget the last search and rows, so that the next evaluation at the same
        positions searches afresh (what a benchmark of one evaluation times)."""
        self._last_candidates = None
        self._last_rows = None

    def clear_history(self) -> None:
        """Forget the recorded sides (they then follow the pressure direction)."""
        self.memory = None
        self._last_rows = None

    #: Record CPU (process) time laps in :attr:`cpu_timings` too (for benchmarks: each
    #: reading is a system call)
    record_cpu_time = False

    def evaluate(self, x: np.ndarray, f_ext: np.ndarray, nodes: np.ndarray | None = None,
                 jacobian: bool = True) -> ContactResult:
        """Contact forces of ``nodes`` (default: all) against the whole surface.

        Parameters
        ----------
        x, f_ext
            ``(N, 3)`` current positions (mm) and external (pressure) nodal
            forces (mN) of all nodes.
        nodes
            Distinct ids of the contacting nodes to process.  Results for
            disjoint sets sum to the result for their union: reactions on
            triangle vertices belong to the result of the contacting node.
        jacobian
            False: forces and diagnostics only, no Jacobian blocks (about three
            times cheaper).  A call with ``True`` at the same ``x``, ``f_ext``
            and ``nodes`` as the forces-only call before it (a solver that
            evaluates its residual, then its Jacobian) reuses that call's
            contact rows and adds only the blocks.
        """
        x = check_positions(x, self.num_nodes, "x")
        f_ext = check_positions(f_ext, self.num_nodes, "f_ext")
        nodes = check_nodes(nodes, self.num_nodes)
        clock = StepClock(cpu=self.record_cpu_time)
        kept = self._last_rows
        if jacobian and kept is not None and all(
                np.array_equal(a, b) for a, b in zip(kept[:3], (x, f_ext, nodes), strict=True)):
            # the Jacobian at the state of the last forces-only call (a solver's residual,
            # then its Jacobian): its rows, their geometry and forces stand, only the blocks
            # are new
            _, _, _, contacts, geometry, forces = kept
            contacts = self._jacobian_terms(x, f_ext, contacts, geometry)
            clock.add("jacobian")
            result = contacts.with_jacobian(forces, self.num_nodes, clock)
        else:
            contacts, geometry = self._find_contacts(x, f_ext, nodes, clock)
            if jacobian:
                contacts = self._jacobian_terms(x, f_ext, contacts, geometry)
                clock.add("jacobian")
            result = contacts.result(self.num_nodes, clock, jacobian=jacobian)
        self._last_rows = None if jacobian else (x.copy(), f_ext.copy(), nodes.copy(), contacts,
                                                 geometry, result)
        self.timings, self.cpu_timings = clock.laps, clock.cpu_laps
        log.debug("surface contact: %d active, max penetration %.3g mm, total force %.4g mN",
                  result.n_active, result.max_penetration, result.total_force)
        return result

    # -- steps of evaluate -------------------------------------------------------------------

    def _find_contacts(self, x: np.ndarray, f_ext: np.ndarray, nodes: np.ndarray,
                       clock: StepClock | None = None) -> tuple[ContactRows, _RowGeometry]:
        """Candidates → sides → window ``-penetration_depth < d < h`` → blend per body → law.

        Returns the contact rows (forces, no derivatives) and the geometry of each row that
        :meth:`_jacobian_terms` needs."""
        p = self.params
        clock = StepClock() if clock is None else clock
        node, tri, d0, gap, lam, offset, plane_lam, n_tri, frames = self._candidates(
            x, nodes, clock)
        s = self._side(node, tri, d0, f_ext, n_tri)
        # face contacts: signed plane distance; edge/vertex contacts: distance to the
        # closest point; each row faded in and out smoothly (its presence)
        thickness = p.thickness * self.thickness_scale[node, self.triangle_body[tri]]
        eps = p.blend_distance
        band = self._row_bands(node, tri)
        edge, d, normal, side_distance, lam_min, in_plane, presence = row_presence(
            side=s, d0=d0, gap=gap, offset=offset, plane_lam=plane_lam, plane_normal=n_tri,
            thickness=thickness, band=band, eps=eps, tapered=p.taper > 0.0, cutoff=p.cutoff)
        kept = np.flatnonzero((d > -p.penetration_depth) & (presence > 0.0))
        node, tri, d, presence, normal = (v[kept] for v in (node, tri, d, presence, normal))
        clock.add("narrow")
        blend = self._blend_weights(node, tri, d, presence)
        f, dfdd = law_force_from_load(d, f_ext[node], normal, p, thickness[kept])
        # rows with no force stay: their distance still moves the blending weights
        a = np.flatnonzero((f > 0.0) | (dfdd != 0.0) | (blend < 1.0))
        node, tri, d, presence, normal, blend, f, dfdd = (
            v[a] for v in (node, tri, d, presence, normal, blend, f, dfdd))
        rows = kept[a]  # of the candidates
        clock.add("forces")
        group = node * len(self.body_labels) + self.triangle_body[tri]
        support = self.triangles[tri]
        contacts = ContactRows(node=node, support=support, weights=lam[rows], normal=normal, d=d,
                               f=f, dfdd=dfdd, partner=tri, group=group, blend=blend,
                               blend_scale=eps, blend_cutoff=p.cutoff, presence=presence,
                               surface_offset=thickness[rows])
        planes = RowPlanes(
            edge=edge[rows], side=s[rows], normal=n_tri[rows], lam=plane_lam[rows],
            distance=d0[rows], side_distance=side_distance[rows], in_plane=in_plane[rows],
            offset=offset[rows], lam_min=lam_min[rows], band=band[rows])
        geometry = _RowGeometry(planes=planes, plane_gradients=frames.gradients(tri))
        return contacts, geometry

    def _jacobian_terms(self, x: np.ndarray, f_ext: np.ndarray, contacts: ContactRows,
                        geometry: _RowGeometry) -> ContactRows:
        """The rows with the derivatives their blocks need: of the presence, of the driving
        force and of the contact direction and point."""
        p = self.params
        eps = p.blend_distance
        node, support, lam, normal, d = (contacts.node, contacts.support, contacts.weights,
                                         contacts.normal, contacts.d)
        g = geometry
        dn, dlam = direction_derivatives(x, node, support, lam, normal, g.planes.edge,
                                         g.plane_gradients)
        B = np.concatenate([np.ones((len(node), 1)), -lam], axis=1)
        grad_logp = presence_gradients(B=B, normal=np.ascontiguousarray(normal), d=d, dlam=dlam,
                                       planes=g.planes, eps=eps, tapered=p.taper > 0.0,
                                       cutoff=p.cutoff)
        # F = -f_ext·n turns with n: ∂f/∂x += ∂f/∂F · (-(∂n/∂x)ᵀ f_ext)
        F = -np.einsum("ij,ij->i", f_ext[node], normal)
        slope = contact_force_slope_in_F(d, np.maximum(F, p.min_driving_force),
                                         p.stiffness, p.cutoff, p.taper)
        slope = np.where(F > p.min_driving_force, slope, 0.0)
        grad_f = turning_load(dn, f_ext[node], slope)
        return replace(contacts, grad_log_presence=grad_logp, grad_f=grad_f,
                       geometric=(dn, dlam))

    def _candidates(self, x: np.ndarray, nodes: np.ndarray, clock: StepClock
                    ) -> tuple[np.ndarray, ...]:
        """All (node, triangle) pairs passing the geometric tests.

        Returns ``node, tri``, the unsided distance ``d0``, the distance ``gap`` to the
        closest point, its barycentric coordinates ``(K, 3)``, the offset from it, those
        of the plane projection (:meth:`_narrow`), the triangle normals ``(K, 3)`` and the
        triangles' frames (:class:`~valve_dolfinx.contact.narrowphase.TriangleFrames`).
        They depend on the positions only: a second search at the positions of the last
        one (a solver's static residual after its step's last Newton residual, with new
        sides and driving forces) returns the arrays of the first, which are not to be
        modified.
        """
        last = self._last_candidates
        if last is not None and np.array_equal(last[0], x) and np.array_equal(last[1], nodes):
            return last[2]
        xt = np.ascontiguousarray(x.T)
        frames = self._frames(xt)
        near = self._search(xt, frames, nodes, clock)
        node, tri, d0, gap, lam, offset, plane_lam = self._narrow(xt, frames, near)
        clock.add("narrow")
        found = node, tri, d0, gap, lam, offset, plane_lam, frames.normal[:, tri].T, frames
        self._last_candidates = (x.copy(), nodes.copy(), found)
        return found

    def _frames(self, xt: np.ndarray) -> TriangleFrames:
        """The triangles' frames at the node positions ``xt`` ``(3, N)``; raises
        :class:`DegenerateGeometryError` naming the collapsed triangles, if any."""
        frames = TriangleFrames.at(xt, self.triangles)
        collapsed = np.flatnonzero(frames.collapsed)
        if len(collapsed):
            raise DegenerateGeometryError(
                f"{len(collapsed)} collapsed (zero-area) contact triangle(s): "
                + "; ".join(self._describe_triangle(t) for t in collapsed[:3])
                + ("; ..." if len(collapsed) > 3 else ""))
        return frames

    def _describe_triangle(self, t: int) -> str:
        label = int(self.body_labels[self.triangle_body[t]])
        body = self.body_names.get(label, f"body {label}")
        return f"triangle {t} (nodes {', '.join(map(str, self.triangles[t]))}) of {body}"

    def _search(self, xt: np.ndarray, frames: TriangleFrames, nodes: np.ndarray,
                clock: StepClock, distance: float | None = None) -> NearPairs:
        """Box test, then :meth:`_near`, block by block of triangles.

        ``distance`` (default: the search distance) bounds the pairs' plane distance."""
        distance = self.search_distance if distance is None else distance
        lo, hi = padded_bounds(xt, self.triangles, distance, frames.normal,
                               slack=PRISM_SLACK)
        # nodes beyond an edge or vertex, within the cut-off of it, meet the triangle too:
        # widen the prism boxes in the triangle's plane (by h·√(1 - n_i²) along axis i)
        lateral = self.params.reach * np.sqrt(np.maximum(1.0 - frames.normal**2, 0.0))
        lo -= lateral
        hi += lateral
        # face rows reach over the fade band, the triangle {λ_j ≥ -b_j}: its prism's box
        # too, corners and all, or a row whose projection lies beyond a corner is cut off
        # by the box and appears with a finite presence (a jump in the residual)
        include_bands(xt, self.triangles, self.side_band, frames.normal, distance, lo, hi)
        index = CellIndex(xt, lo, hi, nodes)
        clock.add("broad")
        found = [NearPairs(node=np.empty(0, dtype=np.int64), tri=np.empty(0, dtype=np.int64),
                           d0=np.empty(0), lam=np.empty((0, 3)), beyond=np.empty(0),
                           in_band=np.empty(0, dtype=bool))]
        for first in range(0, len(self.triangles), BLOCK_SIZE):
            block = slice(first, first + BLOCK_SIZE)
            node, tri = index.box_pairs(lo[:, block], hi[:, block])
            clock.add("broad")
            found.append(self._near(xt, frames, node, tri + first, distance))
            clock.add("narrow")
        return NearPairs(*(np.concatenate(parts) for parts in zip(*found, strict=True)))

    def _near(self, xt: np.ndarray, frames: TriangleFrames, node: np.ndarray,
              tri: np.ndarray, distance: float) -> NearPairs:
        """The cheap tests of :meth:`_narrow`: within ``distance`` of the plane, within reach
        of the triangle or in its fade band, and not in its neighbourhood
        (:func:`~valve_dolfinx.contact.narrowphase.near_pairs`)."""
        return near_pairs(node, tri, xt, frames, node_body=self.node_body,
                          triangle_body=self.triangle_body, side_band=self.side_band,
                          face_band=FACE_BAND, excluded=self.excluded_nodes,
                          search_distance=distance, reach=self.params.reach)

    def _narrow(self, xt: np.ndarray, frames: TriangleFrames, near: NearPairs
                ) -> tuple[np.ndarray, ...]:
        """Pairs within reach of the triangle, closest feature (of :meth:`_near`'s pairs).

        A node whose projection falls inside the triangle meets its face: the
        closest point is the projection, at plane distance ``d0``.  A node
        whose projection falls outside meets the closest point ``q`` on the
        triangle's boundary (an edge or a vertex) if it is within the cut-off
        of it.  Using the closest feature makes the distance to the surface,
        the contact direction and the reaction weights continuous as a node
        slides over a ridge between two triangles or off a free edge -- with
        face-only contact the force jumps there by up to the full pressure
        load, and Newton's method cycles.

        Returns ``node, tri``, the unsided plane distance ``d0 = (x_p - x_{t0})·n_t``,
        the distance ``gap`` to the closest point (``nan`` for face contacts),
        the barycentric coordinates ``(K, 3)`` of the closest point and the
        offset ``x_p - q`` ``(K, 3)``.
        """
        # face rows: the projection inside the triangle or in a thin band around it (where
        # they fade out, see _find_contacts); edge/vertex rows: the projection outside and,
        # by the lower bound √(beyond² + d0²) on the distance, possibly within reach
        return narrow_rows(near, xt, self.triangles, frames.normal, reach=self.params.reach,
                           bound=self.params.reach + _BOUND_MARGIN,
                           inside_tolerance=INSIDE_TOLERANCE)

    def _row_bands(self, node: np.ndarray, tri: np.ndarray) -> np.ndarray:
        """``(K, 3)`` fade bands of face rows: wide beyond another body's free edge."""
        other = self.node_body[node] != self.triangle_body[tri]
        return np.where(other[:, None], self.side_band[tri], FACE_BAND)

    def _side(self, node: np.ndarray, tri: np.ndarray, d0: np.ndarray, f_ext: np.ndarray,
              n_tri: np.ndarray) -> np.ndarray:
        """Side ``s = ±1`` of each node w.r.t. each triangle (see the class docstring):
        remembered, passed on from an adjacent triangle, or the node's present side; before
        any recorded state, opposite to the node's pressure force."""
        if self.memory is None:
            from_pressure = -np.sign(_rowdot(f_ext[node], n_tri))
            return np.where(from_pressure != 0.0, from_pressure, present_side(d0))
        return self._remembered_side(node, tri, d0)

    def _remembered_side(self, node: np.ndarray, tri: np.ndarray, d0: np.ndarray
                         ) -> np.ndarray:
        """The memory's side of each pair (:meth:`SideMemory.lookup`), else the side of the
        triangle's plane the node is on (``d0``, its unsided plane distance)."""
        if self.memory is None:
            return present_side(d0)
        side = self.memory.lookup(node, tri, self.adjacent)
        return np.where(side != 0, side.astype(float), present_side(d0))

    def _blend_weights(self, node: np.ndarray, tri: np.ndarray, d: np.ndarray,
                       presence: np.ndarray | None = None) -> np.ndarray:
        """Weights blending the candidate triangles of each (node, body) into one contact.

        ``w_i ∝ exp(-(d_i - min d)/ε)``, normalised per (node, body), with
        ``ε`` = :attr:`ContactParameters.blend_distance`.  The same contact seen
        through a shared edge or vertex (equal distances) is counted once; a node
        in a crease of a folded sheet, which projects into two faces at an
        angle, feels a force whose direction turns continuously from one face's
        normal to the other's as its distances to them cross.  Keeping only the
        nearest face makes that direction jump, and Newton's method cycles.

        A row of presence ``p < 1`` blends at the distance ``h − p·(h − d)``
        (``h`` the cut-off), i.e. ``w ∝ p·e^{p(h − d)/ε}``: as a row fades out it
        also recedes towards the cut-off.  With ``p e^{-d/ε}`` alone a deep row
        that is fading out (a node far behind the extended plane of a neighbour's
        triangle it has slid past) would outweigh the present rows by ``e^{Δd/ε}``
        until its presence is ~1e-8 and then vanish within ~1e-5 mm: a jump of
        several mN in the node's force (6 mN at the triple point of the normal
        valve meshed at 0.8 mm, 10 mN on a graft) that no solver settles.  Fully
        present rows (``p = 1``) blend as ``e^{-d/ε}``.
        """
        group = node * len(self.body_labels) + self.triangle_body[tri]
        inverse, _ = group_index(group)
        # the signed distance orders the surfaces from the most penetrated to the farthest;
        # |d| would put a penetration and a gap of the same size on a par, and has a kink
        if presence is not None:
            h = self.params.cutoff
            d = h - presence * (h - d)
        nearest = np.full(inverse.max(initial=-1) + 1, np.inf)
        np.minimum.at(nearest, inverse, d)
        w = np.exp(-(d - nearest[inverse]) / self.params.blend_distance)
        if presence is not None:
            w = w * presence
        total = np.bincount(inverse, w)[inverse]
        return np.divide(w, total, out=np.zeros_like(w), where=total > 0.0)
