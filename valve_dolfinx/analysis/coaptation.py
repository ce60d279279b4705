"""Coaptation of the loaded valve: region, height, area and competence (SPEC §6).

Definitions (the reasoning is in ``docs/coaptation.md``):

* **Gap** of a node of leaflet ``L``: the exact Euclidean distance, in the
  loaded configuration, from the node to the nearest triangle of any *other*
  leaflet.  Inside a triangle the gap is the linear (P1) interpolant of its
  nodal values.
* **Coaptation region** of ``L``: ``{gap <= threshold}`` (threshold 0.5 mm,
  about the leaflet thickness).  Nodes shared at a commissure have gap 0 and
  belong to the region: the leaflets meet there.
* **Coaptation height profile** ``h(x)``: on the *flat reference* leaflet, the
  length of the part of the line perpendicular to the free edge (the vertical
  line at abscissa ``x``) that lies in the region.  Computed exactly for the
  P1 gap by clipping the line against every triangle.  ``h`` is piecewise
  linear in ``x``, with breaks only at the abscissae of mesh vertices and of
  the points where the level line ``gap = threshold`` crosses a mesh edge; the
  profile is evaluated at all of them, so its minima are exact, not sampled.
* **Minimum coaptation height**, each side of the midline ``x = m`` on its
  own: ``min_height_left = min h`` over ``x <= m - l/2`` and
  ``min_height_right = min h`` over ``x >= m + l/2``; ``min_height`` is the
  smaller of the two.  ``l`` (``nodulus_length_mm``, default 1 mm: one leaflet
  thickness either side of the triple point) is the length along the free edge
  of the nodulus of Arantius, the thickened tip of a real cusp at the triple
  point, which a membrane model does not have; with ``l = 0`` nothing is left
  out.  ``min_height_raw = min h`` over the whole
  free edge, tip included, is reported beside it.  No fit, no extrapolation.
* **Central coaptation height**: ``h(m)``; with a nodulus length ``l > 0``,
  the smaller of ``h(m - l/2)`` and ``h(m + l/2)`` (the edge of the tip, on
  the lower side).  ``h(m)`` itself is always reported as ``midline_height``.
* **Coaptation area**: the region's area on the loaded triangles (and, for
  reference, on the flat triangles), exact for the P1 level set.
* **Regurgitant orifice area**: see :mod:`valve_dolfinx.analysis.orifice`.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field

import numpy as np

from valve_dolfinx.analysis.distance import distance_to_surface
from valve_dolfinx.analysis.orifice import orifice_leak_map
from valve_dolfinx.config import NODULUS_LENGTH_MM
from valve_dolfinx.exceptions import MeshError, ParameterError, check_range
from valve_dolfinx.geometry.valve import LeafletPatch, ValveMesh

__all__ = [
    "DEFAULT_THRESHOLD_MM",
    "DEFAULT_PIXEL_MM",
    "PROFILE_SAMPLES",
    "LeafletCoaptation",
    "CoaptationResult",
    "analyse_coaptation",
    "regurgitant_orifice_area",
    "distance_to_surface",
    "leaflet_pair_gaps",
    "fraction_below",
    "region_area",
    "coaptation_height_profile",
    "profile_break_points",
]

log = logging.getLogger(__name__)

#: Coaptation threshold (mm): about the leaflet thickness (SPEC §6).
DEFAULT_THRESHOLD_MM = 0.5
#: Pixel edge of the cross-section raster for the regurgitant orifice (mm).
DEFAULT_PIXEL_MM = 0.05
#: Evenly spaced abscissae of the height profile along the flat free edge (for the map);
#: the profile's break points are added to them, so the minima do not depend on this.
PROFILE_SAMPLES = 201
#: Round-off allowance (mm) when a sample is tested against the edge of the nodulus.
_ON_POINT_MM = 1e-9


# --- results -------------------------------------------------------------------------------
@dataclass
class LeafletCoaptation:
    """Coaptation of one leaflet (lengths in mm, areas in mm²).

    ``x_mm``/``height_mm`` are the height profile ``h(x)`` on the flat leaflet
    (sorted abscissae, the profile's break points included); ``node_gap_mm``
    holds, per local node, the loaded distance to the nearest other leaflet's
    surface.  ``min_height_left_mm``/``min_height_right_mm`` are the minima of
    ``h`` on either side of the midline outside the nodulus (``nodulus_length_mm``
    centred on the midline), ``min_height_mm`` the smaller of the two, and
    ``min_height_raw_mm`` the minimum over the whole free edge.
    """

    name: str
    is_graft: bool
    min_height_mm: float
    central_height_mm: float
    area_mm2: float
    reference_area_mm2: float
    x_mm: np.ndarray = field(repr=False)
    height_mm: np.ndarray = field(repr=False)
    node_gap_mm: np.ndarray = field(repr=False)
    min_height_left_mm: float = math.nan
    min_height_right_mm: float = math.nan
    min_height_raw_mm: float = math.nan
    midline_height_mm: float = math.nan
    nodulus_length_mm: float = 0.0

    @property
    def midline_mm(self) -> float:
        """Flat abscissa of the midline (the middle of the free edge)."""
        return 0.5 * float(self.x_mm[0] + self.x_mm[-1])

    def side_mask(self, side: str) -> np.ndarray:
        """Samples of one side (``"left"``/``"right"``) of the midline, outside the nodulus."""
        return _side_mask(self.x_mm, self.midline_mm, self.nodulus_length_mm, side)

    def min_height_x(self, side: str) -> float:
        """Flat abscissa of the minimum of ``h`` on one side of the midline."""
        inside = self.side_mask(side)
        return float(self.x_mm[inside][int(np.argmin(self.height_mm[inside]))])

    @property
    def min_height_x_mm(self) -> float:
        """Flat abscissa of ``min_height_mm`` (the lower side's minimum)."""
        side = "left" if self.min_height_left_mm <= self.min_height_right_mm else "right"
        return self.min_height_x(side)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "is_graft": bool(self.is_graft),
            "min_height_mm": _json_float(self.min_height_mm),
            "min_height_x_mm": _json_float(self.min_height_x_mm),
            "min_height_left_mm": _json_float(self.min_height_left_mm),
            "min_height_left_x_mm": _json_float(self.min_height_x("left")),
            "min_height_right_mm": _json_float(self.min_height_right_mm),
            "min_height_right_x_mm": _json_float(self.min_height_x("right")),
            "min_height_raw_mm": _json_float(self.min_height_raw_mm),
            "central_height_mm": _json_float(self.central_height_mm),
            "midline_height_mm": _json_float(self.midline_height_mm),
            "nodulus_length_mm": _json_float(self.nodulus_length_mm),
            "area_mm2": _json_float(self.area_mm2),
            "reference_area_mm2": _json_float(self.reference_area_mm2),
        }


@dataclass
class CoaptationResult:
    """Coaptation of the whole valve (SPEC §6).

    ``min_native_height_mm`` -- the minimum over native (non-graft) leaflets of
    their minimum coaptation height -- is the study's figure of merit;
    ``min_native_height_raw_mm`` is the same with the nodulus tip included
    (equal to it when ``nodulus_length_mm`` is 0).
    """

    leaflets: dict[str, LeafletCoaptation]
    threshold_mm: float
    regurgitant_orifice_area_mm2: float
    #: the orifice area is exactly 0 (a case's competence also asks for convergence and
    #: no crossing leaflets: :func:`valve_dolfinx.result.competence`)
    sealed: bool
    min_native_height_mm: float
    central_native_height_mm: float
    coaptation_area_mm2: float
    min_native_height_raw_mm: float = math.nan
    nodulus_length_mm: float = 0.0
    #: the raster the orifice area was counted on (see
    #: :func:`~valve_dolfinx.analysis.orifice.orifice_leak_map`), for drawing it
    orifice: dict | None = field(default=None, repr=False, compare=False)

    def to_dict(self) -> dict:
        """JSON-ready scalars (no arrays); NaN becomes ``None``."""
        return {
            "threshold_mm": _json_float(self.threshold_mm),
            "regurgitant_orifice_area_mm2": _json_float(self.regurgitant_orifice_area_mm2),
            "sealed": bool(self.sealed),
            "min_native_height_mm": _json_float(self.min_native_height_mm),
            "min_native_height_raw_mm": _json_float(self.min_native_height_raw_mm),
            "nodulus_length_mm": _json_float(self.nodulus_length_mm),
            "central_native_height_mm": _json_float(self.central_native_height_mm),
            "coaptation_area_mm2": _json_float(self.coaptation_area_mm2),
            "leaflets": {name: lc.to_dict() for name, lc in self.leaflets.items()},
        }

    def result_fields(self) -> dict:
        """The coaptation fields of a case result under their SPEC §7 names."""
        d = self.to_dict()
        return {"min_coaptation_height_mm": d["min_native_height_mm"],
                "min_coaptation_height_raw_mm": d["min_native_height_raw_mm"],
                "central_coaptation_height_mm": d["central_native_height_mm"],
                **{k: d[k] for k in ("coaptation_area_mm2", "regurgitant_orifice_area_mm2")}}


def _side_mask(x: np.ndarray, midline: float, nodulus: float, side: str) -> np.ndarray:
    offset = x - midline
    if side == "left":
        return offset <= -0.5 * nodulus + _ON_POINT_MM
    if side == "right":
        return offset >= 0.5 * nodulus - _ON_POINT_MM
    raise ParameterError(f"side = {side!r}; use 'left' or 'right'")


def _json_float(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


# --- input checks ----------------------------------------------------------------------------
def _check_inputs(positions: np.ndarray, valve: ValveMesh, threshold_mm: float,
                  pixel_mm: float) -> np.ndarray:
    """Validated ``(N, 3)`` float copy of ``positions``; raises naming the bad argument."""
    check_range("threshold_mm", threshold_mm, 0.0, None, low_open=True, unit="mm",
                hint="the coaptation threshold is about the leaflet thickness, 0.5 mm")
    check_range("pixel_mm", pixel_mm, 0.0, 0.5 * threshold_mm, low_open=True, unit="mm",
                hint="the raster must resolve gaps of half the coaptation threshold; "
                "0.05 mm is the default")
    try:
        x = np.asarray(positions, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError("positions must be an (N, 3) array of loaded node positions "
                             "(mm)") from None
    n = len(valve.points)
    if x.shape != (n, 3):
        raise ParameterError(f"positions has shape {x.shape}; expected ({n}, 3), one row per "
                             "valve node in the order of ValveMesh.points")
    bad = ~np.isfinite(x)
    if bad.any():
        raise ParameterError(f"positions contain {int(bad.any(axis=1).sum())} nodes with NaN "
                             "or infinite coordinates; pass the converged loaded positions")
    if len(valve.leaflets) < 2:
        raise MeshError(f"valve has {len(valve.leaflets)} leaflet(s); coaptation needs at least "
                        "two (mirror a single leaflet across its symmetry planes first)")
    for patch in valve.leaflets:
        ok = (patch.nodes.min() >= 0 and patch.nodes.max() < n
              and patch.triangles.min() >= 0 and patch.triangles.max() < len(patch.nodes)
              and patch.flat.shape == (len(patch.nodes), 2) and len(patch.free_edge) >= 2)
        if not ok:
            raise MeshError(f"valve leaflet {patch.name!r} is inconsistent: its nodes, "
                            "triangles, flat coordinates or free edge do not match the valve")
    return x


# --- distances -------------------------------------------------------------------------------
def leaflet_pair_gaps(positions: np.ndarray, valve: ValveMesh
                      ) -> dict[tuple[int, int], np.ndarray]:
    """Nodal distances between leaflets in the loaded configuration.

    Returns ``{(i, j): d}`` for every ordered pair of distinct leaflets, ``d``
    holding for each local node of leaflet ``i`` its distance to the surface of
    leaflet ``j``.
    """
    x = np.asarray(positions, float)
    gaps = {}
    for i, pa in enumerate(valve.leaflets):
        for j, pb in enumerate(valve.leaflets):
            if i != j:
                gaps[i, j] = distance_to_surface(x[pa.nodes], x[pb.nodes], pb.triangles)
    return gaps


# --- region, area, height ----------------------------------------------------------------------
def fraction_below(values: np.ndarray, threshold: float) -> np.ndarray:
    """Fraction of each triangle's area where the P1 field is ``<= threshold``.

    ``values`` are the ``(m, 3)`` nodal values.  The sub-level set of a linear
    function on a triangle is a triangle (one vertex below) or the complement
    of one (two below), cut at the edge points where the field crosses the
    threshold.  The fraction is affine-invariant, so it serves the loaded and
    the flat triangle alike.
    """
    f = np.sort(np.asarray(values, float) - threshold, axis=1)
    a, b, c = f[:, 0], f[:, 1], f[:, 2]
    frac = np.where(c <= 0.0, 1.0, 0.0)
    one = (a <= 0.0) & (b > 0.0)
    frac[one] = a[one] ** 2 / ((b[one] - a[one]) * (c[one] - a[one]))
    two = (b <= 0.0) & (c > 0.0)
    frac[two] = 1.0 - c[two] ** 2 / ((c[two] - a[two]) * (c[two] - b[two]))
    return frac


def _triangle_areas(p: np.ndarray) -> np.ndarray:
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    if p.shape[-1] == 2:
        return 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)


def region_area(vertices: np.ndarray, triangles: np.ndarray, gap: np.ndarray,
                threshold: float) -> float:
    """Area of ``{gap <= threshold}`` on the triangulation (2-D or 3-D vertices), exact for P1."""
    frac = fraction_below(gap[triangles], threshold)
    return float(np.sum(_triangle_areas(vertices[triangles]) * frac))


def _columns_of_triangles(xs: np.ndarray, tx: np.ndarray, x_right: float
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (sample, triangle) with ``xmin <= x < xmax`` (``<=`` on the rightmost boundary).

    The half-open rule counts a line that runs along a vertical mesh edge once,
    not once per neighbouring triangle.
    """
    lo, hi = tx.min(axis=1), tx.max(axis=1)
    i0 = np.searchsorted(xs, lo, side="left")
    i1 = np.where(hi >= x_right, np.searchsorted(xs, hi, side="right"),
                  np.searchsorted(xs, hi, side="left"))
    count = np.maximum(i1 - i0, 0)
    tri = np.repeat(np.arange(len(tx)), count)
    start = np.repeat(np.cumsum(count) - count, count)
    sample = np.repeat(i0, count) + np.arange(count.sum()) - start
    return sample, tri


def coaptation_height_profile(flat: np.ndarray, triangles: np.ndarray, gap: np.ndarray,
                              threshold: float, x: np.ndarray) -> np.ndarray:
    """Length of ``{gap <= threshold}`` on the vertical line at each flat abscissa ``x``.

    Exact for the P1 gap on the flat triangulation: a vertical line cuts a
    triangle in a segment whose end points lie on two edges; the gap is linear
    along the segment, so the part below the threshold is a sub-segment whose
    length follows from the two end values.  Summed over triangles.
    """
    xs = np.asarray(x, float)
    order = np.argsort(xs)
    xs_sorted = xs[order]
    txy = flat[triangles]  # (m, 3, 2)
    tg = gap[triangles]
    sample, tri = _columns_of_triangles(xs_sorted, txy[:, :, 0], float(flat[:, 0].max()))
    xq = xs_sorted[sample]
    ys = np.full((len(sample), 3), np.nan)
    gs = np.full((len(sample), 3), np.nan)
    for e in range(3):  # the three edges
        pa, pb = txy[tri, e], txy[tri, (e + 1) % 3]
        ga, gb = tg[tri, e], tg[tri, (e + 1) % 3]
        dx = pb[:, 0] - pa[:, 0]
        crosses = (dx != 0.0) & (xq >= np.minimum(pa[:, 0], pb[:, 0])) & (
            xq <= np.maximum(pa[:, 0], pb[:, 0]))
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.clip((xq - pa[:, 0]) / dx, 0.0, 1.0)
        ys[crosses, e] = (pa[:, 1] + t * (pb[:, 1] - pa[:, 1]))[crosses]
        gs[crosses, e] = (ga + t * (gb - ga))[crosses]
    has = np.isfinite(ys).sum(axis=1) >= 2
    ys, gs, sample = ys[has], gs[has], sample[has]
    rows = np.arange(len(ys))
    e_lo = np.argmin(np.where(np.isnan(ys), np.inf, ys), axis=1)
    e_hi = np.argmax(np.where(np.isnan(ys), -np.inf, ys), axis=1)
    length = ys[rows, e_hi] - ys[rows, e_lo]
    g_min = np.minimum(gs[rows, e_lo], gs[rows, e_hi])
    g_max = np.maximum(gs[rows, e_lo], gs[rows, e_hi])
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(g_max > g_min, np.clip((threshold - g_min) / (g_max - g_min), 0, 1),
                        (g_min <= threshold).astype(float))
    h_sorted = np.bincount(sample, weights=length * frac, minlength=len(xs))
    h = np.empty_like(h_sorted)
    h[order] = h_sorted
    return h


def profile_break_points(flat: np.ndarray, triangles: np.ndarray, gap: np.ndarray,
                         threshold: float) -> np.ndarray:
    """Abscissae where the height profile ``h(x)`` can change slope (sorted, unique).

    Between two consecutive mesh-vertex abscissae each vertical line cuts the
    same triangles through the same edges, so the cut segments' end points
    move linearly in ``x``; inside a triangle the region's boundary is a
    straight piece of the level line ``gap = threshold``.  ``h`` is therefore
    piecewise linear, with breaks at the vertex abscissae and where the level
    line crosses an edge, and its minimum over an interval is attained at one
    of these points or at the interval's ends.
    """
    edges = np.unique(np.sort(np.concatenate(
        [triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1), axis=0)
    fa, fb = gap[edges[:, 0]] - threshold, gap[edges[:, 1]] - threshold
    cross = fa * fb < 0.0
    t = fa[cross] / (fa[cross] - fb[cross])
    xa, xb = flat[edges[cross, 0], 0], flat[edges[cross, 1], 0]
    return np.unique(np.concatenate([flat[:, 0], xa + t * (xb - xa)]))


def _leaflet_coaptation(patch: LeafletPatch, loaded: np.ndarray, gap: np.ndarray,
                        threshold: float, samples: int, nodulus: float) -> LeafletCoaptation:
    fx = patch.flat[patch.free_edge, 0]
    x_left, x_right = float(fx.min()), float(fx.max())
    if x_right - x_left <= nodulus:
        raise ParameterError(
            f"nodulus_length_mm = {nodulus:g} mm is not shorter than the free edge of "
            f"{patch.name} ({x_right - x_left:.3g} mm, flat); use a smaller one "
            "(0 treats no tip)")
    midline = 0.5 * (x_left + x_right)  # x = 0 for the symmetric leaflet outlines
    tip = [midline - 0.5 * nodulus, midline, midline + 0.5 * nodulus]
    breaks = profile_break_points(patch.flat, patch.triangles, gap, threshold)
    x = np.union1d(np.linspace(x_left, x_right, samples), np.concatenate([breaks, tip]))
    x = x[(x >= x_left) & (x <= x_right)]
    h = coaptation_height_profile(patch.flat, patch.triangles, gap, threshold, x)
    left, right = (float(h[_side_mask(x, midline, nodulus, side)].min())
                   for side in ("left", "right"))
    h_at = [float(h[int(np.argmin(np.abs(x - xt)))]) for xt in tip]
    return LeafletCoaptation(
        name=patch.name,
        is_graft=bool(patch.is_graft),
        min_height_mm=min(left, right),
        central_height_mm=min(h_at[0], h_at[2]),  # the edge of the tip, on the lower side
        area_mm2=region_area(loaded, patch.triangles, gap, threshold),
        reference_area_mm2=region_area(patch.flat, patch.triangles, gap, threshold),
        x_mm=x,
        height_mm=h,
        node_gap_mm=gap,
        min_height_left_mm=left,
        min_height_right_mm=right,
        min_height_raw_mm=float(h.min()),
        midline_height_mm=h_at[1],
        nodulus_length_mm=nodulus,
    )


# --- public entry points -----------------------------------------------------------------------
def regurgitant_orifice_area(positions: np.ndarray, valve: ValveMesh,
                             threshold_mm: float = DEFAULT_THRESHOLD_MM,
                             pixel_mm: float = DEFAULT_PIXEL_MM, *,
                             pair_gaps: dict[tuple[int, int], np.ndarray] | None = None
                             ) -> tuple[float, dict]:
    """Regurgitant orifice area (mm²) of the loaded valve and its raster diagnostics.

    See :func:`valve_dolfinx.analysis.orifice.orifice_leak_map` for the
    definition.  ``pair_gaps`` (from :func:`leaflet_pair_gaps`) may be passed
    to avoid recomputing the leaflet–leaflet distances.
    """
    x = _check_inputs(positions, valve, threshold_mm, pixel_mm)
    if pair_gaps is None:
        pair_gaps = leaflet_pair_gaps(x, valve)
    return orifice_leak_map(x, valve, pair_gaps, float(threshold_mm), float(pixel_mm))


def analyse_coaptation(positions: np.ndarray, valve: ValveMesh,
                       threshold_mm: float = DEFAULT_THRESHOLD_MM,
                       pixel_mm: float = DEFAULT_PIXEL_MM, *,
                       profile_samples: int = PROFILE_SAMPLES,
                       orifice: bool = True,
                       nodulus_length_mm: float = NODULUS_LENGTH_MM
                       ) -> CoaptationResult:
    """Coaptation region, heights, area and competence of a loaded valve (SPEC §6).

    Parameters
    ----------
    positions
        ``(N, 3)`` loaded node positions (mm), indexed like ``valve.points``.
    valve
        The valve mesh (leaflet patches with flat reference coordinates).
    threshold_mm
        Distance below which a leaflet's surface counts as coapted with another
        leaflet (about the leaflet thickness).
    pixel_mm
        Pixel edge of the cross-section raster used for the regurgitant
        orifice area; at most ``threshold_mm / 2``.
    profile_samples
        Number of evenly spaced abscissae of the height profile along the flat
        free edge (for the map); the profile's break points are always added.
    orifice
        Compute the regurgitant orifice area (the default).  ``False`` skips it
        -- for constructed surfaces that have no orifice around the z axis --
        and reports it as NaN (``sealed`` is then ``False``).
    nodulus_length_mm
        Length ``l`` (flat mm along the free edge, centred on the midline) of
        the triple-point tip treated as the nodulus of Arantius: the side
        minima are taken over ``|x - m| >= l/2`` and the central height at
        ``x = m ± l/2`` (the lower of the two).  The default, 1 mm, is one leaflet
        thickness either side of the triple point; 0 leaves nothing out;
        ``min_native_height_raw_mm`` always includes the tip.

    Returns
    -------
    CoaptationResult
        Per-leaflet heights and areas; the figure of merit
        ``min_native_height_mm``; the regurgitant orifice area and competence,
        and the raster it was counted on (``orifice``).
    """
    x = _check_inputs(positions, valve, threshold_mm, pixel_mm)
    if int(profile_samples) < 3:
        raise ParameterError(f"profile_samples = {profile_samples!r}; use at least 3 "
                             "(201 by default)")
    threshold = float(threshold_mm)
    nodulus = check_range("nodulus_length_mm", nodulus_length_mm, 0.0, 5.0, unit="mm",
                          hint="the nodulus of Arantius is a small thickening at the middle "
                          "of the free edge; the default is 1 mm, 0 treats no tip")
    pair_gaps = leaflet_pair_gaps(x, valve)
    leaflets = {}
    for i, patch in enumerate(valve.leaflets):
        gap = np.min([g for (a, _), g in pair_gaps.items() if a == i], axis=0)
        leaflets[patch.name] = _leaflet_coaptation(patch, x[patch.nodes], gap, threshold,
                                                   int(profile_samples), nodulus)
    ro_area, ro_map = (orifice_leak_map(x, valve, pair_gaps, threshold, float(pixel_mm))
                       if orifice else (math.nan, None))
    native = [lc for lc in leaflets.values() if not lc.is_graft]
    if not native:
        log.warning("no native leaflet: the native coaptation heights are undefined (NaN)")
    result = CoaptationResult(
        leaflets=leaflets,
        threshold_mm=threshold,
        regurgitant_orifice_area_mm2=ro_area,
        sealed=ro_area == 0.0,
        min_native_height_mm=min((lc.min_height_mm for lc in native), default=math.nan),
        min_native_height_raw_mm=min((lc.min_height_raw_mm for lc in native),
                                     default=math.nan),
        nodulus_length_mm=nodulus,
        central_native_height_mm=min((lc.central_height_mm for lc in native),
                                     default=math.nan),
        coaptation_area_mm2=float(sum(lc.area_mm2 for lc in leaflets.values())),
        orifice=ro_map,
    )
    log.info("coaptation: min native height %.3f mm (raw %.3f mm), central %.3f mm, "
             "area %.2f mm², regurgitant orifice %.3f mm² (%s)", result.min_native_height_mm,
             result.min_native_height_raw_mm, result.central_native_height_mm,
             result.coaptation_area_mm2, ro_area,
             "sealed" if result.sealed else "leaks")
    return result
