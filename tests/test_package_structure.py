"""The package's structure: no module imports itself back through others, and the settings
of a case and of a study load, validate and lay out a study without DOLFINx."""

from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "valve_dolfinx"


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
