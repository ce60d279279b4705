# ---
# jupyter:
#   jupytext:
#     formats: py:percent
# ---

# %% [markdown]
# # Valve geometry: flat leaflet, normal valve, graft valve
#
# This demo illustrates how to:
# - mesh the flat, stress-free leaflet outline with Gmsh (SPEC §1);
# - join three leaflets at their commissures and wrap them onto the 20 mm
#   root cylinder, as one DOLFINx manifold mesh with leaflet and edge tags;
# - replace the non-coronary leaflet with an enlarged pericardial graft
#   (here W = 21 %, H = 27 %) whose attachment is sewn onto the native
#   attachment locus;
# - write the meshes for ParaView and draw them.
#
# The flat leaflet is bounded by the lower attachment curve
# $y = d\,\sin^2(x/d)/\tan\gamma$ ($\gamma = 34°$, $|x| \le \pi d/6$), two 5 mm
# commissures and the straight free edge of length $\pi d/3$.  Wrapping maps the
# flat abscissa $x$ to the angle $\theta = 2x/d$ and the height to the axial
# coordinate: an isometry, so the wrapped native leaflets are stress-free.
#
# Run: `python demos/valve_geometry.py [--out results/geometry] [--mesh-size 0.8]`

# %%
from __future__ import annotations

import argparse
import logging
from pathlib import Path

from valve_dolfinx._compat import MPI
from valve_dolfinx.geometry.distributed import create_valve_domain, write_domain_xdmf
from valve_dolfinx.geometry.outline import GraftSize
from valve_dolfinx.geometry.valve import DEFAULT_MESH_SIZE, build_valve
from valve_dolfinx.io import export_valve_vtu
from valve_dolfinx.plotting import leaflet_outline, plot_flat_leaflet, plot_valve_3d


def main(argv: list[str] | None = None) -> list[Path]:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--out", type=Path, default=Path("results/geometry"))
    parser.add_argument("--mesh-size", type=float, default=DEFAULT_MESH_SIZE)
    parser.add_argument("--graft-width", type=float, default=21.0, help="W in per cent")
    parser.add_argument("--graft-height", type=float, default=27.0, help="H in per cent")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    comm = MPI.COMM_WORLD
    out: Path = args.out
    written: list[Path] = []

    # %% [markdown]
    # ## The normal valve
    # Built serially on rank 0 (Gmsh), distributed by DOLFINx.

    # %%
    normal = build_valve(mesh_size=args.mesh_size) if comm.rank == 0 else None
    domain = create_valve_domain(normal, comm)
    write_domain_xdmf(domain, out / "normal_valve.xdmf")

    # %% [markdown]
    # ## The graft valve
    # The graft's flat outline is the native one scaled by $(1+W, 1+H)$; it is
    # placed slack on the native leaflet's wrapped surface.

    # %%
    graft = (build_valve(mesh_size=args.mesh_size, graft_width_pct=args.graft_width,
                         graft_height_pct=args.graft_height) if comm.rank == 0 else None)
    graft_domain = create_valve_domain(graft, comm)
    tag = GraftSize(args.graft_width, args.graft_height).stem
    write_domain_xdmf(graft_domain, out / f"graft_valve_{tag}.xdmf")

    # %% [markdown]
    # ## Pictures (rank 0)

    # %%
    if comm.rank == 0:
        patch = normal.leaflets[0]
        tri_fibres = normal.fibres[normal.cell_tags == patch.tag]
        plot_flat_leaflet(
            patch.flat, patch.triangles, out / "flat_leaflet.png", fibres=tri_fibres,
            title=f"flat native leaflet, mesh size {args.mesh_size:g} mm: "
                  f"{len(patch.flat)} nodes, {len(patch.triangles)} triangles")
        gpatch = graft.leaflet("non_coronary")
        plot_flat_leaflet(gpatch.flat, gpatch.triangles, out / f"flat_graft_{tag}.png",
                          outline=leaflet_outline(patch),
                          title=f"flat graft {tag} (black: native outline)")
        plot_valve_3d(normal.points, normal, out / "normal_valve.png", view="side",
                      title=f"normal valve, d = 20 mm ({normal.num_cells} triangles), open")
        plot_valve_3d(graft.points, graft, out / f"graft_valve_{tag}.png", view="side",
                      title=f"graft valve {tag}: the graft placed slack, open")
        written += [out / "flat_leaflet.png", out / f"flat_graft_{tag}.png",
                    out / "normal_valve.png", out / f"graft_valve_{tag}.png"]
        export_valve_vtu(normal, out / "normal_valve.vtu")
        export_valve_vtu(graft, out / f"graft_valve_{tag}.vtu")
        for p in written:
            logging.info("wrote %s", p)
    return written



if __name__ == "__main__":
    main()
