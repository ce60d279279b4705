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

Run: ``.venv/bin/python benchmarks/contact.py`` (single-threaded; prints tables).
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402

import numpy as np  # noqa: E402

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


def growth_exponent(rows: list[dict[str, float]], key: str) -> float:
    """Least-squares slope of log(rows[key]) against log(triangles)."""
    n = np.log([r["triangles"] for r in rows])
    return float(np.polyfit(n, np.log([r[key] for r in rows]), 1)[0])


def print_table(title: str, rows: list[dict[str, float]]) -> None:
    print(f"\n{title}")
    head = (f"{'triangles':>9} {'nodes':>6} {'AABB pairs':>10} {'AABB s':>7} {'prism pairs':>11} "
            f"{'active':>6} {'detect s':>8} {'forces s':>8} {'det+f s':>7} {'µs/tri':>6} "
            f"{'Jacob. s':>8} {'total s':>7} {'CPU d+f':>7} {'CPU tot':>7} {'blocks':>8} "
            f"{'peak MiB':>8}")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['triangles']:>9d} {r['nodes']:>6d} {r['aabb']:>10d} {r['t_aabb']:>7.4f} "
              f"{r['prism']:>11d} {r['active']:>6d} {r['detection']:>8.4f} {r['forces']:>8.4f} "
              f"{r['detect+forces']:>7.4f} {1e6 * r['detect+forces'] / r['triangles']:>6.2f} "
              f"{r['jacobian']:>8.4f} {r['total']:>7.4f} {r['cpu detect+forces']:>7.4f} "
              f"{r['cpu total']:>7.4f} {r['blocks']:>8d} {r['peak']:>8.1f}")
    for small, large in zip(rows[:-1], rows[1:], strict=True):
        ratio = large["triangles"] / small["triangles"]
        nlogn = ratio * np.log(large["triangles"]) / np.log(small["triangles"])
        print(f"  {small['triangles']:>6d} → {large['triangles']:>6d} triangles: detection + "
              f"forces ×{large['detect+forces'] / small['detect+forces']:.2f}, total "
              f"×{large['total'] / small['total']:.2f} (N log N: ×{nlogn:.2f}, prism pairs "
              f"×{large['prism'] / small['prism']:.2f})")
    print(f"  fitted growth exponent α (time ∝ N^α): detection + forces "
          f"{growth_exponent(rows, 'detect+forces'):.2f}, total "
          f"{growth_exponent(rows, 'total'):.2f}, prism pairs "
          f"{growth_exponent(rows, 'prism'):.2f}, "
          f"Jacobian blocks {growth_exponent(rows, 'blocks'):.2f}")


def load_average() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} CPUs"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--sizes", type=int, nargs="+", default=[2_000, 8_000, 32_000, 128_000],
                        help="approximate numbers of triangles")
    args = parser.parse_args()
    print(f"before: {load_average()}")
    length = float(np.sqrt(700.0 / 3.0))
    refine = [measure(round(np.sqrt(m / 6)), length, args.repeats) for m in args.sizes]
    print_table(f"Refinement: 3 sheets of {length:.1f} mm, gap {GAP} mm over half the width "
                f"(target: detection + forces <= 0.1 s at 32k triangles)", refine)
    spacing = length / round(np.sqrt(32_000 / 6))
    grow = [measure(c, c * spacing, args.repeats)
            for c in (round(np.sqrt(m / 6)) for m in args.sizes)]
    print_table(f"Fixed mesh size {spacing:.3f} mm, growing area (algorithmic scaling)", grow)
    print(f"after: {load_average()}")


if __name__ == "__main__":
    main()
