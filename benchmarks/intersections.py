"""Which leaflets pass through one another or through themselves, case by case.

Checks the loaded state of every case folder given with the intersection check of the
result (:func:`valve_dolfinx.analysis.intersection.valve_intersections`: the IPC Toolkit's
exact edge–triangle test on the whole loaded surface) and prints one line per case: the
intersecting edge–triangle pairs, per pair of leaflets (``graft/self``: the graft through
itself), their distance from the nearest commissure post, what the case's ``result.json``
recorded, and the time the check took.  For case folders written before the check was
part of the result, and to check a state again.

Reads the case folders written by ``valve-dolfinx run`` or a study
(``results/graft_sweep/cases/*``), rebuilding each valve mesh from its configuration::

    .venv/bin/python benchmarks/intersections.py results/graft_sweep/cases/*
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from valve_dolfinx.analysis.intersection import valve_intersections
from valve_dolfinx.exceptions import ValveError
from valve_dolfinx.result import load_case


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="+", type=Path, help="finished case folders")
    args = parser.parse_args()
    print("| case | pairs | leaflets | from a post (mm) | recorded | check (s) |")
    print("|---|---:|---|---|---:|---:|")
    unread = []
    for folder in args.cases:
        try:
            case = load_case(folder)
        except (FileNotFoundError, ValveError) as err:
            unread.append(f"{folder}: {err}")
            continue
        found = valve_intersections(case.positions, case.valve)
        span = found.post_distance_mm()
        where = "" if span is None else "{:.2f}–{:.2f}".format(*span)
        leaflets = ", ".join(f"{k} {n}" for k, n in found.between().items())
        recorded = case.result.intersecting_pairs
        print(f"| {folder.name} | {found.count} | {leaflets} | {where} "
              f"| {'' if recorded is None else recorded} | {found.time_s:.3f} |", flush=True)
    if unread:
        sys.exit("not checked:\n" + "\n".join(unread))


if __name__ == "__main__":
    main()
