"""The sizing answer, read from the response surface at the measured resolution (SPEC §7).

The one home of the answer that the study, the nomogram and the plan report:

1. :func:`fit_study` fits, over every member table of a study (all comparison values,
   every uncertainty value, every path), the coaptation surface and the sealing model
   (:mod:`~valve_dolfinx.sizing.surface`) and measures the resolution
   (:mod:`~valve_dolfinx.sizing.resolution`).
2. :func:`read_answer` reads one comparison value's answer from them on a lattice of
   1 % in W and H over the studied range.  Per uncertainty member ``m`` (one value of
   each uncertainty axis; the paths are replicates, their scatter is in the resolution)
   the predicted margin is ``μ_m(W, H) − t_m``, the predicted height minus the member's
   target (its normal valve's height, or a given threshold); the *predicted worst case*
   is the least margin over the members, and a size *seals* when its least probability
   of sealing over the members is at least :data:`SEAL_PROBABILITY`.  A size
   *qualifies* when it seals and its predicted worst case is at least ``−tolerance``.
   The answer is the qualifying size of smallest flat area ``(1 + W)(1 + H)`` (ties:
   narrower, then lower), with the band of every qualifying size and the sealing size
   of highest predicted worst case.  "No graft" only when no size seals, or none comes
   within the tolerance of the target; the closest size's shortfall is then given
   against the tolerance.
3. :func:`common_size` reads, over several comparison values' answers, the smallest size
   that qualifies at every one of them.
4. :func:`sizes_to_confirm` lists the off-grid solves that confirm an answer, and
   :func:`solved_worst_case` gives the same statistic as the prediction from a size's
   solves: per uncertainty member the mean of its paths' heights minus the member's
   target, the least over the members.
5. :func:`bootstrap_stability` measures how far the answer moves when each cell's paths
   are resampled with replacement and the surfaces refitted.

Nothing here imports DOLFINx.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from valve_dolfinx.geometry.outline import LeafletShape
from valve_dolfinx.result import margin_text
from valve_dolfinx.sizing.cells import FIGURE, GraftSize, _number, member_targets
from valve_dolfinx.sizing.resolution import (
    MESH_LADDER,
    Resolution,
    discretisation_error_mm,
    path_scatter_mm,
)
from valve_dolfinx.sizing.surface import (
    CV_FOLDS,
    CoaptationSurface,
    SealingModel,
    SurfacePoint,
    fit_sealing,
    fit_surface,
)

__all__ = ["MemberTable", "StudyFit", "SizingAnswer", "Lattice", "fit_study", "read_answer",
           "common_size", "sizes_to_confirm", "solved_worst_case", "resample_paths",
           "bootstrap_stability", "same_size", "SAME_SIZE_PCT", "member_label",
           "member_values", "SEAL_PROBABILITY", "MIN_CELLS", "TRIM_MM", "trim_check",
           "trim_text"]

#: the least probability of sealing, in every member, of a size that qualifies
SEAL_PROBABILITY = 0.9
#: solved cells a surface needs (over at least two widths and two heights)
MIN_CELLS = 6
#: the lattice step of the answer (per cent of the native leaflet)
STEP_PCT = 1.0
#: two sizes within this many per cent in width and in height are the same answer: about
#: 0.6 mm of the native free edge and 0.4 mm of its height, below the millimetre a graft is
#: trimmed to
SAME_SIZE_PCT = 3.0
#: how far a cut graft may miss its template along the free edge and along the height
#: (mm): a graft is trimmed to the millimetre, so the answer is also read at the sizes a
#: cut this far off makes (:func:`trim_check`)
TRIM_MM = 0.5


def same_size(a: GraftSize | None, b: GraftSize | None) -> bool:
    """Whether two sizes are the same answer: within :data:`SAME_SIZE_PCT` in W and H (two
    "no graft" answers are the same)."""
    if a is None or b is None:
        return a is b
    return (abs(a.width_pct - b.width_pct) <= SAME_SIZE_PCT
            and abs(a.height_pct - b.height_pct) <= SAME_SIZE_PCT)


@dataclass(frozen=True)
class MemberTable:
    """The rows of one member of one comparison value (the normal valve and the grafts).

    ``comparison`` and ``uncertain`` are ``((axis key, value), ...)``; ``path`` the
    numerical path's number; ``label`` the member's name in reports.
    """

    label: str
    rows: Sequence[Mapping]
    comparison: tuple[tuple[str, Any], ...] = ()
    uncertain: tuple[tuple[str, Any], ...] = ()
    path: int = 1

    @property
    def values(self) -> tuple[tuple[str, Any], ...]:
        return self.comparison + self.uncertain


@dataclass
class StudyFit:
    """What :func:`fit_study` measured: the surfaces (None with too few cells, ``why``
    says so), the resolution, the native leaflet, the studied W and H ranges."""

    surface: CoaptationSurface | None
    sealing: SealingModel | None
    resolution: Resolution
    leaflet: LeafletShape
    widths_pct: tuple[float, float]
    heights_pct: tuple[float, float]
    why: str = ""


@dataclass
class Lattice:
    """The answer's 1 % lattice (arrays of shape ``(len(heights), len(widths))``):
    predicted worst-case margin (mm), least probability of sealing, qualifying sizes."""

    widths_pct: np.ndarray
    heights_pct: np.ndarray
    worst_margin_mm: np.ndarray
    seal_probability: np.ndarray
    qualifies: np.ndarray


@dataclass
class SizingAnswer:
    """One comparison value's answer (mm, per cent; members by label, "" alone).

    ``size`` is the recommended graft (None: no graft), with its predicted worst-case
    ``margin_mm`` (negative: short, within the tolerance) and the surface's standard
    deviation there, in ``limiting_member``, its least probability of sealing, its free
    edge and midline height.  ``band`` summarises every qualifying size; ``highest`` is
    the sealing size of highest predicted worst case (any size if none seals), with its
    margin; without a graft, ``shortfall_mm`` is its distance below the target.
    ``why`` is "" with a graft, else ``"no surface"``, ``"no target"``, ``"none seals"``
    or ``"short"``.
    """

    comparison: dict[str, Any]
    members: list[str]
    targets_mm: dict[str, float | None]
    target_source: str
    resolution: Resolution
    seal_threshold: float = SEAL_PROBABILITY
    surface: dict | None = None
    sealing: dict | None = None
    size: GraftSize | None = None
    margin_mm: float | None = None
    margin_sd_mm: float | None = None
    predicted_height_mm: float | None = None
    limiting_member: str | None = None
    seal_probability: float | None = None
    free_edge_mm: float | None = None
    height_mm: float | None = None
    band: dict | None = None
    #: the sizes a cut :data:`TRIM_MM` off the template makes (:func:`trim_check`)
    trim: dict | None = None
    highest: GraftSize | None = None
    highest_margin_mm: float | None = None
    shortfall_mm: float | None = None
    #: the smallest qualifying size, when a confirmed size within :data:`SAME_SIZE_PCT` of
    #: it is the answer instead (``read_answer``'s ``prefer``)
    smallest: GraftSize | None = None
    why: str = ""
    text: str = ""
    lattice: Lattice | None = field(default=None, repr=False)

    @property
    def tolerance_mm(self) -> float | None:
        return self.resolution.tolerance_mm

    @property
    def closest(self) -> GraftSize | None:
        """Without a graft, the size of highest predicted worst case; else None."""
        return self.highest if self.size is None else None

    def to_dict(self) -> dict:
        out = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "lattice"}
        for key in ("size", "highest", "smallest"):
            size = out[key]
            out[key] = None if size is None else {"label": size.label, **size._asdict()}
        out["resolution"] = self.resolution.to_dict()
        out["tolerance_mm"] = self.tolerance_mm
        return out


# --- fitting ----------------------------------------------------------------------------
def _graft_rows(table: MemberTable):
    for row in table.rows:
        if (row.get("graft_width_pct") is not None
                and row.get("status") not in ("damaged", "stale")):
            yield row


def _mesh_size(tables: Sequence[MemberTable]) -> float | None:
    for table in tables:
        for row in table.rows:
            mesh = _number(row, "mesh_size_mm")
            if math.isnan(mesh):
                mesh = _number((row.get("parameters") or {}).get("geometry"), "mesh_size_mm")
            if math.isfinite(mesh):
                return mesh
    return None


def _leaflet(tables: Sequence[MemberTable]) -> LeafletShape:
    """The native leaflet of the study's grafts (the default outline without parameters)."""
    for table in tables:
        for row in _graft_rows(table):
            geometry = (row.get("parameters") or {}).get("geometry") or {}
            if "root_diameter_mm" in geometry:
                return LeafletShape(geometry["root_diameter_mm"], geometry["gamma_deg"],
                                    geometry["commissure_height_mm"])
    return LeafletShape()


