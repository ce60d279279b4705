"""What a plan answers: a graft size, the robust recommendation and its margin, in plain words.

:class:`PlanRecommendation` is the plan's answer as the report prints it, independent of
how the study behind it is organised: the plan's study (:func:`valve_dolfinx.plan.runner.
run_plan_study`) maps the answer read from its response surface
(:mod:`valve_dolfinx.sizing.answer`) onto it.  It is one of three answers:

* a graft is recommended: the smallest size whose predicted worst case over the root
  diameters reaches the target within the model's resolution and that seals (a size off
  the grid, to 1 %), with its predicted margin in the root diameter that limits it;
* no graft is robust: the closest size and its shortfall -- or, when some root diameters
  of the uncertainty are ones that the closed-form bound of :mod:`valve_dolfinx.plan.reach`
  rules out (not computed), the size that qualifies in every member computed, with its
  margin there;
* the native leaflets cannot seal the measured root whatever the graft (the same
  bound): nothing was computed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.result import margin_text, shortfall_digits
from valve_dolfinx.sizing.cells import GraftSize

__all__ = ["GraftSize", "GraftWorstCase", "PlanRecommendation"]


@dataclass(frozen=True)
class GraftWorstCase:
    """One graft of the grid over the plan's members (mm; members in words).

    ``worst_height_mm`` is its lowest minimum coaptation height, ``spread_mm`` the highest
    minus the lowest, ``margin_mm`` the least of its height minus each member's target, in
    ``limiting_member``; ``state`` says in words where it did not converge or seal.
    """

    graft: GraftSize
    worst_height_mm: float | None
    spread_mm: float | None
    margin_mm: float | None
    limiting_member: str | None
    qualifies: bool
    state: str

    def to_dict(self) -> dict:
        return {**asdict(self), "graft": self.graft.label}


@dataclass(frozen=True)
class PlanRecommendation:
    """The plan's answer (mm); exactly one of ``graft``, ``closest`` and ``cannot_seal``
    says what it is (``closest`` may also be None when no graft case produced a figure).

    Attributes
    ----------
    graft
        The recommended graft: it converges, seals and reaches the target in every member.
    margin_mm
        The lowest minimum coaptation height over the members minus the target, of the
        recommended graft -- or of the closest one when it qualifies in every member that
        was computed but some root diameters are beyond the leaflets' reach (the closest
        carries a margin in that case only).
    limiting_member
        The member (root diameter, path) where that margin, or shortfall, is taken.
    closest, shortfall_mm
        When no graft is robust: the graft closest to qualifying and by how much its
        worst member falls short of the target (None: it reaches the target in every
        member computed).
    target_mm, target_source
        The minimum coaptation height a graft must reach (None when it differs between
        members, see ``targets_mm``), and where it comes from.
    members
        The members the recommendation was taken over (root diameter, path), in words.
    targets_mm
        Each member's target.
    grafts
        Every graft of the grid over the members.
    unsealable_roots_mm, unsealable_reason
        Root diameters of the measurement's uncertainty that the closed-form bound rules
        out (no graft seals them; their cases are not computed), and its one-line verdict
        at the largest of them.
    cannot_seal
        The closed-form verdict (one line) when the native leaflets cannot seal the
        measured root whatever the graft; nothing was computed then.
    tolerance_mm
        The model's measured resolution (:mod:`valve_dolfinx.sizing.resolution`): a size
        whose predicted worst case comes within it of the target qualifies.
    """

    graft: GraftSize | None = None
    margin_mm: float | None = None
    limiting_member: str | None = None
    closest: GraftSize | None = None
    shortfall_mm: float | None = None
    target_mm: float | None = None
    target_source: str = ""
    members: tuple[str, ...] = ()
    targets_mm: dict[str, float | None] = field(default_factory=dict)
    grafts: tuple[GraftWorstCase, ...] = ()
    unsealable_roots_mm: tuple[float, ...] = ()
    unsealable_reason: str = ""
    cannot_seal: str | None = None
    tolerance_mm: float | None = None

    def __post_init__(self) -> None:
        answers = sum(x is not None for x in (self.graft, self.closest, self.cannot_seal))
        if answers > 1:
            raise ParameterError("a plan recommends a graft, or names the closest one, or "
                                 "says the leaflets cannot seal: give one of graft, closest "
                                 "and cannot_seal")
        if self.graft is not None and self.margin_mm is None:
            raise ParameterError("a recommended graft needs its margin_mm over the target")
        if self.graft is not None and self.unsealable_roots_mm:
            raise ParameterError("no graft is robust over root diameters the leaflets cannot "
                                 "seal: name it closest, not graft")

    @property
    def template_graft(self) -> GraftSize | None:
        """The graft to draw: the recommended one, else the closest."""
        return self.graft or self.closest

    def _target(self) -> str:
        return ("the target minimum coaptation height ("
                + (f"{self.target_mm:.2f} mm, " if self.target_mm is not None else "")
                + f"{self.target_source or 'as given'})")

    def _unsealable(self) -> str:
        roots = " and ".join(f"{d:.1f}" for d in self.unsealable_roots_mm)
        return (f"No graft is robust over the root's uncertainty: the native "
                f"leaflets cannot seal a {roots} mm root whatever the graft (closed-form "
                "bound; not computed).")

    def headline(self) -> str:
        """The answer in one sentence or two, as the surgeon reads it first."""
        if self.cannot_seal is not None:
            return self.cannot_seal
        n = len(self.members)
        where = f", in {self.limiting_member}" if self.limiting_member else ""
        resolution = ("" if self.tolerance_mm is None else
                      f" (the model's resolution: {margin_text(self.tolerance_mm)} mm)")
        if self.graft is not None:
            scope = f" in all {n} members" if n > 1 else ""
            within = "" if self.tolerance_mm is None else " within the model's resolution"
            return (f"Recommended graft {self.graft.label} (+{self.graft.width_pct:g} % width, "
                    f"+{self.graft.height_pct:g} % height). It converges, seals and reaches "
                    f"{self._target()}{scope}{within}; its smallest margin is "
                    f"{margin_text(self.margin_mm)} mm{where}{resolution}.")
        computed = " computed" if self.unsealable_roots_mm else ""
        if self.closest is not None and self.margin_mm is not None:  # fails beyond reach only
            return (f"{self._unsealable()} In the {n} members{computed}, {self.closest.label} "
                    f"(+{self.closest.width_pct:g} % width, +{self.closest.height_pct:g} % "
                    f"height) converges, seals and reaches {self._target()}; its smallest "
                    f"margin is {margin_text(self.margin_mm)} mm{where}{resolution}.")
        scope = f" in every one of the {n} members{computed}" if n > 1 else ""
        if self.closest is None and not self.unsealable_roots_mm:
            return ("No answer: no size could be read, for too few solved cases or no "
                    "target (the study's report says which); this says nothing for or "
                    "against any graft.")
        if self.unsealable_roots_mm:
            text = (f"{self._unsealable()} Nor does any graft converge, seal and reach "
                    f"{self._target()}{scope}.")
        else:
            text = (f"No graft in the studied range is robust: none converges, seals and "
                    f"reaches {self._target()}{scope}.")
        if self.closest is None:
            return (f"{text} No size could be read: too few solved cases, or no target "
                    "(the study's report says which).")
        if self.shortfall_mm is not None and self.shortfall_mm > 0:
            d = shortfall_digits(self.shortfall_mm)
            short = (f", {self.shortfall_mm:.{d}f} mm short in its worst member{where}"
                     f"{resolution}")
        else:
            state = next((g.state for g in self.grafts if g.graft == self.closest), "")
            short = f" ({state})" if state else ""
        return f"{text} The closest is {self.closest.label}{short}."

    def to_dict(self) -> dict:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        for key in ("graft", "closest"):
            size = out[key]
            out[key] = None if size is None else {"label": size.label, **size._asdict()}
        out["members"] = list(self.members)
        out["targets_mm"] = dict(self.targets_mm)
        out["grafts"] = [g.to_dict() for g in self.grafts]
        out["unsealable_roots_mm"] = list(self.unsealable_roots_mm)
        out["headline"] = self.headline()
        return out
