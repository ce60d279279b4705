"""Running a sizing study: every case once, spread over MPI ranks, resumable (SPEC §7).

Parallel layout
---------------
``mpirun -n N`` with ``ranks_per_case = k`` splits ``COMM_WORLD`` into ``N / k``
groups (``comm.Split``); each group runs one case at a time on its own
communicator.  Load balancing is dynamic: a group that finishes a case takes
the next case nobody has claimed yet (the claim is an ``O_EXCL`` file,
:class:`~valve_dolfinx.study.store.CaseClaim`), so a slow graft case does not
hold up the cheap ones behind it, and two sweeps (or job-array tasks) on the
same folder share the work instead of repeating it.  Each case is computed on
its own communicator exactly as a single run would be, so at one rank per case
the results equal a serial sweep's bit for bit.

Warm starts
-----------
A case may start from another case's loaded state (``StudyCase.start_from``, set by
a numerical path, :mod:`~valve_dolfinx.study.paths`).  Such a case is started only
once its source has finished: a group that reaches it claims and computes the
source first, or, if another process holds the source's claim, takes other cases
and comes back to it.  The case function receives the source's folder
(``start=``).  The source is a fixed function of the study, so a serial sweep,
``mpirun -n N`` and a job array compute the same cases from the same starts;
with ``--case-index`` a task computes the selected case's source too, unless it
is finished or being computed.

Resuming
--------
A finished case records its identity (``case.json``'s ``config_hash``, the
settings hash) and the size of every file it wrote; a rerun skips it if
:func:`~valve_dolfinx.result.check_case` finds it whole with an unchanged
identity, and recomputes it otherwise (a damaged case with a warning naming the
file).  A case is written atomically when it finishes (staging folder renamed
into place), so killing a sweep loses only the cases in flight.  A case that
raises or does not converge is recorded with its reason and the sweep goes on;
an interrupt (SIGINT, SIGTERM) stops the sweep, records nothing for the cases
in flight and releases their claims.

Progress
--------
World rank 0 watches the case folders (a background thread; no MPI calls)
and logs one line per finished case, whichever group computed it; an
optional ``progress`` callback receives the same events (the CLI draws its
bar from them).
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import socket
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from valve_dolfinx._compat import MPI, package_versions
from valve_dolfinx._version import __version__, git_commit
from valve_dolfinx.exceptions import ParameterError, ValveError
from valve_dolfinx.interrupts import deferred_signals, raise_pending
from valve_dolfinx.io import write_json
from valve_dolfinx.result import CaseResult, competence_text, load_case
from valve_dolfinx.study.grid import StudySettings
from valve_dolfinx.study.layout import ROUNDS_FILE, StudyCase, StudyLayout, read_rounds
from valve_dolfinx.study.report import SWEEP_LOG, StudyReport, build_report
from valve_dolfinx.study.rounds import append_round
from valve_dolfinx.study.store import (
    RESULT_FILE,
    SETTINGS_FILE,
    CaseClaim,
    ClaimHeartbeat,
    case_dir,
    check_study_case,
    claim_owner,
    commit_case,
    owner_text,
    prepare_output,
    staging_dir,
)

if TYPE_CHECKING:
    from valve_dolfinx.config import CaseConfig

__all__ = [
    "CaseFunction",
    "SweepOutcome",
    "run_study",
    "run_closure_case",
    "study_status",
]

log = logging.getLogger(__name__)


class CaseFunction(Protocol):
    """What computes one case of a study, on its rank group, into a fresh folder.

    ``config`` is the case's configuration, ``out_dir`` the (staging) folder to write
    into, ``comm`` the group's communicator, and ``start`` the finished folder of the case
    whose loaded state this one starts from (``StudyCase.start_from``; ``None``: the
    unloaded valve).  It returns the case's result (``CaseResult.to_dict()``), which the
    runner writes as ``result.json`` unless the function already did.
    """

    def __call__(self, config: CaseConfig, out_dir: Path, comm: MPI.Comm, *,
                 start: Path | None) -> dict: ...


#: ``progress(event)``: ``{"event": "start" | "case" | "end", "done", "total"}``; a "case"
#: event also has the ``case`` name and its result ``row``
ProgressCallback = Callable[[dict], None]


def run_closure_case(config, out_dir: Path, comm: MPI.Comm, *, start: Path | None = None,
                     figures: bool = True, fields_output: bool = True) -> dict:
    """The study's case: :func:`valve_dolfinx.case.run_case` into ``out_dir``.

    ``start``: the finished case folder whose loaded state the closure starts from (a
    numerical path's warm start); a source that did not converge is no start, and the
    case then takes the path of a case without one (:func:`valve_dolfinx.case.solve_case`).
    """
    from valve_dolfinx.case import run_case

    return run_case(config, out_dir, comm=comm, figures=figures, fields_output=fields_output,
                    start=_loaded_start(start)).to_dict()


def _loaded_start(folder: Path | None):
    """The loaded valve of a finished case folder as a closure's start, or None."""
    from valve_dolfinx.geometry.transfer import ValveState  # SciPy's k-d tree: when needed

    if folder is None:
        return None
    source = load_case(folder)
    if not source.result.converged:
        log.info("%s did not converge: not a start", folder.name)
        return None
    return ValveState(source.valve, source.positions, f"the loaded state of {folder.name}")


def _failure_result(case: StudyCase, config, error: str, n_ranks: int, wall: float) -> dict:
    """result.json of a case that raised: the SPEC fields unknown, the reason recorded."""
    result = CaseResult(graft_width_pct=case.width_pct, graft_height_pct=case.height_pct,
                        converged=False, competence_reason="the case failed",
                        n_ranks=n_ranks, wall_time_s=wall,
                        solver_message=error, parameters=config.to_dict(),
                        versions=package_versions(), settings_hash=config.settings_hash(),
                        version=__version__, git_commit=git_commit()).to_dict()
    result["error"] = error
    return result


def _now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


def case_line(name: str, row: dict, done: int | None = None, total: int | None = None) -> str:
    """One log line with a finished case's coaptation numbers."""
    def num(key: str, fmt: str) -> str:
        v = row.get(key)
        return format(v, fmt) if isinstance(v, int | float) and math.isfinite(v) else "–"

    count = f"[{done}/{total}] " if done is not None else ""
    if row.get("error"):
        return f"{count}{name}: FAILED ({row['error']})"
    state = "converged" if row.get("converged") else "NOT converged"
    return (f"{count}{name}: {state}, {competence_text(row)}, min coaptation "
            f"{num('min_coaptation_height_mm', '.2f')} mm, central "
            f"{num('central_coaptation_height_mm', '.2f')} mm, area "
            f"{num('coaptation_area_mm2', '.0f')} mm², {num('wall_time_s', '.0f')} s")


class _Monitor:
    """Rank 0's watcher of the case folders: one log line and one progress event per case."""

    def __init__(self, out: Path, cases: list[StudyCase], layout: StudyLayout,
                 progress: ProgressCallback | None, poll_s: float) -> None:
        self.out, self.cases, self.layout = out, cases, layout
        self.progress, self.poll_s = progress, poll_s
        self.done = {c.name for c in cases if self._finished(c.name) is not None}
        self.initial = len(self.done)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="study-monitor")

    def start(self) -> None:
        if self.initial:
            log.info("%d of %d cases already finished with this configuration: skipped",
                     self.initial, len(self.cases))
        if self.progress:
            self.progress({"event": "start", "done": self.initial, "total": len(self.cases)})
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(self.poll_s):
            self.scan()

    def _finished(self, name: str) -> dict | None:
        """The result of case ``name`` if its folder holds it finished and whole."""
        check = _check(self.out, self.layout, name)
        return check.result if check.finished else None

    def scan(self) -> None:
        for case in self.cases:
            if case.name in self.done:
                continue
            row = self._finished(case.name)
            if row is None:
                continue
            self.done.add(case.name)
            log.info("%s", case_line(case.name, row, len(self.done), len(self.cases)))
            if self.progress:
                self.progress({"event": "case", "case": case.name, "row": row,
                               "done": len(self.done), "total": len(self.cases)})

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)
        self.scan()
        if self.progress:
            self.progress({"event": "end", "done": len(self.done), "total": len(self.cases)})