def fit_study(tables: Sequence[MemberTable], *, ladder: Path | None = MESH_LADDER,
              cv_folds: int = CV_FOLDS) -> StudyFit:
    """Fit the surfaces to every graft case of ``tables`` and measure the resolution.

    Parameters
    ----------
    tables
        Every member table of the study (all comparison values).
    ladder
        The mesh-ladder table for the discretisation error (None: not measured).
    cv_folds
        Folds of the surface's cross-validation (0: none, for a bootstrap's refits).
    """
    points, heights, seal_points, sealed = [], [], [], []
    replicates: dict[tuple, list[float]] = {}
    for table in tables:
        for row in _graft_rows(table):
            point = SurfacePoint(float(row["graft_width_pct"]), float(row["graft_height_pct"]),
                                 table.values)
            seal_points.append(point)
            sealed.append(bool(row.get("converged")) and bool(row.get("competent")))
            value = _number(row, FIGURE)
            if row.get("converged") and math.isfinite(value):
                points.append(point)
                heights.append(value)
                replicates.setdefault(point.cell, []).append(value)
    scatter, pooled = path_scatter_mm(replicates.values())
    widths = sorted({p.width_pct for p in seal_points}) or [0.0]
    tall = sorted({p.height_pct for p in seal_points}) or [0.0]
    cells = {p.cell for p in points}
    enough = (len(cells) >= MIN_CELLS and len({c[0] for c in cells}) >= 2
              and len({c[1] for c in cells}) >= 2)
    surface = sealing = None
    why = ""
    if enough:
        surface = fit_surface(points, heights, cv_folds=cv_folds)
        sealing = fit_sealing(seal_points, sealed, surface.design)
    else:
        why = (f"a response surface needs at least {MIN_CELLS} solved cells over at least two "
               f"widths and two heights; this study has {len(cells)} converged")
    mesh_error, source = (discretisation_error_mm(ladder, _mesh_size(tables))
                          if ladder is not None else (None, "not measured"))
    resolution = Resolution(scatter, pooled, surface.noise_mm if surface else None,
                            mesh_error, source)
    return StudyFit(surface, sealing, resolution, _leaflet(tables), (widths[0], widths[-1]),
                    (tall[0], tall[-1]), why)


