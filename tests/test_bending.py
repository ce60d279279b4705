"""The quadratic bending model against closed forms: a sheet wrapped on a cylinder, flat
placements and rigid motions."""

from __future__ import annotations

import numpy as np
import pytest

from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.mechanics.bending import bending_stiffness_matrix, flexural_rigidity

D = flexural_rigidity(200.0, 0.5)  # 2.083 mN·mm


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
    with pytest.raises(ParameterError, match="bending_modulus_kpa"):
        flexural_rigidity(-5.0, 0.5)


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