@dataclass
class SweepOutcome:
    """What :func:`run_study` did (the same on every rank)."""

    out: Path
    cases: list[StudyCase]
    computed: list[str] = field(default_factory=list)
    elapsed_s: float = 0.0
    report: StudyReport | None = None
    #: the cases of the selection recorded as failed (they raised): the study is incomplete
    failed: list[str] = field(default_factory=list)
    #: the cases of the selection left unfinished to another live process (``wait=False``),
    #: with who computes them
    in_progress: dict[str, str] = field(default_factory=dict)


def _check(out: Path, layout: StudyLayout, name: str):
    """The resume check of case ``name`` (:func:`~valve_dolfinx.result.check_case`)."""
    return check_study_case(out, name, layout.configs[name], layout.digests[name])


def _decide(out: Path, case: StudyCase, layout: StudyLayout, beat: ClaimHeartbeat, run: str
            ) -> tuple[CaseClaim | None, Path | None]:
    """Leader: claim the case (for the run ``run``) if it is unfinished and unclaimed; its
    staging folder."""
    if _check(out, layout, case.name).finished:
        return None, None
    claim = CaseClaim.for_case(out, case.name, run)
    if not claim.acquire():
        log.debug("%s is being computed by another process", case.name)
        return None, None
    check = _check(out, layout, case.name)
    if check.finished:  # finished between the test and the claim
        claim.release()
        return None, None
    if check.state == "damaged":
        log.warning("%s: %s: recomputing", case_dir(out, case.name), check.reason)
    elif check.state != "empty":
        log.info("%s: configuration changed since it was computed (%s): recomputing",
                 case.name, check.reason)
    beat.add(claim)
    return claim, staging_dir(out, case.name)