# --- reading the answer -------------------------------------------------------------------
def _axis(low: float, high: float) -> np.ndarray:
    """The lattice over [low, high]: whole per cents, the ends included."""
    inner = np.arange(math.ceil(low / STEP_PCT), math.floor(high / STEP_PCT) + 1) * STEP_PCT
    return np.unique(np.concatenate([[low], inner[(inner > low) & (inner < high)], [high]]))


def member_label(uncertain: tuple[tuple[str, Any], ...]) -> str:
    """``key=value, ...`` of an uncertainty member ("" without uncertainty axes)."""
    return ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                     for k, v in uncertain)


def member_values(tables: Sequence[MemberTable]) -> dict[str, tuple]:
    """The uncertainty members of ``tables`` (paths merged): ``{label: axis values}``."""
    values: dict[str, tuple] = {}
    for table in tables:
        values.setdefault(member_label(table.uncertain), table.values)
    return values


def _members(tables: Sequence[MemberTable], target_mm: float | None
             ) -> tuple[dict[str, tuple], dict[str, float | None], str]:
    """The uncertainty members (paths merged) with their values and targets."""
    targets, source = member_targets({t.label: t.rows for t in tables}, target_mm)
    values: dict[str, tuple] = {}
    merged: dict[str, float | None] = {}
    for table in tables:
        label = member_label(table.uncertain)
        values.setdefault(label, table.values)
        if merged.get(label) is None:
            merged[label] = targets[table.label]
    if len(values) == 1:
        source = source.replace(" in each member", "")
    return values, merged, source


