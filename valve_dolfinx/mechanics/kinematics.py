"""Membrane kinematics on a manifold mesh (triangles in 3-D), as pure UFL functions.

Every cell carries a *reference chart*: the map ``J0 = ∂x₀/∂X`` (3×2) from
2-D reference coordinates X -- the flat leaflet outline, or an orthonormal
tangent frame of a curved verification mesh -- to the mesh placement x₀.  The
reference coordinates are an isometric copy of the stress-free state, so the
reference metric is the 2×2 identity.  With the displacement u from the
placement, the current position is x = x₀ + u and

* surface deformation gradient ``F = ∂x/∂X = J0 + ∇u·J0`` (3×2), where ∇ is
  the tangential gradient on the mesh (``ufl.grad`` on a manifold);
* right Cauchy–Green ``C = FᵀF`` and Green–Lagrange ``E = (C − I)/2`` (2×2);
* reference area element ``dA = dA₀ / √det(J0ᵀJ0)`` (dA₀ = mesh area element);
* current area vector per reference area ``n da/dA = F[:,0] × F[:,1]``.

Dimensions come from the shapes of these objects, never from literals of the
mesh (the 2 here is the dimension of the reference chart of a membrane).
"""

from __future__ import annotations

import ufl

__all__ = [
    "deformation_gradient",
    "right_cauchy_green",
    "green_lagrange",
    "material_rotation",
    "to_material_axes",
    "reference_area_factor",
    "area_vector",
]


def deformation_gradient(u, J0):
    """F = J0 + ∇u·J0: tangent map from the reference chart to the current surface (3×2)."""
    return J0 + ufl.grad(u) * J0


def right_cauchy_green(F):
    """C = FᵀF (2×2)."""
    return F.T * F


def green_lagrange(F):
    """E = (FᵀF − I)/2 (2×2) in the reference chart."""
    n = F.ufl_shape[1]
    return 0.5 * (right_cauchy_green(F) - ufl.Identity(n))


def material_rotation(a):
    """R = [a, a⊥]: columns are the fibre and cross-fibre unit vectors (reference chart)."""
    return ufl.as_matrix([[a[0], -a[1]], [a[1], a[0]]])


def to_material_axes(T, a):
    """Components Rᵀ·T·R of a 2×2 chart tensor in the material axes (1 = fibre a)."""
    R = material_rotation(a)
    return R.T * T * R


def reference_area_factor(J0):
    """dA_ref/dA_mesh = 1/√det(J0ᵀJ0)."""
    return 1.0 / ufl.sqrt(ufl.det(J0.T * J0))


def area_vector(F):
    """n·da/dA = F₁ × F₂: current normal times the current-to-reference area ratio."""
    return ufl.cross(F[:, 0], F[:, 1])
