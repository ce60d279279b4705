"""The graft sizing study (SPEC §7): the normal valve and a W × H grid of grafts.

* :mod:`~valve_dolfinx.study.grid`: the grid and study settings, validated (no DOLFINx);
* :mod:`~valve_dolfinx.study.store`: case folders, configuration hashes, exclusive claims;
* :mod:`~valve_dolfinx.study.runner`: every case once, over MPI rank groups, resumable;
* :mod:`~valve_dolfinx.study.table`: ``results.csv`` / ``results.json`` (SPEC §7 schema);
* :mod:`~valve_dolfinx.study.recommend`: the sizing recommendation;
* :mod:`~valve_dolfinx.study.report`: tables, figures (:mod:`valve_dolfinx.plotting.study`) and
  report.md.

The runner imports DOLFINx; import it as ``valve_dolfinx.study.runner`` (``run_study``
is re-exported lazily, so ``import valve_dolfinx.study`` stays light).
"""

from __future__ import annotations

from valve_dolfinx.study.grid import (
    DEFAULT_PANEL_CASES,
    STUDY_HEIGHTS_PCT,
    STUDY_WIDTHS_PCT,
    StudyCase,
    StudySettings,
    load_study_toml,
    parse_percentages,
)
from valve_dolfinx.study.recommend import Recommendation, recommend
from valve_dolfinx.study.report import StudyReport, build_report
from valve_dolfinx.study.table import SPEC_COLUMNS, case_rows

__all__ = [
    "DEFAULT_PANEL_CASES",
    "STUDY_HEIGHTS_PCT",
    "STUDY_WIDTHS_PCT",
    "SPEC_COLUMNS",
    "Recommendation",
    "StudyCase",
    "StudyReport",
    "StudySettings",
    "build_report",
    "case_rows",
    "load_study_toml",
    "parse_percentages",
    "recommend",
    "run_study",
]


def __getattr__(name: str):
    if name == "run_study":
        from valve_dolfinx.study.runner import run_study

        return run_study
    raise AttributeError(name)
