"""Regurgitant orifice area: the leak of the closed valve seen along its axis (SPEC §6).

The cross-section ``z = const`` inside the orifice disk is rasterised with
square pixels of edge ``pixel_mm``.  The disk's radius is the smallest
distance of a loaded attachment node from the valve axis (z), less
:data:`DISK_MARGIN_PIXELS` pixels, so that the faceting of the attachment
line cannot show up as a leak along the wall.

1. **Footprints.**  Each leaflet's triangles are projected along z and every
   pixel centre inside a projected triangle is covered by that leaflet
   (vectorised point-in-triangle; the projection may fold over itself, so no
   2-D triangulation is assumed).  At each covered pixel the leaflet's
   P1-interpolated distance to each *other* leaflet is recorded; where the
   leaflet covers the pixel several times (a fold) the smallest value is
   kept: one layer touching the neighbour closes that column.
2. **Open pixels.**  A pixel that no leaflet footprint, dilated by
   ``threshold/2``, covers.  Gaps narrower than the coaptation threshold
   therefore count as sealed -- the same tolerance as the coaptation region.
3. **Leak channels.**  A pixel covered by two leaflets ``A`` and ``B`` whose
   sheets are farther apart than the threshold: ``A``'s sheet there is more
   than ``threshold`` from ``B``'s surface *and* ``B``'s sheet there is more
   than ``threshold`` from ``A``'s surface.  They overlap in projection without
   touching, which leaves a flow path between them -- unless a third leaflet
   covering the pixel touches both (three sheets stacked at the triple point).
4. **Dead ends.**  When steps 2 and 3 find pixels, the 3-D connectivity check
   of :mod:`valve_dolfinx.analysis.sealing` asks whether any free path joins
   the aorta to the ventricle.  If none does, those pixels are pockets closed
   further along (a free-edge tip standing just over the threshold above a
   sealed coaptation zone, say): they are reported as ``dead_end`` and not
   counted.
5. ``area = (open + channel pixels) × pixel²``; competent iff the area is 0.

Why steps 3 and 4 and their limitations are discussed in ``docs/coaptation.md``.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from scipy.ndimage import distance_transform_edt

from valve_dolfinx.analysis.sealing import DEFAULT_VOXEL_MM, through_flow
from valve_dolfinx.exceptions import MeshError, ParameterError
from valve_dolfinx.geometry.valve import ValveMesh

__all__ = ["DISK_MARGIN_PIXELS", "MAX_RASTER_PIXELS", "orifice_leak_map", "rasterise_footprint"]

log = logging.getLogger(__name__)

#: The orifice disk is the attachment circle shrunk by this many pixels.
DISK_MARGIN_PIXELS = 2
#: Largest raster accepted (pixels); finer rasters are almost surely a typo.
MAX_RASTER_PIXELS = 25_000_000
#: (triangle, pixel) candidates tested at once.
_CANDIDATE_CHUNK = 2_000_000


def _pixel_range(lo: np.ndarray, hi: np.ndarray, origin: float, pixel: float,
                 n: int) -> tuple[np.ndarray, np.ndarray]:
    """First and last pixel indices whose centres ``origin + (i + 1/2)·pixel`` lie in [lo, hi]."""
    i0 = np.ceil((lo - origin) / pixel - 0.5).astype(np.int64)
    i1 = np.floor((hi - origin) / pixel - 0.5).astype(np.int64)
    return np.clip(i0, 0, n), np.clip(i1, -1, n - 1)


def rasterise_footprint(xy: np.ndarray, triangles: np.ndarray, origin: float, pixel: float,
                        n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels covered by the projected triangles on an ``n × n`` raster.

    Pixel ``(iy, ix)`` has its centre at ``origin + (i + 1/2)·pixel`` in each
    direction and flat index ``iy·n + ix``.  Returns, for every (triangle,
    covered pixel) pair, the flat pixel index, the triangle index and the
    barycentric coordinates ``(k, 3)`` of the pixel centre.  Triangles seen
    edge-on (zero projected area) cover nothing.
    """
    p = xy[triangles]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    scale = np.maximum(np.abs(e1).max(axis=1), np.abs(e2).max(axis=1))
    seen = np.abs(det) > 1e-12 * scale**2
    ix0, ix1 = _pixel_range(p[:, :, 0].min(axis=1), p[:, :, 0].max(axis=1), origin, pixel, n)
    iy0, iy1 = _pixel_range(p[:, :, 1].min(axis=1), p[:, :, 1].max(axis=1), origin, pixel, n)
    nx, ny = np.maximum(ix1 - ix0 + 1, 0), np.maximum(iy1 - iy0 + 1, 0)
    count = np.where(seen, nx * ny, 0)
    if count.sum() == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64), np.empty((0, 3))
    pix, tri, bary = [], [], []
    bounds = np.searchsorted(np.cumsum(count), np.arange(0, count.sum(), _CANDIDATE_CHUNK),
                             side="right")
    for t0, t1 in zip(bounds, np.append(bounds[1:], len(count)), strict=True):
        ts = np.arange(t0, t1)
        c = count[ts]
        t = np.repeat(ts, c)
        local = np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c)
        ix = ix0[t] + local % nx[t]
        iy = iy0[t] + local // nx[t]
        qx = origin + (ix + 0.5) * pixel - p[t, 0, 0]
        qy = origin + (iy + 0.5) * pixel - p[t, 0, 1]
        l1 = (qx * e2[t, 1] - qy * e2[t, 0]) / det[t]
        l2 = (e1[t, 0] * qy - e1[t, 1] * qx) / det[t]
        lam = np.stack([1.0 - l1 - l2, l1, l2], axis=1)
        inside = np.all(lam >= -1e-12, axis=1)
        pix.append((iy * n + ix)[inside])
        tri.append(t[inside])
        bary.append(lam[inside])
    return np.concatenate(pix), np.concatenate(tri), np.concatenate(bary)


