"""The benchmarks' tables: figures in a CSV, the Markdown the docs link to drawn from it.

A benchmark writes its figures, one row per measurement at full precision, to
``benchmarks/results/<name>.csv`` and draws ``benchmarks/results/<name>.md`` from that file
alone (:meth:`Table.write`).  The docs link to the Markdown and copy no figure from it, so
a rerun updates what they show.  ``--tables-only`` (:func:`add_tables_only`) redraws the
Markdown from the CSV already there without measuring anything, after a change of how the
table is drawn; ``--results DIR`` sends both files elsewhere (a smoke test).  Empty cells
of the CSV are missing values; ``true``/``false`` are booleans.
"""

from __future__ import annotations

import argparse
import csv
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from valve_dolfinx.io import atomic_write

#: where the benchmarks write their tables
RESULTS = Path(__file__).resolve().parent / "results"

#: what a missing or undefined figure shows
MISSING = "–"


def parse(text: str):
    """A CSV cell as written by :func:`format_csv`: None, a bool, an int, a float or text."""
    if text == "":
        return None
    if text in ("true", "false"):
        return text == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def format_csv(value) -> str:
    """A value as a CSV cell that :func:`parse` reads back unchanged (floats by ``repr``;
    a non-finite float, like None, as an empty cell)."""
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def cell(value, fmt: str = "") -> str:
    """A Markdown table cell: :data:`MISSING` for None or NaN, ``yes``/``no`` for a bool,
    a number by the format spec ``fmt`` (its ``,`` grouping thousands by a space)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return MISSING
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, int | float) and fmt:
        return format(value, fmt).replace(",", " ")
    return str(value)


@dataclass(frozen=True)
class Column:
    """A column of a Markdown table: its heading, the CSV field (or a function of the row)
    it shows, the number format, and whether it is text (left-aligned)."""

    heading: str
    value: str | Callable[[dict], object]
    fmt: str = ""
    text: bool = False

    def of(self, row: dict) -> str:
        value = row.get(self.value) if isinstance(self.value, str) else self.value(row)
        return cell(value, self.fmt)


def markdown_table(columns: Sequence[Column], rows: Sequence[dict]) -> str:
    """A Markdown table with a line per row."""
    lines = ["| " + " | ".join(c.heading for c in columns) + " |",
             "|" + "|".join("---" if c.text else "---:" for c in columns) + "|"]
    lines += ["| " + " | ".join(c.of(row) for c in columns) + " |" for row in rows]
    return "\n".join(lines) + "\n"


@dataclass(frozen=True)
class Table:
    """A benchmark's table: ``results/<name>.csv`` with ``fields``, and ``results/<name>.md``
    that ``draw`` makes from the CSV's rows, under a line naming ``command``."""

    name: str
    command: str
    fields: tuple[str, ...]
    draw: Callable[[list[dict]], str]
    folder: Path = RESULTS

    @property
    def csv_path(self) -> Path:
        return self.folder / f"{self.name}.csv"

    @property
    def markdown_path(self) -> Path:
        return self.folder / f"{self.name}.md"

    def header(self) -> str:
        return (f"_Written by `{self.command}`: the figures in [{self.name}.csv]({self.name}.csv), "
                f"this table drawn from them (`--tables-only` redraws it); do not edit by "
                f"hand._\n")

    def write(self, rows: Sequence[dict]) -> Path:
        """Write the rows to the CSV, then the Markdown drawn from the CSV; the Markdown's
        path."""
        self.folder.mkdir(parents=True, exist_ok=True)
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=self.fields, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({f: format_csv(row.get(f)) for f in self.fields})
        atomic_write(self.csv_path, lambda tmp: tmp.write_text(buffer.getvalue()))
        return self.redraw()

    def read(self) -> list[dict]:
        """The CSV's rows, each cell parsed (:func:`parse`)."""
        with open(self.csv_path, newline="") as fh:
            return [{k: parse(v) for k, v in row.items()} for row in csv.DictReader(fh)]

    def render(self) -> str:
        """The Markdown drawn from the CSV."""
        return self.header() + "\n" + self.draw(self.read())

    def at(self, folder: Path) -> Table:
        """The same table in another folder."""
        return replace(self, folder=Path(folder))

    def arguments(self, parser: argparse.ArgumentParser, argv: Sequence[str] | None = None,
                  parse: Callable | None = None) -> argparse.Namespace:
        """A benchmark's command line: ``parser`` with ``--tables-only`` and ``--results DIR``
        parsed from ``argv`` (by ``parse(parser, argv)`` if given, e.g. one that fills in
        defaults), ``args.table`` this table in that folder.  ``--tables-only`` redraws the
        Markdown from the CSV, prints its path and exits."""
        add_table_options(parser)
        args = parse(parser, argv) if parse is not None else parser.parse_args(argv)
        args.table = self.at(args.results)
        if args.tables_only:
            print(args.table.redraw())
            raise SystemExit(0)
        return args

    def redraw(self) -> Path:
        """Draw the Markdown from the CSV; its path."""
        if not self.csv_path.is_file():
            raise FileNotFoundError(f"{self.csv_path}: no figures to draw the table from; run "
                                    f"`{self.command}` first")
        text = self.render()
        return atomic_write(self.markdown_path, lambda tmp: tmp.write_text(text))


def add_tables_only(parser: argparse.ArgumentParser) -> None:
    """``--tables-only``: redraw the Markdown from the CSV, measure nothing."""
    parser.add_argument("--tables-only", action="store_true",
                        help="redraw the Markdown table(s) from the CSV already there, "
                        "without running anything")


def add_table_options(parser: argparse.ArgumentParser) -> None:
    """``--tables-only`` and ``--results DIR`` (where the CSV and the Markdown go; a smoke
    test's elsewhere than the documented figures)."""
    add_tables_only(parser)
    parser.add_argument("--results", type=Path, default=RESULTS, metavar="DIR",
                        help="folder of the CSV and the Markdown (default: %(default)s)")
