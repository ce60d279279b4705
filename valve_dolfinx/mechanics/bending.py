"""A small bending stiffness for the membrane: the quadratic (isometric) bending model.

The leaflets are membranes (SPEC §4), but a membrane's slack free edge has no
stiffness against folding: at the triple point, where the three free edges
meet, the last millimetre of each free edge folds one way or another at the
scale of the mesh, held by nothing but contact (docs/model.md §3).  A real leaflet has
a flexural rigidity ``D = E_b·t³/12``; this module adds it as the energy of a
plate whose stress-free state is the flat leaflet,

    Π_b = D/2 ∫ (2H)² dA   (H the mean curvature),

which for isometric deformations (the leaflet is close to one where it bends
freely: slack, or the nearly inextensible graft) is the whole Kirchhoff plate
energy, the Gaussian-curvature term integrating to a boundary term.  It is
discretised with the cotangent Laplacian of the flat reference (Wardetzky et
al. 2007; the "quadratic bending" model of Bergou et al. 2006): at an interior
node i with lumped area A_i, ``Σ_j L_ij x_j = −(S x)_i / A_i`` is the mean
curvature vector 2H·n, so

    Π_b = ½ xᵀ K x,  K = D · Sᵀ P A⁻¹ P S   (per Cartesian component),

with S the P1 stiffness matrix of the Laplacian on the flat leaflet (entries
``−½ cot`` of the opposite angles), A the lumped nodal areas and P keeping the
interior nodes (the Laplacian at a boundary node is not a curvature).  K is
constant, symmetric positive semi-definite, and vanishes on every flat
placement and every rigid motion of the flat leaflet; the force is ``−K x``
and the Jacobian ``K``: Newton sees it exactly.  The energy is exact for
isometric bending and an approximation where the membrane also stretches,
which is where membrane tension, not bending, carries the load.

The rigidity is per node, ``D_i`` at interior node i.  Two consequences of
measuring no curvature on the boundary:

* a boundary held in place is a hinge: it takes no moment (a strip held at
  both ends deflects as a simply supported plate);
* two sheets of different rigidity that share boundary nodes (the graft and
  its native neighbours at the commissures) add up without a seam term: an
  interior node and its lumped area belong to one sheet's triangles, so
  ``K`` is the sum of each sheet's own matrix.

Checked in tests/test_bending.py against closed forms: the energy ``D·A/(2R²)``
of a flat sheet wrapped isometrically onto a cylinder of radius R, the
deflection of a simply supported strip under a uniform load, two sheets of
different rigidity bent across their seam, and zero energy and force on flat
placements and rigid motions.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from valve_dolfinx.exceptions import ParameterError, check_range

__all__ = ["bending_stiffness_matrix", "flexural_rigidity"]


def flexural_rigidity(modulus_kpa: float, thickness_mm: float) -> float:
    """D = E·t³/12 (kPa·mm³ = mN·mm) of a plate (Poisson ratio 0)."""
    check_range("flexural modulus E_b", modulus_kpa, 0.0, 1e7, unit="kPa")
    check_range("thickness", thickness_mm, 0.0, 5.0, low_open=True, unit="mm")
    return modulus_kpa * thickness_mm**3 / 12.0


def _cotangent_laplacian(cells: np.ndarray, flat: np.ndarray, num_nodes: int
                         ) -> tuple[sp.csr_matrix, np.ndarray]:
    """P1 stiffness matrix S of −Δ and lumped nodal areas on per-cell flat coordinates."""
    rows, cols, vals = [], [], []
    e1, e2 = flat[:, 1] - flat[:, 0], flat[:, 2] - flat[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])  # twice the triangle areas
    if np.any(area2 <= 1e-14 * np.max(area2)):
        raise ParameterError("bending: degenerate (zero-area) triangle in the flat reference; "
                             "remesh the leaflet")
    for k in range(3):
        i, j = cells[:, (k + 1) % 3], cells[:, (k + 2) % 3]
        # cot of the angle at vertex k = (a·b)/|a×b| with a, b the edges leaving vertex k
        a = flat[:, (k + 1) % 3] - flat[:, k]
        b = flat[:, (k + 2) % 3] - flat[:, k]
        cot = np.einsum("ij,ij->i", a, b) / area2
        rows += [i, j, i, j]
        cols += [j, i, i, j]
        vals += [-0.5 * cot, -0.5 * cot, 0.5 * cot, 0.5 * cot]
    S = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(num_nodes, num_nodes))
    lumped = np.zeros(num_nodes)
    np.add.at(lumped, cells.ravel(), np.repeat(area2 / 6.0, 3))
    return S, lumped


def bending_stiffness_matrix(cells: np.ndarray, flat: np.ndarray, num_nodes: int,
                             boundary_nodes: np.ndarray, rigidity) -> sp.csr_matrix:
    """K (N×N, one Cartesian component) with Π_b = ½ Σ_c x_cᵀ K x_c; see the module docstring.

    Parameters
    ----------
    cells, flat
        ``(M, 3)`` node ids and ``(M, 3, 2)`` flat (stress-free) coordinates per cell.
    boundary_nodes
        Nodes on the mesh boundary (free edge, attachment): no curvature is
        measured at them (they still bend with their interior neighbours).
    rigidity
        Flexural rigidity D (mN·mm), a number or one value per node (the
        tissue of the leaflet the node belongs to; only interior nodes' values
        enter); 0 gives a zero matrix.
    """
    rigidity = np.broadcast_to(np.asarray(rigidity, dtype=float), (num_nodes,))
    if np.any(rigidity < 0) or not np.all(np.isfinite(rigidity)):
        raise ParameterError("bending rigidity must be finite and >= 0 (mN·mm); use 0 to "
                             "switch bending off")
    S, lumped = _cotangent_laplacian(np.asarray(cells), np.asarray(flat, float), num_nodes)
    interior = np.ones(num_nodes, dtype=bool)
    interior[np.asarray(boundary_nodes, dtype=np.int64)] = False
    weight = np.where(interior & (lumped > 0), rigidity / np.where(lumped > 0, lumped, 1.0), 0.0)
    return (S.T @ sp.diags(weight) @ S).tocsr()
