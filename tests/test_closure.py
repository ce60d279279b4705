"""Valve closure under 80 mmHg (SPEC §2, §4, §6, §7; issue 5).

The expected numbers come from outside the code:

* central coaptation height of a normal valve of this size: 3-4 mm clinically
  (Swanson & Clark 1974); the model must land in 2.5-4.5 mm (docs/closure.md
  states what it gives and why);
* a sealed valve has regurgitant orifice area 0;
* the equilibrium is static: the numerical mass and damping (×4) must not move
  it, and neither may the number of MPI ranks;
* the root: a thin-walled tube, hoop stress pR/t = E·ε (Laplace), gives the
  distended diameter in closed form (checked in test_root below).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

from valve_dolfinx._compat import MPI
from valve_dolfinx.closure import MMHG_TO_KPA, CaseConfig, run_case
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.geometry.valve import ValveParameters
from valve_dolfinx.root import RootParameters, distend_root
from valve_dolfinx.solvers.dynamics import DynamicsParameters

#: SPEC §7 fields every result.json carries
RESULT_FIELDS = ("graft_width_pct", "graft_height_pct", "converged", "min_coaptation_height_mm",
                 "central_coaptation_height_mm", "coaptation_area_mm2",
                 "regurgitant_orifice_area_mm2", "competent", "root_diameter_mm",
                 "max_penetration_mm", "n_dofs", "n_ranks", "wall_time_s", "mesh_size_mm")


def _reference(comm=MPI.COMM_SELF, out=None, mesh_size: float | None = None,
               solver: str = "dynamics", **dynamics) -> object:
    geometry = ValveParameters() if mesh_size is None else ValveParameters(mesh_size=mesh_size)
    config = CaseConfig(symmetric_reference=True, geometry=geometry, solver=solver,
                        dynamics=DynamicsParameters(**dynamics))
    return run_case(config, out, comm=comm, figures=out is not None)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One leaflet against the ±60° planes at the default mesh, with all outputs."""
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial fixture")
    out = tmp_path_factory.mktemp("reference")
    return _reference(out=out), out


def test_root_distension_matches_laplace():
    """Thin tube: p·R = E·t·(R - R0)/R0 (Laplace + Hooke), R0 = 10/1.15 mm.

    With a leaflet energy ½K(R - R0)² the pull adds K(R - R0)/(2πL):
    R = a·R0/(a - p) with a = E·t/R0 + K/(2πL).
    """
    params = RootParameters()
    p, L = 80 * MMHG_TO_KPA, 12.0
    R0 = 10.0 / 1.15
    Et = params.youngs_modulus * params.wall_thickness
    free = distend_root(params, 20.0, L, p)
    assert free.zero_pressure_diameter == pytest.approx(20.0 / 1.15, rel=1e-12)
    assert free.radius == pytest.approx(Et / (Et / R0 - p), rel=1e-9)
    K = 50.0
    pulled = distend_root(params, 20.0, L, p, lambda R: 0.5 * K * max(R - R0, 0.0) ** 2)
    a = Et / R0 + K / (2 * math.pi * L)
    assert pulled.radius == pytest.approx(a * R0 / (a - p), rel=1e-6)
    assert pulled.radius < free.radius


def test_reference_closes_and_seals(reference):
    result, out = reference
    assert result.converged, result.solver_message
    # symmetric reference: the leaflet and its two mirror images
    central = result.leaflets["left_coronary"]["central_height_mm"]
    assert 2.5 <= central <= 4.5
    assert result.central_coaptation_height_mm == pytest.approx(central, abs=0.1)
    assert result.regurgitant_orifice_area_mm2 == 0.0
    assert result.competent
    assert result.max_penetration_mm < 0.05
    assert result.min_coaptation_height_mm <= central + 1e-12


