"""One closure case, from geometry to result (SPEC §2-§7).

:func:`run_case` builds the valve (normal, or with a graft), distends the root
(step 1), holds the attachment at the distended root and brings the leaflets to
their static equilibrium under the diastolic pressure with leaflet contact and
bending (step 2: pseudo-transient continuation, or damped BDF2 dynamics as the
cross-check), then measures coaptation, checks that no leaflet passes through another or
through itself (:func:`check_intersections`) and writes the result, the configuration,
ParaView fields and figures.  It never raises because a solve failed: a stalled
or diverged run is reported with ``converged: false`` and where it stopped, and
whatever was computed is written.  An interrupt, or an exception in one of the
solver's callbacks (:class:`~valve_dolfinx.solvers.callbacks.CallbackGuard`), is
raised and writes no result.  :func:`solve_case` and :func:`analyse_case`
are its two halves, for tests and benchmarks that need the live objects.
"""

from __future__ import annotations

import logging
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

from valve_dolfinx._compat import MPI, dolfinx, package_versions
from valve_dolfinx._version import __version__, git_commit
from valve_dolfinx.analysis.intersection import Intersections, valve_intersections
from valve_dolfinx.config import CaseConfig, case_name
from valve_dolfinx.contact import PlaneContact, SurfaceContact
from valve_dolfinx.contact.guard import SurfaceGuard
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.geometry.distributed import ValveDomain, create_valve_domain
from valve_dolfinx.geometry.symmetry import mirror_leaflet, single_leaflet, symmetry_planes
from valve_dolfinx.geometry.transfer import ValveState, transfer_positions
from valve_dolfinx.geometry.valve import ATTACHMENT, ValveMesh, build_valve
from valve_dolfinx.mechanics.bending import bending_stiffness_matrix, flexural_rigidity
from valve_dolfinx.mechanics.boundary_conditions import clamp_edges
from valve_dolfinx.mechanics.membrane import MembraneModel
from valve_dolfinx.mechanics.root import RootState, distend_root
from valve_dolfinx.result import CaseResult, competence, competence_text
from valve_dolfinx.solvers.bending_hook import BendingHook
from valve_dolfinx.solvers.contact_hook import ContactHook
from valve_dolfinx.solvers.dynamics import DampedDynamicsSolver
from valve_dolfinx.solvers.pseudo_transient import PseudoTransientSolver
from valve_dolfinx.solvers.report import SolveReport

__all__ = ["CaseState", "closure_model", "leaflet_rigidity", "leaflet_bending_matrix",
           "solve_case", "analyse_case", "check_intersections", "run_case"]

log = logging.getLogger(__name__)
fem = dolfinx.fem

#: own-body triangles closer than this many contact reaches (reference state) are not
#: contacts (see SurfaceContact: a fold meets itself across about 1.57 reaches of material)
SELF_EXCLUSION_FACTOR = 1.5
#: the aortic pressure acts on the aortic side, against the chart normal
VALVE_PRESSURE_SIDE = -1.0
#: the leaflets' contact thickness against each other grows from 0 at the commissure where
#: they are sewn together to its full value at this distance (mm), measured on the unloaded
#: valve (see SurfaceContact: seam_taper_length)
COMMISSURE_TAPER_MM = 2.5
#: face contacts with a neighbour leaflet fade out over this many triangle heights beyond
#: its free edge (see SurfaceContact: boundary_band): coapting free edges lie level
FREE_EDGE_BAND = 1.0


# --- building blocks -----------------------------------------------------------------------
def closure_model(domain: ValveDomain, config: CaseConfig) -> MembraneModel:
    """The membrane model of a valve domain: native leaflets and (if present) the graft,
    with the membrane forms' quadrature degree 1 (exact for the linear triangles' constant
    strain, :class:`~valve_dolfinx.mechanics.membrane.MembraneModel`)."""
    materials, relaxed = {}, {}
    for patch in domain.valve.leaflets:
        materials[patch.tag] = config.graft_material if patch.is_graft else config.native_material
        relaxed[patch.tag] = config.graft_tension_field or not patch.is_graft
    return MembraneModel(domain, materials, pressure_side=VALVE_PRESSURE_SIDE,
                         wrinkling=relaxed)


def _radial_scaling(model: MembraneModel, factor: float) -> fem.Function:
    """Displacement that scales every node's distance from the valve axis by ``factor``."""
    u = fem.Function(model.V, name="root_scaling")
    u.interpolate(lambda x: np.stack([(factor - 1) * x[0], (factor - 1) * x[1], 0 * x[2]]))
    return u


