"""Does the closed valve let blood from the aorta reach the ventricle?  (3-D check, SPEC §6)

The projected orifice (:mod:`valve_dolfinx.analysis.orifice`) looks along the
valve axis one pixel column at a time.  It cannot tell a channel that runs
through the valve from a *dead end*: a pocket between two leaflets that opens
to the aorta but is closed further down, for example a free-edge tip that
stands a little more than the threshold above its neighbour where the leaflets
below are sealed.  This module answers the connectivity question in 3-D.

The cylinder ``r < radius`` (the orifice disk) between a plane below and a
plane above every leaflet is cut into cubic voxels of edge ``voxel``.  A voxel
is *blocked* when its centre lies outside the cylinder or within
``threshold/2`` of a leaflet (the exact distance to its triangles): the same
rule as the projected measure, where a gap narrower than the threshold seals.
The free voxels are labelled with face connectivity; blood can pass when one
label reaches both planes.

Resolution: a gap ``g`` between two sheets leaves a free layer ``g − threshold``
thick; one at least ``√3·voxel`` thick always holds a face-connected chain of
voxel centres.  So gaps below the threshold always seal, gaps above
``threshold + √3·voxel`` (0.67 mm at the defaults) always pass, and gaps in
between may do either: a through-channel that narrow can be reported as a
dead end (it is still drawn on the orifice map, and logged).

Cost: exact distances are computed only where the Euclidean distance from the
voxels a sheet passes through cannot decide (its error is about one voxel); that
distance is needed only up to the largest one that matters, a few voxels, so it
is taken by stamping a ball of those voxel offsets around each crossed voxel
(the values of a Euclidean distance transform within the ball, none beyond),
over the box of the sheet widened by the ball.  The exact test of a voxel
centre looks only at the triangles whose boxes, padded by the distance, hold
it (the contact's broad phase).
"""

from __future__ import annotations

import logging
import math

import numba
import numpy as np
from scipy.ndimage import label

from valve_dolfinx.analysis.distance import within_distance
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.geometry.valve import ValveMesh

__all__ = ["DEFAULT_VOXEL_MM", "MAX_VOXELS", "crossed_distances", "through_flow"]

log = logging.getLogger(__name__)

#: Edge of the voxels of the 3-D connectivity check (mm).
DEFAULT_VOXEL_MM = 0.1
#: Largest voxel grid accepted; finer grids are almost surely a typo.
MAX_VOXELS = 60_000_000


def _sheet_samples(vertices: np.ndarray, triangles: np.ndarray, spacing: float) -> np.ndarray:
    """Points on the triangles, no two neighbours farther apart than ``spacing``."""
    p = vertices[triangles]
    longest = np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1)
    divisions = np.maximum(np.ceil(longest / spacing).astype(np.int64), 1)
    samples = []
    for k in np.unique(divisions):
        i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
        keep = i + j <= k
        lam = np.stack([k - i[keep] - j[keep], i[keep], j[keep]], axis=1) / k
        samples.append(np.einsum("sj,tjd->tsd", lam, p[divisions == k]).reshape(-1, 3))
    return np.concatenate(samples)