def test_reference_writes_every_output(reference):
    result, out = reference
    data = json.loads((out / "result.json").read_text())
    for key in RESULT_FIELDS:
        assert key in data, key
    assert data["converged"] is True
    assert data["parameters"]["symmetric_reference"] is True
    assert CaseConfig.from_dict(json.loads((out / "config.json").read_text())) \
        .symmetric_reference
    for name in ("closed_valve_ventricular.png", "closed_valve.png", "cut_planes.png",
                 "fields.xdmf", "fields.h5", "history.csv", "loaded_state.npz"):
        assert (out / name).stat().st_size > 0, name


def test_equilibrium_independent_of_mass_and_damping(reference):
    """Damping ×4 (τ ×4) and mass ×4 (ρ = c·mass_ratio·τ: mass_ratio ÷ 4)."""
    base = DynamicsParameters()
    result, _ = reference
    heavy = _reference(relaxation_time=4 * base.relaxation_time,
                       mass_ratio=base.mass_ratio / 4)
    assert heavy.converged, heavy.solver_message
    assert heavy.central_coaptation_height_mm == pytest.approx(
        result.central_coaptation_height_mm, abs=0.02)


def test_relaxation_stops_at_the_dynamics_equilibrium(reference):
    """Explicit dynamic relaxation (stiffness-scaled nodal masses, no damping, full pressure
    at once) and the BDF2 damped dynamics (ramped pressure, tissue-scaled mass and damping)
    take different paths with different numerical masses: they must stop at the same static
    equilibrium (SPEC §4), at the default mesh."""
    result, _ = reference
    relaxed = _reference(solver="relaxation")
    assert relaxed.converged, relaxed.solver_message
    assert "relaxation" in relaxed.solver_message
    assert relaxed.central_coaptation_height_mm == pytest.approx(
        result.central_coaptation_height_mm, abs=0.02)
    assert relaxed.regurgitant_orifice_area_mm2 == 0.0
    assert relaxed.max_penetration_mm < 0.05


@pytest.mark.parametrize("handover_time_s, why", [(0.0, None), (1.0, "(t ≥ 1 s")])
def test_dynamics_handing_over_to_relaxation_stops_at_the_same_equilibrium(
        reference, handover_time_s, why):
    """``solver="dynamics+relaxation"``: BDF2 closes the leaflet until a step moves the
    watched nodes less than 1e-2 mm or t = 10 s (or, with ``handover_time_s`` = 1 s, right
    at the end of the 1 s ramp), the explicit relaxation settles it from there; the
    equilibrium is the BDF2 reference's (default mesh)."""
    result, _ = reference
    hybrid = _reference(solver="dynamics+relaxation", handover_time_s=handover_time_s)
    assert hybrid.converged, hybrid.solver_message
    assert "handed over" in hybrid.solver_message and "relaxation" in hybrid.solver_message
    if why is not None:  # the default hands over on the increment or at t = 10 s
        assert why in hybrid.solver_message
    assert hybrid.central_coaptation_height_mm == pytest.approx(
        result.central_coaptation_height_mm, abs=0.02)
    assert hybrid.regurgitant_orifice_area_mm2 == 0.0
    assert hybrid.max_penetration_mm < 0.05


def test_two_runs_of_the_dynamics_are_bit_for_bit_equal():
    """A sizing study must give the same number twice: 60 BDF2 steps of the reference
    (1.0 mm), run twice in one process, end in identical positions.  With PETSc's default
    classical Gram-Schmidt in GMRES they differed by ~1e-11 mm (docs/closure.md,
    "Session 8"), which the graft valves' relaxation amplified into different results."""
    from valve_dolfinx.closure import solve_case

    config = CaseConfig(symmetric_reference=True, geometry=ValveParameters(mesh_size=1.0),
                        solver="dynamics", dynamics=DynamicsParameters(max_steps=60))
    first, second = (solve_case(config, MPI.COMM_SELF, None) for _ in range(2))
    assert first.report.steps >= 50 and first.report.history[-1]["contacts"] > 0
    assert (first.positions == second.positions).all()


