"""The study's recommendation: the solved cells and the answer read from the surface (SPEC §7).

A study's members are the combinations of its uncertainty values and numerical paths.
:func:`recommend_all` fits one coaptation surface and one sealing model over every
comparison value, uncertainty value and path of a study and reads each comparison
value's answer from them (:mod:`valve_dolfinx.sizing.answer`: the smallest flat area
whose predicted worst case over the uncertainty members reaches the target within the
measured resolution, and that seals); beside it, each graft's worst case over its solved
members (:class:`~valve_dolfinx.sizing.cells.CellSummary`), as solved.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from valve_dolfinx.sizing.answer import (
    MemberTable,
    SizingAnswer,
    fit_study,
    read_answer,
    sizes_to_confirm,
)
from valve_dolfinx.sizing.cells import (
    NORMAL_TARGET,
    CellSummary,
    GraftSize,
    cell_state,
    incompetent_normals,
    member_targets,
    summarise_cells,
)
from valve_dolfinx.sizing.resolution import MESH_LADDER

if TYPE_CHECKING:
    from valve_dolfinx.study.layout import StudyLayout

__all__ = ["Recommendation", "recommend", "recommend_all", "layout_tables", "CellSummary",
           "NORMAL_TARGET", "cell_state"]


@dataclass
class Recommendation:
    """One comparison value's answer and solved cells (mm; members by label).

    ``members`` and ``targets_mm`` are the study's members (uncertainty values and paths)
    and their targets; ``target_mm`` the target when it is the same in every member, else
    None.  ``answer`` is the answer read from the surface; ``cells`` the worst case of
    every solved graft; ``confirm`` the members (labels) where the answer's size is still
    to be solved to confirm it (:func:`~valve_dolfinx.sizing.answer.sizes_to_confirm`);
    ``incompetent_targets`` the members whose target is the height of a normal valve that
    is not competent, with why (``competence_text``): a target no sound valve set.
    The properties name the answer as the nomogram and the plan read it: ``size`` (the
    recommended graft, None without one), ``best_size`` (without a graft: the closest
    size, with ``shortfall_mm``).
    """

    comparison: dict[str, Any]
    members: list[str]
    targets_mm: dict[str, float | None]
    target_mm: float | None
    target_source: str
    answer: SizingAnswer
    cells: list[CellSummary] = field(default_factory=list)
    confirm: list[str] = field(default_factory=list)
    incompetent_targets: dict[str, str] = field(default_factory=dict)
    text: str = ""

    @property
    def size(self) -> GraftSize | None:
        return self.answer.size

    @property
    def recommended(self) -> str | None:
        return None if self.size is None else self.size.label

    @property
    def margin_mm(self) -> float | None:
        return self.answer.margin_mm

    @property
    def recommended_height_mm(self) -> float | None:
        return self.answer.predicted_height_mm

    @property
    def recommended_area_ratio(self) -> float | None:
        return None if self.size is None else self.size.area_ratio

    @property
    def limiting_member(self) -> str | None:
        return self.answer.limiting_member

    @property
    def best_size(self) -> GraftSize | None:
        """Without a graft, the closest size (highest predicted worst case); else None."""
        return self.answer.highest if self.size is None else None

    @property
    def best(self) -> str | None:
        return None if self.best_size is None else self.best_size.label

    @property
    def shortfall_mm(self) -> float | None:
        return self.answer.shortfall_mm

    @property
    def tolerance_mm(self) -> float | None:
        return self.answer.tolerance_mm

    def cell(self, label: str | None) -> CellSummary | None:
        return next((c for c in self.cells if c.label == label), None)

    def to_dict(self) -> dict:
        return {"comparison": self.comparison, "members": self.members,
                "targets_mm": self.targets_mm, "target_mm": self.target_mm,
                "target_source": self.target_source, "recommended": self.recommended,
                "margin_mm": self.margin_mm, "limiting_member": self.limiting_member,
                "best": self.best, "shortfall_mm": self.shortfall_mm,
                "tolerance_mm": self.tolerance_mm, "answer": self.answer.to_dict(),
                "cells": [c.to_dict() for c in self.cells], "confirm": self.confirm,
                "incompetent_targets": self.incompetent_targets, "text": self.text}


def layout_tables(layout: StudyLayout, comparison: int, rows: Sequence[Mapping]
                  ) -> list[MemberTable]:
    """The member tables of one comparison value of a study, from the rows at hand (a case
    not finished yet, damaged or stale is left out)."""
    by_name = {r["case"]: r for r in rows if r.get("status") not in ("damaged", "stale")}
    members = {m.label: m for m in layout.members}
    return [MemberTable(label, [by_name[name] for name in cases.values() if name in by_name],
                        comparison=layout.comparisons[comparison],
                        uncertain=members[label].values, path=members[label].path.number)
            for label, cases in layout.member_cases(comparison).items()]


def _recommendation(answer: SizingAnswer, tables: Sequence[MemberTable],
                    target_mm: float | None, n_paths: int) -> Recommendation:
    targets, source = member_targets({t.label: t.rows for t in tables}, target_mm)
    same = set(targets.values())
    rec = Recommendation(answer.comparison, [t.label for t in tables], targets,
                         next(iter(same)) if len(same) == 1 else None, source, answer,
                         summarise_cells({t.label: t.rows for t in tables}, targets),
                         [table.label for _, table in sizes_to_confirm(answer, tables)])
    lines = [answer.text]
    if target_mm is None:
        rec.incompetent_targets = incompetent_normals({t.label: t.rows for t in tables})
        lines += _incompetent_text(rec)
    if n_paths == 1:
        lines.append("Each cell was solved along one numerical path, so the scatter between "
                     "paths is not measured; `--paths 2` solves every cell along a second one "
                     "(docs/study.md, \"Paths\").")
    rec.text = " ".join(lines)
    return rec


def _incompetent_text(rec: Recommendation) -> list[str]:
    """The sentence that says a target comes from a normal valve that is not competent."""
    if not rec.incompetent_targets:
        return []
    which = "; ".join(f"`{m}`: {why}" if m else why for m, why in rec.incompetent_targets.items())
    return [f"Caution: the target is the height of a normal valve that is not competent "
            f"({which}), not that of a sound valve; give --target-coaptation to measure the "
            "grafts against a height of your choice."]


def recommend_all(groups: Sequence[Sequence[MemberTable]], target_mm: float | None = None,
                  *, n_paths: int = 1, ladder: Path | None = MESH_LADDER
                  ) -> list[Recommendation]:
    """One :class:`Recommendation` per comparison value, from one fit over all of them.

    Parameters
    ----------
    groups
        Per comparison value, its member tables (:func:`layout_tables`).
    target_mm
        Minimum coaptation height to reach in every member; None takes each member's
        normal valve's.
    n_paths
        Numerical paths among the members; with one, the text says the path was not
        varied.
    ladder
        The mesh-ladder table (:mod:`valve_dolfinx.sizing.resolution`).
    """
    fit = fit_study([t for tables in groups for t in tables], ladder=ladder)
    return [_recommendation(read_answer(fit, tables, target_mm,
                                        comparison=dict(tables[0].comparison) if tables else {}),
                            tables, target_mm, n_paths)
            for tables in groups]


def recommend(tables: Sequence[MemberTable] | Sequence[Mapping], target_mm: float | None = None,
              *, n_paths: int = 1, ladder: Path | None = MESH_LADDER) -> Recommendation:
    """The recommendation of one comparison value: ``tables`` are its member tables, or a
    plain list of rows (a study of one member)."""
    if tables and not isinstance(tables[0], MemberTable):
        tables = [MemberTable("", list(tables))]
    return recommend_all([list(tables)], target_mm, n_paths=n_paths, ladder=ladder)[0]
