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

Resuming
--------
A finished case records the settings hash of its configuration and the size of
every file it wrote (``case.json``); a rerun skips it if
:func:`~valve_dolfinx.result.check_case` finds it whole with unchanged settings,
and recomputes it otherwise (a damaged case with a warning naming the file).  A
case is written atomically when it finishes (staging folder renamed into
place), so killing a sweep loses only the cases in flight.  A case that raises
or does not converge is recorded with its reason and the sweep goes on; an
interrupt (SIGINT, SIGTERM) stops the sweep, records nothing for the cases in
flight and releases their claims.

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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from valve_dolfinx._compat import MPI
from valve_dolfinx.exceptions import ParameterError, ValveError
from valve_dolfinx.io import write_json
from valve_dolfinx.result import competence_text
from valve_dolfinx.study.grid import StudyCase, StudySettings
from valve_dolfinx.study.report import SWEEP_LOG, StudyReport, build_report
from valve_dolfinx.study.store import (
    RESULT_FILE,
    SETTINGS_FILE,
    CaseClaim,
    ClaimHeartbeat,
    case_dir,
    check_study_case,
    commit_case,
    prepare_output,
    staging_dir,
)

__all__ = [
    "CaseFunction",
    "SweepOutcome",
    "run_study",
    "run_closure_case",
    "case_configs",
    "study_status",
]

log = logging.getLogger(__name__)

#: ``f(config, out_dir, comm) -> result dict`` (``CaseResult.to_dict()``), writing into out_dir
CaseFunction = Callable[[Any, Path, MPI.Comm], dict]
#: ``progress(event)``: ``{"event": "start" | "case" | "end", "done", "total"}``; a "case"
#: event also has the ``case`` name and its result ``row``
ProgressCallback = Callable[[dict], None]


def run_closure_case(config, out_dir: Path, comm: MPI.Comm, *, figures: bool = True,
                     fields_output: bool = True) -> dict:
    """The study's case: :func:`valve_dolfinx.case.run_case` into ``out_dir``."""
    from valve_dolfinx.case import run_case

    return run_case(config, out_dir, comm=comm, figures=figures,
                    fields_output=fields_output).to_dict()


def case_configs(settings: StudySettings, cases: Sequence[StudyCase]) -> dict[str, Any]:
    """The validated ``CaseConfig`` of every case (raises ParameterError before any run).

    The study's case settings (``settings.case``), then its mesh size and wall-clock
    limit, then each case's graft size (none for the normal valve).
    """
    from valve_dolfinx.config import config_from_dict, set_dotted

    data = json.loads(json.dumps(settings.case))  # a deep copy
    if settings.mesh_size_mm is not None:
        set_dotted(data, "geometry.mesh_size", settings.mesh_size_mm)
    if settings.wall_time_limit_s is not None:  # every solver stage's wall-clock limit
        for stage in ("pseudo_transient", "dynamics"):
            set_dotted(data, f"{stage}.wall_time_limit_s", settings.wall_time_limit_s)
    base = config_from_dict(data, source="study case settings")
    return {c.name: base.with_graft(c.width_pct, c.height_pct) for c in cases}


def _failure_result(case: StudyCase, config, error: str, n_ranks: int, wall: float) -> dict:
    """result.json of a case that raised: the SPEC fields unknown, the reason recorded."""
    from valve_dolfinx._compat import package_versions
    from valve_dolfinx._version import __version__, git_commit
    from valve_dolfinx.result import CaseResult

    result = CaseResult(graft_width_pct=case.width_pct, graft_height_pct=case.height_pct,
                        converged=False, competence_reason="no result (the case failed)",
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

    def __init__(self, out: Path, cases: list[StudyCase], configs: dict,
                 progress: ProgressCallback | None, poll_s: float) -> None:
        self.out, self.cases, self.configs = out, cases, configs
        self.progress, self.poll_s = progress, poll_s
        self.done = {c.name for c in cases if self._finished(c) is not None}
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

    def _finished(self, case: StudyCase) -> dict | None:
        """The result of ``case`` if its folder holds it finished and whole."""
        check = check_study_case(self.out, case.name, self.configs[case.name])
        return check.result if check.finished else None

    def scan(self) -> None:
        for case in self.cases:
            if case.name in self.done:
                continue
            row = self._finished(case)
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
    #: the cases of the selection recorded as failed (they raised): the study is incomplete
    failed: list[str] = field(default_factory=list)
    report: StudyReport | None = None


def _decide(out: Path, case: StudyCase, config, beat: ClaimHeartbeat
            ) -> tuple[CaseClaim | None, Path | None]:
    """Leader: claim the case if it is unfinished and unclaimed; its staging folder."""
    if check_study_case(out, case.name, config).finished:
        return None, None
    claim = CaseClaim.for_case(out, case.name)
    if not claim.acquire():
        log.debug("%s is being computed by another process", case.name)
        return None, None
    check = check_study_case(out, case.name, config)
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


def _run_one(case: StudyCase, config, staging: Path, group: MPI.Comm,
             case_function: CaseFunction, out: Path) -> None:
    """Compute one case on ``group`` into ``staging``; the leader records and commits it."""
    started, t0 = _now(), time.perf_counter()
    error, result = None, None
    try:
        result = case_function(config, staging, group)
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
              "graft_height_pct": case.height_pct, "settings_hash": config.settings_hash(),
              "status": "failed" if failed else "finished", "reason": error or "",
              "converged": bool(result.get("converged")), "started_at": started,
              "finished_at": _now(), "elapsed_s": wall, "host": socket.gethostname(),
              "pid": os.getpid(), "n_ranks": group.size}
    commit_case(out, case.name, staging, record)


