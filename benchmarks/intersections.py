"""Where the loaded leaflets' mid-surfaces pass through one another, case by case.

Prints, for every pair of leaflets of each case folder, the length of the lines along which
their loaded surfaces cross (:func:`valve_dolfinx.analysis.intersection.leaflet_intersections`),
the part inside the valve (more than ``--wall-band`` from the root wall: the attachment
lines meet at the commissures by construction) and where that part lies; ``result.json``
keeps the largest inner length as ``leaflet_intersection_mm``.

Reads the ``loaded_state.npz`` and ``result.json`` (the root diameter) of case folders
written by ``valve-dolfinx run`` or a study (``results/graft_sweep/cases/*``)::

    .venv/bin/python benchmarks/intersections.py results/graft_sweep/cases/*
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from valve_dolfinx.analysis.intersection import leaflet_intersections


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
        if not (state.is_file() and (folder / "result.json").is_file()):
            missing.append(str(folder))
            continue
        data = np.load(state)
        result = json.loads((folder / "result.json").read_text())
        root_radius = 0.5 * result["root_diameter_mm"]
        for pair in leaflet_intersections(data["positions"], data["cells"], data["cell_tags"],
                                          root_radius, args.wall_band):
            r = "" if pair.inner_radius_mm is None else "{:.1f}–{:.1f}".format(
                *pair.inner_radius_mm)
            z = "" if pair.inner_height_mm is None else "{:.1f}–{:.1f}".format(
                *pair.inner_height_mm)
            a, b = pair.leaflets
            print(f"| {folder.name} | {a}–{b} | {pair.total_mm:.2f} | {pair.inner_mm:.2f} "
                  f"| {r} | {z} |", flush=True)
    if missing:
        sys.exit(f"no loaded_state.npz and result.json in {', '.join(missing)}: pass case "
                 "folders written by `valve-dolfinx run` or a study")


if __name__ == "__main__":
    main()