def _dims(leaflet: LeafletShape, size: GraftSize) -> tuple[float, float]:
    graft = LeafletShape(leaflet.root_diameter, leaflet.gamma_deg, leaflet.commissure_height,
                         size.width_pct, size.height_pct)
    return graft.free_edge_length, graft.height


def read_answer(fit: StudyFit, tables: Sequence[MemberTable], target_mm: float | None = None,
                *, comparison: Mapping[str, Any] | None = None,
                seal_threshold: float = SEAL_PROBABILITY,
                prefer: Sequence[GraftSize] = ()) -> SizingAnswer:
    """The answer of one comparison value (its member ``tables``) from ``fit``.

    ``target_mm`` is the minimum coaptation height to reach in every member; None takes
    each member's normal valve's.  ``prefer`` are sizes solved in every member whose
    confirmation held, in the order they were proposed: the first of them that is the same
    answer as the smallest qualifying size (:func:`same_size`) and still qualifies, else
    the first that is the same answer, is the answer instead, so that an answer does not
    creep by a per cent per round of confirmation.  It need not qualify on the surface
    itself: its own solves, now in the fit, have passed the confirmation's test
    (:func:`~valve_dolfinx.sizing.recommendation.confirmation_holds`, the tolerance plus
    a solve's scatter), and reading them again against the tolerance alone would undo that
    test by a difference below a solve's scatter.
    """
    values, targets, source = _members(tables, target_mm)
    answer = SizingAnswer(dict(comparison or {}), list(values), targets, source,
                          fit.resolution, seal_threshold)
    if fit.surface is None:
        answer.why = "no surface"
        answer.text = f"No answer: {fit.why}. The solved cells are in the table below."
        return answer
    answer.surface, answer.sealing = fit.surface.summary(), fit.sealing.summary()
    if any(t is None for t in targets.values()):
        answer.why = "no target"
        answer.text = (f"No target ({source}: the normal valve was not run or did not "
                       "converge in some member; give --target-coaptation).")
        return answer
    widths, heights = _axis(*fit.widths_pct), _axis(*fit.heights_pct)
    ww, hh = np.meshgrid(widths, heights)
    grid = [GraftSize(float(w), float(h)) for w, h in zip(ww.ravel(), hh.ravel(), strict=True)]
    margins, sds, probabilities = [], [], []
    for label, axis_values in values.items():
        points = [SurfacePoint(s.width_pct, s.height_pct, axis_values) for s in grid]
        mean, sd = fit.surface.predict(points)
        margins.append(mean - targets[label])
        sds.append(sd)
        probabilities.append(fit.sealing.probability(points))
    margins, sds, probabilities = np.array(margins), np.array(sds), np.array(probabilities)
    limiting = margins.argmin(axis=0)
    worst = margins.min(axis=0)
    seal = probabilities.min(axis=0)
    tolerance = fit.resolution.tolerance_mm
    seals = seal >= seal_threshold
    qualifies = seals & (worst >= -tolerance)
    shape = ww.shape
    answer.lattice = Lattice(widths, heights, worst.reshape(shape), seal.reshape(shape),
                             qualifies.reshape(shape))
    pool = np.flatnonzero(seals) if seals.any() else np.arange(len(grid))
    top = int(pool[np.argmax(worst[pool])])
    answer.highest, answer.highest_margin_mm = grid[top], float(worst[top])
    labels = list(values)
    if not qualifies.any():
        answer.limiting_member = labels[limiting[top]]
        if not seals.any():
            answer.why = "none seals"
            best = int(np.argmax(seal))
            answer.text = (f"No graft: no size in the studied range ({_range(fit)}) seals"
                           f"{_every(answer)} with a probability of at least "
                           f"{seal_threshold:g}; the highest is {seal[best]:.2f}, at "
                           f"{grid[best].label}. {_resolution(answer)}")
        else:
            answer.why = "short"
            answer.shortfall_mm = -answer.highest_margin_mm
            answer.text = _short_text(answer, fit)
        return answer
    chosen = min(np.flatnonzero(qualifies), key=lambda i: (grid[i].area_ratio, *grid[i]))
    index = {tuple(size): i for i, size in enumerate(grid)}
    kept = [index[tuple(p)] for p in prefer if tuple(p) in index]
    kept = sorted((i for i in kept if same_size(grid[i], grid[chosen])),
                  key=lambda i: not qualifies[i])  # stable: in the order proposed
    if kept and kept[0] != chosen:
        answer.smallest = grid[chosen]
        chosen = kept[0]
    m = int(limiting[chosen])
    answer.size = grid[chosen]
    answer.margin_mm, answer.margin_sd_mm = float(worst[chosen]), float(sds[m, chosen])
    answer.limiting_member = labels[m]
    answer.predicted_height_mm = float(margins[m, chosen] + targets[labels[m]])
    answer.seal_probability = float(seal[chosen])
    answer.free_edge_mm, answer.height_mm = _dims(fit.leaflet, answer.size)
    band = [grid[i] for i in np.flatnonzero(qualifies)]
    areas = [s.area_ratio for s in band]
    answer.band = {"sizes": len(band),
                   "width_pct": [min(s.width_pct for s in band), max(s.width_pct for s in band)],
                   "height_pct": [min(s.height_pct for s in band),
                                  max(s.height_pct for s in band)],
                   "area_ratio": [min(areas), max(areas)]}
    answer.trim = trim_check(answer, fit.leaflet)
    answer.text = _chosen_text(answer, fit)
    return answer


