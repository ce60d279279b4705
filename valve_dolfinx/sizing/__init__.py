"""The graft sizing answer (SPEC §7): one home for the study, the nomogram and the plan.

* :mod:`~valve_dolfinx.sizing.cells`: :class:`GraftSize`; the solved cells, each graft's
  worst case over its members (:class:`CellSummary`) and the members' targets;
* :mod:`~valve_dolfinx.sizing.surface`: the response surfaces, coaptation
  (Gaussian-process regression with a noise term) and sealing (piecewise-linear
  interpolation of each solved cell's share of sealed cases), over W, H and every axis;
* :mod:`~valve_dolfinx.sizing.resolution`: the measured resolution (path scatter, surface
  noise, discretisation error) and the decision tolerance;
* :mod:`~valve_dolfinx.sizing.answer`: the answer read from the surfaces at that
  tolerance, its band and its wording, the sizes to confirm and their solved worst case;
* :mod:`~valve_dolfinx.sizing.recommendation`: one comparison value's answer beside the
  worst case of each solved graft, from one fit over every comparison value (what the
  study, the nomogram and the plan report).

Nothing here imports DOLFINx.
"""

from __future__ import annotations

from valve_dolfinx.sizing.answer import (
    SEAL_PROBABILITY,
    MemberTable,
    SizingAnswer,
    StudyFit,
    bootstrap_stability,
    common_size,
    fit_study,
    read_answer,
    sizes_to_confirm,
    solved_worst_case,
)
from valve_dolfinx.sizing.cells import (
    CellSummary,
    GraftSize,
    cell_state,
    flat_area_ratio,
    incompetent_normals,
    member_targets,
    summarise_cells,
)
from valve_dolfinx.sizing.recommendation import Recommendation, recommend, recommend_all
from valve_dolfinx.sizing.resolution import Resolution

__all__ = [
    "SEAL_PROBABILITY",
    "CellSummary",
    "GraftSize",
    "MemberTable",
    "Recommendation",
    "Resolution",
    "SizingAnswer",
    "StudyFit",
    "bootstrap_stability",
    "cell_state",
    "common_size",
    "fit_study",
    "flat_area_ratio",
    "incompetent_normals",
    "member_targets",
    "read_answer",
    "recommend",
    "recommend_all",
    "sizes_to_confirm",
    "solved_worst_case",
    "summarise_cells",
]
