"""Command-line entry point: ``valve-dolfinx <command> ...``.

Commands
--------
mesh    write the default valve meshes (normal and graft) for ParaView and reuse
run     close one valve (normal, or with a graft) under 80 mmHg and write
        result.json, config.toml, ParaView fields and figures to --out
sweep   the graft sizing study: the normal valve and every graft of a width x height
        grid, over any --vary / --uncertain settings and --paths numerical paths
        (resumable, spread over MPI ranks; --list / --case-index for job arrays)
nomogram  a sweep over loaded root diameters: the recommended graft against the
        diameter (nomogram.png, nomogram.csv)
report  rebuild a study folder's tables, figures, recommendations and report.md, or a
        plan folder's plan.md, plan.pdf, templates and summary.json
plan    one patient's repair from the measured root and leaflet: the recommended graft,
        its template at true size (SVG, PDF) and a one-page report (plan.md, plan.pdf)
config  print the case configuration as TOML, every setting with its unit and meaning

Settings: the defaults < --config FILE < --set table.key=value < the named flags
(--mesh-size, --graft-width, ...).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import sys
import time
from pathlib import Path

from valve_dolfinx.exceptions import ExitCode, NextRoundError, StudyIncompleteError
from valve_dolfinx.interrupts import interrupt_on_signals

__all__ = ["main"]

log = logging.getLogger("valve_dolfinx")


def _version() -> str:
    from valve_dolfinx._version import __version__

    return __version__


def _add_geometry_args(p: argparse.ArgumentParser) -> None:
    from valve_dolfinx.geometry.valve import DEFAULT_MESH_SIZE

    p.add_argument("--mesh-size", type=float, default=None, metavar="MM",
                   help=f"target triangle edge length in mm (default {DEFAULT_MESH_SIZE})")
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
    from valve_dolfinx.io import check_output_folder

    check_output_folder(args.out)
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.geometry.distributed import create_valve_domain, write_domain_xdmf
    from valve_dolfinx.geometry.outline import GraftSize
    from valve_dolfinx.geometry.valve import build_valve
    from valve_dolfinx.io import export_valve_vtu

    comm = MPI.COMM_WORLD
    cases = [(None, None)]
    if graft is not None:
        cases = [graft]
    elif args.defaults:
        cases = [(None, None), (21.0, 27.0)]
    for w, h in cases:
        name = "normal_valve" if w is None else f"graft_valve_{GraftSize(w, h).stem}"
        valve = None
        if comm.rank == 0:
            size = {} if args.mesh_size is None else {"mesh_size": args.mesh_size}
            valve = build_valve(graft_width_pct=w, graft_height_pct=h, **size)
            valve.save(args.out / f"{name}.npz")
            export_valve_vtu(valve, args.out / f"{name}.vtu")
        write_domain_xdmf(create_valve_domain(valve, comm), args.out / f"{name}.xdmf")
        if comm.rank == 0:
            log.info("wrote %s/%s.{npz,vtu,xdmf}", args.out, name)
    return 0


def _step_text(entry: dict) -> str:
    """One accepted step of the closure in words."""
    contacts = f"{entry.get('contacts', 0)} contacts"
    if "residual_mN" in entry:  # pseudo-transient continuation
        return (f"step {entry['step']}, Δτ {entry['dt']:.2g}, residual "
                f"{entry['residual_mN']:.2e} mN, {contacts}")
    return (f"step {entry['step']}, t = {entry['time']:.3g} s, dt {entry['dt']:.2g} s, "
            f"increment {entry['increment_mm']:.1e} mm, {contacts}")  # BDF2 dynamics


def _progress_bar(comm, enabled: bool = True):
    """A tqdm status line of the closure on rank 0 when stderr is a terminal; otherwise a
    debug log line per step (``-v``).  Nothing elsewhere, or with ``enabled`` false (``-q``)."""
    if comm.rank != 0 or not enabled:
        return lambda entry: None, lambda: None
    if not sys.stderr.isatty():
        return lambda entry: log.debug("closing: %s", _step_text(entry)), lambda: None
    from tqdm import tqdm

    bar = tqdm(total=None, desc="closing", dynamic_ncols=True,
               bar_format="{desc} [{elapsed}]")

    def update(entry: dict) -> None:
        bar.set_description_str(f"closing: {_step_text(entry)}", refresh=True)

    return update, bar.close


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", type=Path, default=None, metavar="CASE.TOML",
                   help="configuration file (TOML; `valve-dolfinx config` prints every key); "
                   "the flags given here override it")
    p.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                   dest="overrides",
                   help="override one setting, e.g. --set loading.pressure_mmhg=100 --set "
                   "geometry.mesh_size_mm=1.6 (repeatable)")


def _case_config(args: argparse.Namespace):
    """The case configuration of ``run``/``config``: defaults < --config < --set < flags."""
    from valve_dolfinx.config import WALL_CLOCK_KEY, load_config

    values: dict = {}
    if getattr(args, "mesh_size", None) is not None:
        values["geometry.mesh_size_mm"] = args.mesh_size
    graft = _graft_size(args.parser, args) if hasattr(args, "graft_width") else None
    if graft is not None:
        values["graft.width_pct"], values["graft.height_pct"] = graft
    if getattr(args, "root_diameter", None) is not None:
        values["root.loaded_diameter_mm"] = args.root_diameter
    if getattr(args, "solver", None) is not None:
        values["solver.method"] = args.solver
    if getattr(args, "symmetric_reference", False):
        values["geometry.symmetric_reference"] = True
    if getattr(args, "wall_time_limit", None) is not None:
        values[WALL_CLOCK_KEY] = args.wall_time_limit
    return load_config(args.config, args.overrides, values)


def _stored_result(out: Path, config, force: bool) -> dict | None:
    """The result.json already in ``out`` if it is this case's, finished and whole.

    Before any computation: raises if ``out`` cannot receive the outputs, or holds a
    finished case with other settings and ``force`` is not given.  A damaged case (a file
    missing or unreadable) is computed again with a warning naming the file.
    """
    from valve_dolfinx.exceptions import OutputConflictError
    from valve_dolfinx.io import check_output_folder
    from valve_dolfinx.result import check_case

    check_output_folder(out)
    if force:
        return None
    check = check_case(out, config)
    if check.state == "other":
        raise OutputConflictError(f"--out {out} holds the result of another case (other "
                                  "settings); give another folder, or --force to overwrite it")
    if check.state == "damaged":
        log.warning("%s: %s: computing the case again", out, check.reason)
    return check.result if check.finished else None


def _cmd_run(args: argparse.Namespace) -> int:
    graft = _graft_size(args.parser, args)
    if graft is not None and args.symmetric_reference:
        args.parser.error("--symmetric-reference is the normal valve: drop --graft-width/"
                          "--graft-height, or drop --symmetric-reference")
    config = _case_config(args)  # a bad setting stops here, before DOLFINx is imported
    valve = None
    if args.mesh is not None:
        if graft is not None or args.mesh_size is not None or args.symmetric_reference:
            args.parser.error("--mesh gives the valve and its geometry: drop --graft-width/"
                              "--graft-height/--mesh-size/--symmetric-reference")
        from dataclasses import replace

        from valve_dolfinx.geometry.valve import load_valve_mesh

        valve = load_valve_mesh(args.mesh)  # a missing or broken file stops here
        config = replace(config, geometry=valve.parameters)
    done = _stored_result(args.out, config, args.force)  # before the mesh is built
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.case import run_case
    from valve_dolfinx.result import competence_text

    comm = MPI.COMM_WORLD
    if done is not None:
        if comm.rank == 0:
            print(f"{args.out}/result.json already holds this case (converged: "
                  f"{done['converged']}); --force recomputes it")
        return ExitCode.OK if done["converged"] else ExitCode.NOT_CONVERGED
    update, close = _progress_bar(comm, enabled=not args.quiet)
    try:
        result = run_case(config, args.out, comm=comm, progress=update, valve=valve,
                          figures=not args.no_figures)
    finally:
        close()
    if comm.rank == 0:
        state = "converged" if result.converged else f"NOT converged ({result.solver_message})"
        print(f"{state}, {competence_text(result)}: central coaptation height "
              f"{result.central_coaptation_height_mm:.2f} mm, "
              f"minimum {result.min_coaptation_height_mm:.2f} mm, regurgitant orifice "
              f"{result.regurgitant_orifice_area_mm2:.2f} mm², root diameter "
              f"{result.root_diameter_mm:.2f} mm; {result.wall_time_s:.0f} s -> {args.out}")
    return ExitCode.OK if result.converged else ExitCode.NOT_CONVERGED


def _cmd_config(args: argparse.Namespace) -> int:
    from valve_dolfinx.config import config_toml

    sys.stdout.write(config_toml(_case_config(args)))
    return 0


def _study_settings(args: argparse.Namespace, compared: dict | None = None):
    """Study settings: defaults < --config (its [study] table and case settings) < --set
    (case settings) < command-line flags; ``compared`` adds comparison axes (already
    checked) for the nomogram."""
    from valve_dolfinx.config import apply_overrides
    from valve_dolfinx.study.grid import StudySettings, load_study_toml, parse_percentages

    if args.config:
        settings = load_study_toml(args.config, args.overrides)
    else:
        settings = StudySettings(case=apply_overrides({}, args.overrides), case_source="--set")
    changes = {"mesh_size_mm": args.mesh_size, "ranks_per_case": args.ranks_per_case,
               "target_coaptation_mm": args.target_coaptation,
               "wall_time_limit_s": args.wall_time_limit, "paths": args.paths,
               "budget": args.budget, "design": "adaptive" if args.adaptive else None}
    if args.widths is not None:
        changes["widths_pct"] = parse_percentages("--widths", args.widths, "width")
    if args.heights is not None:
        changes["heights_pct"] = parse_percentages("--heights", args.heights, "height")
    settings = settings.replace(**changes)  # the grid's and the paths' errors first
    vary, uncertain = {**settings.vary, **(compared or {})}, dict(settings.uncertain)
    _add_axes(args, settings.base_case(), vary, uncertain)
    return settings.replace(vary=vary, uncertain=uncertain)


def _add_axes(args: argparse.Namespace, base: dict, vary: dict, uncertain: dict) -> None:
    """Add the --vary and --uncertain axes to ``vary`` and ``uncertain``, checked, each key
    once (also against the configuration file's axes and --set)."""
    from valve_dolfinx.exceptions import ParameterError
    from valve_dolfinx.study.axes import check_axis_values, parse_axis_option

    fixed = {text.partition("=")[0].strip(): text for text in args.overrides}
    for option, axes, texts in (("--vary", vary, args.vary),
                                ("--uncertain", uncertain, args.uncertain)):
        for text in texts:
            key, values = parse_axis_option(option, text)
            if key in vary or key in uncertain:
                raise ParameterError(f"{option} {key}: {key} is already an axis (given twice, "
                                     "or also in the [study] table or --root-diameters); give "
                                     "each key once")
            if key in fixed:
                raise ParameterError(f"{option} {key}: --set {fixed[key]} fixes it too; drop "
                                     "one of them")
            axes[key] = check_axis_values(option, key, values, base)


def _quiet_library(comm, verbose: bool, quiet: bool = False) -> None:
    """Rank 0 alone prints; the study's one line per case, not every solver's log."""
    library = logging.getLogger("valve_dolfinx")
    if comm.rank != 0:
        library.setLevel(logging.ERROR)
    elif not verbose:
        library.setLevel(logging.WARNING)
        logging.getLogger("valve_dolfinx.study").setLevel(
            logging.WARNING if quiet else logging.INFO)


def _sweep_bar(comm, enabled: bool):
    """(progress callback, close) drawing one tqdm bar of cases done/total on rank 0."""
    if comm.rank != 0 or not enabled:
        return None, lambda: None
    from tqdm import tqdm

    state: dict = {}

    def progress(event: dict) -> None:
        if event["event"] == "start":
            state["bar"] = tqdm(total=event["total"], initial=event["done"], unit="case",
                                desc="sweep", dynamic_ncols=True)
        elif event["event"] == "end":
            close()
        elif "bar" in state:
            state["bar"].update(event["done"] - state["bar"].n)
            state["bar"].set_postfix_str(f"last {event['case']}")

    def close() -> None:
        if "bar" in state:
            state.pop("bar").close()

    return progress, close


@contextlib.contextmanager
def _case_progress(comm, enabled: bool):
    """The tqdm bar of cases done (rank 0, when ``enabled`` and stderr is a terminal), the
    log lines routed above it; yields the progress callback (None without a bar)."""
    progress, close = _sweep_bar(comm, enabled and sys.stderr.isatty())
    try:
        if progress is None:
            yield None
        else:
            from tqdm.contrib.logging import logging_redirect_tqdm

            with logging_redirect_tqdm(loggers=[logging.getLogger()]):
                yield progress
    finally:
        close()


def _cmd_sweep(args: argparse.Namespace) -> int:
    settings = _study_settings(args)  # a bad grid stops here, before DOLFINx is imported
    return _run_sweep(args, settings)


def _cmd_nomogram(args: argparse.Namespace) -> int:
    from valve_dolfinx.exceptions import ParameterError
    from valve_dolfinx.study.axes import check_axis_values
    from valve_dolfinx.study.nomogram import NOMOGRAM_KEY

    diameters = check_axis_values("--root-diameters", NOMOGRAM_KEY,
                                  ",".join(args.root_diameters), {})
    if None in diameters:
        raise ParameterError("--root-diameters: give loaded root diameters in mm (10-40); "
                             "'none', the root distended by its wall law, has no diameter")
    diameters = tuple(sorted(diameters))  # the study and its figure by increasing diameter
    settings = _study_settings(args, {NOMOGRAM_KEY: diameters})
    if list(settings.vary) != [NOMOGRAM_KEY]:
        raise ParameterError(f"{args.config} [study] vary: the nomogram's comparison axis is the "
                             "root diameter (--root-diameters); move the others to uncertain")
    return _run_sweep(args, settings)


def _run_sweep(args: argparse.Namespace, settings) -> int:
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.study.runner import run_study, study_status

    comm = MPI.COMM_WORLD
    _quiet_library(comm, args.verbose, args.quiet)
    if args.list:
        rows = study_status(settings, args.out)
        if comm.rank == 0:
            width = max([4, *(len(case.name) for case, _ in rows)])
            print(f"{'index':>5}  {'case':<{width}} {'W %':>6} {'H %':>6}  status in {args.out}")
            for case, state in rows:
                w = "" if case.is_normal else f"{case.width_pct:g}"
                h = "" if case.is_normal else f"{case.height_pct:g}"
                print(f"{case.index:>5}  {case.name:<{width}} {w:>6} {h:>6}  {state}")
        return 0
    indices = None if args.case_index is None else [args.case_index]
    with _case_progress(comm, not args.no_progress and indices is None) as progress:
        outcome = run_study(settings, args.out, comm, case_indices=indices,
                            progress=progress, report=indices is None,
                            figures=not args.no_figures, wait=not args.no_wait)
    if comm.rank == 0:
        print(f"{len(outcome.computed)} case(s) computed, {len(outcome.cases)} in the "
              f"selection; {outcome.elapsed_s:.0f} s -> {args.out}")
        if outcome.report is not None:
            print(outcome.report.text)
            print(f"report: {args.out / 'report.md'}")
            if (args.out / "nomogram.png").is_file():
                print(f"nomogram: {args.out / 'nomogram.png'}, {args.out / 'nomogram.csv'}")
    if outcome.in_progress:
        held = ", ".join(f"{name} ({who})" for name, who in outcome.in_progress.items())
        raise StudyIncompleteError(f"{len(outcome.in_progress)} case(s) in progress in another "
                                   f"process: {held}; no answer written (--no-wait): rerun "
                                   "without --no-wait to wait for them")
    if outcome.failed:
        raise StudyIncompleteError(f"{len(outcome.failed)} case(s) failed: "
                                   f"{', '.join(outcome.failed)}; the report gives each reason "
                                   "(a rerun skips them: delete their folders to retry)")
    if outcome.report is not None and not outcome.report.complete:
        raise StudyIncompleteError(f"{args.out}: {outcome.report.incomplete_text}")
    return 0


def _cmd_report(args: argparse.Namespace) -> int:
    from valve_dolfinx.exceptions import InputFileError, check_range
    from valve_dolfinx.plan.patient import PATIENT_FILE
    from valve_dolfinx.plan.runner import STUDY_DIR
    from valve_dolfinx.study.grid import TARGET_COAPTATION_MAX_MM
    from valve_dolfinx.study.store import CASES_DIR

    target = args.target_coaptation
    if (args.dir / PATIENT_FILE).is_file():
        return _report_plan(args)
    if target is not None:
        check_range("--target-coaptation", target, 0.0, TARGET_COAPTATION_MAX_MM,
                    low_open=True, unit="mm")
    if (args.dir / STUDY_DIR).is_dir() and not (args.dir / CASES_DIR).is_dir():
        raise InputFileError(f"{args.dir} holds a plan's {STUDY_DIR}/ but no {PATIENT_FILE}: a "
                             f"plan folder is reported from its {PATIENT_FILE} (rerun "
                             f"`valve-dolfinx plan PATIENT.toml --out {args.dir}`), or give the "
                             f"study folder itself ({args.dir / STUDY_DIR})")
    from valve_dolfinx.study.report import build_report
    from valve_dolfinx.study.rounds import append_round

    report = build_report(args.dir, target_mm=target)
    print(f"{len(report.rows)} case(s)" + "".join(
        f"; {why}: {', '.join(names)}" for why, names in report.unfinished.items()))
    print(report.text)
    print(f"report: {args.dir / 'report.md'}")
    if not report.complete:
        raise StudyIncompleteError(
            f"{args.dir}: {report.incomplete_text} report.md lists them and why" if report.rows
            else f"{args.dir}: no case has finished yet; run `valve-dolfinx sweep --out "
            f"{args.dir}`")
    plan = report.next_round
    if plan is not None and plan.points and target is None:
        append_round(args.dir, plan)
        raise NextRoundError(f"{args.dir}: round {plan.rounds} written, {plan.new_cases} new "
                             "case(s): run them (`valve-dolfinx sweep ... --list` gives their "
                             "indices, or a sweep runs them all), then `valve-dolfinx report` "
                             "again")
    return 0


def _report_plan(args: argparse.Namespace) -> int:
    """``report DIR`` on a plan folder: its plan rebuilt from patient.toml and the cases."""
    from valve_dolfinx.exceptions import ParameterError
    from valve_dolfinx.plan.runner import rebuild_plan

    if args.target_coaptation is not None:
        raise ParameterError(f"--target-coaptation: {args.dir} is a plan; its target is "
                             "target_coaptation_mm in its patient.toml (rerun `valve-dolfinx "
                             "plan` with --target-coaptation to change it)")
    _print_plan(rebuild_plan(args.dir))
    return 0


def _print_plan(outcome) -> None:
    """The plan's answer and its files, as ``plan`` and ``report`` print them."""
    print(outcome.answers.headline())
    for line in outcome.answers.lines():
        print(line)
    print(f"plan: {outcome.out / 'plan.pdf'}, {outcome.out / 'plan.md'}")
    for template in outcome.templates:
        print(f"template {template.graft.label}: {template.pdf} (print at 100 %)")


def _add_grid_args(p: argparse.ArgumentParser) -> None:
    """The graft grid, the cases' mesh and wall-clock limit, and the progress bar: the
    options ``sweep``, ``nomogram`` and ``plan`` share."""
    p.add_argument("--widths", nargs="*", default=None, metavar="W",
                   help="graft width enlargements in per cent (default 0 7 14 21 27)")
    p.add_argument("--heights", nargs="*", default=None, metavar="H",
                   help="graft height enlargements in per cent (default 0 13 27 40)")
    p.add_argument("--mesh-size", type=float, default=None, metavar="MM",
                   help="target triangle edge length in mm (default: the case default)")
    p.add_argument("--wall-time-limit", type=float, default=None, metavar="SECONDS",
                   help="wall-clock limit of each case (default: the case default)")
    p.add_argument("--no-progress", action="store_true",
                   help="plain log lines, no progress bar (batch jobs)")
    p.add_argument("--no-wait", action="store_true",
                   help="do not wait for the cases another process is computing in --out: "
                   "end with status 9 naming them, writing no answer (default: wait)")
    p.add_argument("--budget", type=int, default=None, metavar="N",
                   help="the most graft cases an adaptive design solves per comparison value "
                   "(default 40)")


def _add_sweep_args(p: argparse.ArgumentParser, out: str, paths: int | None) -> None:
    _add_grid_args(p)
    p.add_argument("--uncertain", action="append", default=[], metavar="KEY=V1,V2",
                   help="an uncertainty axis: values of KEY that are not known, e.g. "
                   "--uncertain root.loaded_diameter_mm=20,21,22; the recommendation holds for all "
                   "of them (repeatable)")
    p.add_argument("--adaptive", action="store_true",
                   help="solve a small design over the grid's width and height range, then "
                   "rounds of cases chosen by the fitted surface until the answer is settled "
                   "or --budget is spent, instead of every graft of the grid (docs/study.md)")
    p.add_argument("--paths", type=int, default=paths, metavar="N",
                   help="solve every graft along the first N numerical paths (1: from the "
                   "closed normal valve, 2: from the open valve, billowed, 3: from the open "
                   "valve, conformal; an uncertainty axis; default "
                   f"{paths if paths else 'the [study] table, else 1'})")
    p.add_argument("--out", type=Path, default=Path(out),
                   help="study folder (default %(default)s)")
    p.add_argument("--config", type=Path, default=None, metavar="STUDY.TOML",
                   help="configuration file: a case configuration (`valve-dolfinx config`) "
                   "applied to every case, with a [study] table for the grid (flags given "
                   "here override it)")
    p.add_argument("--set", action="append", default=[], metavar="TABLE.KEY=VALUE",
                   dest="overrides",
                   help="override one case setting of every case (repeatable)")
    p.add_argument("--ranks-per-case", type=int, default=None, metavar="K",
                   help="MPI ranks per case: mpirun -n N runs N/K cases at a time (default 1)")
    p.add_argument("--target-coaptation", type=float, default=None, metavar="MM",
                   help="minimum coaptation height a graft must reach (default: the normal "
                   "valve's)")
    p.add_argument("--no-figures", action="store_true",
                   help="draw no case figures (batch runs: a case's figures cost seconds); "
                   "by default the cases the report's panels show draw theirs")
    p.add_argument("--list", action="store_true",
                   help="print the cases with their index and state, and exit")
    p.add_argument("--case-index", type=int, default=None, metavar="I",
                   help="run case I only (see --list; for job arrays), no report")


#: plan flags -> the PatientInput keys they set (plan.patient.FIELDS lists each key's flag)
_PATIENT_FLAGS = {"root_diameter": "root_diameter_mm", "root_uncertainty": "root_uncertainty_mm",
                  "leaflet_free_edge": "leaflet_free_edge_mm",
                  "leaflet_height": "leaflet_height_mm", "pressure": "pressure_mmhg",
                  "widths": "graft_widths_pct", "heights": "graft_heights_pct",
                  "target_coaptation": "target_coaptation_mm",
                  "graft_fibre_angle": "graft_fibre_angle_deg", "paths": "paths",
                  "mesh_size": "mesh_size_mm", "wall_time_limit": "wall_time_limit_s",
                  "label": "label", "design": "design", "budget": "budget"}


def _patient(args: argparse.Namespace):
    """The patient of ``plan``: PATIENT.toml with the flags over it, or the flags alone;
    ``--vary`` adds comparison axes to the file's ``vary``."""
    from dataclasses import replace

    from valve_dolfinx.exceptions import ParameterError
    from valve_dolfinx.plan.patient import patient_from_mapping, read_patient
    from valve_dolfinx.study.axes import parse_axis_option

    flags = {key: getattr(args, dest) for dest, key in _PATIENT_FLAGS.items()
             if getattr(args, dest) is not None}
    if args.patient is not None:
        patient = read_patient(args.patient, flags)
    else:
        patient = patient_from_mapping(flags, source="command line")
    vary = dict(patient.vary)
    for text in args.vary:
        key, values = parse_axis_option("--vary", text)
        if key in vary:
            raise ParameterError(f"--vary {key}: {key} is already an axis (given twice, or "
                                 "also in the patient file's vary); give each key once")
        vary[key] = values
    return replace(patient, vary=vary) if args.vary else patient


def _cmd_plan(args: argparse.Namespace) -> int:
    from valve_dolfinx.geometry.outline import GraftSize
    from valve_dolfinx.plan.runner import plan_study_settings

    patient = _patient(args)  # every bad input stops here, before DOLFINx is imported
    templates = [GraftSize.parse(text) for text in args.template]
    plan_study_settings(patient)
    from valve_dolfinx._compat import MPI
    from valve_dolfinx.plan.runner import run_plan

    comm = MPI.COMM_WORLD
    _quiet_library(comm, args.verbose, args.quiet)
    logging.getLogger("valve_dolfinx.plan").setLevel(
        logging.getLogger("valve_dolfinx.study").getEffectiveLevel())
    with _case_progress(comm, not args.no_progress) as progress:
        outcome = run_plan(patient, args.out, comm, templates=templates, force=args.force,
                           progress=progress, wait=not args.no_wait)
    if comm.rank == 0:
        _print_plan(outcome)
    return 0


def _add_plan_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("patient", nargs="?", type=Path, default=None, metavar="PATIENT.toml",
                   help="the measured inputs (docs/plan.md lists the keys); the flags below "
                   "override them, or give them all without a file")
    p.add_argument("--out", type=Path, required=True, help="plan folder (created)")
    p.add_argument("--root-diameter", type=float, default=None, metavar="D",
                   help="loaded root diameter at the base in mm, on echo or CT (16-35)")
    p.add_argument("--root-uncertainty", type=float, default=None, metavar="U",
                   help="± uncertainty of the root diameter in mm (default 1)")
    p.add_argument("--leaflet-free-edge", type=float, default=None, metavar="L",
                   help="free edge of the excised non-coronary leaflet, measured flat, in mm "
                   "(default: the SPEC §1 leaflet's 20.94 mm)")
    p.add_argument("--leaflet-height", type=float, default=None, metavar="H",
                   help="midline height of the excised leaflet in mm (default 12.41)")
    p.add_argument("--pressure", type=float, default=None, metavar="MMHG",
                   help="diastolic pressure in mmHg (default 80)")
    _add_grid_args(p)
    p.add_argument("--target-coaptation", type=float, default=None, metavar="MM",
                   help="minimum coaptation height a graft must reach (default: the normal "
                   "valve's at the same root)")
    p.add_argument("--graft-fibre-angle", type=float, default=None, metavar="DEG",
                   help="the graft's fibre direction from its free edge (default 0: parallel)")
    p.add_argument("--paths", type=int, default=None, metavar="N",
                   help="solve every graft along the first N of the study's numerical paths "
                   "(docs/study.md, Paths); the recommendation takes the worst (default 2)")
    p.add_argument("--full-grid", action="store_const", const="grid", default=None,
                   dest="design",
                   help="solve every graft of the grid in every member instead of the "
                   "adaptive design (about four times the cases)")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2",
                   help="a comparison axis: the plan answers at each value of the case "
                   "setting KEY that is not measured, e.g. --vary "
                   "graft.bending_modulus_kpa=200,2000 (repeatable: every combination, at "
                   "most 3; docs/plan.md)")
    p.add_argument("--label", default=None, help="plan name printed on the template and the "
                   "report (no identifying data needed)")
    p.add_argument("--template", action="append", default=[], metavar="W/H",
                   help="also draw the template of this graft, e.g. 21/27 (repeatable)")
    p.add_argument("--force", action="store_true",
                   help="replace the plan of other inputs or settings in --out: its answer, "
                   "templates and study report are removed before anything is computed")