def _pct_per_mm(leaflet: LeafletShape, size: GraftSize) -> tuple[float, float]:
    """Per cents of width and of height that lengthen ``size``'s free edge and its height
    by one millimetre each (a per cent's difference at ``size``)."""
    free_edge, height = _dims(leaflet, size)
    wider = _dims(leaflet, GraftSize(size.width_pct + 1.0, size.height_pct))[0]
    taller = _dims(leaflet, GraftSize(size.width_pct, size.height_pct + 1.0))[1]
    return 1.0 / (wider - free_edge), 1.0 / (taller - height)


def trim_check(answer: SizingAnswer, leaflet: LeafletShape, trim_mm: float = TRIM_MM
               ) -> dict | None:
    """The answer read at the sizes a cut ``trim_mm`` off its template makes: its free edge
    and its height each shorter, as cut, or longer by ``trim_mm`` (the eight sizes around it
    on the lattice, those inside the studied range).  Returns the offsets (per cent), the
    sizes read, the least predicted worst-case margin and the least probability of sealing
    over them with where each is, the sizes that do not qualify, and ``robust``: every one
    of them qualifies.  None without an answer or a lattice."""
    lattice, size = answer.lattice, answer.size
    if size is None or lattice is None:
        return None
    per_w, per_h = _pct_per_mm(leaflet, size)
    dw = max(STEP_PCT, round(trim_mm * per_w / STEP_PCT) * STEP_PCT)
    dh = max(STEP_PCT, round(trim_mm * per_h / STEP_PCT) * STEP_PCT)
    column = {float(w): j for j, w in enumerate(lattice.widths_pct)}
    row = {float(h): i for i, h in enumerate(lattice.heights_pct)}
    read = []
    for a in (-1, 0, 1):
        for b in (-1, 0, 1):
            w, h = size.width_pct + a * dw, size.height_pct + b * dh
            if (a or b) and w in column and h in row:
                read.append((GraftSize(w, h), row[h], column[w]))
    if not read:
        return None
    margins = [float(lattice.worst_margin_mm[i, j]) for _, i, j in read]
    seals = [float(lattice.seal_probability[i, j]) for _, i, j in read]
    failing = [s.label for s, i, j in read if not lattice.qualifies[i, j]]
    low, weak = int(np.argmin(margins)), int(np.argmin(seals))
    return {"mm": trim_mm, "width_pct": dw, "height_pct": dh,
            "sizes": [s.label for s, _, _ in read],
            "worst_margin_mm": margins[low], "worst_margin_size": read[low][0].label,
            "seal_probability": seals[weak], "seal_size": read[weak][0].label,
            "failing": failing, "robust": not failing}


