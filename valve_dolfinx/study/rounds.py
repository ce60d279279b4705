"""The next round of a study, decided from its answers, and why a study stops (SPEC §7).

After the cases of a round are solved, :func:`plan_round` reads each comparison value's
answer (:class:`~valve_dolfinx.sizing.recommendation.Recommendation`) and decides the
next round's :class:`~valve_dolfinx.study.layout.Point` s:

* **grid** studies confirm each answer by simulation: its size in every member, while it
  is not solved there and fewer than ``CONFIRM_ROUNDS`` sizes were solved to confirm it
  (:attr:`Recommendation.next_confirmation`);
* **adaptive** studies (:mod:`valve_dolfinx.sizing.design`) confirm the answer in the
  same way and add the sizes that could still move it, within the study's case budget.

The sweep runs rounds until one is empty; ``valve-dolfinx report`` appends the next round
to the folder's ``rounds.json`` for a job array to run (:func:`append_round`).  The
:class:`RoundPlan` says why a study stopped, and its text is printed with the answer.
Nothing here imports DOLFINx.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from valve_dolfinx.io import write_json
from valve_dolfinx.sizing.answer import SAME_SIZE_PCT, TRIM_MM, member_label
from valve_dolfinx.sizing.design import (
    EXPECTED_SAVING,
    SETTLE_PROBABILITY,
    Candidate,
    cut_points,
    next_points,
    open_sizes,
)
from valve_dolfinx.sizing.recommendation import Recommendation
from valve_dolfinx.study.layout import ROUNDS_FILE, Point, StudyLayout, read_rounds, rounds_data

__all__ = ["RoundPlan", "plan_round", "append_round", "SETTLED", "BUDGET", "CONFIRMED",
           "STALLED"]

#: why a study stopped: its answers are settled (adaptive), confirmed or their rounds of
#: confirmation spent (grid), the case budget is spent, or nothing is left that a round
#: could add
SETTLED, CONFIRMED, BUDGET, STALLED = "settled", "confirmed", "budget", "stalled"


@dataclass
class RoundPlan:
    """The next round (``points``; empty: the study stops, ``stop`` says why), the graft
    cases it adds, and what is not settled yet, per comparison value (``open``)."""

    design: str
    points: tuple[Point, ...] = ()
    new_cases: int = 0
    stop: str | None = None
    rounds: int = 0
    graft_cases: int = 0
    budget: int | None = None
    open: dict[int, str] = field(default_factory=dict)
    text: str = ""

    def to_dict(self) -> dict:
        return {"design": self.design, "rounds": self.rounds, "graft_cases": self.graft_cases,
                "budget": self.budget, "stop": self.stop,
                "next": [p.to_dict() for p in self.points], "new_cases": self.new_cases,
                "open": {str(c): why for c, why in self.open.items()}, "text": self.text}


def _unsolved_member(layout: StudyLayout, c: int, candidate: Candidate) -> int | None:
    """The index of the first member of ``candidate``'s uncertainty member (its paths in
    order) where its size is not solved yet; None when it is solved along every path."""
    for m, member in enumerate(layout.members):
        if (member_label(member.values) == candidate.member
                and (c, m, tuple(candidate.size)) not in layout.slots):
            return m
    return None


def _new_slots(layout: StudyLayout, point: Point) -> int:
    """The graft cases ``point`` adds to ``layout`` (0 when solved already)."""
    members = range(len(layout.members)) if point.confirms else (point.member,)
    return sum((point.comparison, m, point.size) not in layout.slots for m in members)


def _open_text(rec: Recommendation, candidates: Sequence[Candidate],
               cuts: Sequence[Candidate] = ()) -> str:
    """What keeps one answer from being settled, in words (empty when settled)."""
    answer = rec.answer
    parts = []
    if cuts:
        worst = cuts[0]
        parts.append(f"{len(cuts)} sizes a {TRIM_MM:g} mm cut makes are not solved where "
                     f"their sealing is uncertain (the least, {worst.size.label}, "
                     f"{worst.chance:.2f} in `{worst.member}`)")
    if answer.size is not None and rec.confirm:
        parts.append(f"{answer.size.label} is not solved in {len(rec.confirm)} of its "
                     f"{len(rec.members)} members")
    if candidates:
        best = candidates[0]
        if answer.size is not None:
            parts.append(f"{len(candidates)} smaller sizes could still replace it (expected "
                         f"saving of flat area >= {EXPECTED_SAVING:.0%}; the largest "
                         f"{best.size.label}, chance {best.chance:.2f} in `{best.member}`, "
                         f"saving {best.saving:.1%})")
        else:
            parts.append(f"{len(candidates)} sizes could still qualify (chance >= "
                         f"{SETTLE_PROBABILITY:g}; the likeliest {best.size.label}, "
                         f"{best.chance:.2f}, in `{best.member}`)")
    if rec.solved:
        missed = [e for e in rec.confirmations if e["graft"] == answer.size.label
                  and not e["holds"]]
        if missed:
            parts.append(f"the confirmation of {answer.size.label} missed")
    if answer.why in ("no surface", "no target"):
        parts.append(answer.text)
    return "; ".join(parts)


def _adaptive_points(layout: StudyLayout, c: int, rec: Recommendation
                     ) -> tuple[list[Point], str]:
    """One comparison value's points for the next round of an adaptive study, and what is
    not settled (empty: settled)."""
    answer = rec.answer
    if rec.fit is None or rec.fit.surface is None or answer.lattice is None:
        return [], _open_text(rec, [])
    # a size solved along every path of the member that decides it is as settled as
    # solves can make it
    where = {k: _unsolved_member(layout, c, k) for k in open_sizes(rec.fit, answer, rec.tables)}
    candidates = [k for k, m in where.items() if m is not None]
    points = []
    if rec.next_confirmation is not None:
        points.append(Point(c, None, tuple(rec.next_confirmation)))
    for k in next_points(candidates, (rec.fit.widths_pct, rec.fit.heights_pct)):
        points.append(Point(c, where[k], tuple(k.size)))
    cuts = []
    if not points and not candidates:  # otherwise settled: the cut round
        where = {k: _unsolved_member(layout, c, k)
                 for k in cut_points(rec.fit, answer, rec.tables)}
        cuts = [k for k, m in where.items() if m is not None]
        points = [Point(c, where[k], tuple(k.size)) for k in cuts]
    return points, _open_text(rec, candidates, cuts)


def plan_round(recommendations: Sequence[Recommendation], layout: StudyLayout,
               design: str, budget: int | None = None) -> RoundPlan:
    """The next round of a complete study (its answers ``recommendations``, one per
    comparison value, and its ``layout``); ``design`` is ``"grid"`` or ``"adaptive"``,
    ``budget`` an adaptive study's most graft cases per comparison value."""
    plan = RoundPlan(design, rounds=len(layout.rounds), graft_cases=layout.graft_cases,
                     budget=budget * len(layout.comparisons) if design == "adaptive" else None)
    points: list[Point] = []
    for c, rec in enumerate(recommendations):
        if design == "adaptive":
            mine, why = _adaptive_points(layout, c, rec)
            if why:
                plan.open[c] = why
        else:
            size = rec.next_confirmation
            mine = [] if size is None else [Point(c, None, tuple(size))]
        points += [p for p in mine if _new_slots(layout, p)]
    if plan.budget is not None:
        kept, total = [], layout.graft_cases
        for point in points:
            extra = _new_slots(layout, point)
            if total + extra <= plan.budget:
                kept.append(point)
                total += extra
            elif point.confirms:  # an answer that cannot be confirmed: no more rounds
                kept = []
                break
        if points and not kept:
            plan.stop = BUDGET
        points = kept
    plan.points = tuple(points)
    plan.new_cases = sum(_new_slots(layout, p) for p in points)
    if not points and plan.stop is None:
        if design == "adaptive":
            plan.stop = STALLED if plan.open else SETTLED
        else:
            plan.stop = CONFIRMED
    plan.text = _plan_text(plan, recommendations, layout)
    return plan


