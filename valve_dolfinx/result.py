"""The result of one closure case: the scalars of ``result.json`` (SPEC §7).

One :class:`CaseResult` is one row of a study's ``results.csv``.  Lengths in mm,
areas in mm², forces in mN, times in s.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

__all__ = ["CaseResult"]


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
    n_dofs: int = 0
    n_ranks: int = 1
    wall_time_s: float = 0.0
    mesh_size_mm: float = float("nan")
    n_cells: int = 0
    solver_message: str = ""
    solver: str = ""
    time_steps: int = 0
    newton_iterations: int = 0
    residual_tolerance_mN: float = float("nan")
    equilibrium_residual_mN: float = float("nan")
    leaflets: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    versions: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)