def trim_text(answer: SizingAnswer) -> str:
    """One sentence on the answer cut :data:`TRIM_MM` off its template ("" without)."""
    trim = answer.trim
    if not trim:
        return ""
    n, failing = len(trim["sizes"]), trim["failing"]
    head = (f"Cut {trim['mm']:g} mm off its template (±{trim['width_pct']:g} % width, "
            f"±{trim['height_pct']:g} % height): ")
    least = (f"least margin {margin_text(trim['worst_margin_mm'], signed=True)} mm "
             f"({trim['worst_margin_size']}), least sealing {trim['seal_probability']:.2f} "
             f"({trim['seal_size']})")
    if trim["robust"]:
        return f"{head}all {n} such sizes still qualify; {least}."
    shown = ", ".join(failing[:4]) + (", …" if len(failing) > 4 else "")
    return (f"{head}{len(failing)} of the {n} such sizes do not qualify ({shown}); {least}: "
            "not robust to the cut.")


def _range(fit: StudyFit) -> str:
    (w0, w1), (h0, h1) = fit.widths_pct, fit.heights_pct
    return f"W {w0:g}–{w1:g} %, H {h0:g}–{h1:g} %"


def _every(answer: SizingAnswer) -> str:
    n = len(answer.members)
    return f" in every one of its {n} members" if n > 1 else ""


def _in(member: str | None) -> str:
    return f" in `{member}`" if member else ""


def _resolution(answer: SizingAnswer) -> str:
    surface = answer.surface or {}
    cv = surface.get("cv_rmse_mm")
    fitted = (f" The surface is fitted to {surface.get('cases')} converged graft cases in "
              f"{surface.get('cells')} cells (inputs: {', '.join(surface.get('inputs', []))})"
              + (f"; its cross-validated error is {cv:.2f} mm ({surface.get('cv_folds')}-fold, "
                 "each cell's cases held out together)." if cv is not None else "."))
    return answer.resolution.text() + (fitted if answer.surface else "")


