"""The valve as one DOLFINx manifold mesh, serial and under ``mpirun -n 2``.

Every rank builds the serial :class:`ValveMesh` itself (the reference: counts, areas, tags and
fibres); the distributed mesh is built from rank 0's copy.  Under ``mpirun -n 2`` the tests
check that the two ranks really share the mesh (each owns a part, the parts add up to the
serial whole) -- a mesh left on one rank, or copied onto every rank, fails them.
"""

from __future__ import annotations

import math
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import ufl
from scipy.spatial import cKDTree

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.geometry.distributed import create_valve_domain, write_domain_xdmf
from valve_dolfinx.geometry.valve import ATTACHMENT, FREE_EDGE, LEAFLET_TAGS, build_valve

D = 20.0
GAMMA = math.radians(34.0)
W, H = 0.21, 0.27

pytestmark = pytest.mark.mpi


@pytest.fixture(scope="module")
def graft_valve():
    # every rank builds the same serial description: the reference for the counts
    return build_valve(mesh_size=0.8, graft_width_pct=21, graft_height_pct=27)


@pytest.fixture(scope="module")
def domain(graft_valve):
    return create_valve_domain(graft_valve if MPI.COMM_WORLD.rank == 0 else None)


def _sum(comm, value):
    return comm.allreduce(value, op=MPI.SUM)


def test_global_counts_match_serial(domain, graft_valve):
    assert domain.mesh.geometry.dim == 3 and domain.mesh.topology.dim == 2
    assert domain.num_cells_global() == graft_valve.num_cells
    assert domain.num_nodes_global() == graft_valve.num_nodes
    n_local = domain.mesh.topology.index_map(2).size_local
    assert _sum(domain.comm, n_local) == graft_valve.num_cells


def test_mesh_is_shared_between_ranks(domain, graft_valve):
    """Each rank owns a real part of the mesh; owned cells, owned nodes and the surface area
    add up to the serial mesh's (computed here from its NumPy arrays)."""
    comm = domain.comm
    mesh = domain.mesh
    owned_cells = comm.allgather(mesh.topology.index_map(2).size_local)
    owned_nodes = comm.allgather(mesh.geometry.index_map().size_local)
    ghost_nodes = comm.allgather(mesh.geometry.index_map().num_ghosts)
    assert sum(owned_cells) == graft_valve.num_cells
    assert sum(owned_nodes) == graft_valve.num_nodes
    if comm.size > 1:
        assert min(owned_cells) > 0 and max(owned_cells) < graft_valve.num_cells
        assert min(ghost_nodes) > 0  # the parts meet along an interface
    p = graft_valve.points[graft_valve.cells]
    serial_area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]),
                                       axis=1).sum()
    one = dolfinx.fem.Constant(mesh, dolfinx.default_scalar_type(1.0))
    area = _sum(comm, dolfinx.fem.assemble_scalar(dolfinx.fem.form(one * ufl.dx(domain=mesh))))
    assert area == pytest.approx(serial_area, rel=1e-12)


def test_tags_cover_everything(domain, graft_valve):
    comm = domain.comm
    n_local = domain.mesh.topology.index_map(2).size_local
    assert len(domain.cell_tags.indices) == n_local
    for name, tag in LEAFLET_TAGS.items():
        expected = int(np.sum(graft_valve.cell_tags == tag))
        assert _sum(comm, int(np.sum(domain.cell_tags.values == tag))) == expected, name
    # edges are owned by exactly one rank after distribution
    for tag in (ATTACHMENT, FREE_EDGE):
        expected = int(np.sum(graft_valve.edge_tags == tag))
        imap = domain.mesh.topology.index_map(1)
        owned = domain.facet_tags.indices < imap.size_local
        got = _sum(comm, int(np.sum(domain.facet_tags.values[owned] == tag)))
        assert got == expected


def test_reference_map_gives_flat_area(domain, graft_valve):
    """∫ dA_ref over each leaflet = its flat area (the graft's is (1+W)(1+H) larger)."""
    J = domain.reference
    dA_ref = 1.0 / ufl.sqrt(ufl.det(J.T * J))
    dx = ufl.Measure("dx", domain=domain.mesh, subdomain_data=domain.cell_tags)
    areas = []
    for tag in (1, 3):
        form = dolfinx.fem.form(dA_ref * dx(tag))
        areas.append(_sum(domain.comm, dolfinx.fem.assemble_scalar(form)))
    flat = graft_valve.flat
    a = flat[:, 1] - flat[:, 0]
    b = flat[:, 2] - flat[:, 0]
    flat_area = 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
    for tag, got in zip((1, 3), areas, strict=True):
        assert got == pytest.approx(flat_area[graft_valve.cell_tags == tag].sum(), rel=1e-12)
    # closed form of the native outline: free edge 2a = πd/3 at height h_c + d·sin²(π/6)/tanγ,
    # minus the area under the lower edge, ∫ d·sin²(x/d)/tanγ dx over [-a, a]
    a = math.pi * D / 6
    top = 5.0 + D * math.sin(math.pi / 6) ** 2 / math.tan(GAMMA)
    native = 2 * a * top - D * (a - D * math.sin(2 * a / D) / 2) / math.tan(GAMMA)
    # (flat triangles cut O(h²) off the convex lower edge: ~1e-3 at h = 0.8 mm)
    assert areas[0] == pytest.approx(native, rel=2e-3)
    assert areas[1] == pytest.approx((1 + W) * (1 + H) * native, rel=2e-3)


