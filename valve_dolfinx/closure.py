"""Valve closure under diastolic pressure: one case from geometry to result.json (SPEC §2-§7).

:func:`run_case` builds the valve (normal, or with a graft), distends the root
(step 1), holds the attachment at the distended root and brings the leaflets to
their static equilibrium under 80 mmHg with leaflet contact and bending (step 2:
pseudo-transient continuation, or damped BDF2 dynamics as the cross-check), then
measures coaptation and writes the result, the configuration, ParaView fields
and figures.  It never raises because a solve failed: a stalled or diverged
run is reported with ``converged: false`` and where it stopped, and whatever
was computed is written.
"""

from __future__ import annotations

import logging
import math
import platform
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path

import numpy as np

from valve_dolfinx._compat import MPI, dolfinx, package_versions
from valve_dolfinx.bending import BendingHook, bending_stiffness_matrix, flexural_rigidity
from valve_dolfinx.boundary_conditions import clamp_edges
from valve_dolfinx.contact import ContactParameters, PlaneContact, SurfaceContact
from valve_dolfinx.exceptions import ParameterError, check_range
from valve_dolfinx.geometry.distributed import ValveDomain, create_valve_domain
from valve_dolfinx.geometry.valve import (
    ATTACHMENT,
    FREE_EDGE,
    LEAFLET_TAGS,
    ValveMesh,
    ValveParameters,
    build_valve,
)
from valve_dolfinx.materials import BOVINE_PERICARDIUM, NATIVE_LEAFLET, FungMaterial
from valve_dolfinx.membrane import MembraneModel
from valve_dolfinx.root import RootParameters, RootState, distend_root
from valve_dolfinx.solvers.contact_hook import ContactHook
from valve_dolfinx.solvers.dynamics import DampedDynamicsSolver, DynamicsParameters
from valve_dolfinx.solvers.pseudo_transient import (
    PseudoTransientParameters,
    PseudoTransientSolver,
)

__all__ = ["MMHG_TO_KPA", "CaseConfig", "CaseResult", "run_case", "closure_model"]

log = logging.getLogger(__name__)
fem = dolfinx.fem

#: 1 mmHg in kPa (80 mmHg = 10.666 kPa)
MMHG_TO_KPA = 0.133322
#: Contact of the closing valve (SPEC §5 law, k = 10 mN/mm, h = 0.1 mm) with the numerical
#: choices of docs/contact.md: the leaflets' contact surfaces are offset 0.125 mm (half of
#: ``thickness``) from their mid-surfaces, so the three leaflets cannot wedge into each
#: other's seams at the valve centre; the blending width smooths nodes in mesh-scale creases.
#: The side of every node-triangle pair, between leaflets as within one, is the side the node
#: approaches from (recorded at the last accepted state), whichever face of the triangle that is.
VALVE_CONTACT = ContactParameters(thickness=0.25, penetration_depth=0.3, blend_distance=0.05)
#: own-body triangles closer than this many contact reaches (reference state) are not
#: contacts (see SurfaceContact: a fold meets itself across about 1.57 reaches of material)
SELF_EXCLUSION_FACTOR = 1.5
#: leaflets never contact each other within this distance (mm) of where they are sewn
#: together, measured on the unloaded valve (see SurfaceContact: attached_reference)
COMMISSURE_EXCLUSION_MM = 2.5
#: face contacts with a neighbour leaflet fade out over this many triangle heights beyond
#: its free edge (see SurfaceContact: boundary_band): coapting free edges lie level
FREE_EDGE_BAND = 1.0
#: effective flexural modulus of the leaflets (kPa): D = E_b·t³/12 (docs/closure.md)
BENDING_MODULUS_KPA = 200.0
#: paths to the loaded equilibrium (CaseConfig.solver): pseudo-transient continuation (the
#: default) and damped BDF2 dynamics (SPEC §4, the cross-check)
SOLVERS = ("ptc", "bdf2")
#: the aortic pressure acts on the aortic side, against the chart normal
VALVE_PRESSURE_SIDE = -1.0