def _leaflet_energy_on_cylinder(model: MembraneModel, wrap_radius: float
                                ) -> Callable[[float], float]:
    """R ↦ membrane energy of the unloaded leaflets lying on the cylinder of radius R."""
    energy = fem.form(model.strain_energy())
    comm = model.domain.comm
    saved = model.u.x.array.copy()

    def evaluate(R: float) -> float:
        model.u.x.array[:] = _radial_scaling(model, R / wrap_radius).x.array
        value = comm.allreduce(fem.assemble_scalar(energy), op=MPI.SUM)
        model.u.x.array[:] = saved
        return float(value)

    return evaluate


def leaflet_rigidity(config: CaseConfig, is_graft: bool) -> float:
    """Flexural rigidity D = E_b·t³/12 (mN·mm) of a leaflet's tissue: the graft's
    ``graft.bending_modulus_kpa`` and thickness, or the native leaflets'
    ``native.bending_modulus_kpa`` and thickness."""
    if is_graft:
        return flexural_rigidity(config.graft_bending_modulus_kpa,
                                 config.graft_material.thickness)
    return flexural_rigidity(config.bending_modulus_kpa, config.native_material.thickness)


def leaflet_bending_matrix(valve: ValveMesh, config: CaseConfig):
    """Bending stiffness K of the leaflets (:mod:`valve_dolfinx.mechanics.bending`), each
    node with the rigidity of its leaflet's tissue (:func:`leaflet_rigidity`).

    No curvature is measured on the boundary (free edges and attachment), which holds the
    commissure nodes a leaflet shares with its neighbours: every node that carries a
    curvature lies inside one leaflet and is bent by that leaflet's triangles alone, so K
    is the sum of the leaflets' own matrices, with no term across a seam between tissues.
    """
    node_rigidity = np.zeros(valve.num_nodes)
    for patch in valve.leaflets:
        node_rigidity[patch.nodes] = leaflet_rigidity(config, patch.is_graft)
    return bending_stiffness_matrix(valve.cells, valve.flat, valve.num_nodes,
                                    np.unique(valve.edges), node_rigidity)


# --- the case ---------------------------------------------------------------------------------
@dataclass
class CaseState:
    """Live objects of a solved case, for post-processing and tests."""

    domain: ValveDomain
    model: MembraneModel
    root: RootState
    positions: np.ndarray  # (N, 3) loaded positions (on every rank)
    contact_forces: np.ndarray  # (N, 3)
    report: SolveReport
    coaptation: object | None = None
    #: the intersecting edge–triangle pairs of the loaded valve (:func:`check_intersections`)
    intersections: Intersections | None = None
    #: (valve, positions) to draw: the valve itself, or the single leaflet of the symmetric
    #: reference with its two mirror images
    display: tuple | None = None

    def shown(self) -> tuple:
        """(valve, positions) that the analysis, the figures and the outputs read."""
        return self.display or (self.domain.valve, self.positions)


def _set_free_positions(model: MembraneModel, positions: np.ndarray,
                        fixed_nodes: np.ndarray) -> None:
    """Move every node but ``fixed_nodes`` to ``positions`` (N, 3, the valve's node order)."""
    from valve_dolfinx.geometry.distributed import node_to_dof

    mesh = model.domain.mesh
    node_id = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
    block = node_to_dof(model.V)
    free = ~np.isin(node_id, fixed_nodes)
    u = model.u.x.array.reshape(-1, 3)
    u[block[free]] = positions[node_id[free]] - mesh.geometry.x[free]
    model.u.x.scatter_forward()


