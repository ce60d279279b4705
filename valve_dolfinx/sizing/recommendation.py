"""A study's recommendation: the solved cells and the answer read from the surface (SPEC §7).

A study's members are the combinations of its uncertainty values and numerical paths.
:func:`recommend_all` fits one coaptation surface and one sealing model over every
comparison value, uncertainty value and path of a study and reads each comparison
value's answer from them (:mod:`valve_dolfinx.sizing.answer`: the smallest flat area
whose predicted worst case over the uncertainty members reaches the target within the
measured resolution, and that seals); beside it, each graft's worst case over its solved
members (:class:`~valve_dolfinx.sizing.cells.CellSummary`), as solved.  :func:`headline`
says the answer in a sentence or two, as the plan's page opens with it.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.result import margin_text, shortfall_digits
from valve_dolfinx.sizing.answer import (
    MemberTable,
    SizingAnswer,
    StudyFit,
    fit_study,
    read_answer,
    sizes_to_confirm,
    solved_worst_case,
)
from valve_dolfinx.sizing.cells import (
    CellSummary,
    cell_state,
    incompetent_normals,
    member_targets,
    summarise_cells,
)
from valve_dolfinx.sizing.resolution import MESH_LADDER, Resolution
from valve_dolfinx.sizing.surface import CV_FOLDS

__all__ = ["Recommendation", "recommend", "recommend_all", "headline", "confirmation_holds",
           "miss_limit_mm", "CONFIRM_ROUNDS"]

#: the most rounds of confirmation a study solves (each: the answer's size in every member)
CONFIRM_ROUNDS = 3


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
    ``confirmations`` are the sizes solved to confirm the answer, in the order they were
    proposed, each with its solved worst-case margin (the statistic the answer predicts,
    :func:`~valve_dolfinx.sizing.answer.solved_worst_case`), the member that sets it and
    whether it holds (:func:`confirmation_holds`).
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
    confirmations: list[dict] = field(default_factory=list)
    #: the most sizes solved to confirm the answer (None: no limit, an adaptive study's
    #: case budget bounds them)
    confirm_rounds: int | None = CONFIRM_ROUNDS
    text: str = ""
    #: the fit the answer was read from and the member tables it read (not written out)
    fit: StudyFit | None = field(default=None, repr=False)
    tables: list[MemberTable] = field(default_factory=list, repr=False)

    @property
    def solved(self) -> bool:
        """The answer is a size solved in every member (confirmed, not only read from the
        surface); False when there is no answer."""
        return self.answer.size is not None and not self.confirm

    @property
    def next_confirmation(self) -> GraftSize | None:
        """The size to solve next in every member: the answer's, when it is not solved in
        every member yet and fewer than :attr:`confirm_rounds` sizes have been solved to
        confirm it; else None.  Every confirmation joins the fit, so the answer read after
        one (missed, or held and moved by its cases) is confirmed in turn."""
        if self.answer.size is None or not self.confirm:
            return None
        if self.confirm_rounds is not None and len(self.confirmations) >= self.confirm_rounds:
            return None
        return self.answer.size

    @property
    def margin(self) -> tuple[float | None, str | None, bool]:
        """The answer's worst-case margin (mm), the member that sets it, and whether it is
        solved: a confirmed size's as its solves give it (its held confirmation's solved
        worst case), else the surface's prediction; no margin without an answer."""
        size = self.answer.size
        if size is None:
            return None, self.answer.limiting_member, False
        entry = next((e for e in self.confirmations if e["graft"] == size.label and e["holds"]
                      and e["margin_mm"] is not None), None)
        if entry is None:
            return self.answer.margin_mm, self.answer.limiting_member, False
        return entry["margin_mm"], entry["limiting_member"], True

    def cell(self, label: str | None) -> CellSummary | None:
        return next((c for c in self.cells if c.label == label), None)

    def to_dict(self) -> dict:
        answer, closest = self.answer, self.answer.closest
        return {"comparison": self.comparison, "members": self.members,
                "targets_mm": self.targets_mm, "target_mm": self.target_mm,
                "target_source": self.target_source,
                "recommended": None if answer.size is None else answer.size.label,
                "margin_mm": answer.margin_mm, "limiting_member": answer.limiting_member,
                "best": None if closest is None else closest.label,
                "shortfall_mm": answer.shortfall_mm,
                "tolerance_mm": answer.tolerance_mm, "answer": answer.to_dict(),
                "cells": [c.to_dict() for c in self.cells], "confirm": self.confirm,
                "confirmations": self.confirmations,
                "incompetent_targets": self.incompetent_targets, "text": self.text}


