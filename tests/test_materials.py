"""Tissue law: UFL stresses against hand-differentiated closed forms (SPEC §3, §8).

The closed forms below are written out in this file, independently of the
package: ∂Q/∂E11 = 2(A1 E11 + A3 E22 + A5 E12), ∂Q/∂E22 = 2(A2 E22 + A3 E11 + A6 E12),
∂Q/∂E12 = 2(A4 E12 + A5 E11 + A6 E22); S = c/2·e^Q·∂Q/∂E, the tensor shear
S12 = ½·∂W/∂E12.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from valve_dolfinx._compat import MPI, dolfinx
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.geometry.verification import flat_sheet_domain
from valve_dolfinx.materials import (
    BOVINE_PERICARDIUM,
    NATIVE_LEAFLET,
    FungMaterial,
    equibiaxial_response,
    preset,
)
from valve_dolfinx.mechanics.membrane import MembraneModel

SPEC_TABLE = {  # SPEC §3: c, A1..A6
    "native_leaflet": (9.7, 49.56, 5.29, -3.12, 16.03, -0.004, -0.02),
    "bovine_pericardium": (3056, 25.46, 12.10, 5.07, 25.99, 0, 0),
}


def fung_stress(p, E11, E22, E12):
    c, A1, A2, A3, A4, A5, A6 = p
    Q = A1 * E11**2 + A2 * E22**2 + 2 * A3 * E11 * E22 + A4 * E12**2 + 2 * A5 * E11 * E12 \
        + 2 * A6 * E22 * E12
    g = 0.5 * c * math.exp(Q)
    return np.array([g * 2 * (A1 * E11 + A3 * E22 + A5 * E12),
                     g * 2 * (A2 * E22 + A3 * E11 + A6 * E12),
                     0.5 * g * 2 * (A4 * E12 + A5 * E11 + A6 * E22)])


def rotation(phi):
    return np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])


def test_presets_match_spec_table():
    for name, values in SPEC_TABLE.items():
        m = preset(name)
        assert (m.c, m.A1, m.A2, m.A3, m.A4, m.A5, m.A6) == pytest.approx(values, rel=1e-15)
    with pytest.raises(ParameterError, match="presets"):
        preset("gore-tex")


def test_spec_worked_numbers_equal_pk2():
    """SPEC §3: equal S11 = S22 = 10.67 kPa → E = (0.0301, 0.1884); 60 kPa → (0.0703, 0.4401)."""
    for stress, e11, e22 in ((10.67, 0.0301, 0.1884), (60.0, 0.0703, 0.4401)):
        s = fung_stress(SPEC_TABLE["native_leaflet"], e11, e22, 0.0)
        assert s[:2] == pytest.approx([stress, stress], rel=5e-3)
    curve = equibiaxial_response(NATIVE_LEAFLET, 60.0, n=60, measure="second_pk")
    assert curve["E11"][-1] == pytest.approx(0.0703, abs=2e-4)
    assert curve["E22"][-1] == pytest.approx(0.4401, abs=2e-4)
    peri = equibiaxial_response(BOVINE_PERICARDIUM, 60.0, n=20, measure="second_pk")
    assert peri["E11"][-1] == pytest.approx(0.0005, abs=1e-4)
    assert peri["E22"][-1] == pytest.approx(0.0014, abs=1e-4)


def test_equibiaxial_first_pk_curve_is_consistent():
    """Lagrangian stress P = λ·S equals the level at every point of the curve."""
    for m in (NATIVE_LEAFLET, BOVINE_PERICARDIUM):
        c = equibiaxial_response(m, 60.0, n=30)
        p = np.array([m.c, m.A1, m.A2, m.A3, m.A4, m.A5, m.A6])
        for level, e11, e22 in zip(c["stress"][1:], c["E11"][1:], c["E22"][1:], strict=True):
            s = fung_stress(p, e11, e22, 0.0)
            lam = np.sqrt(1 + 2 * np.array([e11, e22]))
            assert lam * s[:2] == pytest.approx([level, level], rel=1e-9)


def test_invalid_material_rejected():
    with pytest.raises(ParameterError, match="c"):
        FungMaterial(c=-1.0, A1=1, A2=1, A3=0, A4=1)
    with pytest.raises(ParameterError, match="positive definite"):
        FungMaterial(c=1.0, A1=1, A2=1, A3=5, A4=1)
    with pytest.raises(ParameterError, match="thickness"):
        replace(NATIVE_LEAFLET, thickness=0.0)


# --- UFL stress on a homogeneous deformation --------------------------------------------
def _single_cell_model(material, fibre_angle, wrinkling):
    domain = flat_sheet_domain(1.0, 1.0, 1, 1, fibre_angle_deg=fibre_angle,
                               comm=MPI.COMM_SELF)
    return MembraneModel(domain, {1: material}, wrinkling=wrinkling)


def _impose_strain(model, E_chart):
    """u = (F - I)X with F = [U; 0], U = sqrt(I + 2E): a homogeneous in-plane deformation."""
    w, v = np.linalg.eigh(np.eye(2) + 2 * E_chart)
    U = v @ np.diag(np.sqrt(w)) @ v.T
    F3 = np.zeros((3, 3))
    F3[:2, :2] = U
    F3[2, 2] = 1.0
    model.u.interpolate(lambda X: (F3 - np.eye(3)) @ X)


def _ufl_stress(model, material):
    expr = dolfinx.fem.Expression(model.stress(1), np.array([[1 / 3, 1 / 3]]))
    return expr.eval(model.domain.mesh, np.array([0], dtype=np.int32)).reshape(2, 2)


@pytest.mark.parametrize("name", ["native_leaflet", "bovine_pericardium"])
@pytest.mark.parametrize("angle", [0.0, 30.0, -75.0])
def test_ufl_stress_matches_closed_form(name, angle):
    material = preset(name)
    p = SPEC_TABLE[name]
    model = _single_cell_model(material, angle, wrinkling=False)
    rng = np.random.default_rng(7)
    scale = 0.2 if name == "native_leaflet" else 0.02
    R = rotation(math.radians(angle))
    for _ in range(4):
        Em = np.diag(rng.uniform(0.0, scale, 2))
        Em[0, 1] = Em[1, 0] = rng.uniform(-0.5, 0.5) * scale
        _impose_strain(model, R @ Em @ R.T)  # strain given in the material axes
        s = _ufl_stress(model, material)
        exact = fung_stress(p, Em[0, 0], Em[1, 1], Em[0, 1])
        got = np.array([s[0, 0], s[1, 1], s[0, 1]])
        assert np.allclose(got, exact, rtol=1e-10, atol=1e-10 * np.abs(exact).max())
        assert s[0, 1] == pytest.approx(s[1, 0], rel=1e-12)


def _principal_state(material, lam1, lam2, phi, wrinkling=True):
    """UFL stress (material axes) for principal strains (λ1, λ2), n1 at angle φ to the fibre."""
    model = _single_cell_model(material, 0.0, wrinkling)
    R = rotation(phi)
    _impose_strain(model, R @ np.diag([lam1, lam2]) @ R.T)
    return _ufl_stress(model, material), R


def test_slack_membrane_carries_no_stress():
    for material in (NATIVE_LEAFLET, BOVINE_PERICARDIUM):
        s, _ = _principal_state(material, -0.01, -0.05, 0.4)
        assert np.all(s == 0.0)


@pytest.mark.parametrize("phi", [0.0, 0.5, 1.2])
def test_wrinkled_state_frees_the_compressive_direction(phi):
    """Uniaxial tension with compressed cross direction: no stress along n2, exact n1 stress."""
    m = NATIVE_LEAFLET
    lam1 = 0.08
    s, R = _principal_state(m, lam1, -0.2, phi)  # well inside the wrinkled range
    n1, n2 = R[:, 0], R[:, 1]
    assert abs(n2 @ s @ n2) < 1e-10 * np.abs(s).max()
    # exact wrinkled state: E* = λ1 n1n1 + λ2* n2n2 with n2·S(E*)·n2 = 0, worked out here by
    # a 1-D root find on the closed-form stress
    from scipy.optimize import brentq

    p = SPEC_TABLE["native_leaflet"]

    def n2_stress(l2):
        E = lam1 * np.outer(n1, n1) + l2 * np.outer(n2, n2)
        S = fung_stress(p, E[0, 0], E[1, 1], E[0, 1])
        Sm = np.array([[S[0], S[2]], [S[2], S[1]]])
        return n2 @ Sm @ n2

    l2 = brentq(n2_stress, -1.0, 1.0, xtol=1e-15)
    E = lam1 * np.outer(n1, n1) + l2 * np.outer(n2, n2)
    S = fung_stress(p, E[0, 0], E[1, 1], E[0, 1])
    assert n1 @ s @ n1 == pytest.approx(n1 @ np.array([[S[0], S[2]], [S[2], S[1]]]) @ n1,
                                        rel=1e-9)


def test_relaxation_is_stress_continuous_at_wrinkling_onset():
    """At the switch n2·S·n2 = 0 the taut and wrinkled stresses agree (C¹ energy)."""
    m = BOVINE_PERICARDIUM
    lam1 = 1e-3
    lam2_star = -m.A3 / m.A2 * lam1  # fibre along n1: n2·S·n2 ∝ A3·λ1 + A2·λ2
    below, _ = _principal_state(m, lam1, lam2_star - 1e-9, 0.0)
    above, _ = _principal_state(m, lam1, lam2_star + 1e-9, 0.0)
    assert np.allclose(below, above, atol=1e-5 * np.abs(above).max())
    taut, _ = _principal_state(m, lam1, 5e-4, 0.0)
    plain, _ = _principal_state(m, lam1, 5e-4, 0.0, wrinkling=False)
    assert np.allclose(taut, plain, rtol=1e-12)
