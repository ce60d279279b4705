# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Closing the normal valve under diastolic pressure
#
# This demo illustrates how to:
# - close the normal (three native leaflets) valve under 80 mmHg with one call;
# - read the case's key numbers: minimum and central coaptation height, the
#   regurgitant orifice area and whether the valve is competent;
# - load the closed surface and draw it: from the aorta and from the ventricle,
#   coloured by the gap to the neighbouring leaflet, cut through a leaflet's
#   midline, and the coaptation region on the flat leaflets.
#
# A case distends the aortic root by the pressure, clamps the leaflets'
# attachment there and finds the static equilibrium of the Fung membranes with
# leaflet contact (pseudo-transient continuation: PETSc TS with SNES).  The
# coaptation height is the height of the strip along the free edge where a
# leaflet lies within the coaptation threshold (0.5 mm, about the leaflet
# thickness) of another; the valve is competent when the case converged, no
# regurgitant orifice is left when looking along the axis and no two leaflets pass
# through each other (otherwise the key numbers say which of these fails).
#
# Run as a script: `python demos/normal_valve.py [--mesh-size 1.6] [--out DIR]`
# (the default 0.8 mm mesh takes about a minute and a half on one core; 1.6 mm
# about half a minute), or open it as a notebook with jupytext.

# %%
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np
from PIL import Image

from valve_dolfinx import CaseConfig, load_case, run_case
from valve_dolfinx._compat import MPI
from valve_dolfinx.analysis import analyse_coaptation
from valve_dolfinx.geometry.valve import DEFAULT_MESH_SIZE, ValveParameters
from valve_dolfinx.plotting import (
    key_numbers,
    plot_coaptation_map,
    plot_cut_planes,
    plot_gap_3d,
    plot_valve_3d,
)

parser = argparse.ArgumentParser(description="Close the normal valve and draw it.")
parser.add_argument("--mesh-size", type=float, default=DEFAULT_MESH_SIZE,
                    help="target edge length of the leaflet mesh (mm)")
parser.add_argument("--out", type=Path, default=Path("results/normal_valve_demo"))
# parse_known_args: a notebook kernel passes its own arguments
args, _ = parser.parse_known_args()
logging.basicConfig(level=logging.INFO, format="%(message)s")
comm = MPI.COMM_WORLD
out: Path = args.out

# %% [markdown]
# ## Close the valve
# `run_case` builds the mesh, solves and writes `result.json`, `config.toml`,
# `history.csv`, `loaded_state.npz`, the ParaView fields and the case figures
# into `out`.

# %%
config = CaseConfig(geometry=ValveParameters(mesh_size=args.mesh_size))
result = run_case(config, out, comm=comm)
if comm.rank == 0:
    print(f"converged: {result.converged}; {key_numbers(result)}")
    print(f"root diameter {result.root_diameter_mm:.2f} mm, {result.time_steps} pseudo-time "
          f"steps, {result.wall_time_s:.0f} s")

# %% [markdown]
# ## Load the closed surface
# `load_case` reads a finished case folder: the result, the configuration that
# ran, the valve mesh (rebuilt from that configuration) and the loaded node
# positions.  The coaptation analysis is repeated on them to draw it (it is
# serial and takes seconds).  Under `mpirun` every rank draws, rank 0 writes the
# files.

# %%
case = load_case(out)
ran, valve, positions = case.config, case.valve, case.positions
coaptation = analyse_coaptation(positions, valve, threshold_mm=ran.coaptation_threshold_mm,
                                nodulus_length_mm=ran.nodulus_length_mm)


def to(name: str) -> Path | None:
    """Where rank 0 writes a figure (the other ranks draw without writing)."""
    return out / name if comm.rank == 0 else None


# %% [markdown]
# ## The closed valve from the aorta and from the ventricle
# What the surgeon sees, and its mirror image from below.  3-D views come back
# as pictures (arrays); `PIL.Image.fromarray` shows one in a notebook.

# %%
title = f"normal valve\n{key_numbers(result)}"
aortic = plot_valve_3d(positions, valve, to("demo_aortic.png"), view="aortic",
                       title=title + "\nseen from the aorta", orifice=coaptation.orifice)
ventricular = plot_valve_3d(positions, valve, to("demo_ventricular.png"), view="ventricular",
                            title=title + "\nseen from the ventricle",
                            orifice=coaptation.orifice)
Image.fromarray(np.hstack([aortic, ventricular]))

# %% [markdown]
# ## Where the leaflets meet
# Coloured by each point's distance to the nearest other leaflet; the black line
# is the coaptation threshold.

# %%
Image.fromarray(plot_gap_3d(positions, valve, coaptation, to("demo_gap.png"),
                            title="normal valve: gap to the nearest other leaflet"))

# %% [markdown]
# ## Axial cuts and the coaptation map
# Matplotlib figures come back as `Figure` objects, which a notebook shows.

# %%
plot_cut_planes(positions, valve, to("demo_cuts.png"), title="normal valve", result=result)

# %%
plot_coaptation_map(coaptation, valve, to("demo_coaptation_map.png"), title="normal valve",
                    result=result)
if comm.rank == 0:
    print(f"figures in {out}")