#: seconds an MPI rank that fails waits, after writing its error line, before it aborts
#: every rank (the process manager forwards the line meanwhile)
ABORT_GRACE_S = 0.5

_EXIT_STATUS = """exit status:
  0    success
  1    internal error (a bug): rerun with -v and report the traceback
  2    usage, configuration or parameter error (the message names the option or key)
  3    run: the case ran but did not converge (results written with converged: false)
  4    an input file is missing, unreadable or not what it should be
  5    a solver failed, or raised in one of its callbacks: no result written
  6    --out holds another case's results or plan (nothing computed; --force overwrites)
  7    --out, or a folder above it, is a file (nothing computed)
  8    --out (or report's DIR) cannot be created or written (nothing computed)
  9    sweep, nomogram, plan, report: a case failed, is damaged, stale, not run or in
       progress in another process: no answer written (report.md says which and why)
  10   report: the study's next round was written (an answer to confirm, or an adaptive
       design's cases): run its cases, then report again
  130  interrupted (SIGINT, Ctrl-C): nothing unfinished recorded; rerun to continue
  143  terminated (SIGTERM): the same
Under mpirun, an error on any rank ends every rank with that status."""


def _add_logging_args(p: argparse.ArgumentParser, top: bool) -> None:
    """-v/-q/--log-file, before the command or after it (a command's copy does not
    overwrite what was given before it)."""
    unset = {} if top else {"default": argparse.SUPPRESS}
    loud = p.add_mutually_exclusive_group()
    loud.add_argument("-v", "--verbose", action="store_true", **unset,
                      help="debug logging, and the traceback of an error")
    loud.add_argument("-q", "--quiet", action="store_true", **unset,
                      help="warnings and errors only")
    p.add_argument("--log-file", type=Path, metavar="PATH", **unset,
                   help="append the log to PATH as well")


