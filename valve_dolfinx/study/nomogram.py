"""The sizing nomogram: the recommended graft against the loaded root diameter (SPEC §7).

A study whose one comparison axis is the loaded root diameter
(``root.loaded_diameter_mm``, numbers only) -- what ``valve-dolfinx nomogram
--root-diameters 18 19 ...`` runs, with the numerical paths (and any
``--uncertain`` axis) as the members -- also writes:

* ``nomogram.csv``: one row per diameter, the recommendation of that diameter
  (:data:`NOMOGRAM_COLUMNS`);
* ``nomogram.png``: the recommended width and height enlargements and the margin
  against the diameter; a diameter where no graft on the grid qualifies is
  shaded, with the best graft and its shortfall.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from valve_dolfinx.plotting.study import plot_nomogram
from valve_dolfinx.sizing.recommendation import Recommendation
from valve_dolfinx.study.axes import value_text
from valve_dolfinx.study.layout import StudyLayout
from valve_dolfinx.study.table import write_csv

__all__ = ["NOMOGRAM_KEY", "NOMOGRAM_COLUMNS", "is_nomogram", "nomogram_rows",
           "write_nomogram"]

#: the comparison axis of a nomogram
NOMOGRAM_KEY = "root.loaded_diameter_mm"
#: the columns of ``nomogram.csv``: the diameter; the recommended graft, its enlargements,
#: flat area, margin (mm) and limiting member, its worst-case minimum coaptation height and
#: the limiting member's target; when none qualifies, the best graft, its enlargements and
#: shortfall (mm); the number of members of each cell; and the normal valve at that
#: diameter: its minimum coaptation height (mm) and whether it is competent (a normal valve
#: that leaks sets a target no repair should be measured against); the tolerance (mm) and the
#: band of qualifying sizes (its least and greatest W and H)
NOMOGRAM_COLUMNS = (
    "root_loaded_diameter_mm", "recommended", "graft_width_pct", "graft_height_pct",
    "flat_area_ratio", "solved", "margin_mm", "limiting_member", "min_coaptation_height_mm",
    "target_mm", "best", "best_width_pct", "best_height_pct", "shortfall_mm", "members",
    "normal_min_coaptation_mm", "normal_competent", "tolerance_mm", "band_width_min_pct",
    "band_width_max_pct", "band_height_min_pct", "band_height_max_pct",
)


def is_nomogram(layout: StudyLayout) -> bool:
    """A study whose one comparison axis is the loaded root diameter, in millimetres."""
    compared = [a for a in layout.axes if a.is_comparison]
    return (len(compared) == 1 and compared[0].key == NOMOGRAM_KEY
            and all(isinstance(v, float) for v in compared[0].values))


def nomogram_rows(recommendations: Sequence[Recommendation],
                  results: Sequence[dict] = ()) -> list[dict]:
    """One row per diameter (:data:`NOMOGRAM_COLUMNS`), by increasing diameter (the figure's
    axis); the normal valve's columns come from the study's result rows ``results`` (empty
    without them)."""
    normals = {row.get(NOMOGRAM_KEY): row for row in results
               if row.get("graft_width_pct") is None and row.get("status") == "finished"}
    rows = []
    for rec in recommendations:
        normal = normals.get(rec.comparison[NOMOGRAM_KEY], {})
        answer = rec.answer
        chosen, best, band = answer.size, answer.closest, answer.band
        limit = answer.limiting_member
        rows.append({
            "root_loaded_diameter_mm": rec.comparison[NOMOGRAM_KEY],
            "recommended": chosen.label if chosen else "",
            "graft_width_pct": chosen.width_pct if chosen else None,
            "graft_height_pct": chosen.height_pct if chosen else None,
            "flat_area_ratio": chosen.area_ratio if chosen else None,
            "solved": rec.solved if chosen else None,
            "margin_mm": answer.margin_mm,
            "limiting_member": limit if limit is not None else "",
            "min_coaptation_height_mm": answer.predicted_height_mm,
            "target_mm": answer.targets_mm.get(limit) if limit is not None else rec.target_mm,
            "best": best.label if best else "",
            "best_width_pct": best.width_pct if best else None,
            "best_height_pct": best.height_pct if best else None,
            "shortfall_mm": answer.shortfall_mm,
            "members": len(rec.members),
            "normal_min_coaptation_mm": normal.get("min_coaptation_height_mm"),
            "normal_competent": normal.get("competent"),
            "tolerance_mm": answer.tolerance_mm,
            **{f"band_{what}_{end}_pct": (band[f"{what}_pct"][k] if band else None)
               for what in ("width", "height") for k, end in enumerate(("min", "max"))},
        })
    return sorted(rows, key=lambda row: row["root_loaded_diameter_mm"])


def _footnote(layout: StudyLayout, recommendations: Sequence[Recommendation],
              rows: Sequence[dict]) -> str:
    """The settings a nomogram stands on, for its footnote."""
    first = next((r for r in rows if r.get("parameters")), {})
    params = first.get("parameters") or {}
    mesh = (params.get("geometry") or {}).get("mesh_size_mm")
    pressure = (params.get("loading") or {}).get("pressure_mmhg")
    widths = sorted({w for w, _ in layout.sizes})
    heights = sorted({h for _, h in layout.sizes})
    paths = ", ".join(p.name for p in layout.paths)
    uncertain = "; ".join(f"uncertain {a.key}: {', '.join(value_text(v) for v in a.values)}"
                          for a in layout.axes if not a.is_comparison)
    source = recommendations[0].target_source if recommendations else ""
    n = len(layout.sizes)
    design = (f"Per diameter: the normal valve and {n} graft{'s' if n != 1 else ''} (W "
              f"{', '.join(f'{w:g}' for w in widths)} %; H "
              f"{', '.join(f'{h:g}' for h in heights)} % of the native leaflet)" if n else
              f"The normal valve per diameter and an adaptive design of {layout.graft_cases} "
              f"graft cases in {len(layout.rounds)} rounds")
    parts = [f"{design} along {len(layout.paths)} numerical path(s) ({paths})"
             + (f"; {uncertain}" if uncertain else "") + ".",
             f"Read from one response surface over W, H and the diameter: the smallest flat area "
             f"whose predicted worst case reaches the target ({source}) within the tolerance and "
             "that seals with probability 0.9 in every member; bars: the band of sizes that also "
             "qualify; margin = predicted worst case minus target; under each diameter, the "
             "normal valve's minimum coaptation height.",
             f"Mesh {mesh if mesh is not None else '?'} mm, "
             f"{pressure if pressure is not None else '?'} mmHg, valve_dolfinx "
             f"{(first.get('versions') or {}).get('valve_dolfinx', '?')}."]
    return "\n".join(parts)


def write_nomogram(out: Path, recommendations: Sequence[Recommendation], layout: StudyLayout,
                   rows: Sequence[dict]) -> list[Path]:
    """Write ``nomogram.csv`` and ``nomogram.png`` into ``out``; the files written."""
    out = Path(out)
    table = nomogram_rows(recommendations, rows)
    csv_path = write_csv(out / "nomogram.csv", table, NOMOGRAM_COLUMNS)
    png = out / "nomogram.png"
    plot_nomogram(table, png, title="Pericardial graft sizing nomogram: the smallest graft "
                  "that seals and coapts\nlike the normal valve, against the loaded root "
                  "diameter", footnote=_footnote(layout, recommendations, rows))
    return [csv_path, png]
