"""Where the loaded leaflets' mid-surfaces pass through one another.

Node-to-surface contact keeps every node out of its neighbours' contact layers, but it
does not see a triangle that slices through a neighbour between that neighbour's nodes,
and it lets a node go once it is deeper than the penetration window (``max_penetration_mm``
is measured over the active contacts only).  This script checks the loaded surfaces
themselves: for every pair of leaflets it intersects their triangulated mid-surfaces
(VTK's triangle-triangle intersection through PyVista) and prints the length of the
intersection lines, split into the part within ``--wall-band`` of the root wall (where
the leaflets' attachment lines meet at the commissures, by construction) and the part
inside the valve, with where the inner part lies (distance from the axis, height).

Reads the ``loaded_state.npz`` of case folders written by ``valve-dolfinx run`` or a
study (``results/graft_sweep/cases/*``)::

    .venv/bin/python benchmarks/intersections.py results/graft_sweep/cases/*
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np
import pyvista as pv


def _leaflet_surface(points: np.ndarray, cells: np.ndarray) -> pv.PolyData:
    faces = np.hstack([np.full((len(cells), 1), 3), cells]).ravel()
    return pv.PolyData(points, faces).clean()


def intersection_lines(points: np.ndarray, cells: np.ndarray, tags: np.ndarray,
                       wall_band_mm: float) -> list[dict]:
    """Per pair of leaflets (cell tags): total intersection length, the length farther
    than ``wall_band_mm`` from the root wall (the largest distance of a node from the
    axis), and the radius and height range of that inner part."""
    radius = np.hypot(points[:, 0], points[:, 1])
    wall = float(radius.max())
    surfaces = {int(t): _leaflet_surface(points, cells[tags == t]) for t in np.unique(tags)}
    rows = []
    for a, b in itertools.combinations(sorted(surfaces), 2):
        lines, _, _ = surfaces[a].intersection(surfaces[b], split_first=False,
                                               split_second=False)
        total = inner = 0.0
        where = []
        for i in range(lines.n_cells):
            ends = lines.get_cell(i).points
            length = float(np.linalg.norm(ends[-1] - ends[0]))
            mid = ends.mean(axis=0)
            total += length
            if np.hypot(mid[0], mid[1]) < wall - wall_band_mm:
                inner += length
                where.append((np.hypot(mid[0], mid[1]), mid[2]))
        where = np.array(where).reshape(-1, 2)
        rows.append({"pair": (a, b), "total_mm": total, "inner_mm": inner,
                     "r_mm": (where[:, 0].min(), where[:, 0].max()) if len(where) else None,
                     "z_mm": (where[:, 1].min(), where[:, 1].max()) if len(where) else None})
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="+", type=Path, help="case folders (loaded_state.npz)")
    parser.add_argument("--wall-band", type=float, default=1.0,
                        help="band at the root wall left out of the inner length (mm)")
    args = parser.parse_args()
    print("| case | leaflets | intersection (mm) | of it inside the valve (mm) | "
          "r of the inner part (mm) | z of the inner part (mm) |")
    print("|---|---|---:|---:|---|---|")
    missing = []
    for folder in args.cases:
        state = folder / "loaded_state.npz"
        if not state.is_file():
            missing.append(str(folder))
            continue
        data = np.load(state)
        for row in intersection_lines(data["positions"], data["cells"], data["cell_tags"],
                                      args.wall_band):
            r = "" if row["r_mm"] is None else "{:.1f}–{:.1f}".format(*row["r_mm"])
            z = "" if row["z_mm"] is None else "{:.1f}–{:.1f}".format(*row["z_mm"])
            print(f"| {folder.name} | {row['pair'][0]}–{row['pair'][1]} | "
                  f"{row['total_mm']:.2f} | {row['inner_mm']:.2f} | {r} | {z} |", flush=True)
    if missing:
        sys.exit(f"no loaded_state.npz in {', '.join(missing)}: pass case folders written "
                 "by `valve-dolfinx run` or a study")


if __name__ == "__main__":
    main()
