"""Settings of the two paths to the loaded equilibrium (no DOLFINx import).

:class:`PseudoTransientParameters` drives :mod:`~valve_dolfinx.solvers.pseudo_transient`
(the default path), :class:`DynamicsParameters` the damped BDF2 dynamics of
:mod:`~valve_dolfinx.solvers.dynamics` (the cross-check).  They are part of the case
configuration (:mod:`valve_dolfinx.config`), which loads and validates without DOLFINx.
Each path's other numbers (first step, step growth, Newton settings, ...) are constants
of its module, documented there.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from valve_dolfinx.exceptions import check_range
from valve_dolfinx.setting_fields import NOT_A_SETTING, check_setting, setting

__all__ = ["PseudoTransientParameters", "DynamicsParameters"]


@dataclass
class PseudoTransientParameters:
    """Settings of the pseudo-transient continuation: each one's unit and meaning is on its
    field.

    ``residual_tolerance``: the slack free edges at the triple point are held only by
    bending and contact, modes of about 0.3 mN/mm: a residual r leaves them up to r/0.3 mm
    from their equilibrium; 1e-3 mN (the default) leaves them ~0.003 mm away.
    ``mass_length_mm``: the distance an unbalanced node moves in a unit pseudo-time step.
    ``coarse_mesh_mm``: the long approach of the open leaflets to closure costs a fraction
    on the coarse mesh (:func:`valve_dolfinx.case.coarse_start`).  ``petsc_options``
    override the module's own, e.g. ``{"snes_rtol": 1e-12, "snes_max_it": 30}`` for the
    Newton solve of each step.
    """

    residual_tolerance: float = setting(1e-3, "mN", "convergence: max-norm of the static "
                                        "residual")
    mass_length_mm: float = setting(1.0, "mm", "L in the nodal pseudo-mass p·A/L")
    coarse_mesh_mm: float = setting(2.0, "mm", "a valve without a graft on a finer mesh first "
                                    "comes to rest on a mesh of this size and starts from "
                                    "there (0: from the unloaded valve)")
    max_steps: int = setting(4000, "", "limit on pseudo-time steps (accepted + rejected)")
    #: s; wall-clock limit of the solve: not a setting of its own, the configuration's one
    #: limit (``solver.wall_time_limit_s``) sets it (CaseConfig.solver_parameters)
    wall_time_limit_s: float = field(default=900.0, metadata=NOT_A_SETTING)
    petsc_options: dict = setting(default_factory=dict, meaning="extra PETSc options for the "
                                  "TS/SNES/KSP (no prefix), e.g. { snes_rtol = 1e-8 }")

    def __post_init__(self) -> None:
        check_setting(self, "coarse_mesh_mm", 0.0, 2.5,
                      hint="2 mm is the default; 0 starts every case from the unloaded valve; "
                      "the mesh must resolve the 5 mm commissures with two edges")
        check_setting(self, "residual_tolerance", 0.0, 10.0, low_open=True,
                      hint="nodal pressure forces are ~1-10 mN; 1e-3 mN is the default")
        check_setting(self, "mass_length_mm", 0.0, 1e3, low_open=True)
        check_setting(self, "max_steps", 1, 1e7)
        check_range("wall_time_limit_s", self.wall_time_limit_s, 0.0, 1e7, low_open=True,
                    unit="s")


@dataclass
class DynamicsParameters:
    """Settings of the damped BDF2 dynamics: each one's unit and meaning is on its field
    (``relaxation_time``: :mod:`~valve_dolfinx.solvers.dynamics`; ``stop_increment_mm``
    is the increment of the watched nodes, SPEC §4 asks for 1e-5 mm)."""

    relaxation_time: float = setting(1.0, "s", "τ: damping per unit stiffness, c = k·τ/L², "
                                     "and the mass time scale")
    stop_increment_mm: float = setting(1e-5, "mm", "convergence: displacement increment per "
                                       "step")
    #: s; wall-clock limit of the solve, set as the pseudo-transient path's
    wall_time_limit_s: float = field(default=3600.0, metadata=NOT_A_SETTING)

    def __post_init__(self) -> None:
        check_setting(self, "relaxation_time", 0.0, 1e6, low_open=True)
        check_setting(self, "stop_increment_mm", 0.0, 1.0, low_open=True)
        check_range("wall_time_limit_s", self.wall_time_limit_s, 0.0, 1e7, low_open=True,
                    unit="s")