def _chosen_text(answer: SizingAnswer, fit: StudyFit) -> str:
    size, tol = answer.size, answer.tolerance_mm
    head = (f"Recommended graft: **{size.label}** (+{size.width_pct:g} % width, "
            f"+{size.height_pct:g} % height: free edge {answer.free_edge_mm:.1f} mm, height "
            f"{answer.height_mm:.1f} mm; flat area {size.area_ratio:.3f} × native), "
            + ("" if answer.smallest is None else
               f"solved in every member, its confirmation held, and within "
               f"{SAME_SIZE_PCT:g} points in width and height of {answer.smallest.label}, ")
            + f"the smallest size whose predicted worst case reaches the target minimum "
            f"coaptation height ({answer.target_source}){_every(answer)} within the resolution "
            f"of {margin_text(tol)} mm and that seals with a probability of at least "
            f"{answer.seal_threshold:g} ({answer.seal_probability:.2f} at {size.label}).")
    target = answer.targets_mm[answer.limiting_member]
    where = _in(answer.limiting_member)
    if answer.margin_mm >= 0:
        margin = (f"Predicted margin{where}: {margin_text(answer.margin_mm, signed=True)} ± "
                  f"{answer.margin_sd_mm:.2f} mm ({answer.predicted_height_mm:.2f} mm against "
                  f"{target:.2f} mm).")
    else:
        margin = (f"Its predicted worst case is {margin_text(-answer.margin_mm)} mm short of "
                  f"the target{where} ({answer.predicted_height_mm:.2f} mm against "
                  f"{target:.2f} mm, ± {answer.margin_sd_mm:.2f} mm), "
                  + (f"within the resolution of {margin_text(tol)} mm." if -answer.margin_mm <= tol
                     else f"beyond the resolution of {margin_text(tol)} mm on the surface; its "
                     "own solves, which the surface follows there, passed the confirmation's "
                     "test of the tolerance plus a solve's scatter."))
    if answer.smallest is not None:
        margin += (f" Sizes {SAME_SIZE_PCT:g} points apart are the same answer at the "
                   "millimetre a graft is trimmed to, so the solved size stays the answer.")
    band = answer.band
    also = (f"Sizes that also qualify: {band['sizes']} at {STEP_PCT:g} % steps, W "
            f"{band['width_pct'][0]:g}–{band['width_pct'][1]:g} %, H {band['height_pct'][0]:g}"
            f"–{band['height_pct'][1]:g} % (flat area {band['area_ratio'][0]:.3f}–"
            f"{band['area_ratio'][1]:.3f} ×); the highest predicted coaptation is at "
            f"{answer.highest.label} (margin {margin_text(answer.highest_margin_mm, signed=True)}"
            f" mm).")
    return " ".join((head, margin, also, trim_text(answer), _resolution(answer)))


def _short_text(answer: SizingAnswer, fit: StudyFit) -> str:
    tol, short, best = answer.tolerance_mm, answer.shortfall_mm, answer.highest
    free_edge, height = _dims(fit.leaflet, best)
    times = f"{short / tol:.1f} times" if tol > 0 else "beyond"
    return (f"No graft: no size in the studied range ({_range(fit)}) reaches the target "
            f"minimum coaptation height ({answer.target_source}){_every(answer)} within the "
            f"resolution while sealing with a probability of at least "
            f"{answer.seal_threshold:g}. The closest is **{best.label}** (free edge "
            f"{free_edge:.1f} mm, height {height:.1f} mm), {margin_text(short)} mm short"
            f"{_in(answer.limiting_member)}: {times} the resolution of {margin_text(tol)} mm. "
            + _resolution(answer))


def common_size(answers: Sequence[SizingAnswer]) -> GraftSize | None:
    """The smallest flat area that qualifies in every one of ``answers`` (comparison values
    read from one fit, on one lattice), ties going to the narrower, then the lower; None
    when no size qualifies in all of them or one of them has no lattice (no answer read).

    Raises
    ------
    ValueError
        For answers read on different lattices (not from one fit).
    """
    lattices = [a.lattice for a in answers]
    if not lattices or any(lattice is None for lattice in lattices):
        return None
    first = lattices[0]
    if any(not (np.array_equal(lat.widths_pct, first.widths_pct)
                and np.array_equal(lat.heights_pct, first.heights_pct)) for lat in lattices):
        raise ValueError("common_size: the answers were read on different lattices (give the "
                         "answers of one fit)")
    every = np.logical_and.reduce([lattice.qualifies for lattice in lattices])
    if not every.any():
        return None
    ww, hh = np.meshgrid(first.widths_pct, first.heights_pct)
    sizes = [GraftSize(float(w), float(h)) for w, h in zip(ww[every], hh[every], strict=True)]
    return min(sizes, key=lambda s: (s.area_ratio, *s))