@dataclass
class CaseConfig:
    """Everything that defines one closure case (written beside every result).

    ``symmetric_reference=True`` runs the cheap reference of SPEC §4 instead of
    the valve: the left-coronary leaflet alone, closing against the two planes
    through the valve axis at ±60° that its neighbours mirror it across (the
    contact law sees the distance to the mirror image, as between leaflets).

    ``bending_modulus_kpa`` gives the leaflets their flexural rigidity
    ``D = E_b·t³/12`` (:mod:`valve_dolfinx.bending`; 0 = pure membrane): it
    regularises the slack free-edge tip at the triple point, without which the
    three-leaflet valve does not converge (docs/numerics.md).
    ``solver`` picks the path to the equilibrium: ``"ptc"`` (the default:
    pseudo-transient continuation with PETSc TS and SNES, contact and bending
    in the Newton system from the first step,
    :mod:`~valve_dolfinx.solvers.pseudo_transient`) or ``"bdf2"`` (SPEC §4: damped
    BDF2 dynamics with PETSc TS, :mod:`~valve_dolfinx.solvers.dynamics`, the
    cross-check).  Both stop at a static equilibrium.
    ``nodulus_length_mm`` (0 mm) is the free-edge length at the triple point
    treated as the nodulus of Arantius by the coaptation heights
    (:mod:`valve_dolfinx.analysis.coaptation`); 0 leaves nothing out.
    """

    geometry: ValveParameters = field(default_factory=ValveParameters)
    pressure_mmhg: float = 80.0
    native_material: FungMaterial = NATIVE_LEAFLET
    graft_material: FungMaterial = BOVINE_PERICARDIUM
    root: RootParameters = field(default_factory=RootParameters)
    contact: ContactParameters = field(default_factory=lambda: VALVE_CONTACT)
    solver: str = "ptc"
    pseudo_transient: PseudoTransientParameters = field(
        default_factory=PseudoTransientParameters)
    dynamics: DynamicsParameters = field(default_factory=DynamicsParameters)
    coaptation_threshold_mm: float = 0.5
    orifice_pixel_mm: float = 0.05
    nodulus_length_mm: float = 0.0
    commissure_exclusion_mm: float = COMMISSURE_EXCLUSION_MM
    free_edge_band: float = FREE_EDGE_BAND
    quadrature_degree: int = 1
    symmetric_reference: bool = False
    bending_modulus_kpa: float = BENDING_MODULUS_KPA

    def __post_init__(self) -> None:
        check_range("pressure_mmhg", self.pressure_mmhg, 0.0, 300.0, low_open=True,
                    unit="mmHg", hint="diastolic aortic pressure is about 80 mmHg")
        check_range("coaptation_threshold_mm", self.coaptation_threshold_mm, 0.0, 5.0,
                    low_open=True, unit="mm")
        check_range("bending_modulus_kpa", self.bending_modulus_kpa, 0.0, 1e5, unit="kPa",
                    hint="0 switches bending off; leaflets are of order 100 kPa in flexure")
        if self.solver not in SOLVERS:
            raise ParameterError(f"solver = {self.solver!r} is not one of {SOLVERS}: "
                                 "'ptc' (pseudo-transient continuation, the default) or "
                                 "'bdf2' (damped BDF2 dynamics, the cross-check)")
        if self.symmetric_reference and self.geometry.has_graft:
            raise ParameterError("symmetric_reference needs the normal valve (no graft)")

    @property
    def pressure_kpa(self) -> float:
        return self.pressure_mmhg * MMHG_TO_KPA

    def to_dict(self) -> dict:
        out = {}
        for f in fields(self):
            value = getattr(self, f.name)
            out[f.name] = asdict(value) if hasattr(value, "__dataclass_fields__") else value
        return out

    @classmethod
    def from_dict(cls, data: dict) -> CaseConfig:
        kinds = {"geometry": ValveParameters, "native_material": FungMaterial,
                 "graft_material": FungMaterial, "root": RootParameters,
                 "contact": ContactParameters, "dynamics": DynamicsParameters,
                 "pseudo_transient": PseudoTransientParameters}
        unknown = set(data) - {f.name for f in fields(cls)}
        if unknown:
            raise ParameterError(f"unknown configuration keys {sorted(unknown)}")
        kw = {k: (kinds[k](**v) if k in kinds and isinstance(v, dict) else v)
              for k, v in data.items()}
        return cls(**kw)

    def with_graft(self, width_pct: float | None, height_pct: float | None) -> CaseConfig:
        geometry = replace(self.geometry, graft_width_pct=width_pct, graft_height_pct=height_pct)
        return replace(self, geometry=geometry)


