"""What a plan answers: the study's recommendation with its members named in words.

:class:`PlanRecommendation` holds the sizing answer of the plan's study
(:class:`~valve_dolfinx.sizing.recommendation.Recommendation`: the answer read from the
response surface, its wording and every graft's worst case) and what only a plan adds,
from the closed-form bound of :mod:`valve_dolfinx.plan.reach`.  It is one of three
answers:

* a graft is recommended: the smallest size whose predicted worst case over the root
  diameters reaches the target within the model's resolution and that seals (a size off
  the grid, to 1 %), with its predicted margin in the root diameter that limits it;
* no graft is robust: the closest size and its shortfall -- or, when some root diameters
  of the uncertainty are ones that the bound rules out (not computed), the size that
  qualifies in every member computed, with its margin there;
* the native leaflets cannot seal the measured root whatever the graft (the same
  bound): nothing was computed.

A plan with comparison axes (``--vary``) answers at each of their values:
:class:`PlanAnswers` holds one :class:`PlanRecommendation` per value and says whether the
size depends on them (the smallest size that qualifies at every value,
:func:`~valve_dolfinx.sizing.answer.common_size`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.result import margin_text
from valve_dolfinx.sizing.answer import common_size
from valve_dolfinx.sizing.cells import cell_state
from valve_dolfinx.sizing.recommendation import Recommendation, headline
from valve_dolfinx.study.axes import axis_label, value_text

__all__ = ["PlanRecommendation", "PlanAnswers"]


@dataclass(frozen=True)
class PlanRecommendation:
    """The plan's answer.

    Attributes
    ----------
    recommendation
        The sizing answer of the plan's study; None when nothing was computed
        (``cannot_seal``).
    names
        The members in words (``root 22.0 mm, path 1 (...)``, ``root 22.0 mm``), by the
        labels the recommendation uses.
    target_source
        Where the target comes from, in the plan's words.
    unsealable_roots_mm, unsealable_reason
        Root diameters of the measurement's uncertainty that the closed-form bound rules
        out (no graft seals them; their cases are not computed), and its one-line verdict
        at the largest of them.
    cannot_seal
        The closed-form verdict (one line) when the native leaflets cannot seal the
        measured root whatever the graft; nothing was computed then.
    """

    recommendation: Recommendation | None = None
    names: Mapping[str, str] = field(default_factory=dict)
    target_source: str = ""
    unsealable_roots_mm: tuple[float, ...] = ()
    unsealable_reason: str = ""
    cannot_seal: str | None = None

    @property
    def graft(self) -> GraftSize | None:
        """The recommended graft: it seals and reaches the target in every member."""
        if self.recommendation is None or self.unsealable_roots_mm:
            return None
        return self.recommendation.answer.size

    @property
    def closest(self) -> GraftSize | None:
        """Without a robust graft, the one closest to it (the answer's size when it
        qualifies in the members computed only)."""
        if self.recommendation is None:
            return None
        answer = self.recommendation.answer
        return (answer.size or answer.closest) if self.unsealable_roots_mm else answer.closest

    @property
    def template_graft(self) -> GraftSize | None:
        """The graft to draw: the recommended one, else the closest."""
        return self.graft or self.closest

    @property
    def comparison(self) -> dict[str, Any]:
        """The comparison value answered (``{key: value}``; empty without ``--vary``)."""
        return {} if self.recommendation is None else dict(self.recommendation.comparison)

    def name(self, label: str | None) -> str | None:
        """A member's label in words."""
        return None if label is None else self.names.get(label, label)

    def _unsealable(self) -> str:
        roots = " and ".join(f"{d:.1f}" for d in self.unsealable_roots_mm)
        return (f"No graft is robust over the root's uncertainty: the native "
                f"leaflets cannot seal a {roots} mm root whatever the graft (closed-form "
                "bound; not computed).")

    def headline(self) -> str:
        """The answer in one sentence or two
        (:func:`~valve_dolfinx.sizing.recommendation.headline`)."""
        if self.cannot_seal is not None:
            return self.cannot_seal
        return headline(self.recommendation, self.names, target_source=self.target_source,
                        excluded=self._unsealable() if self.unsealable_roots_mm else "")

    def to_dict(self) -> dict:
        """The answer as ``summary.json`` holds it, members in words."""
        rec = self.recommendation
        answer = None if rec is None else rec.answer

        def size(value: GraftSize | None) -> dict | None:
            return None if value is None else {"label": value.label, **value._asdict()}

        grafts = [] if rec is None else [
            {"graft": c.label, "worst_height_mm": c.worst_height_mm, "spread_mm": c.spread_mm,
             "margin_mm": c.margin_mm, "limiting_member": self.name(c.limiting_member),
             "qualifies": c.qualifies, "state": cell_state(c)} for c in rec.cells]
        margin, member, solved = (None, None, False) if rec is None else rec.margin
        return {"comparison": self.comparison, "graft": size(self.graft),
                "margin_mm": margin, "margin_solved": solved,
                "limiting_member": None if member is None else self.name(member),
                "closest": size(self.closest),
                "shortfall_mm": None if answer is None else answer.shortfall_mm,
                "target_mm": None if rec is None else rec.target_mm,
                "target_source": self.target_source,
                "members": [] if rec is None else [self.name(m) for m in rec.members],
                "targets_mm": {} if rec is None else {self.name(m): t
                                                      for m, t in rec.targets_mm.items()},
                "grafts": grafts, "unsealable_roots_mm": list(self.unsealable_roots_mm),
                "unsealable_reason": self.unsealable_reason, "cannot_seal": self.cannot_seal,
                "tolerance_mm": None if answer is None else answer.tolerance_mm,
                "trim": None if answer is None else answer.trim,
                "headline": self.headline()}


