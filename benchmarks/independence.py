"""The loaded equilibrium does not depend on the numerics or on the slack graft's placement.

Prints, at the default mesh, the figure of merit (minimum native coaptation height) of

* W27/H0 and W21/H27 with the default pseudo-time mass and with the mass ×4
  (``mass_length_mm`` ÷ 4): target |Δ| < 0.02 mm;
* W21/H27 placed slack bulged 0.75 mm towards the valve axis and 0.75 mm away from it
  (1.5 mm apart at the graft's free-edge midpoint, SPEC §1): target |Δ| < 0.05 mm in the
  figure of merit and < 0.1 mm in every loaded node position, compared directly or with
  one state mirrored (:func:`~valve_dolfinx.geometry.symmetry.distance_up_to_mirror`)::

    .venv/bin/python benchmarks/independence.py [--mesh-size 0.8]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from valve_dolfinx._compat import MPI
from valve_dolfinx.case import analyse_case, solve_case
from valve_dolfinx.config import CaseConfig
from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.geometry.symmetry import distance_up_to_mirror
from valve_dolfinx.geometry.valve import ValveParameters


def _case(width: float, height: float, mesh_size: float, mass_factor: float = 1.0,
          billow_mm: float | None = None) -> CaseConfig:
    geometry = ValveParameters(mesh_size=mesh_size, graft_width_pct=width,
                               graft_height_pct=height)
    if billow_mm is not None:
        geometry = replace(geometry, graft_placement="billowed", billow_mm=billow_mm)
    config = CaseConfig(geometry=geometry)
    ptc = config.pseudo_transient
    return replace(config, pseudo_transient=replace(
        ptc, mass_length_mm=ptc.mass_length_mm / mass_factor))


def _solve(config: CaseConfig):
    state = solve_case(config, MPI.COMM_SELF)
    fields = analyse_case(state, config).result_fields()
    r = state.report
    print(f"  converged {r.converged}, residual {r.residual_mN:.2e} mN, {r.steps} steps, "
          f"{r.newton_iterations} Newton, {r.wall_time_s:.0f} s: min h "
          f"{fields['min_coaptation_height_mm']:.4f} mm, central "
          f"{fields['central_coaptation_height_mm']:.4f} mm", flush=True)
    return fields["min_coaptation_height_mm"], state


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mesh-size", type=float, default=ValveParameters().mesh_size)
    args = parser.parse_args()
    h = args.mesh_size
    for width, height in ((27.0, 0.0), (21.0, 27.0)):
        label = GraftSize(width, height).label
        print(f"{label}, mass x1:")
        base, _ = _solve(_case(width, height, h))
        print(f"{label}, mass x4:")
        heavy, _ = _solve(_case(width, height, h, mass_factor=4.0))
        print(f"  |Δ figure of merit| = {abs(heavy - base):.4f} mm (target < 0.02 mm)")
    placed = {}
    for billow in (0.75, -0.75):
        print(f"{GraftSize(21, 27).label} placed with billow {billow:+g} mm:")
        placed[billow] = _solve(_case(21.0, 27.0, h, billow_mm=billow))
    (f_in, s_in), (f_out, s_out) = placed[0.75], placed[-0.75]
    valve_in, valve_out = s_in.domain.valve, s_out.domain.valve
    graft = next(p for p in valve_in.leaflets if p.is_graft)
    mid = graft.nodes[graft.midline_free_edge_node]
    apart = np.linalg.norm(valve_in.points[mid] - valve_out.points[mid])
    direct, mirror = distance_up_to_mirror(valve_in, s_in.positions, s_out.positions)
    print(f"placements {apart:.2f} mm apart at the graft's free-edge midpoint: "
          f"|Δ figure of merit| = {abs(f_in - f_out):.4f} mm (target < 0.05 mm), "
          f"largest nodal distance {direct:.4f} mm, {mirror:.4f} mm to the other's mirror "
          f"image (target: the smaller < 0.1 mm)")


if __name__ == "__main__":
    main()
