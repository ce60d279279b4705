# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Planning one patient's repair: from two measurements to a graft cut at true size
#
# This demo illustrates how to:
# - describe a patient by what is measured before the graft is cut (SPEC §9): the loaded
#   root diameter at the base on echo or CT, with its uncertainty, and the excised
#   non-coronary leaflet measured flat (free edge and height) -- as a validated
#   `PatientInput`, written to and read back from `PATIENT.toml`;
# - check in closed form whether the two native leaflets left can reach the centre of
#   this root at all, before anything is computed;
# - run the plan with `run_plan`: the study of the grafts on this patient's valve over the
#   root diameters D − U, D, D + U and two numerical paths (the *members*), the graft that
#   qualifies in every member with its margin and the member that limits it, that graft
#   drawn at true size (SVG and PDF with a 50 mm calibration bar) and the one-page report
#   `plan.pdf`;
# - rebuild the plan's files from its case folders, as `valve-dolfinx report DIR` does.
#
# The worked patient: a 22 mm root (± 1 mm) and an excised leaflet with a 22 mm free edge
# and a 13 mm height.  The native leaflets of the model are the SPEC §1 outline scaled
# to that leaflet: wrapped on a cylinder of 3L/π = 21.0 mm, sewn into a root held at the
# measured 22 mm.  A graft W/H is that leaflet enlarged by W across and H in height.
#
# Run: `python demos/patient_plan.py [--out results/patient_plan] [--mesh-size 0.8]
# [--paths 2] [--full-grid]`, or `mpirun -n 2 python demos/patient_plan.py`.  The same plan
# from the command line: `valve-dolfinx plan PATIENT.toml --out DIR`.

# %%
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from valve_dolfinx._compat import MPI
from valve_dolfinx.logs import configure_logging
from valve_dolfinx.plan.patient import PatientInput, patient_toml, read_patient, write_patient
from valve_dolfinx.plan.reach import free_edge_reach
from valve_dolfinx.plan.runner import plan_study_settings, rebuild_plan, run_plan
from valve_dolfinx.sizing import cell_state
from valve_dolfinx.study import STUDY_HEIGHTS_PCT, STUDY_WIDTHS_PCT


def _mm(value: float | None) -> str:
    """A length in mm, or a dash when no member gave one."""
    return "–" if value is None else f"{value:.2f} mm"


