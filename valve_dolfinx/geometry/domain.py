"""What the membrane model needs from any surface mesh."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from valve_dolfinx._compat import MPI, dolfinx

__all__ = ["MembraneDomain"]


@dataclass
class MembraneDomain:
    """A manifold triangle mesh with per-cell reference charts and material axes.

    Attributes
    ----------
    mesh
        Triangles in 3-D (the placement x₀ the displacement is measured from).
    cell_tags
        Material region of each cell (looked up in the model's material map).
    facet_tags
        Tagged edges (boundary conditions), may be empty.
    reference
        DG0 (3, 2) field J0 = ∂x₀/∂X from the stress-free reference chart X.
    fibre
        DG0 (2,) unit fibre direction in the reference chart.
    """

    mesh: dolfinx.mesh.Mesh
    cell_tags: dolfinx.mesh.MeshTags
    facet_tags: dolfinx.mesh.MeshTags
    reference: dolfinx.fem.Function
    fibre: dolfinx.fem.Function

    @property
    def comm(self) -> MPI.Comm:
        return self.mesh.comm

    def num_cells_global(self) -> int:
        return self.mesh.topology.index_map(self.mesh.topology.dim).size_global

    def num_nodes_global(self) -> int:
        return self.mesh.geometry.index_map().size_global

    def tags(self) -> np.ndarray:
        """All cell tag values present on any rank."""
        local = np.unique(self.cell_tags.values)
        return np.unique(np.concatenate(self.comm.allgather(local)))