def _run_one(case: StudyCase, config, digest: str, staging: Path, group: MPI.Comm,
             case_function: CaseFunction, out: Path) -> None:
    """Compute one case on ``group`` into ``staging``; the leader records and commits it."""
    started, t0 = _now(), time.perf_counter()
    error, result = None, None
    start = case_dir(out, case.start_from) if case.start_from else None
    try:
        result = case_function(config, staging, group, start=start)
    except Exception as err:  # recorded: one failed case must not stop the study
        error = f"{type(err).__name__}: {err}"
        log.debug("case %s failed", case.name, exc_info=True)
    failed = group.allreduce(error is not None, op=MPI.LOR)
    if group.rank != 0:
        return
    wall = time.perf_counter() - t0
    if failed:
        error = error or "failed on another rank of its group"
        result = _failure_result(case, config, error, group.size, wall)
        write_json(staging / RESULT_FILE, result)
    elif not (staging / RESULT_FILE).is_file():
        write_json(staging / RESULT_FILE, result)
    record = {"case": case.name, "index": case.index, "graft_width_pct": case.width_pct,
              "graft_height_pct": case.height_pct, "axes": case.axis_values,
              "start_from": case.start_from, "config_hash": digest,
              "status": "failed" if failed else "finished", "reason": error or "",
              "converged": bool(result.get("converged")), "started_at": started,
              "finished_at": _now(), "elapsed_s": wall, "host": socket.gethostname(),
              "pid": os.getpid(), "n_ranks": group.size}
    commit_case(out, case.name, staging, record)


def _longest_first(case: StudyCase) -> tuple[bool, float]:
    """Normal valves first, then grafts by decreasing flat area (1 + W)(1 + H)."""
    if case.is_normal:
        return False, 0.0
    return True, -(1 + case.width_pct / 100) * (1 + case.height_pct / 100)


class _Scheduler:
    """The group leader's choice of the next case to compute.

    Walks the cases the normal valves first, then the grafts from the largest flat area
    down (the larger a graft, the longer its closure takes, and a study ends sooner when
    its longest cases start first; the order changes no result, since every case's start
    is fixed by the study): a finished case is dropped; a case whose source
    (``start_from``) has not finished waits, unless the source can be claimed, which
    is then computed first; any other case is claimed.  A case another process holds
    waits until that process has finished it (or, if the process ends without finishing
    it, is claimed here); with ``wait`` false, a case that a process of another run holds
    is dropped instead (``held``: its name and who holds it; the groups of this run still
    wait for each other).  When only waiting cases are left, it polls the study folder
    every ``poll_s``.
    """

    def __init__(self, out: Path, cases: list[StudyCase], layout: StudyLayout,
                 beat: ClaimHeartbeat, poll_s: float, run: str, wait: bool) -> None:
        self.out, self.layout = out, layout
        self.todo = sorted(cases, key=_longest_first)
        self.beat, self.poll_s = beat, poll_s
        self.run, self.wait = run, wait
        self.held: dict[str, str] = {}
        self._announced: set[str] = set()

    def _finished(self, name: str) -> bool:
        return _check(self.out, self.layout, name).finished

    def _claim(self, case: StudyCase) -> tuple[StudyCase, CaseClaim, Path] | None:
        claim, staging = _decide(self.out, case, self.layout, self.beat, self.run)
        return None if claim is None else (case, claim, staging)

    def _waits_for(self, name: str) -> bool:
        """Whether to wait for case ``name``, unfinished and held by another process."""
        owner = claim_owner(self.out, name)
        if not owner:  # released meanwhile (the next pass claims it or finds it done), or
            return True  # being written
        if not self.wait and owner.get("run") != self.run:
            self.held[name] = owner_text(owner)
            return False
        if owner.get("run") != self.run and name not in self._announced:
            self._announced.add(name)
            log.info("waiting for %s: %s computes it", name, owner_text(owner))
        return True

    def next(self) -> tuple[StudyCase, CaseClaim, Path] | None:
        """The next case this group computes, claimed, with its staging folder; None when
        nothing is left for it."""
        while self.todo:
            waiting = False
            for case in list(self.todo):
                if self._finished(case.name):
                    self.todo.remove(case)
                    continue
                source = case.start_from
                if source is not None and not self._finished(source):
                    job = self._claim(self.layout.case(source))
                    if job is not None:
                        return job
                    if self._finished(source) or self._waits_for(source):
                        waiting = True
                    else:
                        self.todo.remove(case)
                    continue
                job = self._claim(case)
                if job is not None:
                    self.todo.remove(case)
                    return job
                if self._finished(case.name) or not self._waits_for(case.name):
                    self.todo.remove(case)
                else:
                    waiting = True
            if waiting:
                raise_pending()  # nothing is claimed while waiting: a signal ends it here
                time.sleep(self.poll_s)
        return None


