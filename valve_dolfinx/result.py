"""The result of one closure case: the scalars of ``result.json`` (SPEC §7).

One :class:`CaseResult` is one row of a study's ``results.csv``.  Lengths in mm,
areas in mm², forces in mN, times in s.  :func:`load_case` reads a case folder
back: the result, the configuration that produced it and the loaded surface to
draw.  Nothing here imports DOLFINx.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from valve_dolfinx.config import CONFIG_FILE, CaseConfig, load_config
from valve_dolfinx.exceptions import MeshError

__all__ = ["RESULT_FILE", "POSITIONS_FILE", "CaseResult", "LoadedCase", "load_case"]

#: a case folder's result (written last: its presence means the case finished)
RESULT_FILE = "result.json"
#: the loaded node positions with the valve's topology
POSITIONS_FILE = "loaded_state.npz"


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
    competent: bool = False
    root_diameter_mm: float = float("nan")
    max_penetration_mm: float = float("nan")
    max_contact_layer_overlap_mm: float = float("nan")
    #: length of the lines along which two leaflets' loaded surfaces cross, away from the
    #: root wall (:func:`valve_dolfinx.analysis.intersection.leaflet_intersections`)
    leaflet_intersection_mm: float = float("nan")
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
        If the folder has no ``result.json`` or no ``loaded_state.npz``.
    MeshError
        If the rebuilt mesh is not the one the case was solved on.
    """
    from valve_dolfinx.geometry.symmetry import mirror_leaflet, single_leaflet
    from valve_dolfinx.geometry.valve import build_valve

    folder = Path(folder)
    for name in (RESULT_FILE, POSITIONS_FILE):
        if not (folder / name).is_file():
            raise FileNotFoundError(f"{folder / name}: no such file; {folder} is not a "
                                    "finished case folder (`valve-dolfinx run --out` writes one)")
    result = CaseResult.from_dict(json.loads((folder / RESULT_FILE).read_text()))
    if (folder / CONFIG_FILE).is_file():
        config = load_config(folder / CONFIG_FILE)
    else:
        config = CaseConfig.from_dict({k: v for k, v in result.parameters.items()
                                       if k in CaseConfig.__dataclass_fields__})
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
