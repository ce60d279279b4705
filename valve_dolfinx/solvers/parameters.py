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

__all__ = ["PseudoTransientParameters", "DynamicsParameters"]


@dataclass
class PseudoTransientParameters:
    """Settings of the pseudo-transient continuation (lengths in mm, forces in mN).

    Attributes
    ----------
    residual_tolerance
        Convergence: ``‖R‖∞`` of the static residual at full load (mN).  The slack
        free edges at the triple point are held only by bending and contact, modes of
        about 0.3 mN/mm: a residual r leaves them up to r/0.3 mm from their
        equilibrium; 1e-3 mN (the default) leaves them ~0.003 mm away.
    mass_length_mm
        L in the nodal mass ``p·A_i/L`` (mm): the distance an unbalanced node
        moves in a unit pseudo-time step.
    coarse_mesh_mm
        A valve without a graft on a finer mesh first comes to rest on a mesh of this size
        (mm), and its own mesh starts from that equilibrium
        (:func:`valve_dolfinx.case.coarse_start`): the long approach of the open leaflets
        to closure costs a fraction there.  0: from the unloaded valve.
    max_steps
        Limit on pseudo-time steps (accepted + rejected).
    wall_time_limit_s
        Wall-clock limit (s).
    petsc_options
        Extra PETSc options (without prefix) for the TS/SNES/KSP; they override the
        module's own, e.g. ``{"snes_rtol": 1e-12, "snes_max_it": 30}`` for the Newton
        solve of each step.
    """

    residual_tolerance: float = 1e-3
    mass_length_mm: float = 1.0
    coarse_mesh_mm: float = 2.0
    max_steps: int = 4000
    wall_time_limit_s: float = 900.0
    petsc_options: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_range("coarse_mesh_mm", self.coarse_mesh_mm, 0.0, 2.5, unit="mm",
                    hint="2 mm is the default; 0 starts every case from the unloaded valve; "
                    "the mesh must resolve the 5 mm commissures with two edges")
        check_range("residual_tolerance", self.residual_tolerance, 0.0, 10.0, low_open=True,
                    unit="mN", hint="nodal pressure forces are ~1-10 mN; 1e-3 mN is the default")
        check_range("mass_length_mm", self.mass_length_mm, 0.0, 1e3, low_open=True, unit="mm")
        check_range("max_steps", self.max_steps, 1, 1e7)
        check_range("wall_time_limit_s", self.wall_time_limit_s, 0.0, 1e7, low_open=True,
                    unit="s")


@dataclass
class DynamicsParameters:
    """Settings of the damped BDF2 dynamics (units: s, mm).

    Attributes
    ----------
    relaxation_time
        τ (s): damping per unit stiffness, ``c = k·τ/L²``, and the mass time scale
        (:mod:`~valve_dolfinx.solvers.dynamics`).
    stop_increment_mm
        Convergence: displacement increment of the watched nodes per step (mm; SPEC §4:
        1e-5 mm).
    wall_time_limit_s
        Wall-clock limit of the run (s).
    """

    relaxation_time: float = 1.0
    stop_increment_mm: float = 1e-5
    wall_time_limit_s: float = 3600.0

    def __post_init__(self) -> None:
        check_range("relaxation_time", self.relaxation_time, 0.0, 1e6, low_open=True, unit="s")
        check_range("stop_increment_mm", self.stop_increment_mm, 0.0, 1.0, low_open=True)
        check_range("wall_time_limit_s", self.wall_time_limit_s, 0.0, 1e7, low_open=True)