def _work(group: MPI.Comm, out: Path, layout: StudyLayout, cases: list[StudyCase],
          case_function: CaseFunction, poll_s: float, run: str, wait: bool
          ) -> tuple[list[str], dict[str, str]]:
    """Loop of one rank group over the cases; returns the names it computed and (on the
    group's leader, without ``wait``) the cases it left to another process, with who."""
    leader = group.rank == 0
    computed = []
    with ClaimHeartbeat() as beat:
        scheduler = _Scheduler(out, cases, layout, beat, poll_s, run, wait) if leader else None
        while True:
            job = None
            try:
                # a signal that arrives while a case is claimed is raised once ``job``
                # holds the claim, so that the ``finally`` below releases it
                with deferred_signals():
                    job = scheduler.next() if leader else None
                picked = group.bcast(None if job is None else (job[0].name, str(job[2])),
                                     root=0)
                if picked is None:
                    break
                case = layout.case(picked[0])
                _run_one(case, layout.configs[case.name], layout.digests[case.name],
                         Path(picked[1]), group, case_function, out)
                computed.append(case.name)
            finally:
                if job is not None:
                    job[1].release()
                    beat.remove(job[1])
                    if job[2].exists():  # interrupted before its commit
                        shutil.rmtree(job[2], ignore_errors=True)
    return computed, scheduler.held if leader else {}


def _check_ranks(comm: MPI.Comm, ranks_per_case: int) -> None:
    if comm.size % ranks_per_case:
        raise ParameterError(f"ranks_per_case = {ranks_per_case} does not divide the "
                             f"{comm.size} MPI ranks; use a divisor of {comm.size} "
                             "(--ranks-per-case 1 runs one case per rank)")


def _with_sources(layout: StudyLayout, cases: Sequence[StudyCase]) -> list[StudyCase]:
    """``cases`` and the cases they start from, in the study's order."""
    names = {c.name for c in cases} | {c.start_from for c in cases if c.start_from}
    return [c for c in layout.cases if c.name in names]