def coarse_start(config: CaseConfig, comm: MPI.Comm = MPI.COMM_WORLD) -> ValveState | None:
    """The equilibrium of a valve without a graft on the coarse mesh
    (``solver.pseudo_transient.coarse_mesh_mm``), to start the case's own mesh from; None for a
    graft valve, when the case's mesh is not finer, or when the coarse closure did not
    converge (the case then starts from the unloaded valve).

    A graft valve is not started this way: on the 2 mm mesh most grafts of the study grid
    come to rest with leaflets crossed over 3-6 mm (W21/H0, W21/H40, W27/H0 to W27/H40),
    and a start keeps a crossing, since the contact takes the side each node is on.  A
    graft valve starts from the unloaded valve, or in a study from the closed normal valve.
    """
    size = config.pseudo_transient.coarse_mesh_mm
    if config.solver != "ptc" or size <= config.geometry.mesh_size or config.geometry.has_graft:
        return None
    coarse = replace(config, geometry=replace(config.geometry, mesh_size=size))
    state = solve_case(coarse, comm)
    report = state.report
    log.info("coarse closure on the %g mm mesh: %s (%d + %d Newton iterations, %.1f s)",
             size, "converged" if report.converged else "NOT converged: " + report.reason,
             report.newton_iterations, report.rejected_newton_iterations, report.wall_time_s)
    if not report.converged:
        return None
    # the valve as solved (the symmetric reference's single leaflet, not its mirror images)
    return ValveState(state.domain.valve, state.positions,
                      f"the equilibrium on the {size:g} mm mesh",
                      report.newton_iterations + report.rejected_newton_iterations,
                      report.wall_time_s)


def _geometry_mismatch(valve: ValveMesh | None, config: CaseConfig) -> str | None:
    """Why a given valve mesh is not ``config.geometry``'s, or None."""
    if valve is None or valve.parameters == config.geometry:
        return None
    differ = [f"{f.name} {getattr(valve.parameters, f.name)!r} (config.geometry: "
              f"{getattr(config.geometry, f.name)!r})" for f in fields(config.geometry)
              if getattr(valve.parameters, f.name) != getattr(config.geometry, f.name)]
    return (f"the valve mesh given is not the configuration's geometry: {', '.join(differ)}; "
            "pass the configuration with geometry=valve.parameters (what `valve-dolfinx run "
            "--mesh` does), so that the result records the mesh it solved")


def solve_case(config: CaseConfig, comm: MPI.Comm = MPI.COMM_WORLD,
               progress: Callable[[dict], None] | None = None,
               valve: ValveMesh | None = None,
               start: ValveState | None = None) -> CaseState:
    """Root step and closure solve (no output written).

    ``valve`` (rank 0's is used) must be the mesh of ``config.geometry``; ParameterError
    (on every rank) names what differs.  The closure starts from ``start``, a loaded valve
    whose shape is carried onto this case's mesh
    (:func:`~valve_dolfinx.geometry.transfer.transfer_positions`: another mesh of the same
    valve, or the normal valve for a graft valve); without one, from the case's
    equilibrium on a coarse mesh (:func:`coarse_start`), and failing that from the
    unloaded valve.  The attachment is held at the distended root either way."""
    mismatch = comm.bcast(_geometry_mismatch(valve, config) if comm.rank == 0 else None)
    if mismatch:
        raise ParameterError(mismatch)
    if start is None:
        start = coarse_start(config, comm)
    if start is not None and config.solver != "ptc":
        raise ParameterError("a closure that starts from a loaded valve needs solver.method = "
                             "'ptc' (the BDF2 cross-check starts from the unloaded valve)")
    if valve is None and comm.rank == 0:
        valve = build_valve(config.geometry)
    if config.symmetric_reference and comm.rank == 0:
        valve = single_leaflet(valve)
    domain = create_valve_domain(valve if comm.rank == 0 else None, comm)
    valve = domain.valve
    model = closure_model(domain, config)
    shape = valve.leaflets[0].shape
    wrap_radius = 0.5 * shape.root_diameter

    # step 1: the root
    root = distend_root(config.root, shape.root_diameter, shape.height, config.pressure_kpa,
                        _leaflet_energy_on_cylinder(model, wrap_radius))
    u0 = _radial_scaling(model, root.radius / wrap_radius)

    # step 2: closure with the attachment held at the distended root
    bc = clamp_edges(model.V, domain.facet_tags, [ATTACHMENT], value=u0)
    model.u.x.array[:] = u0.x.array
    if start is not None:
        _set_free_positions(model, transfer_positions(start.valve, start.positions, valve),
                            valve.attachment_nodes())
    watch = [int(p.nodes[p.midline_free_edge_node]) for p in valve.leaflets]
    guard = SurfaceGuard(valve.points, valve.cells, distance=config.contact.guard_distance,
                         stiffness=config.contact.guard_stiffness)
    hooks = _closure_hooks(valve, model, config, guard)
    if config.solver == "ptc":
        solver = PseudoTransientSolver(model, [bc], config.pressure_kpa,
                                       config.solver_parameters(), hooks=hooks,
                                       watch_nodes=watch)
        refused = None
        if start is not None and guard.intersects(solver.coupling.positions(model.u)):
            # a barrier holds a crossing it starts with: start unloaded instead
            refused = f"{start.origin}, carried onto this mesh, has intersecting leaflets"
            log.warning("not starting from %s; starting from the unloaded valve", refused)
            model.u.x.array[:] = u0.x.array
            start = None
        if start is not None:  # contact sides and driving forces of the start
            solver.accept_state()
        report = solver.solve(progress=progress)
        report.start = _start_record(start)
        if refused:
            report.start["refused"] = refused
    else:
        stiffness = {tag: m.stiffness_scale for tag, m in model.materials.items()}
        solver = DampedDynamicsSolver(model, [bc], u0, config.pressure_kpa, stiffness, watch,
                                      config.solver_parameters(), hooks=hooks)
        report = solver.solve(progress=progress)
    state = solver.state
    hook = solver.hooks[0]
    positions = solver.coupling.positions(state)
    forces = hook.contact_forces(state)
    display = mirror_leaflet(valve, positions) if config.symmetric_reference else None
    return CaseState(domain, model, root, positions, forces, report, display=display)


