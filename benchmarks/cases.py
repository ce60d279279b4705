"""What the closure benchmarks share: case names on the command line, their common options,
and one case per single-threaded worker subprocess that prints its figures back."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

from valve_dolfinx.geometry.outline import GraftSize

#: prefix of the worker's line of figures on its standard output
MARK = "BENCHMARK-RESULT "
#: one BLAS/OpenMP thread per worker: a case is measured on one core
SINGLE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}

Case = tuple[float, float] | None


class WorkerFailed(RuntimeError):
    """A worker subprocess ended (or was stopped) without printing its figures."""


def parse_case(text: str) -> Case:
    """``normal`` -> None; ``W21/H27`` (or ``W21_H27``, ``21/27``) -> (21.0, 27.0)."""
    if text.strip().lower() == "normal":
        return None
    match = re.fullmatch(r"\s*W?([\d.]+)\s*[/_,x]\s*H?([\d.]+)\s*", text, re.IGNORECASE)
    if match is None:
        raise argparse.ArgumentTypeError(f"case {text!r}: expected 'normal' or 'W<w>/H<h>'")
    return float(match[1]), float(match[2])


def parse_cases(text: str) -> list[Case]:
    """Comma-separated case names, e.g. ``normal,W27/H0``."""
    return [parse_case(c) for c in text.split(",")]


def case_label(case: Case) -> str:
    """``normal`` or ``W<w>/H<h>`` (what :func:`parse_case` reads)."""
    return "normal" if case is None else GraftSize(*case).label


def case_config(case: Case, mesh_size: float):
    """The default configuration of ``case`` (None: the normal valve) at ``mesh_size``."""
    from valve_dolfinx.config import CaseConfig
    from valve_dolfinx.geometry.valve import ValveParameters

    config = CaseConfig(geometry=ValveParameters(mesh_size=mesh_size))
    return config if case is None else config.with_graft(*case)


def add_common_arguments(parser: argparse.ArgumentParser, default_cases: Sequence[Case]
                         ) -> None:
    """``--cases``, ``--mesh-size``, ``--json`` and the workers' hidden ``--worker``."""
    parser.add_argument("--cases", type=parse_cases, default=list(default_cases),
                        help="comma-separated, e.g. normal,W21/H27 (default: all)")
    parser.add_argument("--mesh-size", type=float, default=None,
                        help="mesh size (mm); default: the package's (0.8 mm)")
    parser.add_argument("--json", type=Path, default=None, help="write the figures to FILE")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)


def parse_arguments(parser: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Parse the command line; a missing ``--mesh-size`` becomes the package's default."""
    args = parser.parse_args(argv)
    if args.mesh_size is None:
        from valve_dolfinx.geometry.valve import DEFAULT_MESH_SIZE
        args.mesh_size = DEFAULT_MESH_SIZE
    return args


def report(figures) -> None:
    """In a worker: print the figures (JSON) for the parent to read."""
    print(MARK + json.dumps(figures), flush=True)


def run_worker(script: str, case: str, mesh_size: float, options: Sequence[str] = (),
               timeout: float | None = None):
    """Run ``script --worker`` on one case in a single-threaded subprocess; its figures.

    Raises :class:`WorkerFailed` if it ends without reporting them or runs past
    ``timeout`` seconds.
    """
    command = [sys.executable, os.path.abspath(script), "--worker", "--cases", case,
               "--mesh-size", str(mesh_size), *options]
    try:
        done = subprocess.run(command, stdout=subprocess.PIPE, text=True,
                              env={**os.environ, **SINGLE_THREAD}, timeout=timeout)
    except subprocess.TimeoutExpired as error:
        raise WorkerFailed(f"killed after {timeout:g} s") from error
    for line in done.stdout.splitlines():
        if line.startswith(MARK):
            return json.loads(line[len(MARK):])
    raise WorkerFailed(f"worker exited with {done.returncode} and no result")


def cell(value, fmt: str) -> str:
    """A table cell: ``-`` for a missing or NaN value, ``fmt`` ``"s"`` for text."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return str(value) if fmt == "s" else format(value, fmt)