def test_failed_solve_is_reported_and_written(tmp_path):
    """A wall-clock limit that cannot be met: converged false, where it stopped, outputs."""
    config = CaseConfig(symmetric_reference=True,
                        dynamics=DynamicsParameters(wall_time_limit_s=0.5))
    result = run_case(config, tmp_path, comm=MPI.COMM_SELF, figures=False)
    assert not result.converged
    assert "wall" in result.solver_message
    assert "t =" in result.solver_message
    data = json.loads((tmp_path / "result.json").read_text())
    assert data["converged"] is False
    assert not data["competent"]


def test_bad_configuration_names_the_parameter():
    with pytest.raises(ParameterError, match="pressure_mmhg"):
        CaseConfig(pressure_mmhg=-80.0)
    with pytest.raises(ParameterError, match="wall_time_limit_s"):
        DynamicsParameters(wall_time_limit_s=0.0)
    with pytest.raises(ParameterError, match="symmetric_reference"):
        CaseConfig(symmetric_reference=True).with_graft(21.0, 27.0)
    with pytest.raises(ParameterError, match="bending_modulus_kpa"):
        CaseConfig(bending_modulus_kpa=-1.0)
    with pytest.raises(ParameterError, match="solver"):
        CaseConfig(solver="newton")


@pytest.fixture(scope="module")
def parallel_reference():
    """The symmetric reference at 1.0 mm solved by all ranks together (under mpirun)."""
    if MPI.COMM_WORLD.size < 2:
        pytest.skip("needs mpirun -n 2")
    return _reference(comm=MPI.COMM_WORLD, mesh_size=1.0)


@pytest.mark.mpi
def test_reference_parallel_equals_serial(parallel_reference):
    """Every rank first solves the case alone (COMM_SELF), then all ranks solve it together."""
    comm = MPI.COMM_WORLD
    serial = _reference(comm=MPI.COMM_SELF, mesh_size=1.0)
    comm.barrier()
    parallel = parallel_reference
    assert serial.converged and parallel.converged
    assert parallel.n_ranks == comm.size
    assert parallel.central_coaptation_height_mm == pytest.approx(
        serial.central_coaptation_height_mm, abs=0.02)
    assert 2.5 <= serial.central_coaptation_height_mm <= 4.5


@pytest.mark.mpi
def test_relaxation_in_parallel_matches_the_parallel_dynamics(parallel_reference):
    """Dynamic relaxation with the valve split across ranks (its power, norms and step
    limits are global reductions) stops at the equilibrium of the parallel dynamics."""
    relaxed = _reference(comm=MPI.COMM_WORLD, mesh_size=1.0, solver="relaxation")
    assert relaxed.converged, relaxed.solver_message
    assert relaxed.n_ranks == MPI.COMM_WORLD.size
    assert relaxed.central_coaptation_height_mm == pytest.approx(
        parallel_reference.central_coaptation_height_mm, abs=0.02)


#: Cases of the issue at the default mesh, and the rank (under ``mpirun -n 2``) that solves
#: each alone: about 4, 1, 5 and 7 minutes (docs/closure.md, "Session 7" and "Session 9";
#: W21/H27 converges through the relaxation's Newton finish).  A case that stalls stops at
#: 20 minutes (converged: false) instead of holding up CI.
_CAPPED = DynamicsParameters(wall_time_limit_s=1200.0)
DEFAULT_MESH_CASES = {
    "normal": (0, CaseConfig(dynamics=_CAPPED)),
    "reference": (1, CaseConfig(dynamics=_CAPPED, symmetric_reference=True)),
    "W0/H0": (0, CaseConfig(dynamics=_CAPPED).with_graft(0.0, 0.0)),
    "W21/H27": (1, CaseConfig(dynamics=_CAPPED).with_graft(21.0, 27.0)),
}


