"""Writing a case's outputs: result.json, config.toml, history.csv, ParaView fields, figures.

Every file is written atomically (temporary file + rename), so an interrupted
run never leaves a truncated result behind; ``result.json`` is written last,
so its presence means the case finished.
"""

from __future__ import annotations

import csv
import io
import logging
import math
from pathlib import Path

import numpy as np

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.config import CONFIG_FILE, write_config
from valve_dolfinx.geometry.distributed import node_to_dof
from valve_dolfinx.geometry.valve import LEAFLET_TAGS
from valve_dolfinx.io import atomic_write, write_json
from valve_dolfinx.result import POSITIONS_FILE, RESULT_FILE

__all__ = ["write_case", "write_result", "plot_cut_planes", "RESULT_FILE"]

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
    from valve_dolfinx.analysis.plots import plot_coaptation_map
    from valve_dolfinx.plotting import plot_valve_3d

    valve, positions = state.display or (state.domain.valve, state.positions)
    graft_tag = next((p.tag for p in valve.leaflets if p.is_graft), None)
    name = _title(result)
    if state.display is not None:
        name += " (one leaflet and its mirror images)"
    try:
        plot_valve_3d(positions, valve.cells, valve.cell_tags,
                      out / "closed_valve_ventricular.png", graft_tag=graft_tag,
                      view="ventricular", title=f"{name}: closed valve from the ventricle")
        plot_valve_3d(positions, valve.cells, valve.cell_tags, out / "closed_valve.png",
                      graft_tag=graft_tag, view="iso", title=f"{name}: closed under "
                      f"{result.parameters.get('pressure_mmhg', 80):g} mmHg")
        plot_cut_planes(positions, valve, out / "cut_planes.png", title=name)
        plot_cross_sections(positions, valve, out / "cross_sections.png", title=name)
        if state.coaptation is not None and len(valve.leaflets) > 1:
            plot_coaptation_map(state.coaptation, valve, out / "coaptation_map.png")
    except Exception as err:  # a figure must never cost the computed result
        log.error("could not draw the figures of %s: %s", out, err)


def _title(result) -> str:
    if result.graft_width_pct is None:
        return "normal valve"
    return f"graft W{result.graft_width_pct:g}% H{result.graft_height_pct:g}%"


def plot_cut_planes(positions: np.ndarray, valve, path: Path, *, title: str = "",
                    angles_deg: tuple[float, float] = (0.0, 120.0)) -> Path:
    """The loaded leaflets cut by planes through the valve axis, drawn in each plane.

    Plane at angle φ contains the axis and the direction (cos φ, sin φ, 0); the
    horizontal coordinate is the signed distance from the axis along that
    direction.  φ = 0 passes through the left-coronary midline and the opposite
    commissure, φ = 120° through the right-coronary midline.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    from valve_dolfinx.plotting import GRAFT_COLOUR, LEAFLET_COLOURS

    fig, axes = plt.subplots(1, len(angles_deg), figsize=(6 * len(angles_deg), 5),
                             constrained_layout=True)
    radius = np.max(np.linalg.norm(positions[valve.attachment_nodes(), :2], axis=1))
    names = {v: k.replace("_", " ") for k, v in LEAFLET_TAGS.items()}
    for ax, phi_deg in zip(np.atleast_1d(axes), angles_deg, strict=True):
        phi = math.radians(phi_deg)
        e = np.array([math.cos(phi), math.sin(phi), 0.0])
        n = np.array([-math.sin(phi), math.cos(phi), 0.0])
        for patch in valve.leaflets:
            segments = _slice_triangles(positions, valve.cells[valve.cell_tags == patch.tag], n)
            if len(segments) == 0:
                continue
            lines = np.stack([segments @ e, segments[..., 2]], axis=-1)
            colour = GRAFT_COLOUR if patch.is_graft else LEAFLET_COLOURS.get(patch.tag, "k")
            label = names.get(patch.tag, patch.name) + (" (graft)" if patch.is_graft else "")
            ax.add_collection(LineCollection(lines, colors=colour, linewidths=2.0, label=label))
        ax.axvline(-radius, color="0.5", lw=1)
        ax.axvline(radius, color="0.5", lw=1)
        ax.axvline(0.0, color="0.8", lw=0.8, ls=":")
        ax.set_aspect("equal")
        ax.set_xlim(-1.15 * radius, 1.15 * radius)
        ax.set_ylim(positions[:, 2].min() - 1.0, positions[:, 2].max() + 1.0)
        ax.set_xlabel(f"distance from the axis along φ = {phi_deg:g}° (mm)")
        ax.set_ylabel("height above the nadir (mm)")
        ax.set_title(f"cut through the axis at φ = {phi_deg:g}°")
        ax.legend(loc="lower right", fontsize=8)
        ax.grid(alpha=0.25)
    if title:
        fig.suptitle(title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=140)
    plt.close(fig)
    return path


def plot_cross_sections(positions: np.ndarray, valve, path: Path, *, title: str = "",
                        heights: tuple[float, ...] | None = None) -> Path:
    """Horizontal cuts (z = const) of the loaded valve: the coaptation lines seen from above."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    from valve_dolfinx.plotting import GRAFT_COLOUR, LEAFLET_COLOURS

    z = positions[:, 2]
    if heights is None:
        heights = tuple(np.round(np.linspace(z.min(), z.max(), 6)[1:-1], 1))
    radius = np.max(np.linalg.norm(positions[valve.attachment_nodes(), :2], axis=1))
    fig, axes = plt.subplots(1, len(heights), figsize=(4.2 * len(heights), 4.6),
                             constrained_layout=True)
    for ax, z0 in zip(np.atleast_1d(axes), heights, strict=True):
        for patch in valve.leaflets:
            cells = valve.cells[valve.cell_tags == patch.tag]
            segments = _slice_triangles(positions, cells, np.array([0.0, 0.0, 1.0]), z0)
            colour = GRAFT_COLOUR if patch.is_graft else LEAFLET_COLOURS.get(patch.tag, "k")
            ax.add_collection(LineCollection(segments[..., :2], colors=colour, linewidths=2.0))
        ax.add_patch(plt.Circle((0.0, 0.0), radius, fill=False, color="0.5"))
        ax.set_xlim(-1.1 * radius, 1.1 * radius)
        ax.set_ylim(-1.1 * radius, 1.1 * radius)
        ax.set_aspect("equal")
        ax.set_title(f"z = {z0:g} mm")
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle((title + ": " if title else "") + "horizontal sections (aortic view)")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _slice_triangles(x: np.ndarray, cells: np.ndarray, normal: np.ndarray,
                     offset: float = 0.0) -> np.ndarray:
    """Segments ``(k, 2, 3)`` where the plane ``normal·x = offset`` cuts the triangles."""
    p = x[cells]
    d = p @ normal - offset
    pos = d > 0
    cut = pos.any(axis=1) & ~pos.all(axis=1)
    p, d, pos = p[cut], d[cut], pos[cut]
    ends = []
    for i, j in ((0, 1), (1, 2), (2, 0)):
        crosses = pos[:, i] != pos[:, j]
        t = np.where(crosses, d[:, i] / np.where(crosses, d[:, i] - d[:, j], 1.0), np.nan)
        ends.append(p[:, i] + t[:, None] * (p[:, j] - p[:, i]))
    ends = np.stack(ends, axis=1)  # (k, 3 edges, 3): exactly two edges are cut
    keep = ~np.isnan(ends[..., 0])
    return ends[keep].reshape(-1, 2, 3)