def _orifice_raster(positions: np.ndarray, valve: ValveMesh, pixel: float
                    ) -> tuple[float, float, int]:
    """Radius of the orifice disk, raster origin and size."""
    att = np.unique(np.concatenate([p.nodes[p.attachment] for p in valve.leaflets]))
    r_att = float(np.min(np.hypot(positions[att, 0], positions[att, 1])))
    radius = r_att - DISK_MARGIN_PIXELS * pixel
    if radius < 10 * pixel:
        raise MeshError(f"the loaded attachment nodes come within {r_att:.3g} mm of the valve "
                        "axis (the z axis through the origin): no orifice to rasterise at "
                        f"pixel_mm = {pixel:g}; is the valve centred on the z axis?")
    n = int(math.ceil(2 * radius / pixel))
    if n * n > MAX_RASTER_PIXELS:
        raise ParameterError(f"pixel_mm = {pixel:g} gives a {n}×{n} raster over a "
                             f"{2 * radius:.1f} mm orifice; use a coarser pixel (0.05 mm)")
    return radius, -0.5 * n * pixel, n


def orifice_leak_map(positions: np.ndarray, valve: ValveMesh,
                     pair_gaps: dict[tuple[int, int], np.ndarray], threshold: float,
                     pixel: float, voxel: float = DEFAULT_VOXEL_MM) -> tuple[float, dict]:
    """Regurgitant orifice area (mm²) and the raster it was counted on.

    ``pair_gaps[i, j]`` holds, per local node of leaflet ``i``, its loaded
    distance to leaflet ``j``'s surface (see
    :func:`valve_dolfinx.analysis.coaptation.leaflet_pair_gaps`).  The inputs
    are assumed checked; ``voxel`` is the edge of the 3-D check's voxels.  The
    diagnostics dict holds the masks (``in_disk``, ``open``, ``channel``,
    ``dead_end``, ``cover`` per leaflet, all ``n × n``, row = y),
    ``origin_mm``, ``pixel_mm``, ``radius_mm``, ``through_flow`` (the 3-D
    check's answer, ``None`` when no pixel needed it) and the open, channel and
    dead-end areas.
    """
    radius, origin, n = _orifice_raster(positions, valve, pixel)
    centres = origin + (np.arange(n) + 0.5) * pixel
    in_disk = (centres[None, :] ** 2 + centres[:, None] ** 2) <= radius**2
    nl = len(valve.leaflets)
    cover, near = _leaflet_cover(positions, valve, pair_gaps, origin, pixel, n)
    covered = cover.any(axis=0).reshape(n, n)
    if covered.any():
        clearance = distance_transform_edt(~covered) * pixel  # to the nearest covered centre
        open_ = in_disk & (clearance > 0.5 * threshold * (1 + 1e-9))
    else:
        open_ = in_disk.copy()
    channel = _overlap_channels(cover, near, threshold).reshape(n, n) & in_disk
    flows = None
    dead_end = np.zeros((n, n), dtype=bool)
    if open_.any() or channel.any():
        flows = through_flow(positions, valve, threshold, radius, voxel)
        if not flows:
            dead_end = open_ | channel
            open_, channel = np.zeros_like(open_), np.zeros_like(channel)
            log.info("%.4f mm² of projected gap are dead ends: no path through the valve "
                     "wider than the %.3g mm threshold (3-D check), not counted",
                     dead_end.sum() * pixel * pixel, threshold)
    pixel_area = pixel * pixel
    open_area = float(open_.sum() * pixel_area)
    channel_area = float(channel.sum() * pixel_area)
    area = open_area + channel_area
    dead_end_area = float(dead_end.sum() * pixel_area)
    log.debug("orifice raster %d×%d (pixel %.3g mm, radius %.3f mm): open %.4f mm², "
              "overlap channels %.4f mm², dead ends %.4f mm²", n, n, pixel, radius, open_area,
              channel_area, dead_end_area)
    diagnostics = {
        "radius_mm": radius,
        "origin_mm": origin,
        "pixel_mm": pixel,
        "in_disk": in_disk,
        "open": open_,
        "channel": channel,
        "dead_end": dead_end,
        "through_flow": flows,
        "cover": cover.reshape(nl, n, n),
        "leaflet_names": [p.name for p in valve.leaflets],
        "open_area_mm2": open_area,
        "channel_area_mm2": channel_area,
        "dead_end_area_mm2": dead_end_area,
    }
    return area, diagnostics


