"""The result of one closure case: the scalars of ``result.json`` (SPEC §7).

One :class:`CaseResult` is one row of a study's ``results.csv``.  Lengths in mm,
areas in mm², forces in mN, times in s.  :func:`competence` is the one definition
of a competent valve.  :func:`check_case` says whether a case folder holds a finished
case, whole and for which settings (``run`` and ``sweep`` resume with it);
:func:`load_case` reads a case folder back: the result, the configuration that produced
it and the loaded surface to draw; :func:`margin_text` writes a margin (mm) with the digits
that show it.  Nothing here imports DOLFINx.
"""

from __future__ import annotations

import hashlib
import json
import math
import zipfile
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from valve_dolfinx.config import (
    CONFIG_FILE,
    TABLES,
    CaseConfig,
    load_config,
    settings_hash,
    wall_clock_limits,
)
from valve_dolfinx.exceptions import InputFileError, MeshError, ValveError

__all__ = ["RESULT_FILE", "POSITIONS_FILE", "RECORD_FILE", "INTERSECTION_REASON", "CaseResult",
           "CaseCheck", "LoadedCase", "check_case", "competence", "competence_text",
           "file_digest", "leaflets_intersect", "load_case", "margin_text", "shortfall_digits"]

#: a case folder's result (written last: its presence means the case finished)
RESULT_FILE = "result.json"
#: the loaded node positions with the valve's topology
POSITIONS_FILE = "loaded_state.npz"
#: a study's record of a case (:mod:`valve_dolfinx.study.store`), beside its result
RECORD_FILE = "case.json"
#: the arrays of ``loaded_state.npz`` that are (N, 3) per node
_NODE_ARRAYS = ("positions", "reference", "contact_forces")


def _area(value: float) -> str:
    return f"{value:.2f}" if value >= 0.005 else f"{value:.1g}"


#: how :func:`competence` starts the reason of an intersection
INTERSECTION_REASON = "leaflets intersect"


def competence(converged: bool, orifice_mm2: float, intersecting_pairs: int,
               where: str = "") -> tuple[bool, str]:
    """Whether a closed valve is competent (SPEC §6), and if not, why.

    Competent: the solve converged to the equilibrium, the regurgitant orifice area is
    0 (the leaflets seal all round) and no leaflet passes through another or through
    itself: no edge of the loaded surface passes through one of its triangles
    (``intersecting_pairs``, :mod:`valve_dolfinx.analysis.intersection`).  An intersection
    makes the coaptation figures meaningless.  The reason lists every condition that fails,
    e.g. ``"leaks 0.40 mm²; leaflets intersect: 30 edge–triangle pairs, 0.20–1.30 mm from a
    post (graft/left-coronary 30)"`` (``where`` says where they are), and is empty for a
    competent valve.
    """
    reasons = []
    if not converged:
        reasons.append("not converged")
    if not math.isfinite(orifice_mm2):
        reasons.append("no orifice area")
    elif orifice_mm2 > 0.0:
        reasons.append(f"leaks {_area(orifice_mm2)} mm²")
    if intersecting_pairs > 0:
        pairs = "1 edge–triangle pair" if intersecting_pairs == 1 else (
            f"{intersecting_pairs} edge–triangle pairs")
        reasons.append(f"{INTERSECTION_REASON}: {pairs}" + (f", {where}" if where else ""))
    return not reasons, "; ".join(reasons)


def leaflets_intersect(result: CaseResult | Mapping) -> bool:
    """Whether a result (a :class:`CaseResult` or ``result.json``'s dict) has leaflets
    passing through each other or through themselves: at least one intersecting
    edge–triangle pair, as :func:`competence` counts them (False when not checked)."""
    data = result if isinstance(result, Mapping) else asdict(result)
    pairs = data.get("intersecting_pairs")
    return isinstance(pairs, int) and not isinstance(pairs, bool) and pairs > 0


def competence_text(result: CaseResult | Mapping) -> str:
    """``competent``, or ``not competent (leaks 0.40 mm²)``: the verdict of a
    result (a :class:`CaseResult` or ``result.json``'s dict) in the words of every log
    line, figure and report."""
    data = result if isinstance(result, Mapping) else asdict(result)
    if data.get("competent"):
        return "competent"
    why = data.get("competence_reason") or ""
    return f"not competent ({why})" if why else "not competent"


#: a margin or shortfall below this (mm) is the round-off of two equal heights: shown as 0.00
ROUND_OFF_MM = 1e-9