def _closure_hooks(valve: ValveMesh, model: MembraneModel, config: CaseConfig,
                   guard: SurfaceGuard) -> list:
    """The solver's hook factories: contact (the leaflets on each other and themselves, and
    on the symmetry planes of the symmetric reference, with ``guard`` keeping every surface
    from passing through another), and bending where a leaflet has a bending rigidity."""

    def make_contact(coupling):
        models = []
        if config.symmetric_reference:
            points, normals = symmetry_planes()
            models.append(PlaneContact(points, normals, config.contact, mirror=True))
            # a single leaflet may still fold onto itself
        models.append(SurfaceContact(valve.cells, valve.num_nodes, config.contact,
                                     triangle_body=valve.cell_tags,
                                     reference=valve.flat,
                                     self_exclusion_radius=SELF_EXCLUSION_FACTOR
                                     * config.contact.reach,
                                     attached_reference=valve.points,
                                     seam_taper_length=COMMISSURE_TAPER_MM,
                                     boundary_band=FREE_EDGE_BAND,
                                     body_names={p.tag: f"leaflet {p.name}"
                                                 for p in valve.leaflets}))
        # PTC freezes the driving force within a pseudo-time step (exact Jacobian); BDF2
        # takes it from the current positions
        return ContactHook(coupling, models, valve.cells, model.pressure, VALVE_PRESSURE_SIDE,
                           lag_driving_force=config.solver == "ptc",
                           fixed_nodes=np.unique(valve.edges[valve.edge_tags == ATTACHMENT]),
                           guard=guard)

    hooks = [make_contact]
    if any(leaflet_rigidity(config, patch.is_graft) > 0 for patch in valve.leaflets):
        K = leaflet_bending_matrix(valve, config)
        hooks.append(lambda coupling: BendingHook(coupling, K))
    return hooks


def _start_record(start: ValveState | None) -> dict:
    """Where a closure started, for the result: the state and what reaching it cost."""
    if start is None:
        return {"from": "the unloaded valve"}
    return {"from": start.origin, "newton_iterations": start.newton_iterations,
            "wall_time_s": start.wall_time_s}


def check_intersections(state: CaseState) -> Intersections:
    """Every edge of the loaded valve, as drawn (:meth:`CaseState.shown`), that passes
    through one of its triangles: between leaflets or within one
    (:func:`~valve_dolfinx.analysis.intersection.valve_intersections`)."""
    valve, positions = state.shown()
    return valve_intersections(positions, valve)


def analyse_case(state: CaseState, config: CaseConfig):
    """Coaptation analysis of a solved case (on every rank; it is serial and cheap)."""
    from valve_dolfinx.analysis import analyse_coaptation

    valve, positions = state.shown()
    result = analyse_coaptation(positions, valve, threshold_mm=config.coaptation_threshold_mm,
                                nodulus_length_mm=config.nodulus_length_mm)
    if config.symmetric_reference:
        # the heights are the solved leaflet's (its images see each other only through it)
        solved = result.leaflets[valve.leaflets[0].name]
        result.min_native_height_mm = solved.min_height_mm
        result.min_native_height_raw_mm = solved.min_height_raw_mm
        result.central_native_height_mm = solved.central_height_mm
    return result