def _one_line(err: BaseException) -> str:
    """The error as one line: what went wrong, about which file or parameter, what to do."""
    from valve_dolfinx.exceptions import ValveError

    if isinstance(err, KeyboardInterrupt):
        name = signal.Signals(getattr(err, "signum", signal.SIGINT)).name
        return (f"interrupted ({name}); nothing unfinished was recorded: rerun the same "
                "command to continue (finished results are kept)")
    if isinstance(err, OSError) and not isinstance(err, ValveError) and err.filename:
        text = (f"{err.filename}: {err.strerror or err}; check the path and its permissions")
    else:
        text = " ".join(str(err).split()) or type(err).__name__
    if isinstance(err, ValveError | OSError):
        return text
    if not isinstance(err, ValueError):
        text = f"internal error ({type(err).__name__}: {text})"
    return f"{text}; rerun with -v for the traceback"


def _fail(err: BaseException, verbose: bool) -> int:
    """Log ``err`` in one line (with its traceback under -v) and return its exit status;
    under MPI with more than one rank, end every rank with it instead of returning."""
    from valve_dolfinx.exceptions import exit_code
    from valve_dolfinx.logs import world_rank_size

    code = int(exit_code(err))
    log.error("error: %s", _one_line(err), exc_info=err if verbose else None)
    if world_rank_size()[1] > 1 and "mpi4py.MPI" in sys.modules:
        mpi = sys.modules["mpi4py.MPI"]
        if mpi.Is_initialized() and not mpi.Is_finalized():
            for handler in logging.getLogger().handlers:
                handler.flush()
            sys.stdout.flush()
            sys.stderr.flush()
            # the process manager forwards the error line through a pipe that the abort
            # closes: give it time to read the line before every rank is killed
            time.sleep(ABORT_GRACE_S)
            mpi.COMM_WORLD.Abort(code)  # the other ranks may wait in a collective call
    return code


