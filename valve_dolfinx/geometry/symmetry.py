"""The normal valve's symmetry-plane reference: one leaflet and its mirror images (SPEC §4).

The cheap reference solves the left-coronary leaflet alone, closing against the
two planes through the valve axis at ±60° that its neighbours mirror it across.
:func:`single_leaflet` cuts that leaflet out of a valve mesh,
:func:`symmetry_planes` gives the planes, and :func:`mirror_leaflet` rebuilds a
three-leaflet valve from the solved leaflet so that the coaptation analysis and
the figures treat it as the full valve.  :func:`distance_up_to_mirror` compares two
loaded states of a valve that is mirror-symmetric about the plane through the axis and
its graft's midline, whose loaded state need not be.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from valve_dolfinx.geometry.valve import LEAFLET_TAGS, ValveMesh

__all__ = ["single_leaflet", "symmetry_planes", "mirror_leaflet", "distance_up_to_mirror"]


def single_leaflet(valve: ValveMesh) -> ValveMesh:
    """The left-coronary leaflet alone (for the symmetry-plane reference)."""
    tag = LEAFLET_TAGS["left_coronary"]
    keep = valve.cell_tags == tag
    nodes = np.unique(valve.cells[keep])
    renumber = np.full(valve.num_nodes, -1, dtype=np.int64)
    renumber[nodes] = np.arange(len(nodes))
    edge_keep = np.all(np.isin(valve.edges, nodes), axis=1)
    patch = valve.leaflet("left_coronary")
    patch = replace(patch, nodes=renumber[patch.nodes])
    return ValveMesh(points=valve.points[nodes], cells=renumber[valve.cells[keep]],
                     cell_tags=valve.cell_tags[keep], flat=valve.flat[keep],
                     fibres=valve.fibres[keep], edges=renumber[valve.edges[edge_keep]],
                     edge_tags=valve.edge_tags[edge_keep], leaflets=(patch,),
                     parameters=valve.parameters).validate()


def symmetry_planes() -> tuple[np.ndarray, np.ndarray]:
    """Points and unit normals (pointing into the leaflet's sector) of the planes at ±60°."""
    normals = []
    for phi in (math.pi / 3, -math.pi / 3):
        n = np.array([-math.sin(phi), math.cos(phi), 0.0])
        normals.append(n if n[0] > 0 else -n)
    return np.zeros((2, 3)), np.array(normals)


def mirror_leaflet(valve: ValveMesh, positions: np.ndarray) -> tuple[ValveMesh, np.ndarray]:
    """Three-leaflet valve made of a single leaflet and its mirror images in the ±60° planes.

    Used to measure the single-leaflet reference with the same coaptation
    analysis as the full valve.
    """
    patch = valve.leaflets[0]
    _, normals = symmetry_planes()
    n = valve.num_nodes
    all_points, all_pos, all_cells, all_tags = [], [], [], []
    all_flat, all_fib, patches = [], [], []
    for k, mirror in enumerate([None, *normals]):
        pts, pos, cells = valve.points, positions, valve.cells
        if mirror is not None:
            reflect = np.eye(3) - 2 * np.outer(mirror, mirror)
            pts, pos = pts @ reflect.T, pos @ reflect.T
            cells = cells[:, [0, 2, 1]]  # keep the normals pointing to the aortic side
        all_points.append(pts)
        all_pos.append(pos)
        all_cells.append(cells + k * n)
        all_tags.append(np.full(len(cells), k + 1, dtype=np.int32))
        flat = valve.flat if mirror is None else valve.flat[:, [0, 2, 1]]
        all_flat.append(flat if mirror is None else flat * np.array([-1.0, 1.0]))
        all_fib.append(valve.fibres if mirror is None else valve.fibres * np.array([-1.0, 1.0]))
        flat_nodes = patch.flat if mirror is None else patch.flat * np.array([-1.0, 1.0])
        tri = patch.triangles if mirror is None else patch.triangles[:, [0, 2, 1]]
        patches.append(replace(patch, name=f"{patch.name}" if mirror is None
                               else f"{patch.name}_mirror{k}", tag=k + 1,
                               nodes=patch.nodes + k * n, flat=flat_nodes, triangles=tri))
    mirrored = ValveMesh(points=np.concatenate(all_points), cells=np.concatenate(all_cells),
                         cell_tags=np.concatenate(all_tags), flat=np.concatenate(all_flat),
                         fibres=np.concatenate(all_fib),
                         edges=np.concatenate([valve.edges + k * n for k in range(3)]),
                         edge_tags=np.tile(valve.edge_tags, 3), leaflets=tuple(patches),
                         parameters=valve.parameters)
    return mirrored, np.concatenate(all_pos)


def distance_up_to_mirror(valve: ValveMesh, a: np.ndarray, b: np.ndarray,
                          tolerance: float = 1e-9) -> tuple[float, float]:
    """Largest nodal distance between two loaded states ``a`` and ``b`` ``(N, 3)`` of a graft
    valve: directly, and with ``b`` mirrored in the plane through the axis and the graft's
    free-edge midpoint.

    A graft valve is mirror-symmetric about that plane (the two coronary leaflets are
    mirror images of each other), but its loaded state may lean to one side, and two runs
    can reach two mirror images of one state.  The mesh must be its own mirror image
    (every node's image a node, within ``tolerance`` mm); raises ``ValueError`` otherwise.
    """
    from scipy.spatial import cKDTree

    graft = next(p for p in valve.leaflets if p.is_graft)
    mid = valve.points[graft.nodes[graft.midline_free_edge_node]]
    across = np.array([-mid[1], mid[0], 0.0]) / math.hypot(mid[0], mid[1])

    def mirrored(x: np.ndarray) -> np.ndarray:
        return x - 2.0 * np.outer(x @ across, across)

    gap, image = cKDTree(valve.points).query(mirrored(valve.points))
    if gap.max() > tolerance:
        raise ValueError(f"the mesh is not its own mirror image ({gap.max():.3g} mm)")
    direct = float(np.linalg.norm(a - b, axis=1).max())
    mirror = float(np.linalg.norm(a - mirrored(b[image]), axis=1).max())
    return direct, mirror
