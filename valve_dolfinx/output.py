"""Writing a case's outputs: result.json, config.toml, history.csv, fields.vtu, figures.

Every file is written atomically (temporary file + rename), so an interrupted
run never leaves a truncated result behind; ``result.json`` is written last,
so its presence means the case finished.  :func:`start_case` checks the folder
before any computation and removes an older ``result.json``; :func:`write_result`
writes none once the command has received SIGINT or SIGTERM.
"""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path

import numpy as np

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.config import CONFIG_FILE, write_config
from valve_dolfinx.interrupts import check_not_interrupted
from valve_dolfinx.io import atomic_write, check_output_folder, export_valve_vtu, write_json
from valve_dolfinx.result import POSITIONS_FILE, RESULT_FILE

__all__ = ["start_case", "write_case", "write_result", "RESULT_FILE", "FIELDS_FILE"]

log = logging.getLogger(__name__)

#: the fields of a case for ParaView, meshio and PyVista
FIELDS_FILE = "fields.vtu"


def start_case(out: Path, comm: MPI.Comm = MPI.COMM_WORLD) -> None:
    """Before computing into ``out``: check that it can receive the outputs (on every
    rank), and remove a ``result.json`` a finished run left there (rank 0)."""
    check_output_folder(out)
    if comm.rank == 0:
        (out / RESULT_FILE).unlink(missing_ok=True)
    comm.barrier()


def write_result(out: Path, result, comm: MPI.Comm = MPI.COMM_WORLD) -> Path | None:
    """Write ``result.json``, the case's last file (rank 0); raise ``Interrupted`` instead
    if the command has received a signal."""
    check_not_interrupted()
    if comm.rank != 0:
        return None
    return write_json(out / RESULT_FILE, result.to_dict())


def write_case(out: Path, config, result, state, *, figures: bool = True,
               fields_output: bool = True) -> None:
    """All outputs of a case except result.json (see :func:`write_result`)."""
    comm = state.domain.comm
    out.mkdir(parents=True, exist_ok=True)
    if fields_output:
        _write_fields(out / FIELDS_FILE, state)
    if comm.rank != 0:
        return
    write_config(out / CONFIG_FILE, config)
    _write_history(out / "history.csv", state.report.history)
    _write_positions(out / POSITIONS_FILE, state)
    if figures:
        _write_figures(out, state, result)


def _write_history(path: Path, history: list[dict]) -> None:
    if not history:
        return
    keys = list(dict.fromkeys(k for row in history for k in row))
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=keys)
    writer.writeheader()
    writer.writerows(history)
    atomic_write(path, lambda tmp: tmp.write_text(buffer.getvalue()))


def _write_positions(path: Path, state) -> None:
    """Loaded node positions with the valve's topology: enough to redo any analysis."""
    valve = state.domain.valve

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, positions=state.positions, reference=valve.points,
                                cells=valve.cells, cell_tags=valve.cell_tags,
                                contact_forces=state.contact_forces)

    atomic_write(path, write)


def _cell_values(f: dolfinx.fem.Function) -> np.ndarray | None:
    """The values (M, k) of a DG0 function per valve cell in input order, on rank 0 (None
    elsewhere; every rank takes part)."""
    V = f.function_space
    mesh = V.mesh
    n_local = mesh.topology.index_map(mesh.topology.dim).size_local
    bs = V.dofmap.index_map_bs
    values = f.x.array.reshape(-1, bs)[V.dofmap.list[:n_local, 0]]
    index = np.asarray(mesh.topology.original_cell_index, dtype=np.int64)[:n_local]
    parts = mesh.comm.gather((index, values), root=0)
    if parts is None:
        return None
    out = np.empty((sum(len(i) for i, _ in parts), bs))
    for i, v in parts:
        out[i] = v
    return out


def _node_gap(state) -> np.ndarray:
    """Each node's distance to the nearest other leaflet (mm; -1 where undefined)."""
    valve = state.domain.valve
    gap = np.full(valve.num_nodes, np.nan)
    for patch in valve.leaflets:
        lc = state.coaptation.leaflets.get(patch.name)
        if lc is not None:
            gap[patch.nodes] = np.where(np.isnan(gap[patch.nodes]), lc.node_gap_mm,
                                        np.minimum(gap[patch.nodes], lc.node_gap_mm))
    return np.nan_to_num(gap, nan=-1.0)


def _write_fields(path: Path, state) -> None:
    """The solved valve as VTK (``.vtu``, rank 0; every rank takes part): the unloaded
    surface with its leaflet tags and fibres, displacement, contact force and coaptation
    gap per node, stress, strain (2×2 in the material axes, row by row) and area stretch
    per cell."""
    valve = state.domain.valve
    cells = {name: _cell_values(f) for name, f in state.model.cell_fields().items()}
    if state.domain.comm.rank != 0:
        return
    point_data = {"displacement": state.positions - valve.points,
                  "contact_force": state.contact_forces}
    if state.coaptation is not None:
        point_data["coaptation_gap"] = _node_gap(state)
    cell_data = {"stress": cells["stress"], "strain": cells["strain"],
                 "area_stretch": cells["area_stretch"][:, 0]}
    export_valve_vtu(valve, path, point_data, cell_data)


def _write_figures(out: Path, state, result) -> None:
    from valve_dolfinx.plotting import write_case_figures

    valve, positions = state.shown()
    try:
        write_case_figures(out, positions, valve, state.coaptation, result,
                           intersections=None if state.intersections is None
                           else state.intersections.points,
                           mirrored=state.display is not None)
    except Exception as err:  # a figure must never cost the computed result
        log.error("could not draw the figures of %s: %s", out, err)
