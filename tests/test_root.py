"""The aortic root step (SPEC §2).

Expected numbers are worked out here by hand, not by the code under test:

* free tube, Laplace + Hooke: p·R = E·t·(R − R₀)/R₀  ⇒  R = R₀/(1 − p·R₀/(E·t));
* a leaflet energy ½K(R − R_w)² beyond the wrap radius R_w adds the line load
  k·(R − R_w), k = K/(2πL), and the balance stays linear in R:
  R = (E·t + k·R_w)/(E·t/R₀ + k − p);
* the default wall data come from the cited pressure-strain modulus
  E_p = 68.4 kPa and thickness 1.5 mm by E = R₀·(E_p + p)/t = 458.35 kPa; the tube
  must then show that E_p at 80 mmHg;
* with the real leaflets the root lands at the 20 mm wrap diameter within 0.2 mm.
"""

from __future__ import annotations

import math

import pytest

from valve_dolfinx._compat import MPI
from valve_dolfinx.exceptions import ParameterError, SolverError
from valve_dolfinx.mechanics.root import RootParameters, distend_root

#: 80 mmHg in kPa, spelled out (1 mmHg = 0.133322 kPa)
P80 = 80 * 0.133322
WRAP_D = 20.0
R_WRAP = 10.0
R0 = 10.0 / 1.15  # 8.6957 mm: the free edges are 15 % longer than the unpressurised circumference
L = 12.41  # mm, leaflet height (nadir to commissure top)


def quadratic_leaflets(K: float):
    """Π_leaf(R) = ½K(R − R_w)² beyond the wrap radius, 0 below (slack leaflets)."""
    return lambda R: 0.5 * K * max(R - R_WRAP, 0.0) ** 2


@pytest.mark.parametrize("E, t", [(458.0, 1.5), (2000.0, 1.6), (300.0, 2.0)])
def test_free_tube_matches_laplace(E, t):
    state = distend_root(RootParameters(youngs_modulus=E, wall_thickness=t), WRAP_D, L, P80)
    R = R0 / (1.0 - P80 * R0 / (E * t))
    assert state.zero_pressure_diameter == pytest.approx(20.0 / 1.15, rel=1e-12)
    assert state.radius == pytest.approx(R, rel=1e-12)
    assert state.hoop_strain == pytest.approx(R / R0 - 1.0, rel=1e-12)
    assert state.leaflet_line_load == 0.0
    assert not state.prescribed


def test_default_free_tube_goes_beyond_the_wrap_diameter():
    """Without the leaflets the default wall would carry the root past 20 mm (to 20.10 mm),
    so the leaflets' pull is a term of the balance, not an idle constraint."""
    Et = 458.0 * 1.5
    free = distend_root(RootParameters(), WRAP_D, L, P80)
    assert free.diameter == pytest.approx(2 * R0 / (1.0 - P80 * R0 / Et), rel=1e-12)
    assert 20.05 < free.diameter < 20.2


def test_default_wall_data_from_the_cited_pressure_strain_modulus():
    """E·t/R₀ = E_p + p with E_p = 68.4 kPa (Martin et al. 2013), t = 1.5 mm (Mensel et al.
    2014): E = 8.69565 × 79.0658 / 1.5 = 458.35 kPa; the tube then has E_p = R·dp/dR."""
    params = RootParameters()
    assert params.wall_thickness == 1.5
    assert params.youngs_modulus == pytest.approx(458.35, abs=0.5)
    dp = 1e-3
    lo = distend_root(params, WRAP_D, L, P80 - dp)
    hi = distend_root(params, WRAP_D, L, P80 + dp)
    mid = distend_root(params, WRAP_D, L, P80)
    pressure_strain = mid.radius * 2 * dp / (hi.radius - lo.radius)
    assert pressure_strain == pytest.approx(68.4, abs=0.5)


@pytest.mark.parametrize("E, t, K", [(300.0, 1.5, 2000.0), (458.0, 1.5, 500.0),
                                     (250.0, 1.0, 5000.0)])
def test_quadratic_leaflet_energy_beyond_wrap_matches_closed_form(E, t, K):
    Et = E * t
    k = K / (2 * math.pi * L)
    R_free = R0 / (1.0 - P80 * R0 / Et)
    assert R_free > R_WRAP  # the wall alone would stretch the leaflets
    R = (Et + k * R_WRAP) / (Et / R0 + k - P80)
    assert R_WRAP < R < R_free

    params = RootParameters(youngs_modulus=E, wall_thickness=t)
    pulled = distend_root(params, WRAP_D, L, P80, quadratic_leaflets(K))
    assert pulled.radius == pytest.approx(R, rel=1e-8)
    assert pulled.leaflet_line_load == pytest.approx(k * (R - R_WRAP), rel=1e-6)
    # the three terms of the balance: pressure = wall + leaflets
    assert P80 * pulled.radius == pytest.approx(
        Et * (pulled.radius - R0) / R0 + pulled.leaflet_line_load, rel=1e-8)


def test_slack_leaflets_leave_a_stiff_wall_alone():
    """A wall that stays below the wrap diameter (E = 2 MPa, t = 1.6 mm: 17.9 mm) never
    stretches the leaflets: their energy adds nothing."""
    params = RootParameters(youngs_modulus=2000.0, wall_thickness=1.6)
    free = distend_root(params, WRAP_D, L, P80)
    with_leaflets = distend_root(params, WRAP_D, L, P80, quadratic_leaflets(5000.0))
    assert free.diameter == pytest.approx(2 * R0 / (1.0 - P80 * R0 / 3200.0), rel=1e-12)
    assert free.diameter < 18.0
    assert with_leaflets.diameter == pytest.approx(free.diameter, rel=1e-9)
    assert with_leaflets.leaflet_line_load == 0.0