def run_study(settings: StudySettings, out: str | Path, comm: MPI.Comm | None = None, *,
              case_indices: Sequence[int] | None = None,
              case_function: CaseFunction | None = None,
              progress: ProgressCallback | None = None, report: bool = True,
              figures: bool = True, fields_output: bool = True,
              poll_s: float = 1.0, wait: bool = True) -> SweepOutcome:
    """Run the cases of a study (all, or ``case_indices``) into ``out`` and build its report.

    Also ``valve_dolfinx.run_sweep``.  Every rank of ``comm`` calls it with the same
    arguments.

    Parameters
    ----------
    settings
        The grid, the axes, the paths and the case settings.
    out
        Study folder (created); see :mod:`valve_dolfinx.study.store` for its layout.
    comm
        The ranks that share the study (default ``COMM_WORLD``), split into groups of
        ``settings.ranks_per_case``.
    case_indices
        Run only these cases (``--case-index``; positions in ``settings.cases()``) and the
        cases they start from; the report is then left to ``valve-dolfinx report``.
    case_function
        Computes one case (:class:`CaseFunction`); default :func:`run_closure_case`
        (looked up at call time).
    progress
        Callback on world rank 0 (see ``ProgressCallback``).
    report
        Rebuild tables, figures and report.md at the end (rank 0).
    figures
        Whether the cases the report's panels show (the first normal valve and the first
        case of each panel graft) draw their PNG figures; the other cases never draw
        theirs (a case's figures cost seconds).  Without them the report has no panels.
    fields_output
        Passed to ``run_case``: the ParaView fields of every case.
    poll_s
        How often a group that waits (for a case another process computes, or for a
        warm start's source) looks at the study folder again (s).
    wait
        Wait for the cases another process (another sweep, plan or job-array task on the
        same folder) is computing, logging which (the default); false: leave them, and list
        them in ``SweepOutcome.in_progress`` (``--no-wait``).

    Returns
    -------
    SweepOutcome
        The selected cases, those this call computed, the elapsed time and (on rank 0,
        with ``report``) the :class:`~valve_dolfinx.study.report.StudyReport`.

    Raises
    ------
    ParameterError
        Before any computation (before the folder is created), for settings that cannot
        run, ranks per case that do not divide the ranks included.
    OutputNotFolderError, OutputNotWritableError
        Before any computation, for an ``out`` that cannot be created or written.
    Interrupted
        On SIGINT or SIGTERM (under :func:`~valve_dolfinx.interrupts.interrupt_on_signals`):
        the cases in flight are not recorded and their claims are released.
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    out = Path(out)
    t0, started = time.perf_counter(), _now()
    layout = settings.layout(comm.bcast(_rounds_of(out, settings) if comm.rank == 0
                                        else None, root=0))
    cases = layout.select(case_indices)
    todo = _with_sources(layout, cases)
    _check_ranks(comm, settings.ranks_per_case)
    if case_function is None:
        case_function = _closure_cases(settings, layout, figures, fields_output)
    run = _open_study(comm, out, settings, write_settings=case_indices is None,
                      started=started)
    computed, held = _compute(comm, out, layout, todo, settings.ranks_per_case, progress,
                              case_function=case_function, poll_s=poll_s, run=run, wait=wait)
    if case_indices is None and report:
        layout, more = _run_rounds(settings, out, comm, layout=layout,
                                   case_function=case_function, poll_s=poll_s, run=run,
                                   wait=wait)
        computed += more
        todo = list(layout.cases)
        cases = list(layout.cases)
    outcome = SweepOutcome(out, cases, computed, time.perf_counter() - t0)
    states = comm.bcast(_states(out, layout, todo) if comm.rank == 0 else None)
    outcome.failed = [case.name for case, state in states if state == "failed"]
    outcome.in_progress = {case.name: held.get(case.name, "another process")
                           for case, state in states if state == "running"}
    if comm.rank == 0:
        entry = {"started": started, "finished": _now(), "elapsed_s": outcome.elapsed_s,
                 "n_ranks": comm.size, "ranks_per_case": settings.ranks_per_case,
                 "cases_run": len(computed), "case_indices": case_indices}
        with open(out / SWEEP_LOG, "a") as fh:
            fh.write(json.dumps(entry) + "\n")
        if report:
            outcome.report = build_report(out, settings)
    comm.barrier()
    return outcome


def _closure_cases(settings: StudySettings, layout: StudyLayout, figures: bool,
                   fields_output: bool) -> CaseFunction:
    """The study's closure of one case: :func:`run_closure_case`, drawing the figures of the
    cases the report's panels show (the first normal valve and the first case of each panel
    graft: :meth:`StudyLayout.panel_cases`), and of no other, unless ``figures`` is false."""
    panels = [layout.configs[case.name]
              for case in layout.panel_cases(settings.panel_cases)] if figures else []

    def case_function(config, folder, group, *, start):
        return run_closure_case(config, folder, group, start=start, figures=config in panels,
                                fields_output=fields_output)
    return case_function


def _open_study(comm: MPI.Comm, out: Path, settings: StudySettings, *, write_settings: bool,
                started: str) -> str:
    """Create the study folder and (``write_settings``, or if it has none) its settings file
    on rank 0; this run's id, on every rank.  Raises rank 0's error on every rank."""
    error, run = None, None
    if comm.rank == 0:
        run = uuid.uuid4().hex
        try:
            prepare_output(out)
            if write_settings or not (out / SETTINGS_FILE).is_file():
                write_json(out / SETTINGS_FILE, {"settings": settings.to_dict(),
                                                 "written_at": started})
        except ValveError as err:
            error = err
    error, run = comm.bcast((error, run), root=0)
    if error:
        raise error
    return run


def _compute(comm: MPI.Comm, out: Path, layout: StudyLayout, todo: list[StudyCase],
             ranks_per_case: int, progress: ProgressCallback | None, *,
             case_function: CaseFunction, poll_s: float, run: str,
             wait: bool) -> tuple[list[str], dict[str, str]]:
    """Compute ``todo`` in groups of ``ranks_per_case`` ranks, rank 0 watching the folder:
    the names of the cases computed, and those another process holds (with its owner),
    gathered from every group."""
    group = comm.Split(comm.rank // ranks_per_case, comm.rank)
    monitor = _Monitor(out, todo, layout, progress, poll_s) if comm.rank == 0 else None
    if monitor:
        monitor.start()
    try:
        computed, held = _work(group, out, layout, todo, case_function, poll_s, run, wait)
        # every group is done: the monitor's last scan sees the other groups' last cases
        computed = sorted(sum(comm.allgather(computed), []))
        held = {k: v for part in comm.allgather(held) for k, v in part.items()}
    finally:
        if monitor:
            monitor.stop()
        group.Free()
    return computed, held


def _rounds_of(out: Path, settings: StudySettings) -> tuple:
    """The rounds after round 0 of a study folder, if it was run with these settings
    (another study's, in a folder being reused, are dropped with their file)."""
    saved = out / SETTINGS_FILE
    try:
        same = (saved.is_file() and StudySettings.from_dict(
            json.loads(saved.read_text())["settings"]) == settings)
    except (ValueError, KeyError, ValveError, OSError):
        same = False
    if not same:
        if (out / ROUNDS_FILE).is_file():
            (out / ROUNDS_FILE).unlink()
        return ()
    return read_rounds(out)


def _run_rounds(settings: StudySettings, out: Path, comm: MPI.Comm, *, layout: StudyLayout,
                case_function: CaseFunction, poll_s: float, run: str, wait: bool
                ) -> tuple[StudyLayout, list[str]]:
    """Run the study's rounds after the cases of ``layout``, until one is empty.

    A round reads the answers from the cases so far (:func:`build_report`) and decides the
    next round (:func:`~valve_dolfinx.study.rounds.plan_round`: the answers'
    confirmations; in an adaptive study also the sizes that could still move them, within
    its budget), appends it to :data:`~valve_dolfinx.study.layout.ROUNDS_FILE` and solves
    its cases as ordinary cases.  An incomplete study (a case failed) decides nothing.
    Returns the layout with every round and the cases computed."""
    computed: list[str] = []
    while True:
        points = None
        if comm.rank == 0:
            plan = build_report(out, settings, draft=True).next_round
            if plan is not None and plan.points:
                append_round(out, plan)
                points = plan.points
                log.info("round %d: %d new case(s)%s", len(layout.rounds), plan.new_cases,
                         f" ({plan.text})" if plan.text else "")
        points = comm.bcast(points, root=0)
        if not points:
            break
        known = {c.name for c in layout.cases}
        layout = settings.layout(comm.bcast(read_rounds(out) if comm.rank == 0 else None,
                                            root=0))
        new = [c for c in layout.cases if c.name not in known]
        group = comm.Split(comm.rank // settings.ranks_per_case, comm.rank)
        try:
            done, _ = _work(group, out, layout, _with_sources(layout, new), case_function,
                            poll_s, run, wait)
        finally:
            group.Free()
        computed += sorted(sum(comm.allgather(done), []))
    return layout, computed


def _states(out: Path, layout: StudyLayout, cases: Sequence[StudyCase]
            ) -> list[tuple[StudyCase, str]]:
    status = []
    for case in cases:
        check = _check(out, layout, case.name)
        if check.finished:
            state = check.record.get("status", "finished")
        elif claim_owner(out, case.name) is not None:
            state = "running"
        else:
            state = {"empty": "pending", "damaged": "damaged"}.get(check.state, "changed")
        status.append((case, state))
    return status


def study_status(settings: StudySettings, out: str | Path) -> list[tuple[StudyCase, str]]:
    """Each case and its state in ``out``: finished, failed, damaged, changed, running or
    pending."""
    layout = settings.layout(read_rounds(out))
    return _states(Path(out), layout, layout.cases)