@pytest.fixture(scope="module")
def default_mesh_cases():
    """Every rank solves its share of :data:`DEFAULT_MESH_CASES` on its own (COMM_SELF, the
    default solver and mesh); all ranks then hold all results."""
    comm = MPI.COMM_WORLD
    if comm.size != 2:
        pytest.skip("needs mpirun -n 2")
    mine = {name: run_case(config, comm=MPI.COMM_SELF, figures=False, fields_output=False)
            for name, (rank, config) in DEFAULT_MESH_CASES.items() if rank == comm.rank}
    return {name: result for part in comm.allgather(mine) for name, result in part.items()}


@pytest.mark.mpi
def test_normal_valve_at_the_default_mesh(default_mesh_cases):
    """Issue 5: converged, central heights in 2.5-4.5 mm (clinical 3-4 mm), the three
    leaflets within 0.1 mm of each other, sealed (orifice 0), penetration below 0.05 mm."""
    full = default_mesh_cases["normal"]
    assert full.converged, full.solver_message
    assert full.mesh_size_mm == ValveParameters().mesh_size
    heights = [leaflet["central_height_mm"] for leaflet in full.leaflets.values()]
    assert len(heights) == 3
    assert all(2.5 <= h <= 4.5 for h in heights), heights
    assert max(heights) - min(heights) < 0.1, heights  # symmetry
    assert full.regurgitant_orifice_area_mm2 == 0.0
    assert full.competent
    assert full.max_penetration_mm < 0.05


@pytest.mark.mpi
def test_full_valve_matches_the_symmetric_reference(default_mesh_cases):
    """SPEC §4: three leaflets closing on each other against one leaflet closing on the two
    symmetry planes (leaflet-leaflet contact checked against plane contact), default mesh."""
    full, reference = default_mesh_cases["normal"], default_mesh_cases["reference"]
    assert full.converged and reference.converged, reference.solver_message
    for leaflet in full.leaflets.values():
        assert leaflet["central_height_mm"] == pytest.approx(
            reference.central_coaptation_height_mm, abs=0.1)


@pytest.mark.mpi
@pytest.mark.parametrize("case", ["W0/H0", "W21/H27"])
def test_graft_valves_converge_at_the_default_mesh(default_mesh_cases, case):
    """Issue 5: the stiff pericardial graft valves run through the same path and converge
    without interpenetration; their numbers are reported, not checked against a value."""
    result = default_mesh_cases[case]
    assert result.converged, result.solver_message
    assert result.max_penetration_mm < 0.05
    assert result.graft_width_pct == float(case[1:case.index("/")])
    graft = [leaflet for leaflet in result.leaflets.values() if leaflet.get("is_graft")]
    assert len(graft) == 1
    assert math.isfinite(result.central_coaptation_height_mm)
    assert result.regurgitant_orifice_area_mm2 >= 0.0


def test_with_graft_keeps_the_rest():
    config = replace(CaseConfig(), pressure_mmhg=90.0).with_graft(21.0, 27.0)
    assert config.geometry.graft_width_pct == 21.0
    assert config.pressure_mmhg == 90.0


def test_cli_run_resumes_a_finished_case(reference, capsys):
    """``valve-dolfinx run`` on a directory that holds the same case does not recompute it."""
    from valve_dolfinx.cli import main

    result, out = reference
    before = (out / "result.json").stat().st_mtime_ns
    assert main(["run", "--symmetric-reference", "--solver", "dynamics", "--out", str(out)]) == 0
    assert "already holds this case" in capsys.readouterr().out
    assert (out / "result.json").stat().st_mtime_ns == before


def test_cli_run_rejects_half_a_graft(capsys):
    from valve_dolfinx.cli import main

    with pytest.raises(SystemExit) as exit_:
        main(["run", "--out", "unused", "--graft-width", "21"])
    assert exit_.value.code == 2
    assert "--graft-height" in capsys.readouterr().err
