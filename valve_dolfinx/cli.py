"""Command-line entry point: ``valve-dolfinx <command> ...``.

Commands
--------
mesh    write the default valve meshes (normal and graft) for ParaView and reuse
run     close one valve (normal, or with a graft) under 80 mmHg and write
        result.json, ParaView fields and figures to --out
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


def _graft_size(parser: argparse.ArgumentParser, args: argparse.Namespace
                ) -> tuple[float, float] | None:
    """(W, H) in per cent from ``--graft-width``/``--graft-height``, or None for the normal
    valve; one without the other is a usage error (argparse exits with status 2)."""
    w, h = args.graft_width, args.graft_height
    if (w is None) != (h is None):
        given, missing = ("--graft-width", "--graft-height") if h is None else (
            "--graft-height", "--graft-width")
        parser.error(f"{given} needs {missing} as well: give both graft enlargements in per "
                     "cent (e.g. --graft-width 21 --graft-height 27; 0 keeps the native size), "
                     "or neither for the normal valve")
    return None if w is None else (w, h)


def _cmd_mesh(args: argparse.Namespace) -> int:
    graft = _graft_size(args.parser, args)  # usage errors before the slow imports
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.geometry.distributed import create_valve_domain, write_domain_xdmf
    from valve_dolfinx.geometry.valve import build_valve
    from valve_dolfinx.io import export_valve_vtu

    comm = MPI.COMM_WORLD
    cases = [(None, None)]
    if graft is not None:
        cases = [graft]
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


def _progress_bar(comm, total_time: float, clock: str = "t = {n:.3g} s "):
    """A tqdm bar over simulated time on rank 0 (a no-op callback elsewhere)."""
    if comm.rank != 0:
        return lambda entry: None, lambda: None
    from tqdm import tqdm

    bar = tqdm(total=total_time, unit="s", desc="closing", dynamic_ncols=True,
               bar_format="{desc}: " + clock + "{postfix} [{elapsed}]")

    def update(entry: dict) -> None:
        bar.n = entry["time"]
        contacts = f"{entry.get('contacts', 0)} contacts"
        if "residual_mN" in entry:  # dynamic relaxation: time is in stable steps
            bar.set_postfix_str(f"iteration {entry['step']}, residual "
                                f"{entry['residual_mN']:.1e} mN, {contacts}", refresh=False)
        else:
            bar.set_postfix_str(f"step {entry['step']}, dt {entry['dt']:.2g} s, increment "
                                f"{entry['increment_mm']:.1e} mm, {contacts}", refresh=False)
        bar.refresh()

    return update, bar.close


def _finished_result(out: Path, config) -> dict | None:
    """The result.json in ``out`` if it was computed with exactly ``config``."""
    import json

    try:
        data = json.loads((out / "result.json").read_text())
    except (FileNotFoundError, json.JSONDecodeError):
        return None
    wanted = json.loads(json.dumps(config.to_dict()))
    same = wanted == {k: v for k, v in data.get("parameters", {}).items() if k in wanted}
    return data if same else None


def _cmd_run(args: argparse.Namespace) -> int:
    graft = _graft_size(args.parser, args)
    if graft is not None and args.symmetric_reference:
        args.parser.error("--symmetric-reference is the normal valve: drop --graft-width/"
                          "--graft-height, or drop --symmetric-reference")
    from dataclasses import replace

    from valve_dolfinx._compat import MPI
    from valve_dolfinx.closure import CaseConfig, run_case
    from valve_dolfinx.geometry.valve import ValveParameters
    from valve_dolfinx.root import RootParameters
    from valve_dolfinx.solvers.dynamics import DynamicsParameters

    config = CaseConfig(geometry=ValveParameters(mesh_size=args.mesh_size),
                        root=RootParameters(loaded_diameter=args.root_diameter),
                        symmetric_reference=args.symmetric_reference, solver=args.solver)
    if graft is not None:
        config = config.with_graft(*graft)
    dynamics = {"wall_time_limit_s": args.wall_time_limit}
    if args.dt_min is not None:
        dynamics["dt_min"] = args.dt_min
    config = replace(config, dynamics=DynamicsParameters(**dynamics))
    comm = MPI.COMM_WORLD
    done = _finished_result(args.out, config)
    if done is not None and not args.force:
        if comm.rank == 0:
            print(f"{args.out}/result.json already holds this case (converged: "
                  f"{done['converged']}); --force recomputes it")
        return 0 if done["converged"] else 3
    update, close = _progress_bar(comm, config.dynamics.ramp_time,
                                  "" if config.solver == "relaxation" else "t = {n:.3g} s ")
    try:
        result = run_case(config, args.out, comm=comm, progress=update)
    finally:
        close()
    if comm.rank == 0:
        state = "converged" if result.converged else f"NOT converged ({result.solver_message})"
        print(f"{state}: central coaptation height {result.central_coaptation_height_mm:.2f} mm, "
              f"minimum {result.min_coaptation_height_mm:.2f} mm, regurgitant orifice "
              f"{result.regurgitant_orifice_area_mm2:.2f} mm², root diameter "
              f"{result.root_diameter_mm:.2f} mm; {result.wall_time_s:.0f} s -> {args.out}")
    return 0 if result.converged else 3


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
    p.set_defaults(func=_cmd_mesh, parser=p)

    p = sub.add_parser("run", help="close one valve under 80 mmHg and analyse its coaptation")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--symmetric-reference", action="store_true",
                   help="one leaflet against the two symmetry planes (the normal valve's "
                   "cheap reference of SPEC §4)")
    # closure.SOLVERS and CaseConfig.solver, spelled out: the parser does not import DOLFINx
    p.add_argument("--solver", choices=("dynamics+relaxation", "dynamics", "relaxation"),
                   default="dynamics+relaxation",
                   help="BDF2 until the valve is shut and dynamic relaxation to settle it "
                   "(the default), BDF2 damped dynamics to the end (SPEC §4), or explicit "
                   "dynamic relaxation alone (docs/closure.md)")
    p.add_argument("--wall-time-limit", type=float, default=3600.0, metavar="SECONDS",
                   help="stop (converged: false, results written) after this wall time")
    p.add_argument("--dt-min", type=float, default=None, metavar="SECONDS",
                   help="time-step floor below which the run counts as stalled")
    p.add_argument("--root-diameter", type=float, default=None, metavar="D",
                   help="prescribe the root diameter at 80 mmHg in mm (a patient's measured "
                   "root, 10-40 mm) instead of distending the root with its wall law")
    p.add_argument("--force", action="store_true",
                   help="recompute even if --out already holds this case's result.json")
    _add_geometry_args(p)
    p.set_defaults(func=_cmd_run, parser=p)

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
