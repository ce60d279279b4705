"""Large-deformation Fung membranes on a manifold mesh: energy, pressure load, forms.

The membrane has no bending stiffness.  Its potential energy is

    Π(u) = Σ_regions ∫ t · W(E(u)) dA_ref

(t the thickness, W the tension-field relaxed Fung energy of
:mod:`valve_dolfinx.materials`), and the diastolic pressure is a *follower*
load acting on the current surface along its current normal:

    δW_p = ∫ s·p · (F₁ × F₂) · δu dA_ref

(s = ±1 chooses the side the pressure acts on).  The residual is
``R = δΠ − δW_p``; the Jacobian is its Gateaux derivative, taken by UFL --
including the non-symmetric load stiffness of the follower pressure.

Quadrature: on P1 triangles F and therefore W are constant per cell and the
pressure integrand is linear, so one-point quadrature integrates everything
exactly; UFL's automatic estimate for ``exp(Q)`` would be far higher (SPEC §4:
85× slower solves).  ``quadrature_degree`` is a parameter (default 1); a test
checks the degree-1 energy and pressure work against their closed-form integrals.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import ufl

from valve_dolfinx._compat import dolfinx
from valve_dolfinx.exceptions import ParameterError
from valve_dolfinx.geometry.domain import MembraneDomain
from valve_dolfinx.materials import FungMaterial, fung_energy, relaxed_energy
from valve_dolfinx.mechanics.kinematics import (
    area_vector,
    deformation_gradient,
    green_lagrange,
    reference_area_factor,
    to_material_axes,
)

__all__ = ["MembraneModel"]

log = logging.getLogger(__name__)

fem = dolfinx.fem


@dataclass
class MembraneModel:
    """UFL forms of a Fung membrane under follower pressure.

    Parameters
    ----------
    domain
        Mesh, cell tags, reference charts and fibres.
    materials
        Material of each cell tag.
    pressure_side
        +1: the pressure pushes the membrane along the chart normal F₁×F₂
        (inflation of a closed surface whose charts point outwards); −1: against
        it (the valve, whose chart normals point to the aortic side).
    quadrature_degree
        Quadrature degree of every integral (1 is exact on P1 triangles).
    wrinkling
        Use the tension-field relaxed energy (no compression): for every region, or
        ``{tag: bool}`` per region (a region left out is relaxed); False gives the plain
        Fung law, which resists compression.
    """

    domain: MembraneDomain
    materials: Mapping[int, FungMaterial]
    pressure_side: float = 1.0
    quadrature_degree: int = 1
    wrinkling: bool | Mapping[int, bool] = True
    V: fem.FunctionSpace = field(init=False)
    u: fem.Function = field(init=False)
    pressure: fem.Constant = field(init=False)

    def __post_init__(self) -> None:
        mesh = self.domain.mesh
        missing = set(int(t) for t in self.domain.tags()) - set(self.materials)
        if missing:
            raise ParameterError(f"materials: no material given for cell tag(s) {sorted(missing)}; "
                                 f"pass a FungMaterial for every region")
        if self.pressure_side not in (1.0, -1.0, 1, -1):
            raise ParameterError("pressure_side must be +1 or -1")
        if self.quadrature_degree not in (1, 2, 3, 4):
            raise ParameterError(f"quadrature_degree = {self.quadrature_degree}: use 1 (exact for "
                                 "P1 membranes) to 4")
        self.V = fem.functionspace(mesh, ("Lagrange", 1, (mesh.geometry.dim,)))
        self.u = fem.Function(self.V, name="displacement")
        self.pressure = fem.Constant(mesh, dolfinx.default_scalar_type(0.0))
        self.dx = ufl.Measure("dx", domain=mesh, subdomain_data=self.domain.cell_tags,
                              metadata={"quadrature_degree": self.quadrature_degree})
        relaxed = self.wrinkling
        self._relaxed = ({tag: bool(relaxed.get(tag, True)) for tag in self.materials}
                         if isinstance(relaxed, Mapping)
                         else dict.fromkeys(self.materials, bool(relaxed)))

    # --- kinematics ---------------------------------------------------------
    def deformation_gradient(self, u=None):
        return deformation_gradient(self.u if u is None else u, self.domain.reference)

    def strain(self, u=None):
        """Green–Lagrange strain in the material axes (E11 along the fibre)."""
        return to_material_axes(green_lagrange(self.deformation_gradient(u)), self.domain.fibre)

    def area_factor(self):
        return reference_area_factor(self.domain.reference)

    # --- energy and forms -----------------------------------------------------
    def _energy(self, tag: int, E):
        """W(E) of region ``tag``: tension-field relaxed, or the plain Fung law."""
        material = self.materials[tag]
        return relaxed_energy(material, E) if self._relaxed[tag] else fung_energy(material, E)

    def energy_density(self, tag: int, u=None):
        """t·W per reference area of region ``tag``."""
        return self.materials[tag].thickness * self._energy(tag, self.strain(u))

    def strain_energy(self, u=None):
        """Π = Σ ∫ t·W dA_ref (UFL form of rank 0)."""
        dA = self.area_factor()
        return sum(self.energy_density(tag, u) * dA * self.dx(tag) for tag in self.materials)

    def pressure_work(self, v, u=None):
        """Virtual work of the follower pressure: ∫ s·p (F₁×F₂)·v dA_ref."""
        n_da = area_vector(self.deformation_gradient(u))
        return (self.pressure_side * self.pressure * ufl.dot(n_da, v) * self.area_factor()
                * self.dx)

    def internal_work(self, w, u=None):
        """Internal virtual work δΠ = Σ ∫ t·S : δE dA_ref for a virtual displacement w.

        ``S = ∂W/∂E`` (material axes) is taken by UFL from the relaxed energy and
        ``δE = Rᵀ sym(Fᵀ ∇w J0) R``; identical to the Gateaux derivative of
        :meth:`strain_energy`, but written so that ``u`` and ``w`` may be any UFL
        expressions (e.g. components of a mixed displacement–velocity state).
        """
        dE = to_material_axes(self.strain_variation(w, u), self.domain.fibre)
        dA = self.area_factor()
        return sum(material.thickness * ufl.inner(self.stress(tag, u), dE) * dA
                   * self.dx(tag) for tag, material in self.materials.items())

    def strain_variation(self, w, u=None):
        """``sym(Fᵀ ∇w J0)`` in the (orthonormal) chart axes: the Green–Lagrange strain's
        variation for a virtual displacement w, or its rate for a velocity w."""
        F = self.deformation_gradient(u)
        dF = ufl.grad(w) * self.domain.reference
        return 0.5 * (F.T * dF + dF.T * F)

    def residual(self, v=None, u=None):
        """R(u; v) = δΠ − δW_p."""
        v = ufl.TestFunction(self.V) if v is None else v
        return self.internal_work(v, u) - self.pressure_work(v, u)

    def jacobian(self, residual=None):
        residual = self.residual() if residual is None else residual
        return ufl.derivative(residual, self.u, ufl.TrialFunction(self.V))

    # --- post-processing ----------------------------------------------------
    def stress(self, tag: int, u=None):
        """Second Piola–Kirchhoff stress (kPa) of region ``tag`` in the material axes,
        from ∂W/∂E."""
        E = ufl.variable(self.strain(u))
        return ufl.diff(self._energy(tag, E), E)

    def cell_fields(self) -> dict[str, fem.Function]:
        """DG0 fields for ParaView: strain and stress (material axes), tension, area stretch."""
        mesh = self.domain.mesh
        out = {
            "strain": fem.Function(fem.functionspace(mesh, ("DG", 0, (2, 2))), name="strain"),
            "stress": fem.Function(fem.functionspace(mesh, ("DG", 0, (2, 2))), name="stress"),
            "area_stretch": fem.Function(fem.functionspace(mesh, ("DG", 0)), name="area_stretch"),
        }
        points = np.array([[1.0 / 3.0, 1.0 / 3.0]])
        F = self.deformation_gradient()
        expr_strain = fem.Expression(self.strain(), points)
        expr_area = fem.Expression(ufl.sqrt(ufl.det(F.T * F)), points)
        out["strain"].interpolate(expr_strain)
        out["area_stretch"].interpolate(expr_area)
        for tag in self.materials:
            cells = self.domain.cell_tags.find(tag)
            out["stress"].interpolate(fem.Expression(self.stress(tag), points), cells0=cells)
        for f in out.values():
            f.x.scatter_forward()
        return out