def _plan_text(plan: RoundPlan, recommendations: Sequence[Recommendation],
               layout: StudyLayout) -> str:
    """The design's state in a sentence or two (grid studies: empty, their answers' texts
    say what the confirmations gave)."""
    if plan.design != "adaptive":
        return ""
    head = (f"Adaptive design: {plan.rounds} round(s), {plan.graft_cases} graft cases of a "
            f"budget of {plan.budget}")
    open_ = "; ".join(f"[{layout.comparison_label(c)}] {why}" if layout.comparison_label(c)
                      else why for c, why in plan.open.items())
    if plan.points:
        return f"{head}; the next round adds {plan.new_cases} case(s). Not settled: {open_}."
    if plan.stop == SETTLED:
        sizes = [rec.answer.size.label if rec.answer.size is not None else "no graft"
                 for rec in recommendations]
        return (f"{head}; settled: the answer ({', '.join(sizes)}) is solved in every "
                f"member, no size more than {SAME_SIZE_PCT:g} points from it could "
                f"replace it with a chance of {SETTLE_PROBABILITY:g} or more and an "
                f"expected saving of flat area of {EXPECTED_SAVING:.0%} or more, and every "
                f"size a {TRIM_MM:g} mm cut makes is solved where its sealing was uncertain.")
    if plan.stop == BUDGET:
        return f"{head}; stopped at the case budget, not settled: {open_}."
    return f"{head}; stopped with nothing left to solve that would settle it: {open_}."


def append_round(out: Path, plan: RoundPlan) -> None:
    """Append ``plan``'s points to the study folder's rounds file (nothing when empty)."""
    if not plan.points:
        return
    rounds = (*read_rounds(out), plan.points)
    write_json(Path(out) / ROUNDS_FILE, rounds_data(rounds))

