"""The valve as one DOLFINx manifold mesh, serial and under ``mpirun -n 2``."""

from __future__ import annotations

import numpy as np
import pytest
import ufl

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.geometry.distributed import create_valve_domain, write_domain_xdmf
from valve_dolfinx.geometry.valve import ATTACHMENT, FREE_EDGE, LEAFLET_TAGS, build_valve

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
    assert areas[1] / areas[0] == pytest.approx(1.21 * 1.27, rel=5e-3)


def test_xdmf_roundtrip(domain, tmp_path_factory):
    comm = domain.comm
    path = comm.bcast(str(tmp_path_factory.mktemp("xdmf") / "valve.xdmf") if comm.rank == 0
                      else None)
    write_domain_xdmf(domain, path)
    with dolfinx.io.XDMFFile(comm, path, "r") as xdmf:
        mesh = xdmf.read_mesh(name="mesh")
        mesh.topology.create_connectivity(1, 2)
        tags = xdmf.read_meshtags(mesh, name="leaflet")
    assert mesh.topology.index_map(2).size_global == domain.num_cells_global()
    owned = tags.indices < mesh.topology.index_map(2).size_local
    total = _sum(comm, int(tags.values[owned].sum()))
    assert total == _sum(comm, int(domain.cell_tags.values.sum()))