def _analysed_result(config: CaseConfig, state: CaseState, comm: MPI.Comm) -> CaseResult:
    """Analyse a solved case (coaptation, intersections, competence) into its result."""
    g = config.geometry
    coaptation = analyse_case(state, config)
    state.coaptation = coaptation
    report = state.report
    last = report.history[-1] if report.history else {}
    fields_ = coaptation.result_fields()
    state.intersections = intersections = check_intersections(state)
    orifice = fields_["regurgitant_orifice_area_mm2"]
    competent, why = competence(bool(report.converged), np.nan if orifice is None else orifice,
                                intersections.count, intersections.where())
    result = CaseResult(
        graft_width_pct=g.graft_width_pct, graft_height_pct=g.graft_height_pct,
        converged=bool(report.converged),
        min_coaptation_height_mm=fields_["min_coaptation_height_mm"],
        min_coaptation_height_raw_mm=fields_["min_coaptation_height_raw_mm"],
        central_coaptation_height_mm=fields_["central_coaptation_height_mm"],
        coaptation_area_mm2=fields_["coaptation_area_mm2"],
        regurgitant_orifice_area_mm2=orifice,
        competent=competent,
        competence_reason=why,
        root_diameter_mm=state.root.diameter,
        max_penetration_mm=float(last.get("max_penetration_mm", 0.0)),
        max_contact_layer_overlap_mm=float(last.get("max_layer_overlap_mm", 0.0)),
        intersecting_pairs=intersections.count,
        intersections=intersections.to_dict(),
        n_dofs=state.model.V.dofmap.index_map.size_global * 3,
        n_ranks=comm.size,
        mesh_size_mm=g.mesh_size,
        n_cells=state.domain.num_cells_global(),
        solver_message=report.reason,
        solver=config.solver,
        time_steps=report.steps,
        newton_iterations=report.newton_iterations,
        rejected_newton_iterations=report.rejected_newton_iterations,
        residual_tolerance_mN=report.residual_tolerance_mN,
        equilibrium_residual_mN=report.residual_mN,
        start=report.start,
        leaflets={name: lc.to_dict() for name, lc in coaptation.leaflets.items()},
        parameters={**config.to_dict(), "root_state": state.root.to_dict(),
                    "python": platform.python_version()},
        versions=package_versions(),
        settings_hash=config.settings_hash(),
        version=__version__,
        git_commit=git_commit(),
    )
    return result


def run_case(config: CaseConfig, out_dir: str | Path | None = None,
             comm: MPI.Comm = MPI.COMM_WORLD, progress: Callable[[dict], None] | None = None,
             figures: bool = True, fields_output: bool = True,
             valve: ValveMesh | None = None, start: ValveState | None = None) -> CaseResult:
    """Solve one case and write its outputs to ``out_dir`` (if given); return the result.

    ``start``: a loaded valve to start the closure from (see :func:`solve_case`).

    ``valve``: the valve mesh to close (rank 0's is used), e.g. one read with
    :func:`~valve_dolfinx.geometry.valve.load_valve_mesh`; by default it is built from
    ``config.geometry``.  A valve given must be ``config.geometry``'s (the result records
    it): otherwise ParameterError names what differs, before any computation.

    ``out_dir`` is checked before any computation
    (:func:`~valve_dolfinx.io.check_output_folder`), and a ``result.json`` already in it
    is removed, so that an unfinished run never leaves an older result beside its files.

    Files: ``result.json`` (SPEC §7 fields, parameters, versions, the settings
    hash), ``config.toml`` (the configuration that ran, reloadable with
    ``valve-dolfinx run --config``), ``history.csv`` (time steps), ``fields.vtu``
    (displacement, stress, strain, contact force) and the PNG figures.
    """
    from valve_dolfinx import output

    t0 = time.perf_counter()
    g = config.geometry
    if out_dir is not None:
        output.start_case(Path(out_dir), comm)
    state = solve_case(config, comm, progress, valve=valve, start=start)
    result = _analysed_result(config, state, comm)
    result.wall_time_s = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    if out_dir is not None:
        output.write_case(Path(out_dir), config, result, state, figures=figures,
                          fields_output=fields_output)
        result.wall_time_s = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        output.write_result(Path(out_dir), result, comm)
    log.info("case %s: %s, %s, central coaptation %.3f mm, min %.3f mm, RO area %.3g mm², "
             "root %.2f mm, %.1f s", case_name(g),
             "converged" if result.converged else "NOT converged", competence_text(result),
             result.central_coaptation_height_mm, result.min_coaptation_height_mm,
             result.regurgitant_orifice_area_mm2, result.root_diameter_mm, result.wall_time_s)
    return result