#: a confirmation misses when its solved statistic falls short of the target by more than
#: the tolerance plus this many times the scatter of a single solve (a one-sided test): a
#: smaller shortfall is within what one solve scatters about the surface, no evidence
#: against the answer
CONFIRM_SCATTERS = 2.0


def miss_limit_mm(resolution: Resolution) -> float:
    """How far short of the target (mm) a confirmation may solve and still hold: the
    tolerance plus :data:`CONFIRM_SCATTERS` times a single solve's scatter (the larger of
    the scatter between paths and the surface's noise; 0 when neither is measured)."""
    scatter = max((v for v in (resolution.path_scatter_mm, resolution.surface_noise_mm)
                   if v is not None), default=0.0)
    return (resolution.tolerance_mm or 0.0) + CONFIRM_SCATTERS * scatter


def confirmation_holds(cell: CellSummary, margin_mm: float | None,
                       resolution: Resolution) -> bool:
    """A confirmation holds when its size converged and sealed in every member (every
    uncertainty value along every path: ``cell``) and its solved worst case ``margin_mm``
    (:func:`~valve_dolfinx.sizing.answer.solved_worst_case`: the statistic the answer
    predicts, paths averaged per uncertainty member, the least over those) is not short of
    the target by more than :func:`miss_limit_mm`; otherwise it misses, joins the fit, and
    the answer is read again."""
    return cell.sound and margin_mm is not None and margin_mm >= -miss_limit_mm(resolution)


def _confirmation_text(rec: Recommendation) -> list[str]:
    """What the confirmations gave, beside the prediction."""
    out = []
    answer = rec.answer
    paths = " (its paths averaged)" if len(rec.members) > len(answer.members) else ""
    for k, entry in enumerate(rec.confirmations, 1):
        cell = rec.cell(entry["graft"])
        solved = ("its worst case is not known" if entry["margin_mm"] is None else
                  f"solved worst-case margin{paths} "
                  f"{margin_text(entry['margin_mm'], signed=True)} mm"
                  f"{_in_member(entry['limiting_member'])}")
        predicted = (f" (the surface now predicts {margin_text(answer.margin_mm, signed=True)}"
                     f" ± {answer.margin_sd_mm:.2f} mm)"
                     if answer.size is not None and answer.size.label == entry["graft"] else "")
        verdict = ("it holds" if entry["holds"] else
                   f"it misses ({_miss(cell, entry['margin_mm'], answer.resolution)}): it "
                   "joined the fit and the answer was read again")
        out.append(f"Confirmation {k}: {entry['graft']} solved in every member, {solved}"
                   f"{predicted}; {verdict}.")
    return out


def _miss(cell: CellSummary, margin_mm: float | None, resolution: Resolution) -> str:
    """Why a confirmation missed, in words."""
    if not cell.sound:
        return cell_state(cell)
    if margin_mm is None:
        return "no worst case"
    return (f"{margin_text(-margin_mm)} mm short, beyond the tolerance of "
            f"{margin_text(resolution.tolerance_mm or 0.0)} mm and twice a solve's scatter "
            f"({margin_text(miss_limit_mm(resolution))} mm in all)")


def _in_member(member: str | None) -> str:
    return f" in `{member}`" if member else ""


