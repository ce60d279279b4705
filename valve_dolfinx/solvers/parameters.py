"""Numerical settings of the two paths to the loaded equilibrium (no DOLFINx import).

:class:`PseudoTransientParameters` drives :mod:`~valve_dolfinx.solvers.pseudo_transient`
(the default path), :class:`DynamicsParameters` the damped BDF2 dynamics of
:mod:`~valve_dolfinx.solvers.dynamics` (the cross-check).  They are part of the case
configuration (:mod:`valve_dolfinx.config`), which loads and validates without DOLFINx.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from valve_dolfinx.exceptions import check_range

__all__ = ["PseudoTransientParameters", "DynamicsParameters"]


@dataclass
class PseudoTransientParameters:
    """Step control of the pseudo-transient continuation (lengths in mm, forces in mN).

    Attributes
    ----------
    residual_tolerance
        Convergence: ``‖R‖∞`` of the static residual at full load (mN).  The slack
        free edges at the triple point are held only by bending and contact, modes of
        about 0.3 mN/mm: a residual r leaves them up to r/0.3 mm from their
        equilibrium.  At 0.05 mN the normal valve's minimum coaptation height moved by
        0.2 mm with the Newton settings; at 1e-3 mN (the default, ~0.003 mm) two
        settings gave the same height to 0.001 mm, for a few Newton steps more.
    mass_length_mm
        L in the nodal mass ``p·A_i/L`` (mm): the distance an unbalanced node
        moves in a unit pseudo-time step.
    dt_initial, dt_min, dt_max
        Pseudo-time steps (dimensionless); below ``dt_min`` the run has stalled.
    increment
        Factor on the residual ratio of switched evolution relaxation (PETSc's
        ``-ts_pseudo_increment``): Δτ grows by it while the residual stalls.
    growth_limit
        Largest factor by which Δτ grows (or shrinks) from one step to the next.
    max_step_motion_mm
        The next Δτ is shortened so that no node is expected to move further
        than this in one step.
    newton_motion_mm
        Largest nodal motion of one Newton update (mm); longer updates are
        scaled down (contact is evaluated at every Newton iterate).
    newton_max_it, newton_rtol
        Newton iterations per step and the relative residual reduction that ends
        a step's Newton solve; a step whose Newton solve fails is retried with
        half the Δτ.  0.5 throughout takes a third fewer Newton iterations over the
        study grid but moves the resting states of path-sensitive cases
        (docs/numerics.md, §2).
    settled_residual_mN, newton_rtol_settled
        Once the static residual of the accepted state is below
        ``settled_residual_mN``, a step's Newton solve ends at ``newton_rtol_settled``
        (0.5: once its residual has halved) instead of ``newton_rtol``.  0 (the
        default) solves every step to ``newton_rtol``.  1 mN (a tenth of the pressure
        force on a node of the default mesh) saves 14 % of the study grid's Newton
        iterations, but the looser settled steps can carry a case into a neighbouring
        resting state: W21/H27 with the numerical mass ×4 came to rest 0.19 mm lower
        (docs/numerics.md, §2).
    newton_cycle_tolerance
        A Newton solve whose residual norms repeat every second or third iteration
        to this relative tolerance has settled into a cycle and ends as failed at
        once instead of at ``newton_max_it`` (0: never).  A failed solve's step is
        retried from its start, so where it ends does not change the path; in the
        runs measured no solve that went on to converge was ever cut at 1e-3, so
        the result does not depend on it.
    newton_reversal_damping
        A Newton update that points back along the previous one (cosine below -0.9:
        the iterates jump to and fro across a kink of the residual, such as the
        relaxed membrane energy's taut/wrinkled switch) is scaled by this factor, so
        that the iterate lands between the two sides instead of on the other one
        (1: never).  A step's first update is compared with the last update of the
        previous accepted step: solves of one update each cycle across steps.
    predictor_motion_mm
        Each step's Newton solve starts from the accepted state moved on by the last
        accepted step's motion, scaled by the ratio of the pseudo-time steps (a linear
        predictor), at most this far at any node (mm); 0 (the default): from the accepted
        state.  The equilibria are the same; the path is not.  0.1 took W21/H27 from
        1 709 to 540 Newton iterations (failed solves included) and W21/H40 from 2 970 to
        1 215, to the same figures of merit, but ten path-sensitive cells of the study grid
        came to rest in other states (docs/numerics.md, §2).
    max_steps
        Limit on pseudo-time steps (accepted + rejected).
    wall_time_limit_s
        Wall-clock limit (s).
    pressure_ramp_steps
        The pressure rises to its target in this many equal increments, one per
        accepted pseudo-time step, and a case converges only once it is at the target
        (0, the default: the target from the first step).  Where the loaded valve
        has more than one equilibrium the path selects one (docs/numerics.md, §2).
    coarse_mesh_mm
        A valve without a graft on a finer mesh first comes to rest on a mesh of this size
        (mm), and its own mesh starts from that equilibrium
        (:func:`valve_dolfinx.case.coarse_start`): the long approach of the open leaflets
        to closure costs a fraction there.  0: from the unloaded valve.
    petsc_options
        Extra PETSc options (without prefix) for the TS/SNES/KSP.
    """

    residual_tolerance: float = 1e-3
    mass_length_mm: float = 1.0
    dt_initial: float = 0.05
    dt_min: float = 1e-8
    dt_max: float = 1e12
    increment: float = 1.2
    growth_limit: float = 3.0
    max_step_motion_mm: float = 0.5
    newton_motion_mm: float = 0.1
    newton_max_it: int = 12
    newton_rtol: float = 0.05
    settled_residual_mN: float = 0.0
    newton_rtol_settled: float = 0.5
    newton_cycle_tolerance: float = 1e-3
    newton_reversal_damping: float = 0.5
    predictor_motion_mm: float = 0.0
    max_steps: int = 4000
    wall_time_limit_s: float = 900.0
    pressure_ramp_steps: int = 0
    coarse_mesh_mm: float = 2.0
    petsc_options: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_range("coarse_mesh_mm", self.coarse_mesh_mm, 0.0, 2.5, unit="mm",
                    hint="2 mm is the default; 0 starts every case from the unloaded valve; "
                    "the mesh must resolve the 5 mm commissures with two edges")
        check_range("residual_tolerance", self.residual_tolerance, 0.0, 10.0, low_open=True,
                    unit="mN", hint="nodal pressure forces are ~1-10 mN; 1e-3 mN is the default")
        check_range("pressure_ramp_steps", self.pressure_ramp_steps, 0, 1e6, unit="",
                    hint="0 (the default) applies the full pressure from the first step")
        check_range("mass_length_mm", self.mass_length_mm, 0.0, 1e3, low_open=True, unit="mm")
        check_range("dt_min", self.dt_min, 0.0, self.dt_initial, low_open=True)
        check_range("dt_initial", self.dt_initial, self.dt_min, self.dt_max)
        check_range("increment", self.increment, 1.0, 10.0)
        check_range("growth_limit", self.growth_limit, 1.0, 100.0, low_open=True)
        check_range("max_step_motion_mm", self.max_step_motion_mm, 0.0, 10.0, low_open=True,
                    unit="mm")
        check_range("newton_motion_mm", self.newton_motion_mm, 0.0, 10.0, low_open=True,
                    unit="mm", hint="keep it below the contact's penetration window")
        check_range("newton_max_it", self.newton_max_it, 1, 1000)
        check_range("newton_rtol", self.newton_rtol, 0.0, 1.0, low_open=True)
        check_range("settled_residual_mN", self.settled_residual_mN, 0.0, 1e3, unit="mN",
                    hint="0 (the default) solves every step to newton_rtol")
        check_range("newton_rtol_settled", self.newton_rtol_settled, 0.0, 1.0,
                    low_open=True)
        check_range("newton_cycle_tolerance", self.newton_cycle_tolerance, 0.0, 0.1,
                    hint="1e-3 is the default; 0 lets cycling solves run to newton_max_it")
        check_range("newton_reversal_damping", self.newton_reversal_damping, 0.0, 1.0,
                    low_open=True, unit="",
                    hint="0.5 (the default) halves a reversing update; 1 leaves it as it is")
        check_range("predictor_motion_mm", self.predictor_motion_mm, 0.0, 10.0, unit="mm",
                    hint="0 (the default) starts each step's Newton solve at the accepted "
                    "state; keep it below the contact's penetration window")
        check_range("max_steps", self.max_steps, 1, 1e7)
        check_range("wall_time_limit_s", self.wall_time_limit_s, 0.0, 1e7, low_open=True,
                    unit="s")


@dataclass
class DynamicsParameters:
    """Numerical mass, damping and step control (units: s, mm).

    Attributes
    ----------
    relaxation_time
        τ (s): damping per unit stiffness, ``c = k·τ/L²``.
    mass_ratio
        Mass time scale over τ: ``ρ = c·mass_ratio·τ`` (small: over-damped).
    length_scale
        L (mm) in the stiffness-per-area estimate k/L².
    stiffness_exponent
        β in ``c ∝ (k_tissue/k_ref)^β`` (1: damping proportional to stiffness).
    ramp_time
        Pressure ramp duration (s), smooth-step shaped.
    dt_initial, dt_min, dt_max
        Time steps (s); ``dt_min`` is the floor below which the run is
        declared stalled.
    t_max
        Simulated time limit (s).
    error_tolerance_mm
        Local truncation error target of the displacement (mm).
    stop_increment_mm
        Convergence: displacement increment of the watched nodes per step (mm).
    equilibrium_tolerance
        Convergence also needs the static residual (internal − pressure −
        contact forces at rest), max-norm over the free nodes, below this (mN):
        small increments alone can also mean a stalled, tiny time step.
    max_increment_mm
        Largest nodal displacement per step (mm): the next step is shortened
        so that no node moves further, which keeps nodes from tunnelling
        through a surface between two contact evaluations (the contact search
        only sees penetrations shallower than ``penetration_depth``).
    wall_time_limit_s
        Wall-clock limit of the run (s).
    max_steps
        Limit on accepted + rejected steps.
    newton_max_it
        Newton iterations per step before the step is retried smaller.
    petsc_options
        Extra PETSc options for the TS/SNES/KSP (without prefix), e.g.
        ``{"snes_linesearch_type": "l2"}``.
    """

    relaxation_time: float = 1.0
    mass_ratio: float = 0.05
    length_scale: float = 10.0
    stiffness_exponent: float = 1.0
    ramp_time: float = 1.0
    dt_initial: float = 1e-3
    dt_min: float = 1e-8
    dt_max: float = 50.0
    t_max: float = 1e5
    error_tolerance_mm: float = 0.01
    stop_increment_mm: float = 1e-5
    max_increment_mm: float = 0.1
    equilibrium_tolerance: float = 0.05
    wall_time_limit_s: float = 3600.0
    max_steps: int = 20000
    newton_max_it: int = 20
    petsc_options: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_range("relaxation_time", self.relaxation_time, 0.0, 1e6, low_open=True, unit="s")
        check_range("mass_ratio", self.mass_ratio, 0.0, 1e3, unit="")
        check_range("length_scale", self.length_scale, 0.0, 1e3, low_open=True, unit="mm")
        check_range("stiffness_exponent", self.stiffness_exponent, 0.0, 1.0)
        check_range("ramp_time", self.ramp_time, 0.0, 1e6, low_open=True, unit="s")
        check_range("dt_min", self.dt_min, 0.0, self.dt_initial, low_open=True, unit="s")
        check_range("dt_initial", self.dt_initial, self.dt_min, self.dt_max, unit="s")
        check_range("error_tolerance_mm", self.error_tolerance_mm, 0.0, 10.0, low_open=True)
        check_range("stop_increment_mm", self.stop_increment_mm, 0.0, 1.0, low_open=True)
        check_range("wall_time_limit_s", self.wall_time_limit_s, 0.0, 1e7, low_open=True)
