"""The resolution of the figure of merit, measured: the tolerance an answer is read at.

Three measurements, each a standard deviation in mm of the minimum coaptation height:

* **path scatter**: the pooled standard deviation between the numerical paths of the
  same cell, ``sqrt(Σ_cells Σ_paths (y − ȳ_cell)² / Σ_cells (n_cell − 1))`` over the
  cells solved along two paths or more (None with one path);
* **surface noise**: the white-noise term of the coaptation surface
  (:class:`~valve_dolfinx.sizing.surface.CoaptationSurface`), the scatter of a case
  about the smooth surface;
* **discretisation error**: the root-mean-square difference, over the cells of a mesh
  ladder (``benchmarks/mesh_ladder.py``, table ``benchmarks/results/mesh_ladder.csv``),
  between the study's mesh size and the finest mesh of the ladder (None when no ladder
  table holds the study's mesh size: not measured).

The **tolerance** is the largest of those measured.  Not their root-sum-square: they are
not independent errors — the surface's noise already holds the scatter between paths
and the cell-to-cell roughness the mesh puts on the figure — so adding them would count
the same scatter twice; the largest is the finest difference one of the measurements
says the model cannot resolve.  Nothing here imports DOLFINx.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from valve_dolfinx.result import margin_text

__all__ = ["Resolution", "path_scatter_mm", "discretisation_error_mm", "MESH_LADDER"]

#: where ``benchmarks/mesh_ladder.py`` writes its table, in the source tree
MESH_LADDER = Path(__file__).resolve().parents[2] / "benchmarks" / "results" / "mesh_ladder.csv"


def path_scatter_mm(cells: Iterable[Sequence[float]]) -> tuple[float | None, int]:
    """Pooled standard deviation between the replicates (paths) of each cell, and the
    number of cells with two replicates or more that it pools (None, 0 without any)."""
    squares, dof, n = 0.0, 0, 0
    for values in cells:
        y = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
        if len(y) < 2:
            continue
        squares += float(((y - y.mean()) ** 2).sum())
        dof += len(y) - 1
        n += 1
    return (math.sqrt(squares / dof), n) if dof else (None, 0)


def _float(text: str | None) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return math.nan


def discretisation_error_mm(table: Path, mesh_size_mm: float | None
                            ) -> tuple[float | None, str]:
    """The RMS difference of the minimum coaptation height between ``mesh_size_mm`` and the
    finest mesh of a mesh-ladder table, over the cases converged and competent at both;
    and where it comes from, in words (why not, when None)."""
    if mesh_size_mm is None or not Path(table).is_file():
        return None, "not measured (no mesh-ladder table: benchmarks/mesh_ladder.py)"
    with open(table, newline="") as fh:
        rows = list(csv.DictReader(fh))
    sound = {}
    for row in rows:
        if row.get("converged") == "true" and row.get("competent") == "true":
            key = (row.get("graft_width_pct") or "", row.get("graft_height_pct") or "")
            sound.setdefault(_float(row.get("mesh_size_mm")), {})[key] = _float(
                row.get("min_coaptation_height_mm"))
    meshes = sorted(m for m in sound if math.isfinite(m))
    here = next((m for m in meshes if math.isclose(m, mesh_size_mm)), None)
    if here is None or here == meshes[0]:
        sizes = ", ".join(f"{m:g}" for m in meshes) or "none"
        return None, (f"not measured at the {mesh_size_mm:g} mm mesh (the mesh ladder "
                      f"{Path(table).name} has {sizes} mm)")
    finest = meshes[0]
    both = [k for k in sound[here] if k in sound[finest]]
    if not both:
        return None, f"not measured (no case sound at both {here:g} and {finest:g} mm)"
    diff = np.array([sound[here][k] - sound[finest][k] for k in both])
    return float(np.sqrt(np.mean(diff**2))), (
        f"{here:g} mm against {finest:g} mm over {len(both)} cases of the mesh ladder")


@dataclass(frozen=True)
class Resolution:
    """The measured resolution of the minimum coaptation height (mm) and the tolerance.

    ``path_cells`` is the number of cells the path scatter pools; ``discretisation_source``
    says what the discretisation error compares, or why it is not measured.
    """

    path_scatter_mm: float | None
    path_cells: int
    surface_noise_mm: float | None
    discretisation_mm: float | None
    discretisation_source: str

    @property
    def tolerance_mm(self) -> float | None:
        """The largest measured figure (None when nothing is measured)."""
        measured = [v for v in (self.path_scatter_mm, self.surface_noise_mm,
                                self.discretisation_mm) if v is not None]
        return max(measured) if measured else None

    def text(self) -> str:
        """One sentence: the tolerance and the figures it is the largest of."""
        paths = ("the scatter between paths not measured (one path)"
                 if self.path_scatter_mm is None else
                 f"the scatter between paths {margin_text(self.path_scatter_mm)} mm (pooled over "
                 f"{self.path_cells} cells)")
        noise = ("the surface's noise not measured" if self.surface_noise_mm is None else
                 f"the surface's noise {margin_text(self.surface_noise_mm)} mm")
        mesh = ("the mesh's discretisation error " + (
            self.discretisation_source if self.discretisation_mm is None else
            f"{margin_text(self.discretisation_mm)} mm ({self.discretisation_source})"))
        if self.tolerance_mm is None:
            return f"The resolution is not measured: {paths}, {noise}, {mesh}."
        return (f"Resolution (decision tolerance) {margin_text(self.tolerance_mm)} mm, the "
                f"largest of {paths}, {noise} and {mesh}.")

    def to_dict(self) -> dict:
        return {**asdict(self), "tolerance_mm": self.tolerance_mm}