def sizes_to_confirm(answer: SizingAnswer, tables: Sequence[MemberTable]
                     ) -> list[tuple[GraftSize, MemberTable]]:
    """The solves that confirm ``answer``: its size in every member (each uncertainty value
    along each path) where that size has not been solved yet; empty without a graft."""
    if answer.size is None:
        return []
    out = []
    for table in tables:
        solved = {(float(r["graft_width_pct"]), float(r["graft_height_pct"]))
                  for r in _graft_rows(table)}
        if tuple(answer.size) not in solved:
            out.append((answer.size, table))
    return out


def solved_worst_case(answer: SizingAnswer, tables: Sequence[MemberTable], size: GraftSize
                      ) -> tuple[float | None, str | None]:
    """The solved counterpart of ``answer``'s predicted worst case, at ``size``.

    The statistic the answer predicts: per uncertainty member (``answer.members``; its
    paths are replicates, as in the fit), the mean minimum coaptation height of the size's
    converged cases along its paths minus the member's target (``answer.targets_mm``); the
    least of these over the members.  Returns that margin (mm) and its member, or
    ``(None, None)`` when some member has no converged case of the size or no target.
    """
    heights: dict[str, list[float]] = {}
    for table in tables:
        for row in _graft_rows(table):
            value = _number(row, FIGURE)
            if ((float(row["graft_width_pct"]), float(row["graft_height_pct"])) == tuple(size)
                    and row.get("converged") and math.isfinite(value)):
                heights.setdefault(member_label(table.uncertain), []).append(value)
    margins = {}
    for member in answer.members:
        target = answer.targets_mm.get(member)
        if target is None or not heights.get(member):
            return None, None
        margins[member] = float(np.mean(heights[member])) - target
    limiting = min(margins, key=margins.get)
    return margins[limiting], limiting


def resample_paths(tables: Sequence[MemberTable], rng: np.random.Generator
                   ) -> list[MemberTable]:
    """A bootstrap resample of the replicates: in every cell (a graft at one value of each
    axis), each path's case is replaced by a case drawn with replacement from the cell's
    paths.  The normal valves stay as they are."""
    groups: dict[tuple, list[MemberTable]] = {}
    for table in tables:
        groups.setdefault(table.values, []).append(table)
    drawn: dict[str, list[Mapping]] = {}
    for group in groups.values():
        cells: dict[tuple, list[Mapping]] = {}
        for table in group:
            for row in _graft_rows(table):
                cells.setdefault((row["graft_width_pct"], row["graft_height_pct"]), []).append(
                    row)
        for table in group:
            rows = [r for r in table.rows if r.get("graft_width_pct") is None]
            for row in _graft_rows(table):
                pool = cells[(row["graft_width_pct"], row["graft_height_pct"])]
                rows.append(pool[rng.integers(len(pool))])
            drawn[table.label] = rows
    return [MemberTable(t.label, drawn[t.label], t.comparison, t.uncertain, t.path)
            for t in tables]


def bootstrap_stability(tables: Sequence[MemberTable], answer: SizingAnswer,
                        resamples: int = 20, *, points: float = SAME_SIZE_PCT, seed: int = 0,
                        target_mm: float | None = None) -> tuple[float, list[GraftSize | None]]:
    """The share of path resamples (:func:`resample_paths`) whose answer stays within
    ``points`` per cent of ``answer`` in both W and H (a "no graft" matches only "no graft"),
    and each resample's answer.  ``tables`` are one comparison value's; each refit skips the
    cross-validation and reads the same tolerance rule."""
    rng = np.random.default_rng(seed)
    sizes = []
    for _ in range(resamples):
        drawn = resample_paths(tables, rng)
        refit = read_answer(fit_study(drawn, ladder=None, cv_folds=0), drawn, target_mm,
                            comparison=answer.comparison, seal_threshold=answer.seal_threshold)
        sizes.append(refit.size)

    def close(size: GraftSize | None) -> bool:
        if size is None or answer.size is None:
            return size is answer.size
        return all(abs(a - b) <= points for a, b in zip(size, answer.size, strict=True))

    return sum(close(s) for s in sizes) / resamples, sizes
