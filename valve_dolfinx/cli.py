"""Command-line entry point: ``valve-dolfinx <command> ...``.

Commands
--------
mesh    write the default valve meshes (normal and graft) for ParaView and reuse
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

__all__ = ["main"]

log = logging.getLogger("valve_dolfinx")


def _add_geometry_args(p: argparse.ArgumentParser) -> None:
    from valve_dolfinx.geometry.valve import DEFAULT_MESH_SIZE

    p.add_argument("--mesh-size", type=float, default=DEFAULT_MESH_SIZE,
                   help="target triangle edge length in mm (default %(default)s)")
    p.add_argument("--graft-width", type=float, default=None, metavar="W",
                   help="graft width enlargement in per cent (omit for the normal valve)")
    p.add_argument("--graft-height", type=float, default=None, metavar="H",
                   help="graft height enlargement in per cent")


def _cmd_mesh(args: argparse.Namespace) -> int:
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.geometry.distributed import create_valve_domain, write_domain_xdmf
    from valve_dolfinx.geometry.valve import build_valve
    from valve_dolfinx.io import export_valve_vtu

    comm = MPI.COMM_WORLD
    cases = [(None, None)]
    if args.graft_width is not None or args.graft_height is not None:
        cases = [(args.graft_width or 0.0, args.graft_height or 0.0)]
    elif args.defaults:
        cases = [(None, None), (21.0, 27.0)]
    for w, h in cases:
        name = "normal_valve" if w is None else f"graft_valve_W{w:g}_H{h:g}"
        valve = None
        if comm.rank == 0:
            valve = build_valve(mesh_size=args.mesh_size, graft_width_pct=w, graft_height_pct=h)
            valve.save(args.out / f"{name}.npz")
            export_valve_vtu(valve, args.out / f"{name}.vtu")
        write_domain_xdmf(create_valve_domain(valve, comm), args.out / f"{name}.xdmf")
        if comm.rank == 0:
            log.info("wrote %s/%s.{npz,vtu,xdmf}", args.out, name)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="valve-dolfinx", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("mesh", help="write valve meshes (.npz to reload, .vtu/.xdmf for ParaView)")
    p.add_argument("--out", type=Path, default=Path("meshes"))
    p.add_argument("--defaults", action="store_true",
                   help="write the normal valve and the W21/H27 graft valve")
    _add_geometry_args(p)
    p.set_defaults(func=_cmd_mesh)

    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.INFO,
                        format="%(message)s")
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as err:
        log.error("error: %s", err)
        return 2


if __name__ == "__main__":
    sys.exit(main())
