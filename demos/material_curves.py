# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Equibiaxial response of the two tissues
#
# This demo illustrates how to:
# - use the Fung tissue presets of SPEC §3 (native human aortic leaflet,
#   Billiar & Sacks 2000; glutaraldehyde-treated bovine pericardium, Sacks 1999);
# - compute the equibiaxial stress–strain response from the closed form;
# - draw the figure that characterises each material.
#
# Equibiaxial test: E12 = 0 and equal Lagrangian (first Piola–Kirchhoff,
# nominal) stresses along the fibre and cross-fibre axes,
# $P_i = \lambda_i S_i$, $\lambda_i = \sqrt{1 + 2E_i}$, with
# $S_1 = c\,e^Q (A_1E_{11} + A_3E_{22})$ and $S_2 = c\,e^Q (A_2E_{22} + A_3E_{11})$.
# Each stress level up to 60 kPa is solved for $(E_{11}, E_{22})$.
#
# The native leaflet is stiff along its fibres and very distensible across
# them; the treated pericardium is almost inextensible (strains of order 0.1 %)
# -- the contrast behind graft oversizing.
#
# Run: `python demos/material_curves.py [--out docs]`

# %%
from __future__ import annotations

import argparse
import logging
from pathlib import Path

import numpy as np

from valve_dolfinx.materials import (
    BOVINE_PERICARDIUM,
    NATIVE_LEAFLET,
    FungMaterial,
    equibiaxial_response,
)
from valve_dolfinx.plotting.style import OKABE_ITO, new_figure, save_figure

MATERIALS = (NATIVE_LEAFLET, BOVINE_PERICARDIUM)


# %% [markdown]
# ## The curves
# `equibiaxial_response` solves, level by level, the two closed-form equations
# $P_1(E_{11}, E_{22}) = P_2(E_{11}, E_{22}) = P$ for the strains.


# %%
def equibiaxial_curves(max_stress: float = 60.0, n: int = 120,
                       materials: tuple[FungMaterial, ...] = MATERIALS
                       ) -> dict[str, dict[str, np.ndarray]]:
    """Per material name: ``stress`` levels (Lagrangian, kPa, 0..max_stress in n steps)
    and the strains ``E11`` (fibre) and ``E22`` (cross-fibre) that carry them."""
    return {m.name: equibiaxial_response(m, max_stress, n=n) for m in materials}


# %% [markdown]
# ## The figure
# Strain on the horizontal axis (per cent for the pericardium, whose strains
# are a thousand times smaller), stress up.


# %%
def plot_curves(curves: dict[str, dict[str, np.ndarray]], path: Path,
                materials: tuple[FungMaterial, ...] = MATERIALS) -> Path:
    """Draw the fibre and cross-fibre curves of each material side by side; write ``path``."""
    max_stress = max(float(c["stress"][-1]) for c in curves.values())
    fig = new_figure(5.5 * len(materials), 4.4)
    axes = fig.subplots(1, len(materials), squeeze=False)[0]
    for ax, m in zip(axes, materials, strict=True):
        curve = curves[m.name]
        unit = 1.0 if curve["E22"][-1] > 0.01 else 100.0
        scale = "" if unit == 1.0 else " (%)"
        ax.plot(curve["E11"] * unit, curve["stress"], lw=2, color=OKABE_ITO["blue"],
                label="fibre (E11)")
        ax.plot(curve["E22"] * unit, curve["stress"], lw=2, ls="--", color=OKABE_ITO["orange"],
                label="cross-fibre (E22)")
        ax.set_xlabel(f"Green–Lagrange strain{scale}")
        ax.set_ylabel("Lagrangian (1st Piola–Kirchhoff) stress (kPa)")
        ax.set_title(f"{m.name.replace('_', ' ')}: c = {m.c:g} kPa\n{m.reference.split(';')[0]}",
                     fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend()
        ax.set_ylim(0, max_stress * 1.02)
    fig.suptitle("Equibiaxial response (equal Lagrangian stresses, E12 = 0)")
    save_figure(fig, path)
    return Path(path)


# %%
def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description="equibiaxial curves of the tissue presets")
    parser.add_argument("--out", type=Path, default=Path("docs"))
    parser.add_argument("--max-stress", type=float, default=60.0, help="kPa")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    curves = equibiaxial_curves(args.max_stress)
    for name, curve in curves.items():
        logging.info("%s at %g kPa: E11 = %.4f, E22 = %.4f", name, args.max_stress,
                     curve["E11"][-1], curve["E22"][-1])
    path = plot_curves(curves, args.out / "material_curves.png")
    logging.info("wrote %s", path)
    return path


if __name__ == "__main__":
    main()
