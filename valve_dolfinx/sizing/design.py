"""An adaptive design of a sizing study: where to solve next, and when to stop (SPEC §7).

A full grid solves every graft of a width × height grid in every member (each value of
the uncertainty axes along each numerical path); most of those cases lie far from the
decision.  An adaptive study solves instead:

1. **An initial design** (:func:`initial_design`): a ``levels × levels`` lattice over
   the studied width and height range, each size in *one* uncertainty member, assigned as
   a Latin square (size ``(i, j)`` in member ``(i + j) mod U``), so that every member
   sees every width level and every height level once per ``U`` sizes; the lattice's
   diagonal is solved along every other numerical path too, which measures the scatter
   between paths.  The surface fitted to it (:mod:`~valve_dolfinx.sizing.surface`) has
   the root diameter as an input, so a size solved at one diameter informs the others.
2. **Rounds** (:func:`next_points`).  After each round the surfaces are refitted and the
   answer read (:mod:`~valve_dolfinx.sizing.answer`).  The next round solves

   * the answer's size in every member where it is not solved yet (its confirmation), and
   * up to :data:`EXPLORE_PER_ROUND` sizes that could still move the answer: sizes of
     smaller flat area than the answer that lie more than :data:`SAME_SIZE_PCT` from it,
     whose chance of qualifying (:func:`qualify_chance`) is at least
     :data:`SETTLE_PROBABILITY` and whose *expected saving* (that chance times the share
     of flat area the size saves over the answer) is at least :data:`EXPECTED_SAVING`
     (without an answer: any size whose chance is at least :data:`SETTLE_PROBABILITY`);
     the largest expected saving (the likeliest) first, each in the
     uncertainty member that decides it (along its first path where the size is not
     solved yet: a size solved along every path there is as settled as solves make it),
     none within :data:`SPREAD` of another (scaled width and height).
3. **The cut round** (:func:`cut_points`).  Once the answer is solved in every member and
   no size could move it, the sizes a cut half a millimetre off its template makes
   (:func:`~valve_dolfinx.sizing.answer.trim_check`) whose probability of sealing is below
   the answer's threshold in some member are solved in the member where it is least
   (along its first path where the size is not solved yet): between solved cells the
   sealing is an interpolation, and this is where it decides whether the answer survives
   a cut of the millimetre a graft is trimmed to.  It informs the report; the answer's
   rule does not change.
4. **A stop** (``valve_dolfinx.study.rounds``): *settled* when the answer's size is
   solved in every member, its confirmation holds, no size is left that could move it
   (item 2; for "no graft": no size has a chance of at least :data:`SETTLE_PROBABILITY`)
   and no cut size's sealing is left open (item 3); *budget* when the next round's
   confirmation would exceed the study's case budget, saying what is not settled.

The chance that a size qualifies is an upper bound: the least, over the members, of the
probability that the member's margin reaches ``−tolerance`` (normal predictive
distribution of the smooth surface), times the size's least probability of sealing.  A
size below :data:`SETTLE_PROBABILITY` by that bound cannot become the answer with more
than that probability.

:data:`SAME_SIZE_PCT` is 3 points of width and of height: about 0.6 mm of the native
free edge and 0.4 mm of its height, below the millimetre a surgeon trims a graft to, and
the measure by which the answer's bootstrap stability is judged.  Everything here is a
deterministic function of the solved cases, so a serial sweep, ``mpirun`` and a job array
choose the same rounds.  Nothing here imports DOLFINx.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr  # the standard normal distribution function

from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.sizing.answer import (
    MemberTable,
    SizingAnswer,
    StudyFit,
    member_values,
    same_size,
)
from valve_dolfinx.sizing.surface import SurfacePoint

__all__ = ["INITIAL_LEVELS", "EXPLORE_PER_ROUND", "SETTLE_PROBABILITY", "EXPECTED_SAVING",
           "SPREAD", "Candidate", "initial_design", "qualify_chance", "open_sizes",
           "next_points", "cut_points"]

#: width and height levels of the initial lattice
INITIAL_LEVELS = 3
#: exploration sizes a round adds, at most (beside the answer's confirmation)
EXPLORE_PER_ROUND = 4
#: a size whose chance of qualifying is below this cannot move the answer
SETTLE_PROBABILITY = 0.05
#: nor can a size whose expected saving of flat area over the answer (its chance of
#: qualifying times the share of flat area it saves) is below this share: 1 % of the
#: default leaflet's flat area is about 2 mm², a tenth of a millimetre's trim along its
#: free edge
EXPECTED_SAVING = 0.01
#: the least distance between two sizes of one round, in the width and height scaled to
#: the studied range
SPREAD = 0.2


def _levels(low: float, high: float, n: int) -> list[float]:
    """``n`` whole per cents from ``low`` to ``high``, evenly spread, ends included."""
    if high <= low:
        return [float(low)]
    return list(dict.fromkeys(float(round(v)) if low < v < high else float(v)
                              for v in np.linspace(low, high, n)))


def initial_design(widths: tuple[float, float], heights: tuple[float, float],
                   n_uncertain: int, n_paths: int, levels: int = INITIAL_LEVELS
                   ) -> list[tuple[int, GraftSize]]:
    """The initial design: ``(member index, size)`` (module docstring, item 1).

    ``widths`` and ``heights`` are the studied ranges (per cent); the members are indexed
    as a study orders them, uncertainty member ``u`` along path ``p`` (0-based) being
    ``u · n_paths + p``.
    """
    ws, hs = _levels(*widths, levels), _levels(*heights, levels)
    points = []
    for i, w in enumerate(ws):
        for j, h in enumerate(hs):
            points.append((((i + j) % n_uncertain) * n_paths, GraftSize(w, h)))
    for k in range(min(len(ws), len(hs))):
        u = (2 * k) % n_uncertain
        points += [(u * n_paths + p, GraftSize(ws[k], hs[k])) for p in range(1, n_paths)]
    return points


@dataclass(frozen=True)
class Candidate:
    """A size that could still move the answer: its chance of qualifying, its expected
    saving (chance × the share of flat area it saves over the answer; the chance itself
    without an answer), and the uncertainty member (its label and index among the
    answer's members) that decides it."""

    size: GraftSize
    chance: float
    saving: float
    member: str
    member_index: int


def qualify_chance(fit: StudyFit, answer: SizingAnswer, tables: Sequence[MemberTable],
                   sizes: Sequence[GraftSize]) -> tuple[np.ndarray, np.ndarray]:
    """Per size, the upper bound of its chance of qualifying (module docstring) and the
    index (among ``answer.members``) of the member with the least chance."""
    values = member_values(tables)
    tolerance = answer.tolerance_mm or 0.0
    chances, seals = [], []
    for label in answer.members:
        points = [SurfacePoint(s.width_pct, s.height_pct, values[label]) for s in sizes]
        mean, sd = fit.surface.predict(points)
        margin = mean - answer.targets_mm[label] + tolerance
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(sd > 0, margin / np.where(sd > 0, sd, 1.0), np.sign(margin) * np.inf)
        chances.append(ndtr(z))
        seals.append(fit.sealing.probability(points))
    chances, seals = np.array(chances), np.array(seals)
    deciding = chances.argmin(axis=0)
    return chances.min(axis=0) * seals.min(axis=0), deciding


def open_sizes(fit: StudyFit, answer: SizingAnswer, tables: Sequence[MemberTable]
               ) -> list[Candidate]:
    """The sizes of the answer's lattice that could still move it (module docstring, item
    2), the most likely first."""
    lattice = answer.lattice
    if lattice is None or fit.surface is None:
        return []
    ww, hh = np.meshgrid(lattice.widths_pct, lattice.heights_pct)
    sizes = [GraftSize(float(w), float(h)) for w, h in zip(ww.ravel(), hh.ravel(), strict=True)]
    if answer.size is not None:
        area = answer.size.area_ratio
        sizes = [s for s in sizes if s.area_ratio < area and not same_size(s, answer.size)]
    if not sizes:
        return []
    chance, deciding = qualify_chance(fit, answer, tables, sizes)
    if answer.size is None:
        saving, least = chance, SETTLE_PROBABILITY
    else:
        share = np.array([1.0 - s.area_ratio / answer.size.area_ratio for s in sizes])
        saving, least = chance * share, EXPECTED_SAVING
    order = np.argsort(-saving, kind="stable")
    return [Candidate(sizes[i], float(chance[i]), float(saving[i]), answer.members[deciding[i]],
                      int(deciding[i]))
            for i in order if saving[i] >= least and chance[i] >= SETTLE_PROBABILITY]


def next_points(candidates: Sequence[Candidate], ranges: tuple[tuple[float, float],
                                                               tuple[float, float]],
                limit: int = EXPLORE_PER_ROUND) -> list[Candidate]:
    """Up to ``limit`` of ``candidates`` (most likely first), none within :data:`SPREAD` of
    an earlier one in the width and height scaled to ``ranges``."""
    (w0, w1), (h0, h1) = ranges
    span_w, span_h = max(w1 - w0, 1.0), max(h1 - h0, 1.0)
    chosen: list[Candidate] = []
    for candidate in candidates:
        if len(chosen) >= limit:
            break
        if all(math.hypot((candidate.size.width_pct - c.size.width_pct) / span_w,
                          (candidate.size.height_pct - c.size.height_pct) / span_h) >= SPREAD
               for c in chosen):
            chosen.append(candidate)
    return chosen



def cut_points(fit: StudyFit, answer: SizingAnswer, tables: Sequence[MemberTable]
               ) -> list[Candidate]:
    """The sizes a cut half a millimetre off the answer's template makes whose least
    probability of sealing over the members is below the answer's threshold (module
    docstring, item 3), each with that probability as its ``chance`` (``saving`` 0) and
    the member where it is least; the least likely to seal first."""
    trim = answer.trim
    if answer.size is None or fit.sealing is None or not trim:
        return []
    sizes = [GraftSize.parse(label) for label in trim["sizes"]]
    values = member_values(tables)
    seals = np.array([fit.sealing.probability(
        [SurfacePoint(s.width_pct, s.height_pct, values[label]) for s in sizes])
        for label in answer.members])
    deciding, least = seals.argmin(axis=0), seals.min(axis=0)
    order = np.argsort(least, kind="stable")
    return [Candidate(sizes[i], float(least[i]), 0.0, answer.members[deciding[i]],
                      int(deciding[i]))
            for i in order if least[i] < answer.seal_threshold]
