"""Cost of one contact evaluation (detection + forces, and the Jacobian blocks) vs mesh size.

Surfaces: three wavy sheets (three bodies, like three leaflets) of
15.3 mm × 15.3 mm each — together ~700 mm², the leaflet area of a 23 mm valve —
stacked 0.06 mm apart over half of their width (fully coapted there, so the
middle sheet touches both others) and opening up to 1 mm over the other half.
Nodes are jittered in-plane so the triangulation is irregular.  The same
geometry is meshed with 2k … 128k triangles, so this is a refinement study:
with a fixed search distance (0.2 mm) the candidates per node grow as the
mesh gets finer than the search distance.  A second table keeps the mesh size
fixed and grows the area, which isolates the algorithmic scaling.

Columns: padded-AABB pairs (what :func:`candidate_pairs` returns, and its
time alone), contact-prism pairs (the tighter boxes the model queries),
active contacts, then the model's own timings (``SurfaceContact.timings``):
detection (broad phase: grid build and box queries; narrow phase: exact
point–triangle tests, sides, penetration window), forces (blending, the SPEC
§5 law, nodal forces and reactions) — the two together are the figure the
target applies to — then the Jacobian blocks and the whole evaluation, the
number of 3×3 Jacobian blocks (summed per node pair) and the peak memory traced during one
evaluation.  Times are wall-clock, the fastest of ``--repeats`` runs; the "CPU"
columns are the same in process time (which leaves out waiting for a core on a
loaded machine, but counts the kernel's page-fault work); below each table the
growth exponent ``α`` of ``time ∝ N^α`` fitted by least squares over the sizes
(N log N between 2k and 128k is α ≈ 1.1).  The load average of the machine is
printed before and after, since other work on a shared machine slows the runs.

The figures go to ``benchmarks/results/contact.csv`` (a row per surface and series) and the
tables drawn from them to ``contact.md`` (``--tables-only`` redraws them from the CSV).

Run: ``.venv/bin/python benchmarks/contact.py`` (single-threaded).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402

# benchmarks/result_tables.py, beside this script
from result_tables import Column, Table, markdown_table  # noqa: E402

from valve_dolfinx.contact import ContactParameters, SurfaceContact, candidate_pairs  # noqa: E402

PRESSURE = 10.0     # kPa = mN/mm², a closing transvalvular pressure of ~75 mmHg
GAP = 0.06          # mm between coapted sheets
WAVE = (1.0, 8.0)   # amplitude and wavelength (mm) of the sheets' waviness


def stacked_sheets(cells: int, length: float, sheets: int = 3, seed: int = 0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Positions, triangles, body labels and nodal pressure forces of wavy stacked sheets."""
    rng = np.random.default_rng(seed)
    h = length / cells
    u = np.linspace(0.0, length, cells + 1)
    X, Y = (a.ravel() for a in np.meshgrid(u, u, indexing="ij"))
    interior = (X > 0) & (X < length) & (Y > 0) & (Y < length)
    i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    v = (i * (cells + 1) + j).ravel()
    quads = np.stack([v, v + cells + 1, v + cells + 2, v + 1], axis=1)
    sheet_tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    amplitude, wavelength = WAVE
    gap = GAP + (1.0 - GAP) * np.clip(2.0 * X / length - 1.0, 0.0, 1.0)
    xs, tris, body, fext = [], [], [], []
    for k in range(sheets):
        jitter = 0.2 * h * rng.uniform(-1, 1, (len(X), 2)) * interior[:, None]
        x, y = X + jitter[:, 0], Y + jitter[:, 1]
        z = (amplitude * np.sin(2 * np.pi * x / wavelength) * np.sin(2 * np.pi * y / wavelength)
             + (k - (sheets - 1) / 2) * gap)
        xs.append(np.stack([x, y, z], axis=1))
        tris.append(sheet_tris + k * len(X))
        body.append(np.full(len(sheet_tris), k))
        push = -np.sign(k - (sheets - 1) / 2) or 1.0     # outer sheets pushed inwards
        fext.append(np.tile([0.0, 0.0, push * PRESSURE * h * h], (len(X), 1)))
    return np.concatenate(xs), np.concatenate(tris), np.concatenate(body), np.concatenate(fext)


def fastest(fn, repeats: int):
    """Return value and wall time (s) of the fastest of ``repeats`` calls."""
    best = (None, np.inf)
    for _ in range(repeats):
        t0 = time.perf_counter()
        value = fn()
        elapsed = time.perf_counter() - t0
        if elapsed < best[1]:
            best = (value, elapsed)
    return best