def shortfall_digits(shortfall: float) -> int:
    """Decimals that show a shortfall (one that rounds to 0.00 mm is shown to its first two
    significant digits; zero, or round-off below :data:`ROUND_OFF_MM`, is 0.00)."""
    if shortfall >= 0.005 or shortfall < ROUND_OFF_MM:
        return 2
    return max(3, 1 - math.floor(math.log10(shortfall)))


def margin_text(margin_mm: float, *, signed: bool = False) -> str:
    """A margin or shortfall (mm) with the decimals that show it (:func:`shortfall_digits`):
    0.0023 mm reads 0.0023, not 0.00; ``signed`` writes its sign (+0.0023); round-off of a
    tie reads 0.00 (+0.00), without a sign of its own."""
    value = 0.0 if abs(margin_mm) < ROUND_OFF_MM else margin_mm
    return f"{value:{'+' if signed else ''}.{shortfall_digits(abs(value))}f}"


@dataclass
class CaseResult:
    """Scalars of one case (``result.json``; one row of the study's ``results.csv``)."""

    graft_width_pct: float | None
    graft_height_pct: float | None
    converged: bool
    min_coaptation_height_mm: float = float("nan")
    min_coaptation_height_raw_mm: float = float("nan")
    central_coaptation_height_mm: float = float("nan")
    coaptation_area_mm2: float = float("nan")
    regurgitant_orifice_area_mm2: float = float("nan")
    #: :func:`competence`, and why not (empty when competent)
    competent: bool = False
    competence_reason: str = ""
    root_diameter_mm: float = float("nan")
    max_penetration_mm: float = float("nan")
    max_contact_layer_overlap_mm: float = float("nan")
    #: edges of the loaded surface that pass through one of its triangles, between
    #: leaflets or within one (:mod:`valve_dolfinx.analysis.intersection`; None: not checked)
    intersecting_pairs: int | None = None
    #: where they are: pairs per leaflets, distance from the nearest commissure post, the
    #: pairs nearest a post (:meth:`~valve_dolfinx.analysis.intersection.Intersections.to_dict`)
    intersections: dict = field(default_factory=dict)
    n_dofs: int = 0
    n_ranks: int = 1
    wall_time_s: float = 0.0
    mesh_size_mm: float = float("nan")
    n_cells: int = 0
    solver_message: str = ""
    solver: str = ""
    time_steps: int = 0
    newton_iterations: int = 0
    rejected_newton_iterations: int = 0
    residual_tolerance_mN: float = float("nan")
    equilibrium_residual_mN: float = float("nan")
    #: where the closure started: ``from`` (the unloaded valve, the equilibrium on a
    #: coarse mesh, or another case's loaded state) and what a coarse start cost
    start: dict = field(default_factory=dict)
    leaflets: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    versions: dict = field(default_factory=dict)
    #: :meth:`CaseConfig.settings_hash` of the configuration that ran
    settings_hash: str = ""
    #: the package's version, and the git commit when run from a checkout (else None)
    version: str = ""
    git_commit: str | None = None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CaseResult:
        """The result of a ``result.json`` (keys it does not know are ignored; null -> NaN)."""
        kw = {}
        for f in fields(cls):
            if f.name not in data:
                continue
            value = data[f.name]
            if value is None and f.type == "float":
                value = math.nan
            kw[f.name] = value
        return cls(**kw)


@dataclass(frozen=True)
class CaseCheck:
    """What a case folder holds (:func:`check_case`).

    ``state`` is one of

    * ``"empty"``: no finished case (nothing, or the files of a run that did not finish);
    * ``"damaged"``: a file of a finished case is missing, unreadable or disagrees with the
      others; ``reason`` names the file and what is wrong;
    * ``"other"``: a finished case with other settings (another settings hash);
    * ``"outdated"``: this case, but it did not converge under another wall-clock limit
      (computed again);
    * ``"finished"``: this case, whole.

    ``result`` is ``result.json`` as written, ``record`` a study's ``case.json``.
    """

    state: str
    reason: str = ""
    result: dict | None = None
    record: dict | None = None

    @property
    def finished(self) -> bool:
        return self.state == "finished"


class _Damaged(Exception):
    """A file of a finished case is missing, unreadable or disagrees with the others."""