@dataclass
class CaseResult:
    """Scalars of one case (``result.json``; one row of the study's ``results.csv``)."""

    graft_width_pct: float | None
    graft_height_pct: float | None
    converged: bool
    min_coaptation_height_mm: float = float("nan")
    min_coaptation_height_raw_mm: float = float("nan")
    central_coaptation_height_mm: float = float("nan")
    coaptation_area_mm2: float = float("nan")
    regurgitant_orifice_area_mm2: float = float("nan")
    competent: bool = False
    root_diameter_mm: float = float("nan")
    max_penetration_mm: float = float("nan")
    max_contact_layer_overlap_mm: float = float("nan")
    n_dofs: int = 0
    n_ranks: int = 1
    wall_time_s: float = 0.0
    mesh_size_mm: float = float("nan")
    n_cells: int = 0
    solver_message: str = ""
    solver: str = ""
    time_steps: int = 0
    newton_iterations: int = 0
    residual_tolerance_mN: float = float("nan")
    equilibrium_residual_mN: float = float("nan")
    leaflets: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    versions: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return asdict(self)


# --- building blocks -----------------------------------------------------------------------
def closure_model(domain: ValveDomain, config: CaseConfig) -> MembraneModel:
    """The membrane model of a valve domain: native leaflets and (if present) the graft."""
    materials = {}
    for patch in domain.valve.leaflets:
        materials[patch.tag] = config.graft_material if patch.is_graft else config.native_material
    return MembraneModel(domain, materials, pressure_side=VALVE_PRESSURE_SIDE,
                         quadrature_degree=config.quadrature_degree)


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


def leaflet_bending_matrix(valve: ValveMesh, model: MembraneModel, modulus_kpa: float):
    """Bending stiffness K of the leaflets (:mod:`valve_dolfinx.bending`), D = E_b·t³/12 with
    the thickness of each node's tissue; no curvature is measured on the boundary."""
    node_rigidity = np.zeros(valve.num_nodes)
    for tag, material in model.materials.items():
        cells = valve.cells[valve.cell_tags == tag]
        node_rigidity[cells.ravel()] = flexural_rigidity(modulus_kpa, material.thickness)
    return bending_stiffness_matrix(valve.cells, valve.flat, valve.num_nodes,
                                    np.unique(valve.edges), node_rigidity)


def _single_leaflet(valve: ValveMesh) -> ValveMesh:
    """The left-coronary leaflet alone (for the symmetry-plane reference)."""
    tag = LEAFLET_TAGS["left_coronary"]
    keep = valve.cell_tags == tag
    nodes = np.unique(valve.cells[keep])
    renumber = np.full(valve.num_nodes, -1, dtype=np.int64)
    renumber[nodes] = np.arange(len(nodes))
    edge_keep = np.all(np.isin(valve.edges, nodes), axis=1)
    patch = valve.leaflet("left_coronary")
    patch = replace(patch, nodes=renumber[patch.nodes])
    return ValveMesh(points=valve.points[nodes], cells=renumber[valve.cells[keep]],
                     cell_tags=valve.cell_tags[keep], flat=valve.flat[keep],
                     fibres=valve.fibres[keep], edges=renumber[valve.edges[edge_keep]],
                     edge_tags=valve.edge_tags[edge_keep], leaflets=(patch,),
                     parameters=valve.parameters).validate()


def symmetry_planes() -> tuple[np.ndarray, np.ndarray]:
    """Points and unit normals (pointing into the leaflet's sector) of the planes at ±60°."""
    normals = []
    for phi in (math.pi / 3, -math.pi / 3):
        n = np.array([-math.sin(phi), math.cos(phi), 0.0])
        normals.append(n if n[0] > 0 else -n)
    return np.zeros((2, 3)), np.array(normals)