def _recommendation(answer: SizingAnswer, tables: Sequence[MemberTable],
                    target_mm: float | None, n_paths: int,
                    confirmed: Sequence[GraftSize] = (),
                    confirm_rounds: int | None = CONFIRM_ROUNDS) -> Recommendation:
    targets, source = member_targets({t.label: t.rows for t in tables}, target_mm)
    same = set(targets.values())
    rec = Recommendation(answer.comparison, [t.label for t in tables], targets,
                         next(iter(same)) if len(same) == 1 else None, source, answer,
                         summarise_cells({t.label: t.rows for t in tables}, targets),
                         [table.label for _, table in sizes_to_confirm(answer, tables)],
                         confirm_rounds=confirm_rounds)
    for cell in rec.cells:
        cell.confirmation = cell.size in confirmed
    for size in confirmed:
        cell = rec.cell(GraftSize(*size).label)
        if cell is not None:
            solved, member = solved_worst_case(answer, tables, cell.size)
            rec.confirmations.append({
                "graft": cell.label, "margin_mm": solved, "limiting_member": member,
                "holds": confirmation_holds(cell, solved, answer.resolution)})
    lines = [answer.text, *_confirmation_text(rec)]
    if rec.confirm:
        if confirm_rounds is None:
            then = ("the adaptive design solves it there next, while its case budget allows "
                    "(the design's state says whether it did)")
        elif rec.next_confirmation is not None:
            then = "a sweep solves it there to confirm it"
        else:
            then = (f"the {confirm_rounds} rounds of confirmation are spent, so it is not "
                    "confirmed")
        lines.append(f"{answer.size.label} is read from the surface and not solved in "
                     f"{len(rec.confirm)} of the {len(tables)} members: {then}.")
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
                  *, n_paths: int = 1, ladder: Path | None = MESH_LADDER,
                  confirmed: Mapping[int, Sequence[GraftSize]] | None = None,
                  cv_folds: int = CV_FOLDS, confirm_rounds: int | None = CONFIRM_ROUNDS
                  ) -> list[Recommendation]:
    """One :class:`Recommendation` per comparison value, from one fit over all of them.

    Parameters
    ----------
    groups
        Per comparison value, its member tables (a study's:
        :func:`valve_dolfinx.study.layout.layout_tables`).
    target_mm
        Minimum coaptation height to reach in every member; None takes each member's
        normal valve's.
    n_paths
        Numerical paths among the members; with one, the text says the path was not
        varied.
    ladder
        The mesh-ladder table (:mod:`valve_dolfinx.sizing.resolution`).
    confirmed
        Per comparison index, the sizes solved to confirm its answer, in the order they
        were proposed (their cases are among the tables' rows, and in the fit).
    cv_folds
        Folds of the surface's cross-validation (0: none; the answer does not depend on
        it, only the error it reports).
    confirm_rounds
        The most sizes solved to confirm an answer (a grid study's; None for an adaptive
        study, whose case budget bounds them).
    """
    confirmed = confirmed or {}
    fit = fit_study([t for tables in groups for t in tables], ladder=ladder, cv_folds=cv_folds)
    recs = []
    for c, tables in enumerate(groups):
        comparison = dict(tables[0].comparison) if tables else {}
        sizes = [GraftSize(*s) for s in confirmed.get(c, ())]
        answer = read_answer(fit, tables, target_mm, comparison=comparison)
        rec = _recommendation(answer, tables, target_mm, n_paths, sizes, confirm_rounds)
        held = [rec.cell(entry["graft"]).size for entry in rec.confirmations if entry["holds"]]
        if held and answer.size is not None and answer.size not in held:
            again = read_answer(fit, tables, target_mm, comparison=comparison, prefer=held)
            if again.size != answer.size:
                rec = _recommendation(again, tables, target_mm, n_paths, sizes, confirm_rounds)
        rec.fit, rec.tables = fit, list(tables)
        recs.append(rec)
    return recs


def recommend(tables: Sequence[MemberTable] | Sequence[Mapping], target_mm: float | None = None,
              *, n_paths: int = 1, ladder: Path | None = MESH_LADDER) -> Recommendation:
    """The recommendation of one comparison value: ``tables`` are its member tables, or a
    plain list of rows (a study of one member)."""
    if tables and not isinstance(tables[0], MemberTable):
        tables = [MemberTable("", list(tables))]
    return recommend_all([list(tables)], target_mm, n_paths=n_paths, ladder=ladder)[0]