def check_case(folder: str | Path, config: CaseConfig | None = None, *,
               record: bool = False, digest: str | None = None) -> CaseCheck:
    """Whether ``folder`` holds a finished case, whole, and whether it is ``config``'s.

    This is the resume check of ``valve-dolfinx run`` (a folder that already holds this
    case's result is not computed again) and of the sweep (``record=True``: a study's case
    folder, with its ``case.json``).  A finished case needs every one of its files:
    ``result.json`` parses; ``case.json`` parses and agrees with it (settings, graft size,
    convergence) and every file it lists is there with the size and content it was written
    with;
    unless the case failed, ``loaded_state.npz`` loads with the result's number of nodes
    and ``config.toml`` loads with the result's settings (a study's case: those of them
    its record lists).  Without ``config`` a whole case is ``"finished"``.

    The case is ``config``'s when its identity is ``digest`` (a study's ``case.json``
    holds it as ``config_hash``: :func:`valve_dolfinx.study.layout.case_digest`), by
    default when its settings hash is :meth:`CaseConfig.settings_hash` (physics and
    numerics).  A case that converged is this case whatever wall-clock limit it ran under;
    one that did not is computed again under another limit.
    """
    folder = Path(folder)
    if not (folder / RESULT_FILE).exists() and not (record and (folder / RECORD_FILE).exists()):
        return CaseCheck("empty")
    try:
        result = _read_json(folder / RESULT_FILE)
        settings = _result_settings(result)
        rec = _read_record(folder, result, settings) if record else None
        _check_outputs(folder, result, settings, rec)
    except _Damaged as err:
        return CaseCheck("damaged", str(err))
    if config is None:
        return CaseCheck("finished", result=result, record=rec)
    identity = settings if rec is None else rec.get("config_hash")
    if identity != (digest or config.settings_hash()):
        return CaseCheck("other", "a case with other settings", result, rec)
    if not result.get("converged") and not _same_limits(result, config):
        return CaseCheck("outdated", "not converged under another wall-clock limit", result,
                         rec)
    return CaseCheck("finished", result=result, record=rec)


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise _Damaged(f"{path.name} is missing") from None
    except OSError as err:
        raise _Damaged(f"{path.name} cannot be read ({err.strerror})") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise _Damaged(f"{path.name} is not valid JSON ({err})") from None
    if not isinstance(data, dict):
        raise _Damaged(f"{path.name} holds no JSON object")
    return data


def _result_settings(result: dict) -> str:
    """The settings hash of a result (computed from its parameters if it has none)."""
    if "converged" not in result:
        raise _Damaged(f"{RESULT_FILE} is not a case result (no 'converged')")
    if result.get("settings_hash"):
        return str(result["settings_hash"])
    if isinstance(result.get("parameters"), dict):
        return settings_hash(result["parameters"])
    raise _Damaged(f"{RESULT_FILE} has neither settings_hash nor parameters")


def _read_record(folder: Path, result: dict, settings: str) -> dict:
    rec = _read_json(folder / RECORD_FILE)
    agree = [("converged", bool(result["converged"])),
             ("graft_width_pct", result.get("graft_width_pct")),
             ("graft_height_pct", result.get("graft_height_pct"))]
    if rec.get("start_from") is None:  # a warm start's identity includes its start's
        agree.append(("config_hash", settings))
    for key, value in agree:
        if rec.get(key) != value:
            raise _Damaged(f"{RECORD_FILE} and {RESULT_FILE} disagree on {key} "
                           f"({rec.get(key)!r} and {value!r})")
    digests = rec.get("sha256") or {}
    for name, size in (rec.get("files") or {}).items():
        path = folder / name
        if not path.is_file():
            raise _Damaged(f"{name} is missing")
        if path.stat().st_size != size:
            raise _Damaged(f"{name} has {path.stat().st_size} bytes, {size} were written")
        if name in digests and file_digest(path) != digests[name]:
            raise _Damaged(f"{name} has changed since it was written (its SHA-256 differs "
                           f"from the one in {RECORD_FILE})")
    return rec


def file_digest(path: Path) -> str:
    """SHA-256 of a file's content (hex): what a study's ``case.json`` records per file."""
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _check_outputs(folder: Path, result: dict, settings: str, rec: dict | None) -> None:
    """loaded_state.npz and config.toml of a case that did not fail (see check_case)."""
    if result.get("error") or (rec is not None and rec.get("status") == "failed"):
        return
    needed = set(rec.get("files") or ()) if rec is not None else {POSITIONS_FILE, CONFIG_FILE}
    if POSITIONS_FILE in needed:
        nodes = _positions_nodes(folder / POSITIONS_FILE)
        n_dofs = result.get("n_dofs")
        if isinstance(n_dofs, int) and n_dofs > 0 and n_dofs != 3 * nodes:
            raise _Damaged(f"{POSITIONS_FILE} has {nodes} nodes, {RESULT_FILE} "
                           f"{n_dofs // 3} (n_dofs = {n_dofs})")
    if CONFIG_FILE in needed:
        try:
            written = load_config(folder / CONFIG_FILE)
        except (ValveError, OSError) as err:
            raise _Damaged(f"{CONFIG_FILE} cannot be loaded ({err})") from None
        if written.settings_hash() != settings:
            raise _Damaged(f"{CONFIG_FILE} holds other settings than {RESULT_FILE}")