def main(argv: list[str] | None = None):
    parser = argparse.ArgumentParser(description="plan one patient's repair (SPEC §9)")
    parser.add_argument("--out", type=Path, default=Path("results/patient_plan"))
    parser.add_argument("--mesh-size", type=float, default=None,
                        help="triangle edge length in mm (default: the case default, 0.8)")
    parser.add_argument("--widths", type=float, nargs="+", default=list(STUDY_WIDTHS_PCT))
    parser.add_argument("--heights", type=float, nargs="+", default=list(STUDY_HEIGHTS_PCT))
    parser.add_argument("--full-grid", action="store_const", const="grid", default="adaptive",
                        dest="design", help="every graft of the grid instead of the adaptive "
                        "design (a grid of one size, as the test runs it, needs it)")
    parser.add_argument("--paths", type=int, default=2,
                        help="numerical paths every graft is solved along (default 2)")
    args = parser.parse_args(argv)
    configure_logging()
    comm = MPI.COMM_WORLD

    # %% [markdown]
    # ## The patient
    # Every input carries its unit in its name and is checked against a clinical range
    # (docs/plan.md cites them) before anything runs: a 2.2 for a 22 mm root (cm for mm)
    # stops here with a message naming `root_diameter_mm` and its range.  The file
    # written here is what `valve-dolfinx plan PATIENT.toml` reads; reading it back gives
    # the same inputs, to the last digit.

    # %%
    patient = PatientInput(root_diameter_mm=22.0, root_uncertainty_mm=1.0,
                           leaflet_free_edge_mm=22.0, leaflet_height_mm=13.0,
                           graft_widths_pct=tuple(args.widths),
                           graft_heights_pct=tuple(args.heights), paths=args.paths,
                           design=args.design, label="worked patient")
    if comm.rank == 0:
        path = write_patient(args.out / "worked_patient.toml", patient)
        print(patient_toml(patient))
        print(f"{path} read back gives the same inputs: {read_patient(path) == patient}")
    settings = plan_study_settings(patient, args.mesh_size)  # every case setting, checked
    layout = settings.layout()
    shape = patient.native_shape
    if comm.rank == 0:
        print(f"native leaflets: free edge {shape.free_edge_length:.2f} mm, height "
              f"{shape.height:.2f} mm, wrapped on {shape.root_diameter:.2f} mm (3L/π)")
        print(f"{len(layout.members)} members, {len(layout.cases)} cases: "
              + "; ".join(member.label for member in layout.members))

    # %% [markdown]
    # ## Can these leaflets close this root at all?
    # Each free edge must reach from its commissures to the centre: its loaded length
    # must be at least the root's diameter.  The free edge carries tension along itself
    # only, at most the pressure times the root diameter (docs/plan.md), and the fibres
    # along it are stiff, so its stretch is bounded in closed form.  A root beyond that
    # reach is answered in one line, without computing a grid that cannot succeed.

    # %%
    for diameter in patient.root_diameters_mm:
        reach = free_edge_reach(patient.leaflet_free_edge_mm, diameter, patient.pressure_mmhg)
        if comm.rank == 0:
            print(f"root {diameter:.1f} mm: reach {reach.reach_mm:.1f} mm (stretch at most "
                  f"{reach.stretch:.3f}) -> {'can' if reach.can_seal else 'CANNOT'} seal")

    # %% [markdown]
    # ## The plan
    # `run_plan` runs the study of the grafts on this valve (resumable: a rerun skips the
    # cases already done).  Every graft is solved in every member: at each root diameter
    # of the uncertainty (the normal valve once per diameter, its height that member's
    # target) and along each numerical path (a loaded valve can have several resting
    # states, and the path decides which one a solve reaches).  The recommendation is read
    # from a response surface over the graft size and the diameter: the smallest size whose
    # predicted worst case over the diameters reaches the target within the model's
    # measured resolution and that seals; its margin is the least over the diameters, and
    # the diameter where it is taken limits it.
    # A diameter the native leaflets cannot span is not computed (the bound above): no
    # graft would then be robust, and the answer says so.

    # %%
    library = logging.getLogger("valve_dolfinx")
    library.setLevel(logging.WARNING if comm.rank == 0 else logging.ERROR)
    if comm.rank == 0:
        logging.getLogger("valve_dolfinx.study").setLevel(logging.INFO)
    outcome = run_plan(patient, args.out, comm, mesh_size_mm=args.mesh_size)

    # %% [markdown]
    # ## What the surgeon takes away
    # `plan.pdf`: the answer, the inputs, the template's thumbnail, the sizing map and the
    # closed valve; `template_W<w>_H<h>.pdf` (and `.svg`): the graft at true size, with
    # the 1 mm suturing margin along its attachment edge, none along its free edge, the
    # fibre direction and a 50 mm bar to check the print; `summary.json`: the same in
    # numbers.

    # %%
    if comm.rank == 0:
        rec = outcome.answers.values[0]  # one answer: the plan varies nothing
        print(rec.headline())
        for cell in rec.recommendation.cells if rec.recommendation else ():
            print(f"  {cell.label}: lowest minimum coaptation "
                  f"{_mm(cell.worst_height_mm)}, margin {_mm(cell.margin_mm)} in "
                  f"{rec.name(cell.limiting_member)}; {cell_state(cell)}")
        for template in outcome.templates:
            print(f"template {template.graft.label}: {template.cut_width_mm:.1f} x "
                  f"{template.cut_height_mm:.1f} mm cut piece -> {template.pdf}")
        print(f"report: {args.out / 'plan.pdf'}")

    # %% [markdown]
    # ## Rebuilding the plan from its cases
    # The plan folder holds the inputs (`patient.toml`) and every case; the plan's files
    # follow from them.  `rebuild_plan` (what `valve-dolfinx report DIR` runs on a plan
    # folder) rewrites the report, the templates and `summary.json` without computing.

    # %%
    if comm.rank == 0:
        rebuilt = rebuild_plan(args.out)
        same = rebuilt.answers.to_dict() == outcome.answers.to_dict()
        print(f"rebuilt from the case folders: {same}")
    return outcome


# %% [markdown]
# ## References
# - SPEC §9 (the plan), §1 (the leaflet outline), §2 (the prescribed root), §3 (the
#   tissue law behind the reach bound).
# - docs/plan.md: the inputs' clinical ranges and their sources, the reach bound, the
#   template and the report.

# %%
if __name__ == "__main__":
    main()