def mirror_leaflet(valve: ValveMesh, positions: np.ndarray) -> tuple[ValveMesh, np.ndarray]:
    """Three-leaflet valve made of a single leaflet and its mirror images in the ±60° planes.

    Used to measure the single-leaflet reference with the same coaptation
    analysis as the full valve.
    """
    patch = valve.leaflets[0]
    _, normals = symmetry_planes()
    n = valve.num_nodes
    all_points, all_pos, all_cells, all_tags = [], [], [], []
    all_flat, all_fib, patches = [], [], []
    for k, mirror in enumerate([None, *normals]):
        pts, pos, cells = valve.points, positions, valve.cells
        if mirror is not None:
            reflect = np.eye(3) - 2 * np.outer(mirror, mirror)
            pts, pos = pts @ reflect.T, pos @ reflect.T
            cells = cells[:, [0, 2, 1]]  # keep the normals pointing to the aortic side
        all_points.append(pts)
        all_pos.append(pos)
        all_cells.append(cells + k * n)
        all_tags.append(np.full(len(cells), k + 1, dtype=np.int32))
        flat = valve.flat if mirror is None else valve.flat[:, [0, 2, 1]]
        all_flat.append(flat if mirror is None else flat * np.array([-1.0, 1.0]))
        all_fib.append(valve.fibres if mirror is None else valve.fibres * np.array([-1.0, 1.0]))
        flat_nodes = patch.flat if mirror is None else patch.flat * np.array([-1.0, 1.0])
        tri = patch.triangles if mirror is None else patch.triangles[:, [0, 2, 1]]
        patches.append(replace(patch, name=f"{patch.name}" if mirror is None
                               else f"{patch.name}_mirror{k}", tag=k + 1,
                               nodes=patch.nodes + k * n, flat=flat_nodes, triangles=tri))
    mirrored = ValveMesh(points=np.concatenate(all_points), cells=np.concatenate(all_cells),
                         cell_tags=np.concatenate(all_tags), flat=np.concatenate(all_flat),
                         fibres=np.concatenate(all_fib),
                         edges=np.concatenate([valve.edges + k * n for k in range(3)]),
                         edge_tags=np.tile(valve.edge_tags, 3), leaflets=tuple(patches),
                         parameters=valve.parameters)
    return mirrored, np.concatenate(all_pos)


# --- the case ---------------------------------------------------------------------------------
@dataclass
class CaseState:
    """Live objects of a solved case, for post-processing and tests."""

    domain: ValveDomain
    model: MembraneModel
    root: RootState
    positions: np.ndarray  # (N, 3) loaded positions (on every rank)
    contact_forces: np.ndarray  # (N, 3)
    report: object
    coaptation: object | None = None
    #: (valve, positions) to draw: the valve itself, or the single leaflet of the symmetric
    #: reference with its two mirror images
    display: tuple | None = None


def solve_case(config: CaseConfig, comm: MPI.Comm = MPI.COMM_WORLD,
               progress: Callable[[dict], None] | None = None,
               valve: ValveMesh | None = None) -> CaseState:
    """Root step and closure solve (no output written)."""
    if valve is None and comm.rank == 0:
        valve = build_valve(config.geometry)
    if config.symmetric_reference and comm.rank == 0:
        valve = _single_leaflet(valve)
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
    watch = [int(p.nodes[p.midline_free_edge_node]) for p in valve.leaflets]

    def make_hook(coupling):
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
                                     attached_exclusion_radius=config.commissure_exclusion_mm,
                                     boundary_band=config.free_edge_band))
        # PTC freezes the driving force within a pseudo-time step (exact Jacobian); BDF2
        # takes it from the current positions
        return ContactHook(coupling, models, valve.cells, model.pressure, VALVE_PRESSURE_SIDE,
                           lag_driving_force=config.solver == "ptc",
                           fixed_nodes=np.unique(valve.edges[valve.edge_tags == ATTACHMENT]))

    hooks = [make_hook]
    if config.bending_modulus_kpa > 0:
        K = leaflet_bending_matrix(valve, model, config.bending_modulus_kpa)
        hooks.append(lambda coupling: BendingHook(coupling, K))
    if config.solver == "ptc":
        solver = PseudoTransientSolver(model, [bc], config.pressure_kpa,
                                       config.pseudo_transient, hooks=hooks, watch_nodes=watch)
        report = solver.solve(progress=progress)
        state = model.u
    else:
        stiffness = {tag: m.stiffness_scale for tag, m in model.materials.items()}
        solver = DampedDynamicsSolver(model, [bc], u0, config.pressure_kpa, stiffness, watch,
                                      config.dynamics, hooks=hooks)
        report = solver.solve(progress=progress)
        state = solver.U
    hook = solver.hooks[0]
    positions = solver.coupling.positions(state)
    forces = hook.contact_forces(state)
    display = mirror_leaflet(valve, positions) if config.symmetric_reference else None
    return CaseState(domain, model, root, positions, forces, report, display=display)