def _read_cell_vectors(comm, xdmf_path: Path, name: str) -> np.ndarray:
    """All rows (file order) of the cell-centred vector attribute ``name`` of an XDMF file.

    DOLFINx has no reader for functions in XDMF; its reader of mesh geometry reads any
    ``(n, 3)`` HDF5 dataset, though.  A small companion XDMF file (beside a copy of the
    ``.h5`` file, which DOLFINx pairs by name) declares the attribute's dataset as the
    geometry of a grid; the rows come back distributed over the ranks and are gathered.
    """
    companion = None
    if comm.rank == 0:
        root = ET.parse(xdmf_path).getroot()
        item = next(a for a in root.iter("Attribute") if a.get("Name") == name).find("DataItem")
        folder = xdmf_path.parent / f"{xdmf_path.stem}_{name}"
        folder.mkdir(exist_ok=True)
        shutil.copyfile(xdmf_path.with_suffix(".h5"), folder / f"{xdmf_path.stem}.h5")
        companion = folder / xdmf_path.name
        dataset = item.text.strip().split(":", 1)[1]
        companion.write_text(
            '<?xml version="1.0"?>\n<Xdmf Version="3.0"><Domain><Grid Name="values">'
            f'<Geometry GeometryType="XYZ"><DataItem Dimensions="{item.get("Dimensions")}" '
            f'Format="HDF">{xdmf_path.stem}.h5:{dataset}</DataItem></Geometry>'
            "</Grid></Domain></Xdmf>\n")
    companion = comm.bcast(companion, root=0)
    with dolfinx.io.XDMFFile(comm, str(companion), "r") as xdmf:
        local = xdmf.read_geometry_data(name="values").reshape(-1, 3)
    return np.concatenate(comm.allgather(local))


def _match(points: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Index of the reference point at each point's place (they must coincide)."""
    dist, index = cKDTree(reference).query(points)
    assert np.all(dist < 1e-9 * D)
    return index


def test_xdmf_roundtrip(domain, graft_valve, tmp_path_factory):
    """Mesh, leaflet tags, edge tags (attachment, free edge) and fibres survive write + read;
    every read entity is identified by position with the serial mesh's and checked there."""
    comm = domain.comm
    path = comm.bcast(tmp_path_factory.mktemp("xdmf") / "valve.xdmf" if comm.rank == 0
                      else None)
    write_domain_xdmf(domain, path)
    with dolfinx.io.XDMFFile(comm, str(path), "r") as xdmf:
        mesh = xdmf.read_mesh(name="mesh")
        mesh.topology.create_connectivity(1, 2)
        cell_tags = xdmf.read_meshtags(mesh, name="leaflet")
        facet_tags = xdmf.read_meshtags(mesh, name="edges")
    fibres_in_file = _read_cell_vectors(comm, path, "fibre")
    assert mesh.topology.index_map(2).size_global == graft_valve.num_cells
    assert mesh.geometry.index_map().size_global == graft_valve.num_nodes
    assert len(fibres_in_file) == graft_valve.num_cells

    # cells: tag and fibre of every owned cell = the serial cell at the same place
    n_local = mesh.topology.index_map(2).size_local
    x = mesh.geometry.x
    centroids = x[mesh.geometry.dofmaps[0][:n_local]].mean(axis=1)
    serial_centroids = graft_valve.points[graft_valve.cells].mean(axis=1)
    cell = _match(centroids, serial_centroids)
    assert len(np.unique(np.concatenate(comm.allgather(cell)))) == graft_valve.num_cells
    owned = cell_tags.indices < n_local
    assert _sum(comm, int(owned.sum())) == graft_valve.num_cells  # every cell tagged
    tagged = cell_tags.indices[owned]
    assert np.array_equal(cell_tags.values[owned], graft_valve.cell_tags[cell[tagged]])
    rows = np.asarray(mesh.topology.original_cell_index[:n_local], dtype=np.int64)
    fibres = fibres_in_file[rows]
    assert np.max(np.abs(fibres - graft_valve.fibres_3d()[cell])) < 1e-12
    assert np.allclose(np.linalg.norm(fibres, axis=1), 1.0, atol=1e-12)

    # edges: every tagged edge of the serial mesh comes back once, with its tag
    n_edges = mesh.topology.index_map(1).size_local
    owned = facet_tags.indices < n_edges
    ends = dolfinx.mesh.entities_to_geometry(mesh, 1, facet_tags.indices[owned])
    serial_mid = graft_valve.points[graft_valve.edges].mean(axis=1)
    edge = _match(x[ends].mean(axis=1), serial_mid)
    assert np.array_equal(facet_tags.values[owned], graft_valve.edge_tags[edge])
    edges_read = np.concatenate(comm.allgather(edge))
    assert len(edges_read) == len(np.unique(edges_read)) == len(graft_valve.edges)
    for tag in (ATTACHMENT, FREE_EDGE):
        got = _sum(comm, int(np.sum(facet_tags.values[owned] == tag)))
        assert got == int(np.sum(graft_valve.edge_tags == tag)) > 0
