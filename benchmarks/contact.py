"""Cost of one contact evaluation (detection + forces + Jacobian blocks) vs mesh size.

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
active contacts, then the model's own timings — broad phase (grid build and
box queries), narrow phase + forces + Jacobian blocks — and the peak memory
traced during one evaluation.  Times are the fastest of ``--repeats`` runs.

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
    params = ContactParameters()
    contact = SurfaceContact(tris, len(x), params, triangle_body=body)
    contact.update_history(x)
    pad = params.search_distance
    (aabb, _), t_aabb = fastest(lambda: candidate_pairs(x, tris, None, pad), repeats)
    prism, _ = candidate_pairs(x, tris, None, pad, prism=True)
    (result, timings), t_total = fastest(lambda: (contact.evaluate(x, fext), contact.timings),
                                         repeats)
    tracemalloc.start()
    contact.evaluate(x, fext)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {"triangles": len(tris), "nodes": len(x), "aabb": len(aabb), "prism": len(prism),
            "active": result.n_active, "t_aabb": t_aabb, "broad": timings["broad"],
            "narrow": t_total - timings["broad"], "total": t_total, "peak": peak / 2**20}


def print_table(title: str, rows: list[dict[str, float]]) -> None:
    print(f"\n{title}")
    head = (f"{'triangles':>9} {'nodes':>6} {'AABB pairs':>10} {'AABB s':>7} {'prism pairs':>11} "
            f"{'active':>6} {'broad s':>7} {'narrow+f s':>10} {'total s':>7} {'peak MiB':>8} "
            f"{'µs/tri':>6}")
    print(head)
    print("-" * len(head))
    for r in rows:
        print(f"{r['triangles']:>9d} {r['nodes']:>6d} {r['aabb']:>10d} {r['t_aabb']:>7.4f} "
              f"{r['prism']:>11d} {r['active']:>6d} {r['broad']:>7.4f} {r['narrow']:>10.4f} "
              f"{r['total']:>7.4f} {r['peak']:>8.1f} {1e6 * r['total'] / r['triangles']:>6.2f}")
    for small, large in zip(rows[:-1], rows[1:], strict=True):
        ratio = large["triangles"] / small["triangles"]
        nlogn = ratio * np.log(large["triangles"]) / np.log(small["triangles"])
        print(f"  {small['triangles']:>6d} → {large['triangles']:>6d} triangles: time "
              f"×{large['total'] / small['total']:.2f} (N log N: ×{nlogn:.2f}, pairs "
              f"×{large['prism'] / small['prism']:.2f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    length = float(np.sqrt(700.0 / 3.0))
    sizes = [2_000, 8_000, 32_000, 128_000]
    refine = [measure(round(np.sqrt(m / 6)), length, args.repeats) for m in sizes]
    print_table(f"Refinement: 3 sheets of {length:.1f} mm, "
                f"gap {GAP} mm over half the width (target: total <= 0.1 s at 32k)", refine)
    spacing = length / round(np.sqrt(32_000 / 6))
    grow = [measure(c, c * spacing, args.repeats) for c in (round(np.sqrt(m / 6)) for m in sizes)]
    print_table(f"Fixed mesh size {spacing:.3f} mm, growing area (algorithmic scaling)", grow)


if __name__ == "__main__":
    main()
