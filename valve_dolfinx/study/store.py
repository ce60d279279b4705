"""The study folder on disk: case folders, configuration hashes and exclusive claims.

Layout of a study folder ``DIR``::

    DIR/study.json                 the settings the study was started with
    DIR/cases/<name>/              one finished case: everything ``run`` writes,
                                   result.json, and case.json (the study's record)
    DIR/cases/.claims/<name>.claim who is computing <name> right now
    DIR/cases/.staging/...         cases in flight (renamed into cases/ when done)

A case is computed in a staging folder and renamed into ``cases/<name>`` when
it is complete, so ``cases/<name>`` is either absent or whole: a sweep that is
killed loses only the cases in flight.  ``case.json`` records the identity of
the case (:func:`valve_dolfinx.study.layout.case_digest`, its ``config_hash``:
the settings hash, and the start's identity for a warm start) and the size of
every file the case wrote; a rerun skips the cases that
:func:`~valve_dolfinx.result.check_case` finds finished, whole and with an
unchanged identity, and recomputes the others (a damaged case with a warning
naming the file).

Before a case is computed, its claim file is created with ``O_CREAT | O_EXCL``
(atomic, also on NFS v3+), so two sweeps on the same folder -- two MPI rank
groups, two job-array tasks, a sweep started twice -- never compute the same
case.  A claim left behind by a process that was killed is recognised as
stale (same host: the process is gone; another host: its heartbeat stopped)
and taken over.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import socket
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

from valve_dolfinx.interrupts import check_not_interrupted
from valve_dolfinx.io import check_output_folder, write_json
from valve_dolfinx.result import RECORD_FILE, RESULT_FILE, CaseCheck, check_case, file_digest

__all__ = [
    "CASES_DIR",
    "RECORD_FILE",
    "RESULT_FILE",
    "SETTINGS_FILE",
    "CaseClaim",
    "ClaimHeartbeat",
    "case_dir",
    "check_study_case",
    "claim_owner",
    "owner_text",
    "prepare_output",
    "staging_dir",
    "commit_case",
]

log = logging.getLogger(__name__)

CASES_DIR = "cases"
SETTINGS_FILE = "study.json"
_CLAIMS = ".claims"
_STAGING = ".staging"
_TRASH = ".trash"
#: a claim from another host is stale once its heartbeat is older than this (s)
STALE_AFTER_S = 600.0
#: how often a running sweep refreshes its claims (s)
HEARTBEAT_S = 60.0


def case_dir(out: Path, name: str) -> Path:
    return Path(out) / CASES_DIR / name


def check_study_case(out: Path, name: str, config=None, digest: str | None = None
                     ) -> CaseCheck:
    """:func:`~valve_dolfinx.result.check_case` of the case folder ``name`` of a study, whose
    identity is ``digest`` (:func:`~valve_dolfinx.study.layout.case_digest`)."""
    return check_case(case_dir(out, name), config, record=True, digest=digest)


def prepare_output(out: Path) -> Path:
    """Check the study folder, then create it and its subfolders, before any computation.

    Raises
    ------
    OutputNotFolderError, OutputNotWritableError
        If the folder cannot be created or written, naming it and the fix.
    """
    out = check_output_folder(out)
    for sub in ("", CASES_DIR, f"{CASES_DIR}/{_CLAIMS}", f"{CASES_DIR}/{_STAGING}"):
        check_output_folder(out / sub).mkdir(parents=True, exist_ok=True)
    return out


# --- claims ---------------------------------------------------------------------------------
def _process_start(pid: int) -> str | None:
    """Start time of a process in clock ticks since boot (Linux), to tell reused pids apart."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return stat.rsplit(")", 1)[1].split()[19]


def _alive(pid: int, start: str | None) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    now = _process_start(pid)
    return start is None or now is None or now == start


@dataclass
class CaseClaim:
    """Exclusive claim of one case by this process (an ``O_EXCL`` lock file)."""

    path: Path
    held: bool = False
    _token: dict = field(default_factory=dict, repr=False)

    #: the run (one sweep or plan, all its ranks) the claim is for
    run: str = ""

    @classmethod
    def for_case(cls, out: Path, name: str, run: str = "") -> CaseClaim:
        return cls(Path(out) / CASES_DIR / _CLAIMS / f"{name}.claim", run=run)

    def _owner(self) -> dict:
        pid = os.getpid()
        return {"host": socket.gethostname(), "pid": pid, "start": _process_start(pid),
                "claimed_at": time.time(), "token": uuid.uuid4().hex, "run": self.run}

    def acquire(self) -> bool:
        """Try to claim the case; False if a live process holds it."""
        for _ in range(2):  # second try after breaking a stale claim
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                if not self._break_if_stale():
                    return False
                continue
            self._token = self._owner()
            with os.fdopen(fd, "w") as fh:
                json.dump(self._token, fh)
            self.held = True
            return True
        return False

    def _break_if_stale(self) -> bool:
        try:
            text = self.path.read_text()
            age = time.time() - self.path.stat().st_mtime
        except FileNotFoundError:
            return True  # released meanwhile
        owner = _live_owner(text, age)
        if owner is not None:
            return False
        owner = _parsed(text)
        with contextlib.suppress(OSError):
            if self.path.read_text() == text:  # still the claim judged stale
                self.path.unlink()
                log.warning("took over the stale claim %s (%s)", self.path.name,
                            f"pid {owner.get('pid')} on {owner.get('host')}" if owner
                            else "unreadable")
        return True

    def refresh(self) -> None:
        """Heartbeat: touch the claim so other hosts see it is alive."""
        if self.held:
            with contextlib.suppress(OSError):
                os.utime(self.path)

    def release(self) -> None:
        if not self.held:
            return
        self.held = False
        with contextlib.suppress(OSError):
            if json.loads(self.path.read_text()).get("token") == self._token.get("token"):
                self.path.unlink()


