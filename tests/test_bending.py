"""The quadratic bending model against closed forms: a sheet wrapped on a cylinder, a
simply supported strip under a uniform load for each tissue's rigidity, two tissues bent
across their seam, the valve's two tissues at the commissures, flat placements and rigid
motions."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from valve_dolfinx.config import CaseConfig
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.mechanics.bending import bending_stiffness_matrix, flexural_rigidity

D = flexural_rigidity(200.0, 0.5)  # 2.083 mN·mm
#: the default mesh size (mm)
H_DEFAULT = 0.8


def sheet(n: int, width=6.0, length=4.0, jitter=0.2, seed=1):
    """Flat rectangle, n × n cells split in triangles, interior nodes moved at random."""
    u, v = np.meshgrid(np.linspace(0, width, n + 1), np.linspace(0, length, n + 1),
                       indexing="ij")
    flat = np.stack([u.ravel(), v.ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    inner = np.ones((n + 1, n + 1), dtype=bool)
    inner[[0, -1], :] = inner[:, [0, -1]] = False
    rng = np.random.default_rng(seed)
    h = np.array([width, length]) / n
    flat[inner.ravel()] += jitter * h * rng.uniform(-1, 1, (inner.sum(), 2))
    a, b, c, d = (idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(),
                  idx[:-1, 1:].ravel())
    cells = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    boundary = idx[~inner]
    return flat, cells, boundary


def interior_area(flat, cells, boundary):
    p = flat[cells]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    lumped = np.zeros(len(flat))
    np.add.at(lumped, cells.ravel(), np.repeat(area / 3, 3))
    lumped[boundary] = 0.0
    return lumped.sum()


def energy(K, x):
    return 0.5 * float(np.einsum("ij,ij->", x, K @ x))


def wrapped_energy_error(n: int, radius: float, jitter: float) -> float:
    """Relative error of Π_b for the sheet wrapped isometrically on a cylinder of radius R,
    against the closed form D·A/(2R²) (mean curvature H = 1/(2R))."""
    flat, cells, boundary = sheet(n, jitter=jitter)
    K = bending_stiffness_matrix(cells, flat[cells], len(flat), boundary, D)
    angle = flat[:, 0] / radius
    x = np.stack([radius * np.sin(angle), flat[:, 1], radius * (1 - np.cos(angle))], axis=1)
    exact = D * interior_area(flat, cells, boundary) / (2 * radius**2)
    return energy(K, x) / exact - 1


@pytest.mark.parametrize("radius", [3.0, 8.0])
def test_wrapped_cylinder_energy_converges_at_second_order(radius):
    errors = [abs(wrapped_energy_error(n, radius, jitter=0.0)) for n in (8, 16, 32)]
    rates = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all((rates > 1.9) & (rates < 2.1)), (errors, rates)
    assert errors[-1] < 1e-3


def test_wrapped_cylinder_energy_on_irregular_meshes_within_two_percent():
    """The pointwise cotangent Laplacian is not consistent on irregular meshes (its error
    stays about 1 %); the bending energy is a regularisation, so that is enough."""
    for n in (8, 16, 32):
        for radius in (3.0, 8.0):
            assert abs(wrapped_energy_error(n, radius, jitter=0.2)) < 0.02


def test_flat_placements_and_rigid_motions_carry_no_bending():
    flat, cells, boundary = sheet(10)
    K = bending_stiffness_matrix(cells, flat[cells], len(flat), boundary, D)
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    x = np.c_[flat, np.zeros(len(flat))] @ q.T + rng.normal(size=3)
    assert np.max(np.abs(K @ x)) < 1e-10 * D
    # and it is positive semi-definite: a random bump costs energy
    bump = x + 0.1 * rng.normal(size=x.shape)
    assert energy(K, bump) > 0
    assert np.min(np.linalg.eigvalsh(K.toarray())) > -1e-10 * D


def test_rigidity_scales_the_energy_per_node_and_zero_switches_off():
    flat, cells, boundary = sheet(8)
    x = np.c_[flat, 0.1 * np.sin(flat[:, 0])]
    K1 = bending_stiffness_matrix(cells, flat[cells], len(flat), boundary, D)
    K2 = bending_stiffness_matrix(cells, flat[cells], len(flat), boundary,
                                  np.full(len(flat), 3 * D))
    assert energy(K2, x) == pytest.approx(3 * energy(K1, x), rel=1e-12)
    assert bending_stiffness_matrix(cells, flat[cells], len(flat), boundary, 0.0).nnz == 0 \
        or np.abs(bending_stiffness_matrix(cells, flat[cells], len(flat), boundary,
                                           0.0).data).max() == 0


def test_bad_rigidity_and_degenerate_triangles_are_refused():
    flat, cells, boundary = sheet(4)
    with pytest.raises(ParameterError, match="rigidity"):
        bending_stiffness_matrix(cells, flat[cells], len(flat), boundary, -1.0)
    squashed = flat.copy()
    squashed[:, 1] = 0.0
    with pytest.raises(ParameterError, match="degenerate"):
        bending_stiffness_matrix(cells, squashed[cells], len(flat), boundary, D)
    with pytest.raises(ParameterError, match="flexural modulus"):
        flexural_rigidity(-5.0, 0.5)


def periodic_strip(span, width, h, jitter=0.2, seed=2):
    """A flat strip 0 ≤ x ≤ span, periodic in y with period ``width`` (no side edges), in
    triangles of size about h with the inner nodes moved at random.

    Returns cells, per-cell flat coordinates, the number of nodes, the nodes of the two
    ends x = 0 and x = span (the mesh's boundary) and every node's x.
    """
    nx, ny = int(round(span / h)), int(round(width / h))
    X, Y = np.meshgrid(np.linspace(0, span, nx + 1), np.linspace(0, width, ny + 1),
                       indexing="ij")
    flat = np.stack([X, Y], axis=-1)
    rng = np.random.default_rng(seed)
    move = jitter * np.array([span / nx, width / ny]) * rng.uniform(-1, 1, (nx + 1, ny, 2))
    move[[0, -1], :, 0] = 0.0  # the ends stay straight
    flat[:, :-1] += move
    flat[:, -1] += move[:, 0]  # the row at y = width is the row at y = 0
    ids = np.arange((nx + 1) * ny).reshape(nx + 1, ny)
    ids = np.concatenate([ids, ids[:, :1]], axis=1)
    corners = [(slice(None, -1), slice(None, -1)), (slice(1, None), slice(None, -1)),
               (slice(1, None), slice(1, None)), (slice(None, -1), slice(1, None))]
    a, b, c, d = (ids[k] for k in corners)
    fa, fb, fc, fd = (flat[k] for k in corners)
    cells = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    flat_cells = np.concatenate([np.stack([fa, fb, fc], -2).reshape(-1, 3, 2),
                                 np.stack([fa, fc, fd], -2).reshape(-1, 3, 2)])
    ends = np.concatenate([ids[0, :-1], ids[-1, :-1]])
    return cells, flat_cells, (nx + 1) * ny, ends, flat[:, :-1, 0].ravel()


@pytest.mark.parametrize("is_graft", [False, True], ids=["native", "graft"])
def test_strip_held_at_both_ends_deflects_as_a_simply_supported_plate(is_graft):
    """A flat strip held at x = 0 and x = L (no curvature is measured there: a hinge) under
    a uniform pressure q deflects as the simply supported plate in cylindrical bending
    (Poisson ratio 0): w(x) = q·x·(L³ − 2L·x² + x³)/(24·D), 5qL⁴/(384·D) at midspan, with
    D = E_b·t³/12 of the tissue; checked at the default mesh size on an irregular mesh."""
    from valve_dolfinx.case import leaflet_rigidity

    config = CaseConfig(bending_modulus_kpa=200.0, graft_bending_modulus_kpa=2000.0)
    modulus, tissue = ((config.graft_bending_modulus_kpa, config.graft_material) if is_graft
                       else (config.bending_modulus_kpa, config.native_material))
    rigidity = modulus * tissue.thickness**3 / 12.0  # 20.83 (graft), 2.083 mN·mm (native)
    assert leaflet_rigidity(config, is_graft) == pytest.approx(rigidity, rel=1e-14)

    span, q = 10.0, 0.05  # mm, kPa
    cells, flat, n, ends, x = periodic_strip(span, 4.0, H_DEFAULT)
    K = bending_stiffness_matrix(cells, flat, n, ends, leaflet_rigidity(config, is_graft))
    e1, e2 = flat[:, 1] - flat[:, 0], flat[:, 2] - flat[:, 0]
    area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    load = np.zeros(n)
    np.add.at(load, cells.ravel(), np.repeat(q * area / 3.0, 3))
    free = np.setdiff1d(np.arange(n), ends)
    w = np.zeros(n)
    w[free] = spla.spsolve(K[free][:, free].tocsc(), load[free])
    exact = q * x * (span**3 - 2 * span * x**2 + x**3) / (24 * rigidity)
    midspan = 5 * q * span**4 / (384 * rigidity)
    assert np.max(np.abs(w - exact)) < 0.02 * midspan


def two_tissue_sheet(n, side=4.0, jitter=0.2):
    """Two square sheets side by side, sharing the n + 1 nodes of the seam x = side: cells
    and per-cell flat coordinates of each, their boundary nodes (the seam in both) and the
    positions of all nodes."""
    flat_a, cells_a, boundary_a = sheet(n, side, side, jitter, seed=1)
    flat_b, cells_b, boundary_b = sheet(n, side, side, jitter, seed=5)
    m = n + 1
    local = np.arange(m * m).reshape(m, m)  # sheet() numbers node (i along x, j along y)
    to_joint = np.empty(m * m, dtype=np.int64)
    to_joint[local[0]] = local[n]  # B's left column is A's right column
    to_joint[local[1:].ravel()] = m * m + np.arange(n * m)
    flat = np.zeros((m * m + n * m, 2))
    flat[:m * m] = flat_a
    flat[to_joint] = flat_b + [side, 0.0]
    sheets = [(cells_a, flat_a[cells_a], boundary_a),
              (to_joint[cells_b], flat_b[cells_b] + [side, 0.0], to_joint[boundary_b])]
    return sheets, flat


def test_two_tissues_bent_across_their_seam_add_without_a_seam_term():
    """Two sheets of rigidities D and 100·D that share a seam (as the graft and its
    neighbours share the commissures), wrapped on a cylinder whose curvature crosses the
    seam: the energy is D·A₁/(2R²) + 100·D·A₂/(2R²) (each sheet's measured area), and the
    joined matrix is the sum of the two sheets' own: nothing acts across the seam."""
    sheets, flat = two_tissue_sheet(5)  # 0.8 mm triangles
    num_nodes = len(flat)
    rigidities = (D, 100.0 * D)
    node_rigidity = np.zeros(num_nodes)
    for (cells, _, _), rigidity in zip(sheets, rigidities, strict=True):
        node_rigidity[cells.ravel()] = rigidity
    K = bending_stiffness_matrix(np.concatenate([s[0] for s in sheets]),
                                 np.concatenate([s[1] for s in sheets]), num_nodes,
                                 np.concatenate([s[2] for s in sheets]), node_rigidity)
    separate = [bending_stiffness_matrix(cells, flat_cells, num_nodes, boundary, rigidity)
                for (cells, flat_cells, boundary), rigidity in zip(sheets, rigidities,
                                                                   strict=True)]
    assert abs(K - separate[0] - separate[1]).max() < 1e-12 * abs(K).max()

    R = 5.0
    angle = flat[:, 0] / R
    x = np.stack([R * np.sin(angle), flat[:, 1], R * (1 - np.cos(angle))], axis=1)
    exact = sum(rigidity * interior_area(flat, cells, boundary) / (2 * R**2)
                for (cells, _, boundary), rigidity in zip(sheets, rigidities, strict=True))
    assert energy(K, x) == pytest.approx(exact, rel=0.01)


def test_valve_bending_matrix_is_the_sum_of_each_leaflets_own():
    """On a graft valve the leaflets' K is the sum of each leaflet's own matrix, with its
    tissue's rigidity and its own boundary (the commissures it shares included): the graft
    (here 100 times the native modulus) adds nothing across the commissures.  The normal
    valve does not see the graft's modulus."""
    from valve_dolfinx.case import leaflet_bending_matrix, leaflet_rigidity
    from valve_dolfinx.geometry.valve import build_valve

    config = CaseConfig(graft_bending_modulus_kpa=20000.0).with_graft(21.0, 27.0)
    config = replace(config, geometry=replace(config.geometry, mesh_size=2.0))
    valve = build_valve(config.geometry)
    K = leaflet_bending_matrix(valve, config)
    total = sp.csr_matrix(K.shape)
    for patch in valve.leaflets:
        own = bending_stiffness_matrix(patch.triangles, patch.flat[patch.triangles],
                                       len(patch.nodes),
                                       np.union1d(patch.free_edge, patch.attachment),
                                       leaflet_rigidity(config, patch.is_graft))
        embed = sp.csr_matrix((np.ones(len(patch.nodes)), (patch.nodes,
                                                           np.arange(len(patch.nodes)))),
                              shape=(valve.num_nodes, len(patch.nodes)))
        total = total + embed @ own @ embed.T
    assert [p.is_graft for p in valve.leaflets].count(True) == 1
    assert abs(K - total).max() < 1e-12 * abs(K).max()

    normal = replace(config, geometry=replace(config.geometry, graft_width_pct=None,
                                              graft_height_pct=None))
    normal_valve = build_valve(normal.geometry)
    assert (leaflet_bending_matrix(normal_valve, normal)
            != leaflet_bending_matrix(normal_valve, CaseConfig())).nnz == 0


@pytest.mark.mpi
def test_hook_adds_K_to_the_momentum_rows_of_a_state_matrix():
    """BendingHook puts K_ij·I into (momentum row of i, displacement column of j) of a
    (u, v) state matrix, once per call, on every rank's rows (serial and mpirun -n 2)."""
    import basix.ufl

    from valve_dolfinx._compat import MPI, PETSc, dolfinx
    from valve_dolfinx.solvers.bending_hook import BendingHook
    from valve_dolfinx.solvers.dynamics import STATE_LAYOUT
    from valve_dolfinx.solvers.nodal import NodalCoupling

    comm = MPI.COMM_WORLD
    flat, cells, boundary = sheet(6)
    x = np.column_stack([flat, 0.1 * flat[:, 0] * flat[:, 1]])
    element = basix.ufl.element("Lagrange", "triangle", 1, shape=(3,))
    mesh = dolfinx.mesh.create_mesh(comm, cells if comm.rank == 0 else np.empty((0, 3), np.int64),
                                    element, x if comm.rank == 0 else np.empty((0, 3)))
    W = dolfinx.fem.functionspace(mesh, ("Lagrange", 1, (6,)))
    coupling = NodalCoupling(W, STATE_LAYOUT)
    K = bending_stiffness_matrix(cells, flat[cells], len(flat), boundary, D)
    hook = BendingHook(coupling, K)

    n_local = 6 * W.dofmap.index_map.size_local
    A = PETSc.Mat().createAIJ(((n_local, None), (n_local, None)), comm=comm)
    A.setUp()
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
    for _ in range(2):  # the second call adds K again
        hook.add_jacobian(None, A)
    A.assemble()
    dense = np.zeros((A.getSize()[0],) * 2)
    r0, r1 = A.getOwnershipRange()
    for row in range(r0, r1):
        cols, vals = A.getRow(row)
        dense[row, cols] = vals
    dense = comm.allreduce(dense)
    expected = np.zeros_like(dense)
    rows = coupling.row_indices(np.arange(len(flat)))
    cols = coupling.col_indices(np.arange(len(flat)))
    Kd = K.toarray()
    for c in range(3):
        expected[np.ix_(rows[:, c], cols[:, c])] = 2.0 * Kd
    assert np.abs(Kd).max() > 0.0
    np.testing.assert_allclose(dense, expected, atol=1e-12 * np.abs(Kd).max())