def measure(cells: int, length: float, repeats: int) -> dict[str, float]:
    x, tris, body, fext = stacked_sheets(cells, length)
    # the SPEC law on zero-thickness sheets: no contact layer, search distance 0.2 mm
    params = ContactParameters(thickness=0.0, crossing_stiffness=0.0, penetration_depth=0.2,
                               blend_distance=0.01)
    contact = SurfaceContact(tris, len(x), params, triangle_body=body)
    contact.record_cpu_time = True
    contact.update_history(x)
    pad = params.search_distance
    (aabb, _), t_aabb = fastest(lambda: candidate_pairs(x, tris, None, pad), repeats)
    prism, _ = candidate_pairs(x, tris, None, pad, prism=True)
    best = dict.fromkeys(("detection", "forces", "detect+forces", "jacobian", "total",
                          "cpu detect+forces", "cpu total"), np.inf)
    for _ in range(repeats):
        contact.forget_search()
        t0, c0 = time.perf_counter(), time.process_time()
        result = contact.evaluate(x, fext)
        total, cpu_total = time.perf_counter() - t0, time.process_time() - c0
        laps, cpu = contact.timings, contact.cpu_timings
        detection = laps["broad"] + laps["narrow"]
        run = {"detection": detection, "forces": laps["forces"],
               "detect+forces": detection + laps["forces"], "jacobian": laps["jacobian"],
               "total": total, "cpu total": cpu_total,
               "cpu detect+forces": cpu["broad"] + cpu["narrow"] + cpu["forces"]}
        best = {key: min(best[key], run[key]) for key in best}
    contact.forget_search()
    tracemalloc.start()
    contact.evaluate(x, fext)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"triangles": len(tris), "nodes": len(x), "aabb": len(aabb), "prism": len(prism),
            "active": result.n_active, "t_aabb": t_aabb, "blocks": len(result.jac_blocks),
            "peak": peak / 2**20, **best}


#: the measured figures of one surface (see :func:`measure`)
FIGURES = ("triangles", "nodes", "aabb", "t_aabb", "prism", "active", "detection", "forces",
           "detect+forces", "jacobian", "total", "cpu detect+forces", "cpu total", "blocks",
           "peak")
#: the two series: refinement of one surface, and a growing surface at one mesh size
SERIES = {"refine": "Refinement: 3 sheets of {length:.1f} mm, gap {gap} mm over half the width "
                    "(target: detection + forces <= 0.1 s at 32k triangles)",
          "grow": "Fixed mesh size {spacing:.3f} mm, growing area (algorithmic scaling)"}
COLUMNS = [Column("triangles", "triangles", ","), Column("nodes", "nodes", ","),
           Column("AABB pairs", "aabb", ","), Column("AABB s", "t_aabb", ".4f"),
           Column("prism pairs", "prism", ","), Column("active", "active", ","),
           Column("detect s", "detection", ".4f"), Column("forces s", "forces", ".4f"),
           Column("det+f s", "detect+forces", ".4f"),
           Column("µs/tri", lambda r: 1e6 * r["detect+forces"] / r["triangles"], ".2f"),
           Column("Jacob. s", "jacobian", ".4f"), Column("total s", "total", ".4f"),
           Column("CPU d+f", "cpu detect+forces", ".4f"), Column("CPU tot", "cpu total", ".4f"),
           Column("blocks", "blocks", ","), Column("peak MiB", "peak", ".1f")]


def growth_exponent(rows: list[dict[str, float]], key: str) -> float:
    """Least-squares slope of log(rows[key]) against log(triangles)."""
    n = np.log([r["triangles"] for r in rows])
    return float(np.polyfit(n, np.log([r[key] for r in rows]), 1)[0])


def draw(rows: list[dict]) -> str:
    """Per series its table, the growth from one size to the next and the fitted exponents;
    the machine's load before and after."""
    parts = [f"Before: {rows[0]['load_before']}; after: {rows[0]['load_after']}.\n"]
    for series in dict.fromkeys(r["series"] for r in rows):
        mine = [r for r in rows if r["series"] == series]
        parts += [f"{mine[0]['title']}:\n", markdown_table(COLUMNS, mine)]
        lines = []
        for small, large in zip(mine[:-1], mine[1:], strict=True):
            ratio = large["triangles"] / small["triangles"]
            nlogn = ratio * np.log(large["triangles"]) / np.log(small["triangles"])
            lines.append(f"- {small['triangles']} → {large['triangles']} triangles: detection "
                         f"+ forces ×{large['detect+forces'] / small['detect+forces']:.2f}, "
                         f"total ×{large['total'] / small['total']:.2f} (N log N: "
                         f"×{nlogn:.2f}, prism pairs ×{large['prism'] / small['prism']:.2f})")
        if len(mine) > 1:
            lines.append(f"- fitted growth exponent α (time ∝ N^α): detection + forces "
                         f"{growth_exponent(mine, 'detect+forces'):.2f}, total "
                         f"{growth_exponent(mine, 'total'):.2f}, prism pairs "
                         f"{growth_exponent(mine, 'prism'):.2f}, Jacobian blocks "
                         f"{growth_exponent(mine, 'blocks'):.2f}")
        parts.append("\n".join(lines) + "\n")
    return "\n".join(parts)


TABLE = Table("contact", ".venv/bin/python benchmarks/contact.py",
              ("series", "title", *FIGURES, "load_before", "load_after"), draw)


def load_average() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} CPUs"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sizes", type=int, nargs="+", default=[2_000, 8_000, 32_000, 128_000],
                        help="approximate numbers of triangles")
    args = TABLE.arguments(parser)
    before = load_average()
    length = float(np.sqrt(700.0 / 3.0))
    spacing = length / round(np.sqrt(32_000 / 6))
    rows = []
    for size in args.sizes:
        cells = round(np.sqrt(size / 6))
        rows.append({"series": "refine", **measure(cells, length, args.repeats)})
    for size in args.sizes:
        cells = round(np.sqrt(size / 6))
        rows.append({"series": "grow", **measure(cells, cells * spacing, args.repeats)})
    after = load_average()
    for row in rows:
        row.update(title=SERIES[row["series"]].format(length=length, gap=GAP, spacing=spacing),
                   load_before=before, load_after=after)
    print(args.table.write(rows).read_text())


if __name__ == "__main__":
    main()