def _leaflet_cover(positions: np.ndarray, valve: ValveMesh,
                   pair_gaps: dict[tuple[int, int], np.ndarray], origin: float, pixel: float,
                   n: int) -> tuple[np.ndarray, dict[tuple[int, int], np.ndarray]]:
    """Which pixels each leaflet's projection covers (``(leaflets, n·n)``), and per pair
    ``(a, b)`` the smallest gap from leaflet ``a`` to ``b`` over each pixel (inf where
    ``a`` does not cover it)."""
    cover = np.zeros((len(valve.leaflets), n * n), dtype=bool)
    near = {key: np.full(n * n, np.inf) for key in pair_gaps}
    for i, patch in enumerate(valve.leaflets):
        xy = positions[patch.nodes, :2]
        pix, tri, bary = rasterise_footprint(xy, patch.triangles, origin, pixel, n)
        cover[i, pix] = True
        for (a, b), gap in pair_gaps.items():
            if a == i:
                sheet_gap = np.einsum("kj,kj->k", bary, gap[patch.triangles[tri]])
                np.minimum.at(near[a, b], pix, sheet_gap)
    return cover, near


def _overlap_channels(cover: np.ndarray, near: dict[tuple[int, int], np.ndarray],
                      threshold: float) -> np.ndarray:
    """Pixels (``n·n``) where two leaflets overlap without touching (a gap wider than
    ``threshold`` between them) and no third leaflet touching both fills the gap."""
    nl = len(cover)

    def touching(a: int, b: int) -> np.ndarray:
        return (near[a, b] <= threshold) | (near[b, a] <= threshold)

    channel = np.zeros(cover.shape[1], dtype=bool)
    for a in range(nl):
        for b in range(a + 1, nl):
            gap = cover[a] & cover[b] & ~touching(a, b)
            for c in set(range(nl)) - {a, b}:
                # a third leaflet in the column that touches both fills the gap between them
                gap &= ~(cover[c] & touching(a, c) & touching(b, c))
            channel |= gap
    return channel
