"""The package's structure: no module imports itself back through others, no function
outside the tests runs over 80 lines of code without a reason written beside it, and the
settings of a case and of a study load, validate and lay out a study without DOLFINx."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "valve_dolfinx"
#: the folders whose functions are held to :data:`MAX_CODE_LINES`
SOURCES = ("valve_dolfinx", "benchmarks", "demos")
#: the most lines of code a function may have without a ``# long: <reason>`` on its signature
MAX_CODE_LINES = 80
_LONG = re.compile(r"#\s*long:\s*\S")


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph() -> dict[str, set[str]]:
    """Every module of the package and the package modules it imports anywhere in its
    source: at module level, inside functions, and under ``if TYPE_CHECKING:``."""
    modules = {_module_name(p): p for p in PACKAGE.rglob("*.py")}

    def owner(name: str) -> str | None:  # the module a dotted name lives in
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph = {}
    for name, path in modules.items():
        targets = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets |= {owner(a.name) for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                targets |= {owner(f"{node.module}.{a.name}") for a in node.names}
        graph[name] = {t for t in targets if t and t != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The groups of modules that reach one another (strongly connected, more than one)."""
    def reach(start: str) -> set[str]:
        seen, todo = set(), [start]
        while todo:
            for nxt in graph[todo.pop()]:
                if nxt not in seen:
                    seen.add(nxt)
                    todo.append(nxt)
        return seen

    reached = {m: reach(m) for m in graph}
    groups = {frozenset({m} | {n for n in reached[m] if m in reached[n]}) for m in graph}
    return [set(g) for g in groups if len(g) > 1]


def test_the_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [{"a", "b", "c"}]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_of_the_package_imports_itself_back():
    graph = import_graph()
    assert {"valve_dolfinx.study.grid", "valve_dolfinx.study.layout"} <= set(graph)
    assert "valve_dolfinx.study.layout" in graph["valve_dolfinx.study.grid"]
    assert cycles(graph) == []


def _docstring_lines(tree: ast.AST) -> set[int]:
    """The lines of every docstring in ``tree`` (modules, classes, functions)."""
    lines = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0] if node.body else None
            if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                    and isinstance(first.value.value, str)):
                lines |= set(range(first.lineno, first.end_lineno + 1))
    return lines


def long_functions(source: str, limit: int = MAX_CODE_LINES) -> list[tuple[str, int]]:
    """The functions (nested ones included, each counted with what it contains) of more
    than ``limit`` lines of code -- blank lines, comments and docstrings not counted --
    whose signature carries no ``# long: <reason>``, as (name, lines of code)."""
    tree = ast.parse(source)
    text = source.splitlines()
    docs = _docstring_lines(tree)
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        code = sum(1 for n in range(node.lineno, node.end_lineno + 1)
                   if n not in docs and text[n - 1].strip()
                   and not text[n - 1].lstrip().startswith("#"))
        signature = text[node.lineno - 1:node.body[0].lineno - 1]
        if code > limit and not any(_LONG.search(line) for line in signature):
            found.append((node.name, code))
    return found


def test_the_length_count_skips_docstrings_comments_and_blank_lines():
    body = "".join(f"    x{k} = {k}\n" for k in range(4))
    source = (f'def short():\n    """A docstring\n\n    of four lines."""\n{body}'
              "    # a comment\n\n    return x0\n")
    assert long_functions(source, limit=6) == []  # the def, four lines and the return
    assert long_functions(source, limit=5) == [("short", 6)]
    marked = source.replace("def short():", "def short():  # long: one table, read in order")
    assert long_functions(marked, limit=5) == []
    nested = "def outer():\n" + textwrap.indent(source, "    ") + "    return short\n"
    assert long_functions(nested, limit=7) == [("outer", 8)]


def test_no_function_outside_the_tests_is_long_without_a_reason():
    """A function of more than 80 lines of code is split, or says why not on its signature
    (``# long: <reason>``)."""
    long = [f"{path.relative_to(ROOT)}:{name} ({lines} lines of code)"
            for folder in SOURCES for path in sorted((ROOT / folder).rglob("*.py"))
            for name, lines in long_functions(path.read_text())]
    assert long == []


def test_case_and_study_settings_need_no_dolfinx():
    """With DOLFINx, PETSc, MPI and Gmsh unimportable, a configuration loads and a study's
    settings validate and enumerate its cases: the normal valve once per comparison value
    (it depends on no path), every graft once per comparison value and path."""
    code = textwrap.dedent("""
        import sys

        class Unavailable:
            def find_spec(self, name, path=None, target=None):
                if name.partition(".")[0] in {"dolfinx", "petsc4py", "mpi4py", "gmsh",
                                              "basix", "ffcx"}:
                    raise ImportError(f"{name} is not available here")

        sys.meta_path.insert(0, Unavailable())
        from valve_dolfinx.config import config_toml, load_config
        from valve_dolfinx.study.grid import StudySettings

        config_toml(load_config(overrides=["loading.pressure_mmhg=90"]))
        settings = StudySettings(widths_pct=(0.0, 14.0), heights_pct=(13.0,), paths=2,
                                 vary={"native.bending_modulus_kpa": [0, 200]})
        names = [case.name for case in settings.layout().cases]
        assert len(names) == 2 + 2 * 2 * 2, names
        assert names[:2] == ["normal__native.bending_modulus_kpa=0",
                             "normal__native.bending_modulus_kpa=200"]
        assert "W14_H13__native.bending_modulus_kpa=200__path=2" in names
        print("ok")
    """)
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr
