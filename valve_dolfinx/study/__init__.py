"""The graft sizing study (SPEC §7): the normal valve and a W × H grid of grafts, over axes.

* :mod:`~valve_dolfinx.study.grid`: the grid and study settings, validated (no DOLFINx);
* :mod:`~valve_dolfinx.study.axes`: comparison and uncertainty axes (``--vary``,
  ``--uncertain``);
* :mod:`~valve_dolfinx.study.paths`: the numerical paths (``--paths``);
* :mod:`~valve_dolfinx.study.layout`: the cases, their names and configurations, the
  slot (comparison value, member, graft) each fills, and the member tables the answer
  reads (:mod:`valve_dolfinx.sizing`: one response surface over every comparison value);
* :mod:`~valve_dolfinx.study.store`: case folders and exclusive claims;
* :mod:`~valve_dolfinx.study.runner`: every case once, over MPI rank groups, resumable;
* :mod:`~valve_dolfinx.study.table`: ``results.csv`` / ``results.json`` (SPEC §7 schema);
* :mod:`~valve_dolfinx.study.nomogram`: the recommendation against the root diameter;
* :mod:`~valve_dolfinx.study.report`: tables, figures (:mod:`valve_dolfinx.plotting.study`) and
  report.md.

The runner imports DOLFINx; import it as ``valve_dolfinx.study.runner`` (``run_study``
is re-exported lazily, so ``import valve_dolfinx.study`` stays light).
"""

from __future__ import annotations

from valve_dolfinx.study.axes import COMPARISON, UNCERTAINTY, StudyAxis
from valve_dolfinx.study.grid import (
    DEFAULT_PANEL_CASES,
    STUDY_HEIGHTS_PCT,
    STUDY_WIDTHS_PCT,
    StudySettings,
    load_study_toml,
    parse_percentages,
)
from valve_dolfinx.study.layout import Member, StudyCase, StudyLayout
from valve_dolfinx.study.nomogram import NOMOGRAM_KEY, nomogram_rows
from valve_dolfinx.study.paths import PATHS, StudyPath
from valve_dolfinx.study.report import StudyReport, build_report
from valve_dolfinx.study.table import SPEC_COLUMNS, case_rows

__all__ = [
    "COMPARISON",
    "DEFAULT_PANEL_CASES",
    "NOMOGRAM_KEY",
    "PATHS",
    "STUDY_HEIGHTS_PCT",
    "STUDY_WIDTHS_PCT",
    "SPEC_COLUMNS",
    "UNCERTAINTY",
    "Member",
    "StudyAxis",
    "StudyCase",
    "StudyLayout",
    "StudyPath",
    "StudyReport",
    "StudySettings",
    "build_report",
    "case_rows",
    "load_study_toml",
    "nomogram_rows",
    "parse_percentages",
    "run_study",
]


def __getattr__(name: str):
    if name == "run_study":
        from valve_dolfinx.study.runner import run_study

        return run_study
    raise AttributeError(name)
