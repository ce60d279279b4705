"""Writing a case's outputs: result.json, config.toml, history.csv, ParaView fields, figures.

Every file is written atomically (temporary file + rename), so an interrupted
run never leaves a truncated result behind; ``result.json`` is written last,
so its presence means the case finished.
"""

from __future__ import annotations

import csv
import io
import logging
from pathlib import Path

import numpy as np

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.config import CONFIG_FILE, write_config
from valve_dolfinx.geometry.distributed import node_to_dof
from valve_dolfinx.io import atomic_write, write_json
from valve_dolfinx.result import POSITIONS_FILE, RESULT_FILE

__all__ = ["write_case", "write_result", "RESULT_FILE"]

log = logging.getLogger(__name__)


def write_result(out: Path, result, comm: MPI.Comm = MPI.COMM_WORLD) -> Path | None:
    if comm.rank != 0:
        return None
    return write_json(out / RESULT_FILE, result.to_dict())


def write_case(out: Path, config, result, state, *, figures: bool = True,
               fields_output: bool = True) -> None:
    """All outputs of a case except result.json (see :func:`write_result`)."""
    comm = state.domain.comm
    out.mkdir(parents=True, exist_ok=True)
    if fields_output:
        _write_fields(out / "fields.xdmf", state)
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


def _nodal_function(V, values: np.ndarray, name: str) -> dolfinx.fem.Function:
    """P1 function from per-mesh-node values (N, k) in input order."""
    f = dolfinx.fem.Function(V, name=name)
    mesh = V.mesh
    ids = np.asarray(mesh.geometry.input_global_indices)
    dofs = node_to_dof(V)
    bs = V.dofmap.index_map_bs
    f.x.array.reshape(-1, bs)[dofs] = values[ids].reshape(len(ids), bs)
    return f


def _write_fields(path: Path, state) -> None:
    """Displacement, contact force, coaptation gap (P1) and stress/strain (DG0) to XDMF."""
    model, domain = state.model, state.domain
    mesh = domain.mesh
    functions = [model.u]
    functions[0].name = "displacement"
    functions.append(_nodal_function(model.V, state.contact_forces, "contact_force"))
    if state.coaptation is not None:
        gap = np.full(domain.valve.num_nodes, np.nan)
        for patch in domain.valve.leaflets:
            lc = state.coaptation.leaflets.get(patch.name)
            if lc is not None:
                gap[patch.nodes] = np.where(np.isnan(gap[patch.nodes]), lc.node_gap_mm,
                                            np.minimum(gap[patch.nodes], lc.node_gap_mm))
        S = dolfinx.fem.functionspace(mesh, ("Lagrange", 1))
        functions.append(_nodal_function(S, np.nan_to_num(gap, nan=-1.0)[:, None],
                                         "coaptation_gap"))
    cell_fields = model.cell_fields()
    functions += [cell_fields["stress"], cell_fields["strain"], cell_fields["area_stretch"]]
    path.parent.mkdir(parents=True, exist_ok=True)
    with dolfinx.io.XDMFFile(domain.comm, str(path), "w") as xdmf:
        xdmf.write_mesh(mesh)
        xdmf.write_meshtags(domain.cell_tags, mesh.geometry)
        for f in functions:
            xdmf.write_function(f)


def _write_figures(out: Path, state, result) -> None:
    from valve_dolfinx.plotting import write_case_figures

    valve, positions = state.shown()
    try:
        write_case_figures(out, positions, valve, state.coaptation, result,
                           mirrored=state.display is not None)
    except Exception as err:  # a figure must never cost the computed result
        log.error("could not draw the figures of %s: %s", out, err)