@dataclass(frozen=True)
class PlanAnswers:
    """The plan's answer at each comparison value (one :class:`PlanRecommendation`, with an
    empty ``comparison``, when nothing is varied), in the study's order of the values."""

    values: tuple[PlanRecommendation, ...]

    @property
    def varied(self) -> bool:
        return len(self.values) > 1

    @property
    def axes(self) -> dict[str, list[Any]]:
        """``{key: [values]}`` of the comparison axes (empty when nothing is varied)."""
        out: dict[str, list[Any]] = {}
        for value in self.values:
            for key, v in value.comparison.items():
                if v not in out.setdefault(key, []):
                    out[key].append(v)
        return out

    @property
    def kind(self) -> str:
        """``"cannot_seal"``, ``"graft"`` (a graft at every value) or ``"closest"``."""
        if any(v.cannot_seal is not None for v in self.values):
            return "cannot_seal"
        return "graft" if all(v.graft is not None for v in self.values) else "closest"

    @property
    def common(self) -> GraftSize | None:
        """With comparison axes, the smallest size that qualifies at every value (read from
        the one surface of the plan's study); None when nothing is varied, or no size
        qualifies at every value."""
        recs = [v.recommendation for v in self.values]
        if not self.varied or any(r is None for r in recs) or any(
                v.unsealable_roots_mm for v in self.values):
            return None
        return common_size([r.answer for r in recs])

    @property
    def template_grafts(self) -> list[GraftSize]:
        """The grafts to draw: the common size (if any), then each value's recommended or
        closest graft, each once."""
        grafts = [self.common, *(v.template_graft for v in self.values)]
        return list(dict.fromkeys(g for g in grafts if g is not None))

    def label(self, value: PlanRecommendation) -> str:
        """A value as the page names it (``graft.bending_modulus_kpa=200``)."""
        return axis_label(value.comparison.items())

    def _value(self, value: PlanRecommendation) -> str:
        """A value in a list over one axis (``200``; every key with several axes)."""
        if len(self.axes) == 1:
            return value_text(next(iter(value.comparison.values())))
        return self.label(value)

    def dependence(self) -> str:
        """Whether the size depends on the comparison axes, in a sentence or two ("" when
        nothing is varied or nothing was computed)."""
        if not self.varied or self.kind == "cannot_seal":
            return ""
        axes = " and ".join(self.axes)
        sizes = [v.graft for v in self.values]
        if all(s is not None for s in sizes) and len(set(sizes)) == 1:
            values = ", ".join(self._value(v) for v in self.values)
            return (f"The recommended graft is {sizes[0].label} at every value of {axes} "
                    f"studied ({values}): the size does not depend on it.")
        answers = ", ".join(f"{s.label if s else 'no graft'} at {self._value(v)}"
                            for v, s in zip(self.values, sizes, strict=True))
        head = f"The answer differs with {axes}: {answers}."
        common = self.common
        if common is None:
            return f"{head} No size qualifies at every value."
        solved = [v.recommendation.cell(common.label) is not None for v in self.values]
        if all(solved):
            how = "solved at every value"
        elif any(solved):
            at = [", ".join(self._value(v) for v, s in zip(self.values, solved, strict=True)
                            if s is flag) for flag in (True, False)]
            how = f"solved at {at[0]}, read from the surface at {at[1]}"
        else:
            how = "read from the surface, not solved"
        return (f"{head} {common.label} (+{common.width_pct:g} % width, "
                f"+{common.height_pct:g} % height) is the smallest size that qualifies at "
                f"every value ({how}).")

    def headline(self) -> str:
        """The plan's answer as it opens the page: the one value's headline, or whether the
        size depends on the comparison axes."""
        if not self.varied:
            return self.values[0].headline()
        return self.dependence() or self.values[0].headline()

    def lines(self) -> list[str]:
        """Each value's answer in a line, named by its value ([] when nothing is varied)."""
        if not self.varied:
            return []
        out = []
        for value in self.values:
            answer = value.recommendation.answer if value.recommendation else None
            where = value.name(answer.limiting_member) if answer else None
            where = f" in {where}" if where else ""
            if value.graft is not None:
                graft = value.graft
                margin, member, solved = value.recommendation.margin
                where = f" in {value.name(member)}" if member else ""
                text = (f"{graft.label} (+{graft.width_pct:g} % width, +{graft.height_pct:g} % "
                        f"height), {'solved' if solved else 'predicted'} worst-case margin "
                        f"{margin_text(margin, signed=True)} mm{where}.")
            elif answer is not None and answer.shortfall_mm is not None and value.closest:
                text = (f"no graft is robust; the closest, {value.closest.label}, is "
                        f"{margin_text(answer.shortfall_mm)} mm short{where}.")
            else:
                text = value.headline()
            out.append(f"At {self.label(value)}: {text}")
        return out

    def to_dict(self) -> dict:
        common = self.common
        return {"axes": self.axes,
                "common": None if common is None else {"label": common.label,
                                                       **common._asdict()},
                "dependence": self.dependence(), "headline": self.headline(),
                "values": [v.to_dict() for v in self.values]}