def ball_offsets(radius: float, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """The integer voxel offsets ``(K, 3)`` within ``radius`` (mm) and their lengths (mm),
    computed as :func:`scipy.ndimage.distance_transform_edt` computes a distance with
    ``sampling=voxel``: √((Δi·v)² + (Δj·v)² + (Δk·v)²)."""
    r = int(math.floor(radius / voxel)) + 1
    offsets = np.stack(np.meshgrid(*[np.arange(-r, r + 1)] * 3, indexing="ij"),
                       axis=-1).reshape(-1, 3)
    scaled = offsets.astype(np.float64) * voxel
    length = np.sqrt((scaled[:, 0] ** 2 + scaled[:, 1] ** 2) + scaled[:, 2] ** 2)
    keep = length <= radius
    return offsets[keep], length[keep]


def crossed_distances(crossed: np.ndarray, radius: float, voxel: float) -> np.ndarray:
    """Distance (mm) from each voxel of the grid ``crossed`` (bool, 3-D) to the centre of
    the nearest ``crossed`` voxel, where it is at most ``radius``, else ``inf``: the
    Euclidean distance transform of ``~crossed`` (``sampling=voxel``) up to ``radius``,
    stamped around each crossed voxel instead of transformed over the whole grid."""
    offsets, length = ball_offsets(radius, voxel)
    out = np.full(crossed.shape, np.inf)
    _stamp(np.argwhere(crossed), offsets, length, out)
    return out


@numba.njit(cache=True)
def _stamp(cells, offsets, length, out):  # pragma: no cover
    """``out[c + o] = min(out[c + o], length[o])`` over the cells and offsets inside."""
    n0, n1, n2 = out.shape
    for c in range(len(cells)):
        i, j, k = cells[c, 0], cells[c, 1], cells[c, 2]
        for o in range(len(offsets)):
            a, b, e = i + offsets[o, 0], j + offsets[o, 1], k + offsets[o, 2]
            if 0 <= a < n0 and 0 <= b < n1 and 0 <= e < n2 and length[o] < out[a, b, e]:
                out[a, b, e] = length[o]


def through_flow(positions: np.ndarray, valve: ValveMesh, threshold: float, radius: float,
                 voxel: float = DEFAULT_VOXEL_MM) -> bool:
    """Whether a free path joins the planes below and above the leaflets (see the module doc).

    ``positions`` are the loaded node positions; ``radius`` is the orifice
    disk's (the root wall, less a margin).
    """
    if not 0.0 < voxel <= threshold / 4:
        raise ParameterError(f"voxel_mm = {voxel:g} must lie in (0, threshold/4 = "
                             f"{threshold / 4:g}] mm, or gaps of the threshold cannot be "
                             "resolved; 0.1 mm is the default")
    reach = 0.5 * threshold
    nodes = np.unique(np.concatenate([p.nodes for p in valve.leaflets]))
    z = positions[nodes, 2]
    margin = threshold + 2 * voxel
    n = int(math.ceil(2 * radius / voxel)) + 2
    nz = int(math.ceil((float(z.max() - z.min()) + 2 * margin) / voxel))
    if n * n * nz > MAX_VOXELS:
        raise ParameterError(f"voxel_mm = {voxel:g} gives a {n}×{n}×{nz} grid; use a coarser "
                             f"voxel ({DEFAULT_VOXEL_MM:g} mm)")
    origin = np.array([-0.5 * n * voxel, -0.5 * n * voxel, float(z.min()) - margin])
    shape = np.array([n, n, nz])

    # The distance transform of the voxels a sheet passes through (sampled every
    # voxel/4) lies within [d − (√3/2)·voxel, d + (√3/2 + 1/(4√3))·voxel] of the
    # exact distance d; only voxels it cannot decide get the exact distance.  It is taken
    # over the box of the sheet's voxels widened by the largest distance that matters
    # (voxels farther out are free and decided): within the box every voxel's nearest
    # sheet voxel is inside it, so its distance is the whole grid's.
    below_err, above_err = 0.87 * voxel, 1.05 * voxel
    pad = int(math.ceil((reach + above_err) / voxel)) + 1
    free = np.ones(shape, dtype=bool)
    exact_count = 0
    for patch in valve.leaflets:
        pts = _sheet_samples(positions[patch.nodes], patch.triangles, 0.25 * voxel)
        idx = np.floor((pts - origin) / voxel).astype(np.int64)
        idx = idx[np.all((idx >= 0) & (idx < shape), axis=1)]
        if len(idx) == 0:  # the sheet is outside the grid
            continue
        low = np.maximum(idx.min(axis=0) - pad, 0)
        box = tuple(slice(a, b) for a, b in zip(low, np.minimum(idx.max(axis=0) + pad + 1,
                                                                 shape), strict=True))
        crossed = np.zeros([b.stop - b.start for b in box], dtype=bool)
        crossed[tuple((idx - low).T)] = True
        approx = crossed_distances(crossed, reach + above_err, voxel)
        del crossed
        near = free[box]  # a view: blocking a voxel here blocks it in the grid
        undecided = near & (approx > reach - below_err) & (approx <= reach + above_err)
        near &= approx > reach - below_err
        shell = np.argwhere(undecided) + low
        del approx, undecided
        centres = origin + (shell + 0.5) * voxel
        free[tuple(shell.T)] = ~within_distance(centres, positions[patch.nodes],
                                                patch.triangles, reach)
        exact_count += len(shell)
    c = origin[0] + (np.arange(n) + 0.5) * voxel
    free &= (c[:, None] ** 2 + c[None, :] ** 2 < radius**2)[:, :, None]
    labels, _ = label(free)
    del free
    below, above = np.unique(labels[:, :, 0]), np.unique(labels[:, :, -1])
    passing = np.intersect1d(below[below > 0], above[above > 0])
    log.debug("3-D sealing check: %d×%d×%d voxels of %.3g mm, %d exact distances, %s",
              n, n, nz, voxel, exact_count, "flow passes" if passing.size else "sealed")
    return bool(passing.size)
