"""Membranes with exact solutions: a closed sphere, a closed-end tube (capsule), a flat sheet.

The reference (stress-free) configuration of these meshes is the mesh itself.
Each cell's reference chart is an orthonormal tangent frame (e1, e2) of the
triangle, oriented so that e1 × e2 is the outward normal, so J0 = [e1 e2] and
lengths in the chart are true lengths.
"""

from __future__ import annotations

import logging
import math

import basix.ufl
import gmsh
import numpy as np

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.exceptions import MeshError
from valve_dolfinx.geometry.distributed import cell_function
from valve_dolfinx.geometry.domain import MembraneDomain
from valve_dolfinx.interrupts import reclaim_signals

__all__ = [
    "sphere_domain",
    "capsule_domain",
    "flat_sheet_domain",
    "membrane_domain_from_arrays",
    "tangent_frames",
    "CAP_TAG",
    "TUBE_TAG",
]

log = logging.getLogger(__name__)

TUBE_TAG = 1
CAP_TAG = 2


def tangent_frames(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-cell orthonormal tangent frames J0 = [e1 e2] ``(M, 3, 2)`` and unit normals."""
    p = points[cells]
    e1 = p[:, 1] - p[:, 0]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    e2 = np.cross(n, e1)
    return np.stack([e1, e2], axis=2), n


def chart_direction(frames: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Chart components (unit) of 3-D tangent directions ``t`` ``(M, 3)``."""
    a = np.einsum("mik,mi->mk", frames, t)
    norm = np.linalg.norm(a, axis=1, keepdims=True)
    if np.any(norm < 1e-8):
        raise MeshError("a requested fibre direction is normal to a cell")
    return a / norm


def membrane_domain_from_arrays(comm: MPI.Comm, points: np.ndarray, cells: np.ndarray,
                                cell_tags: np.ndarray, reference: np.ndarray,
                                fibres: np.ndarray) -> MembraneDomain:
    """Distribute a triangle surface given on rank 0 (other ranks' arrays are ignored).

    ``reference`` ``(M, 3, 2)`` and ``fibres`` ``(M, 2)`` are per-cell data in
    the input cell order; they are broadcast and looked up by original index.
    """
    root = comm.rank == 0
    reference, fibres, cell_tags = comm.bcast((reference, fibres, cell_tags) if root else None)
    element = basix.ufl.element("Lagrange", "triangle", 1, shape=(3,))
    mesh = dolfinx.mesh.create_mesh(comm, cells if root else np.empty((0, 3), np.int64), element,
                                    points if root else np.empty((0, 3)))
    tdim = mesh.topology.dim
    n_local = mesh.topology.index_map(tdim).size_local
    index = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[:n_local]
    tags = dolfinx.mesh.meshtags(mesh, tdim, np.arange(n_local, dtype=np.int32),
                                 np.asarray(cell_tags, dtype=np.int32)[index])
    mesh.topology.create_entities(tdim - 1)
    facets = dolfinx.mesh.meshtags(mesh, tdim - 1, np.empty(0, np.int32), np.empty(0, np.int32))
    return MembraneDomain(mesh, tags, facets, cell_function(mesh, reference[index], "reference"),
                          cell_function(mesh, fibres[index], "fibre"))


def _gmsh_surface(build, mesh_size: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run ``build()`` (adds OCC entities and returns {surface tag: cell tag}) and mesh it."""
    initialised_here = not gmsh.isInitialized()
    if initialised_here:
        gmsh.initialize(interruptible=False)
        reclaim_signals()  # Gmsh installs its own SIGTERM handler
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.add(f"verification_{id(build)}")
        surface_tags = build()
        gmsh.model.occ.synchronize()
        gmsh.option.setNumber("Mesh.MeshSizeMin", mesh_size)
        gmsh.option.setNumber("Mesh.MeshSizeMax", mesh_size)
        gmsh.option.setNumber("Mesh.Algorithm", 6)
        gmsh.model.mesh.generate(2)
        gmsh.model.mesh.removeDuplicateNodes()
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        index = np.zeros(int(node_tags.max()) + 1, dtype=np.int64)
        index[node_tags.astype(np.int64)] = np.arange(len(node_tags))
        points = coords.reshape(-1, 3)
        cells, tags = [], []
        for surf, tag in surface_tags.items():
            types, _, nodes = gmsh.model.mesh.getElements(2, surf)
            tri = index[nodes[list(types).index(2)].astype(np.int64)].reshape(-1, 3)
            cells.append(tri)
            tags.append(np.full(len(tri), tag, dtype=np.int32))
        gmsh.model.remove()
    finally:
        if initialised_here:
            gmsh.finalize()
    cells = np.concatenate(cells)
    used = np.unique(cells)
    renumber = np.full(len(points), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    return points[used], renumber[cells], np.concatenate(tags)


def _orient_outward(points: np.ndarray, cells: np.ndarray, outward: np.ndarray) -> np.ndarray:
    """Flip triangles whose normal points against ``outward`` (per-cell reference vectors)."""
    p = points[cells]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", n, outward) < 0
    cells = cells.copy()
    cells[flip, 1], cells[flip, 2] = cells[flip, 2], cells[flip, 1].copy()
    return cells


def sphere_domain(radius: float = 10.0, mesh_size: float = 1.0,
                  comm: MPI.Comm = MPI.COMM_WORLD) -> MembraneDomain:
    """Closed sphere centred at the origin, charts with outward normals (tag 1)."""
    data = None
    if comm.rank == 0:
        def build():
            gmsh.model.occ.addSphere(0, 0, 0, radius)
            gmsh.model.occ.synchronize()
            return {s[1]: TUBE_TAG for s in gmsh.model.getEntities(2)}

        points, cells, tags = _gmsh_surface(build, mesh_size)
        cells = _orient_outward(points, cells, points[cells].mean(axis=1))
        frames, _ = tangent_frames(points, cells)
        fibres = np.tile([1.0, 0.0], (len(cells), 1))
        data = (points, cells, tags, frames, fibres)
    return _distribute(comm, data)


def capsule_domain(radius: float = 5.0, length: float = 30.0, mesh_size: float = 1.0,
                   fibre: str = "circumferential", comm: MPI.Comm = MPI.COMM_WORLD
                   ) -> MembraneDomain:
    """Closed-end tube: a cylinder of ``length`` along z capped by hemispheres.

    Cells of the cylinder carry tag :data:`TUBE_TAG`, of the caps
    :data:`CAP_TAG`.  Fibres run ``"circumferential"`` (e_θ) or ``"axial"``
    (e_z) on the tube and along the parallels on the caps.
    """
    if fibre not in ("circumferential", "axial"):
        raise ValueError(f"fibre = {fibre!r}: choose 'circumferential' or 'axial'")
    data = None
    if comm.rank == 0:
        def build():
            occ = gmsh.model.occ
            cyl = occ.addCylinder(0, 0, -length / 2, 0, 0, length, radius)
            s1 = occ.addSphere(0, 0, -length / 2, radius)
            s2 = occ.addSphere(0, 0, length / 2, radius)
            occ.fuse([(3, cyl)], [(3, s1), (3, s2)])
            occ.synchronize()
            out = {}
            for _, s in gmsh.model.getEntities(2):
                z = gmsh.model.occ.getCenterOfMass(2, s)[2]
                out[s] = TUBE_TAG if abs(z) < length / 2 - 1e-6 else CAP_TAG
            return out

        points, cells, tags = _gmsh_surface(build, mesh_size)
        c = points[cells].mean(axis=1)
        axis_point = np.zeros_like(c)
        axis_point[:, 2] = np.clip(c[:, 2], -length / 2, length / 2)
        cells = _orient_outward(points, cells, c - axis_point)
        frames, _ = tangent_frames(points, cells)
        c = points[cells].mean(axis=1)
        e_theta = np.stack([-c[:, 1], c[:, 0], np.zeros(len(c))], axis=1)
        e_theta /= np.linalg.norm(e_theta, axis=1, keepdims=True)
        direction = e_theta.copy()
        if fibre == "axial":
            direction[tags == TUBE_TAG] = [0.0, 0.0, 1.0]
        data = (points, cells, tags, frames, chart_direction(frames, direction))
    return _distribute(comm, data)


def flat_sheet_domain(lx: float = 4.0, ly: float = 3.0, nx: int = 8, ny: int = 6,
                      fibre_angle_deg: float = 0.0, comm: MPI.Comm = MPI.COMM_WORLD
                      ) -> MembraneDomain:
    """Structured triangulation of [0, lx]×[0, ly] in the plane z = 0 (normal +z)."""
    data = None
    if comm.rank == 0:
        xs, ys = np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1), indexing="ij")
        points = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
        idx = np.arange(points.shape[0]).reshape(nx + 1, ny + 1)
        a, b = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel()
        c, d = idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        cells = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
        frames = np.tile(np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]), (len(cells), 1, 1))
        ang = math.radians(fibre_angle_deg)
        fibres = np.tile([math.cos(ang), math.sin(ang)], (len(cells), 1))
        data = (points, cells, np.ones(len(cells), np.int32), frames, fibres)
    return _distribute(comm, data)


def _distribute(comm: MPI.Comm, data) -> MembraneDomain:
    if comm.rank == 0:
        points, cells, tags, frames, fibres = data
        return membrane_domain_from_arrays(comm, points, cells, tags, frames, fibres)
    return membrane_domain_from_arrays(comm, None, None, None, None, None)