# --- the answer in a sentence -------------------------------------------------------------
def _target_words(rec: Recommendation, source: str) -> str:
    return ("the target minimum coaptation height ("
            + (f"{rec.target_mm:.2f} mm, " if rec.target_mm is not None else "")
            + f"{source or 'as given'})")


def headline(rec: Recommendation, names: Mapping[str, str] | None = None, *,
             target_source: str | None = None, excluded: str = "") -> str:
    """The answer in one sentence or two, as a surgeon reads it first.

    Parameters
    ----------
    rec
        The recommendation.
    names
        The members' names in words (by label; a label without a name is printed as is).
    target_source
        Where the target comes from, in the reader's words (default ``rec.target_source``).
    excluded
        A sentence naming members that were not computed because no graft can serve them:
        then no graft is robust, and a size that qualifies in the members computed is
        named the closest, with its margin there.
    """
    names = names or {}
    answer = rec.answer
    n = len(rec.members)
    limiting = names.get(answer.limiting_member, answer.limiting_member)
    where = f", in {limiting}" if limiting else ""
    tol = answer.tolerance_mm
    resolution = "" if tol is None else f" (the model's resolution: {margin_text(tol)} mm)"
    target = _target_words(rec, rec.target_source if target_source is None else target_source)
    computed = " computed" if excluded else ""
    size = answer.size
    if size is not None and not excluded:
        scope = f" in all {n} members" if n > 1 else ""
        within = "" if tol is None else " within the model's resolution"
        if rec.solved:
            margin, member, solved = rec.margin
            if solved:
                member = names.get(member, member)
                where = f", in {member}" if member else ""
                if tol is not None and -margin > tol:
                    within = (f" within the model's resolution and a solve's scatter (the "
                              f"{margin_text(miss_limit_mm(answer.resolution))} mm its "
                              "confirmation was tested against)")
            return (f"Recommended graft {size.label} (+{size.width_pct:g} % width, "
                    f"+{size.height_pct:g} % height). It converges, seals and reaches "
                    f"{target}{scope}{within}; its smallest{' solved' if solved else ''} "
                    f"margin is {margin_text(margin)} mm{where}{resolution}.")
        solved = ", ".join(entry["graft"] for entry in rec.confirmations)
        return (f"Recommended graft {size.label} (+{size.width_pct:g} % width, "
                f"+{size.height_pct:g} % height), read from the surface fitted to the solved "
                f"grafts, which predicts that it converges, seals and reaches "
                f"{target}{scope}{within}; its smallest predicted margin is "
                f"{margin_text(answer.margin_mm)} mm{where}{resolution}.  It was not solved "
                f"itself: " + (f"the sizes solved to confirm the answer ({solved}) each moved "
                               "it, and " + ("the rounds of confirmation are spent."
                                             if rec.confirm_rounds is not None else
                                             "the adaptive design stopped before solving it.")
                               if solved else "the study has not confirmed it yet."))
    if size is not None:  # qualifies in the members computed, fails beyond them
        return (f"{excluded} In the {n} members{computed}, {size.label} "
                f"(+{size.width_pct:g} % width, +{size.height_pct:g} % height) converges, "
                f"seals and reaches {target}; its smallest margin is "
                f"{margin_text(answer.margin_mm)} mm{where}{resolution}.")
    closest = answer.closest
    if closest is None and not excluded:
        return ("No answer: no size could be read, for too few solved cases or no target "
                "(the study's report says which); this says nothing for or against any "
                "graft.")
    scope = f" in every one of the {n} members{computed}" if n > 1 else ""
    if excluded:
        text = (f"{excluded} Nor does any graft converge, seal and reach {target}{scope}.")
    else:
        text = (f"No graft in the studied range is robust: none converges, seals and "
                f"reaches {target}{scope}.")
    if closest is None:
        return (f"{text} No size could be read: too few solved cases, or no target (the "
                "study's report says which).")
    short = answer.shortfall_mm
    if short is not None and short > 0:
        tail = (f", {short:.{shortfall_digits(short)}f} mm short in its worst member{where}"
                f"{resolution}")
    else:
        cell = rec.cell(closest.label)
        tail = f" ({cell_state(cell)})" if cell is not None else ""
    return f"{text} The closest is {closest.label}{tail}."
