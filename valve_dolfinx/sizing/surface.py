"""Response surfaces of a study: coaptation and sealing over the graft size and the axes.

Every solved graft case is a point ``(W, H, axis values)``: its width and height
enlargements and its value of every axis of the study (comparison and uncertainty; the
loaded root diameter first).  A numeric axis is one input; an axis of other values (a
choice, ``none``) is one 0/1 input per value after its first.  Inputs are scaled to
[0, 1] over the range the study covers; an input that takes one value only is left out.
The numerical path is not an input: the paths of a cell are replicates.

* :class:`CoaptationSurface`: scikit-learn's ``GaussianProcessRegressor`` with the kernel
  ``C · Matern(ν = 5/2, one length scale per input) + White``, fitted to the minimum
  coaptation height of every converged graft case (standardised); the white-noise term
  is the scatter the inputs do not explain (paths, mesh), reported in mm, and a grouped
  K-fold cross-validation (all cases of a cell held out together) gives its
  out-of-sample error.
* :class:`SealingModel`: the probability that a graft converges, seals and has no
  leaflets that intersect (``competent``), read from the solved cells by piecewise-linear
  interpolation (scipy's ``LinearNDInterpolator`` on a Delaunay triangulation of the
  cells' scaled inputs) of each cell's share of sealed cases (its paths).  It is not
  smoothed: sealing is not a smooth function of the size (a graft folding through a
  neighbour at a post, or a second resting state, flips it between neighbouring cells),
  so a size counts as sealing with probability 1 only where every solved cell around it
  sealed, and a smooth classifier fitted to a few tens of cells would let the failures of
  some cells decide the sizes beside sealed ones.

Both are deterministic: the surface has a fixed ``random_state`` and a fixed number of
optimiser restarts.  Nothing here imports DOLFINx.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.interpolate import LinearNDInterpolator, NearestNDInterpolator
from scipy.spatial import QhullError
from threadpoolctl import threadpool_limits

if TYPE_CHECKING:  # scikit-learn is imported by the fits (importing it takes about 1 s)
    from sklearn.gaussian_process import GaussianProcessRegressor

__all__ = ["SurfacePoint", "Design", "CoaptationSurface", "SealingModel", "fit_surface",
           "fit_sealing", "ROOT_KEY", "RANDOM_STATE", "RESTARTS", "CV_FOLDS"]

log = logging.getLogger(__name__)

#: the axis that comes first among the inputs, after W and H
ROOT_KEY = "root.loaded_diameter_mm"
#: the seed of every optimiser restart (the fits are deterministic)
RANDOM_STATE = 0
#: optimiser restarts from random hyperparameters, beside the initial ones
RESTARTS = 4
#: folds of the grouped cross-validation (fewer when the study has fewer cells)
CV_FOLDS = 5
#: bounds of the scaled length scales: a tenth of the studied range to 20 times it
_LENGTH_BOUNDS = (0.1, 20.0)

#: Every fit and reading of the surfaces runs on one thread of the BLAS and OpenMP pools:
#: they are small dense problems (tens to hundreds of cases) that threads do not speed up,
#: and under ``mpirun`` (or pytest-xdist) every process's pool would claim every core; a
#: stand-in adaptive sweep under ``mpirun -n 2`` on 2 cores took 17.8 s with the default
#: pools and 2.0 s with one thread each.
_one_thread = threadpool_limits.wrap(limits=1)


@dataclass(frozen=True)
class SurfacePoint:
    """One graft size at one value of each axis: where a case was solved, or a prediction.

    ``values`` are ``((axis key, value), ...)`` (no path).
    """

    width_pct: float
    height_pct: float
    values: tuple[tuple[str, Any], ...] = ()

    @property
    def cell(self) -> tuple:
        """The cell the point belongs to (its replicates, the paths, share it)."""
        return (self.width_pct, self.height_pct, self.values)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(
        value)


@dataclass(frozen=True)
class Design:
    """How points become the scaled inputs of a fit.

    ``columns`` name the inputs (``graft_width_pct``, ``graft_height_pct``, numeric axis
    keys, ``key=value`` indicators), ``low`` and ``span`` scale each to [0, 1].
    """

    columns: tuple[str, ...]
    low: tuple[float, ...]
    span: tuple[float, ...]

    @classmethod
    def of(cls, points: Sequence[SurfacePoint]) -> Design:
        """The inputs that vary over ``points``, scaled to their range."""
        keys = list(dict.fromkeys(k for p in points for k, _ in p.values))
        keys.sort(key=lambda k: k != ROOT_KEY)  # the root diameter first, then axis order
        columns = ["graft_width_pct", "graft_height_pct"]
        for key in keys:
            seen = list(dict.fromkeys(dict(p.values).get(key) for p in points))
            if all(_is_number(v) for v in seen):
                columns.append(key)
            else:
                columns += [f"{key}={v!r}" for v in seen[1:]]
        raw = _raw(points, columns)
        low, high = raw.min(axis=0), raw.max(axis=0)
        keep = high > low
        return cls(tuple(c for c, k in zip(columns, keep, strict=True) if k),
                   tuple(low[keep]), tuple((high - low)[keep]))

    def matrix(self, points: Sequence[SurfacePoint]) -> np.ndarray:
        """The scaled inputs of ``points`` (rows), shape ``(len(points), len(columns))``."""
        return (_raw(points, self.columns) - np.array(self.low)) / np.array(self.span)


def _raw(points: Sequence[SurfacePoint], columns: Sequence[str]) -> np.ndarray:
    out = np.zeros((len(points), len(columns)))
    for i, p in enumerate(points):
        values = dict(p.values)
        for j, column in enumerate(columns):
            if column == "graft_width_pct":
                out[i, j] = p.width_pct
            elif column == "graft_height_pct":
                out[i, j] = p.height_pct
            elif column in values:
                out[i, j] = float(values[column])
            else:  # an indicator key=value
                key, _, value = column.partition("=")
                out[i, j] = float(repr(values.get(key)) == value)
    return out


def _cell_groups(points: Sequence[SurfacePoint]) -> np.ndarray:
    """The number of each point's cell: a cross-validation holds a cell's replicates out
    together."""
    numbers: dict[tuple, int] = {}
    return np.array([numbers.setdefault(p.cell, len(numbers)) for p in points])


def _quiet_fit(model, x: np.ndarray, y: np.ndarray):
    """Fit, with scikit-learn's warnings about hyperparameters at their bounds logged at
    debug level (a length scale at its upper bound is an input the figure barely
    depends on, not an error)."""
    from sklearn.exceptions import ConvergenceWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", ConvergenceWarning)
        model.fit(x, y)
    for w in caught:
        log.debug("fit: %s", w.message)
    return model


@dataclass
class CoaptationSurface:
    """The fitted minimum coaptation height (mm) over the design's inputs.

    Attributes
    ----------
    design
        The inputs and their scaling.
    model
        The fitted ``GaussianProcessRegressor`` (standardised heights).
    mean_mm, scale_mm
        The standardisation of the heights.
    noise_mm
        The white-noise term's standard deviation, in mm: the scatter of a case about
        the smooth surface (paths, mesh artefacts).
    cv_rmse_mm
        Root-mean-square error of the grouped K-fold cross-validated predictions (mm);
        None with fewer than 3 folds.
    cv_folds, n_cases, n_cells
        How it was measured and on what.
    """

    design: Design
    model: GaussianProcessRegressor
    mean_mm: float
    scale_mm: float
    noise_mm: float
    cv_rmse_mm: float | None
    cv_folds: int
    n_cases: int
    n_cells: int

    @_one_thread
    def predict(self, points: Sequence[SurfacePoint]) -> tuple[np.ndarray, np.ndarray]:
        """The predicted height (mm) and the standard deviation of the smooth surface there
        (mm; the noise term left out: how well the surface is known, not a case's scatter)."""
        mean, sd = self.model.predict(self.design.matrix(points), return_std=True)
        noise = self.noise_mm / self.scale_mm
        latent = np.sqrt(np.maximum(sd**2 - noise**2, 0.0))
        return self.mean_mm + self.scale_mm * mean, self.scale_mm * latent

    @property
    def kernel_text(self) -> str:
        return str(self.model.kernel_)

    def summary(self) -> dict:
        return {"inputs": list(self.design.columns), "kernel": self.kernel_text,
                "noise_mm": self.noise_mm, "cv_rmse_mm": self.cv_rmse_mm,
                "cv_folds": self.cv_folds, "cases": self.n_cases, "cells": self.n_cells}


def _regressor(n_inputs: int) -> GaussianProcessRegressor:
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    kernel = (ConstantKernel(1.0, (1e-2, 1e2))
              * Matern(np.ones(n_inputs), _LENGTH_BOUNDS, nu=2.5)
              + WhiteKernel(0.05, (1e-6, 1.0)))
    return GaussianProcessRegressor(kernel, n_restarts_optimizer=RESTARTS,
                                    random_state=RANDOM_STATE)


@_one_thread
def fit_surface(points: Sequence[SurfacePoint], heights_mm: Sequence[float], *,
                cv_folds: int = CV_FOLDS) -> CoaptationSurface:
    """Fit :class:`CoaptationSurface` to ``heights_mm`` solved at ``points`` (replicates,
    such as the paths of a cell, are separate points at the same place); ``cv_folds``: the
    folds of the cross-validation (0: none, as a bootstrap of the answer refits)."""
    from sklearn.base import clone
    from sklearn.exceptions import ConvergenceWarning
    from sklearn.model_selection import GroupKFold, cross_val_predict

    design = Design.of(points)
    x = design.matrix(points)
    y = np.asarray(heights_mm, dtype=float)
    mean, scale = float(y.mean()), float(y.std()) or 1.0
    z = (y - mean) / scale
    model = _quiet_fit(_regressor(x.shape[1]), x, z)
    noise = math.sqrt(model.kernel_.k2.noise_level) * scale
    groups = _cell_groups(points)
    folds = min(cv_folds, len(set(groups)))
    rmse = None
    if folds >= 3:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            held_out = cross_val_predict(clone(_regressor(x.shape[1])), x, z, groups=groups,
                                         cv=GroupKFold(n_splits=folds))
        rmse = float(np.sqrt(np.mean((held_out - z) ** 2))) * scale
    log.debug("coaptation surface: %s; noise %.3f mm, CV error %s mm", model.kernel_, noise,
              rmse)
    return CoaptationSurface(design, model, mean, scale, noise, rmse, folds, len(y),
                             len(set(groups)))


@dataclass
class SealingModel:
    """The probability that a graft case converges, seals and has no leaflets that
    intersect: the share of sealed cases of each solved cell (``cells``: their scaled
    inputs; ``share``), interpolated piecewise-linearly between the cells (a Delaunay
    triangulation of them; with one input, linearly along it) and taken from the nearest
    cell outside their hull or where the cells span fewer dimensions than the inputs."""

    design: Design
    n_cases: int
    n_sealed: int
    cells: np.ndarray
    share: np.ndarray

    @_one_thread
    def probability(self, points: Sequence[SurfacePoint]) -> np.ndarray:
        x = self.design.matrix(points)
        nearest = NearestNDInterpolator(self.cells, self.share)
        if self.cells.shape[1] == 0:
            return np.full(len(points), float(self.share.mean()))
        if self.cells.shape[1] == 1:
            order = np.argsort(self.cells[:, 0])
            return np.interp(x[:, 0], self.cells[order, 0], self.share[order])
        try:
            p = LinearNDInterpolator(self.cells, self.share)(x)
        except QhullError:  # the cells lie in a lower-dimensional set
            return nearest(x)
        outside = ~np.isfinite(p)
        p[outside] = nearest(x[outside]) if outside.any() else p[outside]
        return np.clip(p, 0.0, 1.0)

    def summary(self) -> dict:
        return {"cases": self.n_cases, "sealed": self.n_sealed, "cells": len(self.share),
                "model": "piecewise-linear interpolation of each solved cell's share of "
                         "sealed cases"}


@_one_thread
def fit_sealing(points: Sequence[SurfacePoint], sealed: Sequence[bool],
                design: Design | None = None) -> SealingModel:
    """:class:`SealingModel` of the outcomes ``sealed`` at ``points``; ``design``: the
    inputs to use (the coaptation surface's, so that both read the same axes).  The cases
    of a cell (its paths) give the cell's share of sealed cases."""
    design = design or Design.of(points)
    y = np.asarray(sealed, dtype=float)
    groups = _cell_groups(points)
    x = design.matrix(points)
    labels = np.unique(groups)
    cells = np.array([x[groups == g][0] for g in labels]).reshape(len(labels), x.shape[1])
    share = np.array([y[groups == g].mean() for g in labels])
    return SealingModel(design, len(y), int(y.sum()), cells, share)