class ClaimHeartbeat:
    """A daemon thread that refreshes the claims this process holds every ``HEARTBEAT_S``."""

    def __init__(self, interval: float = HEARTBEAT_S) -> None:
        self._objects: dict[int, CaseClaim] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="claim-heartbeat")
        self._interval = interval
        self._lock = threading.Lock()

    def __enter__(self) -> ClaimHeartbeat:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def add(self, claim: CaseClaim) -> None:
        with self._lock:
            self._objects[id(claim)] = claim

    def remove(self, claim: CaseClaim) -> None:
        with self._lock:
            self._objects.pop(id(claim), None)

    def _run(self) -> None:
        while not self._stop.wait(self._interval):
            with self._lock:
                claims = list(self._objects.values())
            for claim in claims:
                claim.refresh()


def _parsed(text: str) -> dict:
    try:
        owner = json.loads(text)
    except json.JSONDecodeError:
        return {}
    return owner if isinstance(owner, dict) else {}


def _live_owner(text: str, age: float) -> dict | None:
    """The owner of a claim (its file's ``text``, last touched ``age`` s ago) if the claim is
    live, None if it is stale: same host, its process is gone; another host, its heartbeat
    stopped; unreadable (being written, or torn by a crash) for more than 10 s."""
    owner = _parsed(text)
    if not owner:
        return {} if age <= 10.0 else None
    if owner.get("host") == socket.gethostname():
        alive = _alive(int(owner.get("pid", -1)), owner.get("start"))
    else:
        alive = age <= STALE_AFTER_S
    return owner if alive else None


def claim_owner(out: Path, name: str) -> dict | None:
    """Who computes case ``name`` of the study ``out`` right now (host, pid, claimed_at), or
    None when nobody does (no claim, or a stale one)."""
    path = CaseClaim.for_case(out, name).path
    try:
        text = path.read_text()
        age = time.time() - path.stat().st_mtime
    except OSError:
        return None
    return _live_owner(text, age)


def owner_text(owner: dict) -> str:
    """``pid 123 on host`` of a claim's owner (:func:`claim_owner`)."""
    if not owner:
        return "a process that is writing its claim"
    return f"pid {owner.get('pid')} on {owner.get('host')}"


# --- staging and commit ---------------------------------------------------------------------
def staging_dir(out: Path, name: str) -> Path:
    """A fresh, empty staging folder for case ``name``; leftovers of killed runs go first.

    Call it only while holding the case's claim: any other staging folder of the
    case then belongs to a process that is gone.
    """
    root = Path(out) / CASES_DIR / _STAGING
    for old in root.glob(f"{name}@*"):
        shutil.rmtree(old, ignore_errors=True)
    path = root / f"{name}@{socket.gethostname()}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    path.mkdir(parents=True)
    return path


def commit_case(out: Path, name: str, staging: Path, record: dict) -> Path:
    """Write the record into ``staging`` and rename it to ``cases/<name>`` (replacing an old one).

    The record lists every file of the case with its size (``files``) and the SHA-256 of its
    content (``sha256``: :func:`~valve_dolfinx.result.file_digest`).  It is written
    last inside the staging folder and the folder renamed in one step, so readers see
    the old case, no case, or the new case whole.  Nothing is committed once the command
    has received SIGINT or SIGTERM.
    """
    paths = [p for p in sorted(staging.rglob("*")) if p.is_file()]
    files = {str(p.relative_to(staging)): p.stat().st_size for p in paths}
    digests = {str(p.relative_to(staging)): file_digest(p) for p in paths}
    write_json(staging / RECORD_FILE, {**record, "files": files, "sha256": digests})
    check_not_interrupted()
    final = case_dir(out, name)
    if final.exists():
        trash = Path(out) / CASES_DIR / _TRASH / f"{name}@{uuid.uuid4().hex[:8]}"
        trash.parent.mkdir(parents=True, exist_ok=True)
        os.replace(final, trash)
        os.replace(staging, final)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        os.replace(staging, final)
    return final