def _positions_nodes(path: Path) -> int:
    """The number of nodes in a loaded_state.npz whose arrays load and agree."""
    if not path.is_file():
        raise _Damaged(f"{path.name} is missing")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {name: data[name] for name in (*_NODE_ARRAYS, "cells", "cell_tags")}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as err:
        raise _Damaged(f"{path.name} cannot be loaded ({type(err).__name__}: {err})") from None
    shape = arrays["positions"].shape
    if len(shape) != 2 or shape[1] != 3 or any(arrays[k].shape != shape for k in _NODE_ARRAYS):
        raise _Damaged(f"{path.name}: its node arrays disagree in shape")
    if not np.all(np.isfinite(arrays["positions"])):
        raise _Damaged(f"{path.name}: positions that are not finite")
    return shape[0]


def _same_limits(result: dict, config: CaseConfig) -> bool:
    """Whether a result ran under the wall-clock limits of ``config``."""
    return wall_clock_limits(result.get("parameters") or {}) == wall_clock_limits(
        config.to_dict())


@dataclass
class LoadedCase:
    """A case read back from its folder (:func:`load_case`).

    ``valve`` and ``positions`` are what to draw: the valve mesh rebuilt from the
    configuration and its loaded node positions (mm).  For the symmetric reference
    they are the solved leaflet with its two mirror images, as in the case's figures.
    ``contact_forces`` (mN, per node of the solved mesh) are as written.
    """

    folder: Path
    result: CaseResult
    config: CaseConfig
    valve: Any
    positions: np.ndarray
    contact_forces: np.ndarray


def load_case(folder: str | Path) -> LoadedCase:
    """Read a case folder written by :func:`valve_dolfinx.case.run_case`.

    The result comes from ``result.json``, the configuration from ``config.toml``
    and the loaded surface from ``loaded_state.npz``; the valve's mesh (leaflets,
    tags, edges) is rebuilt from the configuration's geometry with Gmsh and checked
    against the written reference positions.

    Raises
    ------
    FileNotFoundError
        If the folder holds no finished case.
    InputFileError
        If a file of the case is missing, unreadable or disagrees with the others
        (:func:`check_case`), naming it.
    MeshError
        If the rebuilt mesh is not the one the case was solved on.
    """
    from valve_dolfinx.geometry.symmetry import mirror_leaflet, single_leaflet
    from valve_dolfinx.geometry.valve import build_valve

    folder = Path(folder)
    check = check_case(folder)
    if check.state == "empty":
        raise FileNotFoundError(f"{folder / RESULT_FILE}: no such file; {folder} is not a "
                                "finished case folder (`valve-dolfinx run --out` writes one)")
    if not check.finished:
        raise InputFileError(f"{folder}: {check.reason}; compute the case again "
                             "(`valve-dolfinx run --out` into the same folder)")
    if check.result.get("error"):
        raise InputFileError(f"{folder}: the case failed ({check.result['error']}); it has no "
                             "loaded state")
    result = CaseResult.from_dict(check.result)
    if (folder / CONFIG_FILE).is_file():
        config = load_config(folder / CONFIG_FILE)
    else:
        config = CaseConfig.from_dict({k: v for k, v in result.parameters.items()
                                       if k in TABLES})
    with np.load(folder / POSITIONS_FILE, allow_pickle=False) as data:
        positions, reference = data["positions"], data["reference"]
        forces = data["contact_forces"]
    valve = build_valve(config.geometry)
    if config.symmetric_reference:
        valve = single_leaflet(valve)
    if valve.points.shape != reference.shape or not np.allclose(valve.points, reference,
                                                                atol=1e-9):
        raise MeshError(f"{folder}: the valve rebuilt from {CONFIG_FILE} is not the mesh the "
                        f"case was solved on ({len(valve.points)} nodes, {len(reference)} "
                        "written); was it written by another version of valve_dolfinx?")
    if config.symmetric_reference:
        valve, positions = mirror_leaflet(valve, positions)
    return LoadedCase(folder, result, config, valve, positions, forces)