def analyse_case(state: CaseState, config: CaseConfig):
    """Coaptation analysis of a solved case (on every rank; it is serial and cheap)."""
    from valve_dolfinx.analysis import analyse_coaptation

    valve, positions = state.display or (state.domain.valve, state.positions)
    result = analyse_coaptation(positions, valve, threshold_mm=config.coaptation_threshold_mm,
                                pixel_mm=config.orifice_pixel_mm,
                                nodulus_length_mm=config.nodulus_length_mm)
    if config.symmetric_reference:
        # the heights are the solved leaflet's (its images see each other only through it)
        solved = result.leaflets[valve.leaflets[0].name]
        result.min_native_height_mm = solved.min_height_mm
        result.min_native_height_raw_mm = solved.min_height_raw_mm
        result.central_native_height_mm = solved.central_height_mm
    return result


def run_case(config: CaseConfig, out_dir: str | Path | None = None,
             comm: MPI.Comm = MPI.COMM_WORLD, progress: Callable[[dict], None] | None = None,
             figures: bool = True, fields_output: bool = True) -> CaseResult:
    """Solve one case and write its outputs to ``out_dir`` (if given); return the result.

    Files: ``result.json`` (SPEC §7 fields + parameters + versions),
    ``config.json``, ``history.csv`` (time steps), ``fields.xdmf``/``.h5``
    (displacement, stress, strain, contact force) and the PNG figures.
    """
    from valve_dolfinx import output

    t0 = time.perf_counter()
    g = config.geometry
    state = solve_case(config, comm, progress)
    coaptation = analyse_case(state, config)
    state.coaptation = coaptation
    report = state.report
    last = report.history[-1] if report.history else {}
    fields_ = coaptation.result_fields()
    result = CaseResult(
        graft_width_pct=g.graft_width_pct, graft_height_pct=g.graft_height_pct,
        converged=bool(report.converged),
        min_coaptation_height_mm=fields_["min_coaptation_height_mm"],
        min_coaptation_height_raw_mm=fields_["min_coaptation_height_raw_mm"],
        central_coaptation_height_mm=fields_["central_coaptation_height_mm"],
        coaptation_area_mm2=fields_["coaptation_area_mm2"],
        regurgitant_orifice_area_mm2=fields_["regurgitant_orifice_area_mm2"],
        competent=bool(fields_["competent"]) and bool(report.converged),
        root_diameter_mm=state.root.diameter,
        max_penetration_mm=float(last.get("max_penetration_mm", 0.0)),
        max_contact_layer_overlap_mm=float(last.get("max_layer_overlap_mm", 0.0)),
        n_dofs=state.model.V.dofmap.index_map.size_global * 3,
        n_ranks=comm.size,
        mesh_size_mm=g.mesh_size,
        n_cells=state.domain.num_cells_global(),
        solver_message=report.reason,
        solver=config.solver,
        time_steps=report.steps,
        newton_iterations=report.newton_iterations,
        residual_tolerance_mN=(config.pseudo_transient.residual_tolerance
                               if config.solver == "ptc"
                               else config.dynamics.equilibrium_tolerance),
        equilibrium_residual_mN=(report.residual_mN if config.solver == "ptc"
                                 else report.equilibrium_residual),
        leaflets={name: lc.to_dict() for name, lc in coaptation.leaflets.items()},
        parameters={**config.to_dict(), "root_state": state.root.to_dict(),
                    "python": platform.python_version()},
        versions=package_versions(),
    )
    result.wall_time_s = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    if out_dir is not None:
        output.write_case(Path(out_dir), config, result, state, figures=figures,
                          fields_output=fields_output)
        result.wall_time_s = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        output.write_result(Path(out_dir), result, comm)
    log.info("case %s: converged=%s, central coaptation %.3f mm, min %.3f mm, RO area %.3g mm², "
             "root %.2f mm, %.1f s", case_name(g), result.converged,
             result.central_coaptation_height_mm, result.min_coaptation_height_mm,
             result.regurgitant_orifice_area_mm2, result.root_diameter_mm, result.wall_time_s)
    return result


def case_name(geometry: ValveParameters) -> str:
    if not geometry.has_graft:
        return "normal"
    return f"W{geometry.graft_width_pct:g}_H{geometry.graft_height_pct:g}"
