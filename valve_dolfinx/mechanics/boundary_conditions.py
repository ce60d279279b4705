"""Dirichlet conditions: clamped (sewn) edges and statically determinate supports."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.exceptions import MeshError

__all__ = ["clamp_edges", "point_supports"]

fem = dolfinx.fem


def clamp_edges(V: fem.FunctionSpace, facet_tags: dolfinx.mesh.MeshTags, tags: Iterable[int],
                value: fem.Function | None = None) -> fem.DirichletBC:
    """Fix all displacement components on the edges carrying ``tags``.

    ``value`` (a function on V) gives the prescribed displacement; zero if omitted.
    """
    mesh = V.mesh
    edges = np.concatenate([facet_tags.find(t) for t in tags]).astype(np.int32)
    mesh.topology.create_connectivity(mesh.topology.dim - 1, mesh.topology.dim)
    dofs = fem.locate_dofs_topological(V, mesh.topology.dim - 1, np.unique(edges))
    if value is None:
        value = fem.Function(V)
    return fem.dirichletbc(value, dofs)


def point_supports(V: fem.FunctionSpace, supports: Sequence[tuple[Sequence[float], Sequence[int]]]
                   ) -> list[fem.DirichletBC]:
    """Zero displacement components at the mesh nodes nearest to given points.

    ``supports = [(point, components), ...]``.  A 3-2-1 choice (one node fixed
    in x, y, z; a second in two directions; a third in one) removes the six
    rigid-body motions of a free closed surface without reacting to a
    self-equilibrated load such as internal pressure.
    """
    mesh = V.mesh
    comm = mesh.comm
    n_owned = mesh.geometry.index_map().size_local
    x = mesh.geometry.x[:n_owned]
    bcs = []
    for point, components in supports:
        p = np.asarray(point, dtype=float)
        dist = np.linalg.norm(x - p, axis=1)
        local_best = float(dist.min()) if len(dist) else np.inf
        best, owner = comm.allreduce((local_best, comm.rank), op=MPI.MINLOC)
        if not np.isfinite(best):
            raise MeshError(f"no mesh node near support point {tuple(p)}")
        target = comm.bcast(x[int(np.argmin(dist))] if comm.rank == owner else None, root=owner)

        def at_node(xx, target=target):
            return np.linalg.norm(xx.T - target, axis=1) < 1e-12 * max(1.0, np.abs(target).max())

        for c in components:
            Vc, _ = V.sub(c).collapse()
            dofs = fem.locate_dofs_geometrical((V.sub(c), Vc), at_node)
            bcs.append(fem.dirichletbc(fem.Function(Vc), dofs, V.sub(c)))
    return bcs
