"""Hand a serial :class:`ValveMesh` to DOLFINx: one manifold mesh distributed over MPI.

Gmsh runs on rank 0 only; the (small) NumPy description of the valve is then
broadcast, so every rank can look up per-cell data (flat reference
coordinates, fibres, tags) through ``mesh.topology.original_cell_index`` and
per-node data through ``mesh.geometry.input_global_indices``.  At the sizes of
this problem (10^3-10^5 triangles) the replicated description costs well under
10 MB per rank.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import basix.ufl
import numpy as np

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.geometry.domain import MembraneDomain
from valve_dolfinx.geometry.valve import (
    ValveMesh,
    ValveParameters,
    build_valve,
    reference_jacobians,
)

__all__ = ["ValveDomain", "create_valve_domain", "node_to_dof", "cell_function"]

log = logging.getLogger(__name__)


@dataclass
class ValveDomain(MembraneDomain):
    """The distributed valve: DOLFINx mesh, tags and per-cell reference data.

    Attributes
    ----------
    mesh
        Triangles in 3-D (``tdim = 2``, ``gdim = 3``) in the initial placement.
    cell_tags
        Leaflet tag per cell (:data:`~valve_dolfinx.geometry.valve.LEAFLET_TAGS`).
    facet_tags
        ``ATTACHMENT`` and ``FREE_EDGE`` edges.
    valve
        The serial description (identical on every rank).
    cell_index
        Index into ``valve.cells`` of each local cell.
    reference
        DG0 ``(3, 2)`` field J0 = d(placement)/d(flat reference coordinates).
    fibre
        DG0 ``(2,)`` unit fibre direction in flat reference coordinates.
    """

    valve: ValveMesh | None = None
    cell_index: np.ndarray | None = None

    def fibre_3d(self) -> dolfinx.fem.Function:
        """Unit fibre vectors in 3-D (DG0), J0·a normalised: for ParaView and checks."""
        values = self.valve.fibres_3d()[self.cell_index]
        return cell_function(self.mesh, values, "fibre")


def cell_function(mesh: dolfinx.mesh.Mesh, values: np.ndarray, name: str = "f"
                  ) -> dolfinx.fem.Function:
    """A DG0 function whose value on local cell ``c`` is ``values[c]`` (shape (n_cells, ...))."""
    values = np.asarray(values, dtype=dolfinx.default_scalar_type)
    shape = values.shape[1:]
    V = dolfinx.fem.functionspace(mesh, ("DG", 0, shape) if shape else ("DG", 0))
    f = dolfinx.fem.Function(V, name=name)
    n_local = mesh.topology.index_map(mesh.topology.dim).size_local
    dofs = V.dofmap.list[:n_local, 0]
    bs = V.dofmap.index_map_bs
    f.x.array.reshape(-1, bs)[dofs] = values[:n_local].reshape(n_local, bs)
    f.x.scatter_forward()
    return f


def node_to_dof(V: dolfinx.fem.FunctionSpace) -> np.ndarray:
    """Local (blocked) dof of each local geometry node, for a P1 space on a P1 mesh."""
    mesh = V.mesh
    geom = mesh.geometry.dofmaps[0]
    dofs = V.dofmap.list
    out = np.full(len(mesh.geometry.x), -1, dtype=np.int32)
    out[geom.ravel()] = dofs.ravel()
    return out


def create_valve_domain(valve: ValveMesh | ValveParameters | None = None,
                        comm: MPI.Comm = MPI.COMM_WORLD) -> ValveDomain:
    """Build (on rank 0) and distribute the valve mesh with its tags and reference data.

    ``valve`` may be a ready :class:`ValveMesh`, the :class:`ValveParameters` to
    build one, or ``None`` for the default normal valve.
    """
    if comm.rank == 0:
        if not isinstance(valve, ValveMesh):
            valve = build_valve(valve)
        valve = comm.bcast(valve.validate(), root=0)
    else:
        valve = comm.bcast(None, root=0)

    root = comm.rank == 0
    element = basix.ufl.element("Lagrange", "triangle", 1, shape=(3,))
    cells = valve.cells if root else np.empty((0, 3), dtype=np.int64)
    x = valve.points if root else np.empty((0, 3))
    mesh = dolfinx.mesh.create_mesh(comm, cells, element, x)

    tdim = mesh.topology.dim
    n_local = mesh.topology.index_map(tdim).size_local
    cell_index = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[:n_local]
    local = np.arange(n_local, dtype=np.int32)
    cell_tags = dolfinx.mesh.meshtags(mesh, tdim, local, valve.cell_tags[cell_index])
    cell_tags.name = "leaflet"

    edges = valve.edges if root else np.empty((0, 2), dtype=np.int64)
    edge_values = valve.edge_tags if root else np.empty((0,), dtype=np.int32)
    mesh.topology.create_connectivity(tdim - 1, tdim)
    entities, values = dolfinx.io.distribute_entity_data(mesh, tdim - 1, edges, edge_values)
    facet_tags = dolfinx.mesh.meshtags_from_entities(
        mesh, tdim - 1, dolfinx.graph.adjacencylist(entities), values.astype(np.int32))
    facet_tags.name = "edges"

    J0 = reference_jacobians(valve.points, valve.cells, valve.flat)[cell_index]
    reference = cell_function(mesh, J0, "reference_jacobian")
    fibre = cell_function(mesh, valve.fibres[cell_index], "fibre_flat")
    domain = ValveDomain(mesh, cell_tags, facet_tags, reference, fibre, valve, cell_index)
    if comm.rank == 0:
        log.info("distributed valve: %d cells, %d nodes on %d rank(s)", valve.num_cells,
                 valve.num_nodes, comm.size)
    return domain


def write_domain_xdmf(domain: ValveDomain, path) -> None:
    """Write mesh, leaflet tags, edge tags and 3-D fibres to XDMF (+ .h5) for ParaView."""
    from pathlib import Path

    path = Path(path).with_suffix(".xdmf")
    path.parent.mkdir(parents=True, exist_ok=True)
    mesh = domain.mesh
    with dolfinx.io.XDMFFile(domain.comm, str(path), "w") as xdmf:
        xdmf.write_mesh(mesh)
        mesh.topology.create_connectivity(mesh.topology.dim - 1, mesh.topology.dim)
        xdmf.write_meshtags(domain.cell_tags, mesh.geometry)
        xdmf.write_meshtags(domain.facet_tags, mesh.geometry)
        xdmf.write_function(domain.fibre_3d())
