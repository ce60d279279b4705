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

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from valve_dolfinx.materials import BOVINE_PERICARDIUM, NATIVE_LEAFLET, equibiaxial_response  # noqa: E402


def main(argv: list[str] | None = None) -> Path:
    parser = argparse.ArgumentParser(description="equibiaxial curves of the tissue presets")
    parser.add_argument("--out", type=Path, default=Path("docs"))
    parser.add_argument("--max-stress", type=float, default=60.0, help="kPa")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.4), constrained_layout=True)
    for ax, m, unit in zip(axes, (NATIVE_LEAFLET, BOVINE_PERICARDIUM), (1.0, 100.0), strict=True):
        curve = equibiaxial_response(m, args.max_stress, n=120)
        scale = "" if unit == 1.0 else " (%)"
        ax.plot(curve["E11"] * unit, curve["stress"], lw=2, label="fibre (E11)")
        ax.plot(curve["E22"] * unit, curve["stress"], lw=2, ls="--", label="cross-fibre (E22)")
        ax.set_xlabel(f"Green–Lagrange strain{scale}")
        ax.set_ylabel("Lagrangian (1st Piola–Kirchhoff) stress (kPa)")
        ax.set_title(f"{m.name.replace('_', ' ')}: c = {m.c:g} kPa\n{m.reference.split(';')[0]}",
                     fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend()
        ax.set_ylim(0, args.max_stress * 1.02)
        logging.info("%s at %g kPa: E11 = %.4f, E22 = %.4f", m.name, args.max_stress,
                     curve["E11"][-1], curve["E22"][-1])
    fig.suptitle("Equibiaxial response (equal Lagrangian stresses, E12 = 0)")
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "material_curves.png"
    fig.savefig(path, dpi=150)
    plt.close(fig)
    logging.info("wrote %s", path)
    return path


if __name__ == "__main__":
    main()