def _parser() -> argparse.ArgumentParser:
    """The command line: every command with its options."""
    parser = argparse.ArgumentParser(prog="valve-dolfinx", description=__doc__,
                                     epilog=_EXIT_STATUS,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("mesh", help="write valve meshes (.npz to reload, .vtu/.xdmf for ParaView)")
    p.add_argument("--out", type=Path, default=Path("meshes"))
    p.add_argument("--defaults", action="store_true",
                   help="write the normal valve and the W21/H27 graft valve")
    _add_geometry_args(p)
    p.set_defaults(func=_cmd_mesh, parser=p)

    _add_run_command(sub)

    p = sub.add_parser("sweep", help="graft sizing study: normal valve + width x height grid")
    p.add_argument("--vary", action="append", default=[], metavar="KEY=V1,V2",
                   help="a comparison axis: a table, maps and a recommendation per value of the "
                   "case setting KEY (as --set takes it), e.g. --vary "
                   "native.bending_modulus_kpa=0,200 (repeatable: every combination)")
    _add_sweep_args(p, "results/graft_sweep", None)
    p.set_defaults(func=_cmd_sweep, parser=p)

    p = sub.add_parser("nomogram", help="the recommended graft against the loaded root "
                       "diameter: a sweep over --root-diameters (nomogram.png, nomogram.csv)")
    p.add_argument("--root-diameters", nargs="+", required=True, metavar="D",
                   help="loaded root diameters at 80 mmHg in mm (10-40), e.g. 18 19 20 21 22 23")
    _add_sweep_args(p, "results/nomogram", 2)
    p.set_defaults(func=_cmd_nomogram, parser=p, vary=[])  # the diameters are the comparison

    p = sub.add_parser("report", help="rebuild a study folder's tables, figures and report, "
                       "or a plan folder's plan, templates and summary")
    p.add_argument("dir", type=Path, help="study folder written by `valve-dolfinx sweep`, or "
                   "plan folder written by `valve-dolfinx plan`")
    p.add_argument("--target-coaptation", type=float, default=None, metavar="MM",
                   help="minimum coaptation height a graft must reach (default: the normal "
                   "valve's, or the study's)")
    p.set_defaults(func=_cmd_report, parser=p)

    p = sub.add_parser("plan", help="plan one patient's repair: the recommended graft from the "
                       "measured root and leaflet, its template at true size, a one-page report")
    _add_plan_args(p)
    p.set_defaults(func=_cmd_plan, parser=p)

    p = sub.add_parser("config", help="print the case configuration as TOML (defaults, or "
                       "--config with --set applied), every key with its unit and meaning")
    _add_config_args(p)
    p.set_defaults(func=_cmd_config, parser=p)

    _add_logging_args(parser, top=True)
    for command in sub.choices.values():
        _add_logging_args(command, top=False)
    return parser


def _add_run_command(sub) -> None:
    """``valve-dolfinx run``: one case."""
    p = sub.add_parser("run", help="close one valve under 80 mmHg and analyse its coaptation")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--symmetric-reference", action="store_true",
                   help="one leaflet against the two symmetry planes (the normal valve's "
                   "cheap reference of SPEC §4)")
    # config.SOLVERS, spelled out: the parser imports nothing of the package
    p.add_argument("--solver", choices=("ptc", "bdf2"), default=None,
                   help="pseudo-transient continuation to the static equilibrium (the "
                   "default), or damped BDF2 dynamics (SPEC §4, the cross-check)")
    p.add_argument("--wall-time-limit", type=float, default=None, metavar="SECONDS",
                   help="stop (converged: false, results written) after this wall time "
                   "(default: the solver's, 900 s)")
    p.add_argument("--root-diameter", type=float, default=None, metavar="D",
                   help="prescribe the root diameter at 80 mmHg in mm (a patient's measured "
                   "root, 10-40 mm) instead of distending the root with its wall law")
    p.add_argument("--force", action="store_true",
                   help="recompute even if --out already holds this case's result.json, or "
                   "overwrite another case's result there")
    p.add_argument("--mesh", type=Path, default=None, metavar="VALVE.npz",
                   help="close this valve mesh (written by `valve-dolfinx mesh`) instead of "
                   "building one; its geometry replaces the configuration's")
    p.add_argument("--no-figures", action="store_true",
                   help="write result.json, config.toml, history.csv and fields.vtu but no "
                   "PNG figures (batch runs: drawing them costs seconds)")
    _add_config_args(p)
    _add_geometry_args(p)
    p.set_defaults(func=_cmd_run, parser=p)


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    if args.verbose and args.quiet:
        parser.error("-v/--verbose and -q/--quiet contradict each other: give one")
    from valve_dolfinx.logs import configure_logging

    try:
        logs = configure_logging(1 if args.verbose else -1 if args.quiet else 0, args.log_file)
    except OSError as err:
        parser.error(f"--log-file {args.log_file}: {err.strerror or err}; give a writable path")
    with logs, interrupt_on_signals():
        try:
            return args.func(args)
        except (Exception, KeyboardInterrupt) as err:
            return _fail(err, args.verbose)


if __name__ == "__main__":
    sys.exit(main())