@pytest.mark.parametrize("d", [18.0, 20.0, 21.0])
def test_prescribed_loaded_diameter(d):
    K = 2000.0
    # a wall far too soft to hold the pressure: the prescribed diameter does not use it
    params = RootParameters(youngs_modulus=5.0, wall_thickness=1.0, loaded_diameter=d)
    state = distend_root(params, WRAP_D, L, P80, quadratic_leaflets(K))
    assert state.prescribed
    assert state.diameter == d
    assert state.zero_pressure_diameter == pytest.approx(20.0 / 1.15, rel=1e-12)
    assert state.hoop_strain == pytest.approx(d / (20.0 / 1.15) - 1.0, rel=1e-12)
    pull = K * max(0.5 * d - R_WRAP, 0.0) / (2 * math.pi * L)
    # (at d = 20 mm the central difference straddles the C¹ kink of Π_leaf at R_w)
    assert state.leaflet_line_load == pytest.approx(pull, rel=1e-6, abs=1e-2)
    assert state.to_dict()["diameter"] == d


@pytest.mark.parametrize("value", [5.0, 9.99, 40.5, -20.0, float("nan"), float("inf"), "wide"])
def test_bad_loaded_diameter_is_named(value):
    with pytest.raises(ParameterError, match=r"root\.loaded_diameter") as err:
        RootParameters(loaded_diameter=value)
    if not isinstance(value, str):
        assert "[10, 40] mm" in str(err.value)


@pytest.mark.parametrize("field, value", [("youngs_modulus", 0.0), ("wall_thickness", -1.0),
                                          ("free_edge_excess", 2.0)])
def test_bad_wall_data_are_named(field, value):
    with pytest.raises(ParameterError, match=rf"root\.{field}"):
        RootParameters(**{field: value})


def test_wall_that_cannot_hold_the_pressure_says_what_to_change():
    """p·R₀ ≥ E·t: the free tube has no equilibrium (10.67 × 8.70 = 92.7 > 50 × 1.5)."""
    with pytest.raises(SolverError, match=r"root\.youngs_modulus.*root\.loaded_diameter"):
        distend_root(RootParameters(youngs_modulus=50.0), WRAP_D, L, P80)


def test_config_round_trip_keeps_the_loaded_diameter():
    from valve_dolfinx.config import CaseConfig

    config = CaseConfig(root=RootParameters(loaded_diameter=19.0))
    again = CaseConfig.from_dict(config.to_dict())
    assert again.root == config.root
    assert again.root.loaded_diameter == 19.0


def test_default_wall_with_the_real_leaflets_reaches_the_wrap_diameter():
    """The leaflets' membrane energy on the cylinder of radius R (coarse valve, as
    ``solve_case`` builds it): the default root lands at 20 mm within 0.2 mm, pulled back
    from the free tube by leaflets stretched beyond the wrap diameter."""
    from valve_dolfinx.case import _leaflet_energy_on_cylinder, closure_model
    from valve_dolfinx.config import CaseConfig
    from valve_dolfinx.geometry.distributed import create_valve_domain
    from valve_dolfinx.geometry.valve import ValveParameters, build_valve

    comm = MPI.COMM_WORLD
    config = CaseConfig(geometry=ValveParameters(mesh_size=1.2))
    valve = build_valve(config.geometry) if comm.rank == 0 else None
    domain = create_valve_domain(valve, comm)
    model = closure_model(domain, config)
    shape = domain.valve.leaflets[0].shape
    assert shape.root_diameter == pytest.approx(WRAP_D)
    energy = _leaflet_energy_on_cylinder(model, 0.5 * shape.root_diameter)
    assert abs(energy(0.99 * R_WRAP)) < 1e-3  # slack below the wrap radius
    assert energy(1.02 * R_WRAP) > 1.0  # stretched beyond it

    root = distend_root(config.root, shape.root_diameter, shape.height, P80, energy)
    free = distend_root(config.root, shape.root_diameter, shape.height, P80)
    assert root.diameter == pytest.approx(20.0, abs=0.2)
    assert WRAP_D < root.diameter < free.diameter
    assert root.leaflet_line_load > 0.1  # mN/mm
    Et = config.root.youngs_modulus * config.root.wall_thickness
    assert P80 * root.radius == pytest.approx(
        Et * (root.radius - R0) / R0 + root.leaflet_line_load, rel=1e-6)


def test_cli_root_diameter_reaches_the_case_config(tmp_path, monkeypatch):
    """``valve-dolfinx run --root-diameter D`` runs the case with
    RootParameters(loaded_diameter=D); the configuration is captured as the case starts."""
    import valve_dolfinx.case as case
    from valve_dolfinx.cli import main

    class Captured(BaseException):  # main turns every Exception into an exit status
        pass

    def capture(config, *args, **kwargs):
        raise Captured(config)

    monkeypatch.setattr(case, "run_case", capture)
    with pytest.raises(Captured) as caught:
        main(["run", "--out", str(tmp_path / "case"), "--root-diameter", "21.5"])
    assert caught.value.args[0].root == RootParameters(loaded_diameter=21.5)
    with pytest.raises(Captured) as caught:
        main(["run", "--out", str(tmp_path / "case")])
    assert caught.value.args[0].root == RootParameters()