def _work(group: MPI.Comm, out: Path, cases: list[StudyCase], configs: dict,
          case_function: CaseFunction) -> list[str]:
    """Loop of one rank group over the cases; returns the names it computed."""
    leader = group.rank == 0
    computed = []
    with ClaimHeartbeat() as beat:
        for case in cases:
            claim, staging = (_decide(out, case, configs[case.name], beat) if leader
                              else (None, None))
            staging = group.bcast(str(staging) if staging else None, root=0)
            if staging is None:
                continue
            try:
                _run_one(case, configs[case.name], Path(staging), group, case_function, out)
                computed.append(case.name)
            finally:
                if leader:
                    claim.release()
                    beat.remove(claim)
                    if Path(staging).exists():  # interrupted before its commit
                        shutil.rmtree(staging, ignore_errors=True)
    return computed


def _split(comm: MPI.Comm, ranks_per_case: int) -> MPI.Comm:
    if comm.size % ranks_per_case:
        raise ParameterError(f"ranks_per_case = {ranks_per_case} does not divide the "
                             f"{comm.size} MPI ranks; use a divisor of {comm.size} "
                             "(--ranks-per-case 1 runs one case per rank)")
    return comm.Split(comm.rank // ranks_per_case, comm.rank)


def run_study(settings: StudySettings, out: str | Path, comm: MPI.Comm | None = None, *,
              case_indices: Sequence[int] | None = None,
              case_function: CaseFunction | None = None,
              progress: ProgressCallback | None = None, report: bool = True,
              figures: bool = True, fields_output: bool = True,
              poll_s: float = 1.0) -> SweepOutcome:
    """Run the cases of a study (all, or ``case_indices``) into ``out`` and build its report.

    Parameters
    ----------
    settings
        The grid and the case settings.
    out
        Study folder (created); see :mod:`valve_dolfinx.study.store` for its layout.
    comm
        The ranks that share the study (default ``COMM_WORLD``), split into groups of
        ``settings.ranks_per_case``.
    case_indices
        Run only these cases (``--case-index``); the report is then left to
        ``valve-dolfinx report``.
    case_function
        ``f(config, out_dir, comm) -> dict`` computing one case; default
        :func:`run_closure_case` (looked up at call time).
    progress
        Callback on world rank 0 (see ``ProgressCallback``).
    report
        Rebuild tables, figures and report.md at the end (rank 0).
    figures, fields_output
        Passed to ``run_case``: the PNG figures and the ParaView fields of every case.

    Raises
    ------
    ParameterError
        Before any computation, for settings that cannot run.
    OutputNotFolderError, OutputNotWritableError
        Before any computation, for an ``out`` that cannot be created or written.
    Interrupted
        On SIGINT or SIGTERM (under :func:`~valve_dolfinx.interrupts.interrupt_on_signals`):
        the cases in flight are not recorded and their claims are released.
    """
    comm = MPI.COMM_WORLD if comm is None else comm
    out = Path(out)
    t0, started = time.perf_counter(), _now()
    cases = settings.select(case_indices)
    configs = case_configs(settings, cases)
    if case_function is None:
        def case_function(config, folder, group):
            return run_closure_case(config, folder, group, figures=figures,
                                    fields_output=fields_output)
    error = None
    if comm.rank == 0:
        try:
            prepare_output(out)
            if case_indices is None or not (out / SETTINGS_FILE).is_file():
                write_json(out / SETTINGS_FILE, {"settings": settings.to_dict(),
                                                 "written_at": started})
        except ValveError as err:
            error = err
    error = comm.bcast(error, root=0)
    if error:
        raise error
    group = _split(comm, settings.ranks_per_case)
    monitor = _Monitor(out, cases, configs, progress, poll_s) if comm.rank == 0 else None
    if monitor:
        monitor.start()
    try:
        computed = _work(group, out, cases, configs, case_function)
    finally:
        if monitor:
            monitor.stop()
        group.Free()
    computed = sorted(sum(comm.allgather(computed), []))
    outcome = SweepOutcome(out, cases, computed, time.perf_counter() - t0)
    states = comm.bcast(study_status(settings, out, cases) if comm.rank == 0 else None)
    outcome.failed = [case.name for case, state in states if state == "failed"]
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


def study_status(settings: StudySettings, out: str | Path,
                 cases: Sequence[StudyCase] | None = None) -> list[tuple[StudyCase, str]]:
    """Each case (all, or ``cases``) and its state in ``out``: finished, failed, damaged,
    changed, running or pending."""
    out = Path(out)
    cases = settings.cases() if cases is None else list(cases)
    configs = case_configs(settings, cases)
    status = []
    for case in cases:
        check = check_study_case(out, case.name, configs[case.name])
        if check.finished:
            state = check.record.get("status", "finished")
        elif CaseClaim.for_case(out, case.name).path.exists():
            state = "running"
        else:
            state = {"empty": "pending", "damaged": "damaged"}.get(check.state, "changed")
        status.append((case, state))
    return status
