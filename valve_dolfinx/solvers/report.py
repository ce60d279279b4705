"""How a solve to the loaded equilibrium ended: one report type for every solver path."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["SolveReport", "DynamicsReport"]


@dataclass
class SolveReport:
    """How a solve ended; ``history`` has a row per accepted step.

    Attributes
    ----------
    converged, reason
        Whether the static equilibrium was reached, and why the run stopped.
    steps, rejected_steps, newton_iterations
        Accepted time steps, rejected ones, and Newton iterations over the accepted steps.
    rejected_newton_iterations
        Newton iterations spent in steps that were rejected and retried with a shorter
        one: failed Newton solves (under BDF2 also steps rejected for their motion); not
        counted in ``newton_iterations``.
    time
        Time reached: pseudo-time (dimensionless) for the pseudo-transient
        continuation, simulated time (s) for the damped dynamics.
    residual_mN, residual_tolerance_mN
        ``‖R‖∞`` of the static residual at the final state (mN), and the tolerance
        convergence asks it to be below.
    wall_time_s
        Wall-clock time of the solve (s).
    timings
        Wall-clock time (s) per part of the solve, where the solver measures it.
    start
        Where the solve started (``from``) and, for a start another solve reached first,
        that solve's Newton iterations and wall-clock time.
    """

    converged: bool = False
    reason: str = ""
    steps: int = 0
    rejected_steps: int = 0
    newton_iterations: int = 0
    rejected_newton_iterations: int = 0
    time: float = 0.0
    residual_mN: float = float("nan")
    residual_tolerance_mN: float = float("nan")
    wall_time_s: float = 0.0
    timings: dict = field(default_factory=dict)
    start: dict = field(default_factory=dict)
    history: list[dict] = field(default_factory=list)

    def count_rejections(self, ts) -> None:
        """Rejected steps and their Newton iterations from a finished PETSc TS (which counts
        the iterations of every Newton solve, rejected steps' included); call it after
        ``newton_iterations`` has summed the accepted steps'."""
        self.rejected_steps = ts.getStepRejections()
        self.rejected_newton_iterations = ts.getSNESIterations() - self.newton_iterations


@dataclass
class DynamicsReport(SolveReport):
    """:class:`SolveReport` of the damped dynamics, with its step-motion control.

    ``rejected_for_motion`` counts steps retried because a node would have moved further
    than :data:`~valve_dolfinx.solvers.dynamics.MAX_INCREMENT_MM`.
    """

    rejected_for_motion: int = 0
