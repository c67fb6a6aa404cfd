"""The house's layering, read from the source with :mod:`ast` (every import, also those inside functions).

- the simulator depends on the real code, never the reverse: no module outside ``drivers/sim`` imports
  ``drivers.sim`` (tests and ``bench/`` may; the registry names it only as strings, imported when chosen);
- ``analysis`` imports neither ``acq`` nor ``drivers``; ``drivers`` does not import ``acq``;
- outside ``analysis/`` the analysis is reached through its face, the package ``analysis`` (its
  ``__init__``), never a module of it (tests and ``bench/`` may);
- ``acqcore`` (the ground floor: errors) imports nothing of ours, and the catalogue and the readers of
  other tools' files need no ``drivers`` for it;
- no import cycles among the packages' modules, counting annotations-only imports under
  ``if TYPE_CHECKING:`` too (a cycle there is a cycle of the design, even when it never runs).
- presentation apart from computation: only ``acq.ui`` imports rich, click, Qt or matplotlib, and
  nothing outside it imports ``acq.ui`` (``MIXED`` names the modules still to be split).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).parents[1]
PACKAGES = ("acq", "acqcore", "analysis", "drivers")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_module(name: str) -> bool:
    """True when ``name`` is one of our modules or packages (``from pkg import submodule`` runs the submodule
    only, not ``pkg``'s ``__init__`` beyond what importing anything in ``pkg`` runs)."""
    path = ROOT.joinpath(*name.split("."))
    return path.with_suffix(".py").is_file() or (path / "__init__.py").is_file()


def _type_only(tree: ast.Module) -> set[ast.AST]:
    """The import statements under ``if TYPE_CHECKING:`` (never executed)."""
    guarded: set[ast.AST] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            guarded.update(n for stmt in node.body for n in ast.walk(stmt))
    return guarded


def _imports(path: Path, *, type_only: bool = True) -> set[str]:
    """Absolute names of the modules ``path`` imports (``from a.b import c`` gives ``a.b`` and ``a.b.c``),
    with or without those under ``if TYPE_CHECKING:``."""
    package = _module_name(path) if path.name == "__init__.py" else _module_name(path).rpartition(".")[0]
    names: set[str] = set()
    tree = ast.parse(path.read_text(), str(path))
    skip = set() if type_only else _type_only(tree)
    for node in ast.walk(tree):
        if node in skip:
            continue
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            submodules = {f"{base}.{alias.name}" for alias in node.names if _is_module(f"{base}.{alias.name}")}
            if len(submodules) < len(node.names):  # names defined by the module ``base`` itself
                names.add(base)
            names.update(submodules | {f"{base}.{alias.name}" for alias in node.names})
    return names


def import_graph(*, type_only: bool = True) -> dict[str, set[str]]:
    """Module → the modules of our packages it imports (also inside functions; type-only ones if asked)."""
    files = {_module_name(p): p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")}
    return {name: {m for m in _imports(path, type_only=type_only) if m in files and m != name}
            for name, path in files.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle per strongly connected component of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_no_module_outside_the_simulator_imports_it() -> None:
    offenders = {m: sorted(i for i in deps if i.startswith("drivers.sim"))
                 for m, deps in import_graph().items() if not m.startswith("drivers.sim")}
    assert {m: d for m, d in offenders.items() if d} == {}


def test_analysis_imports_neither_acq_nor_drivers() -> None:
    offenders = {m: sorted(i for i in deps if i.split(".")[0] in ("acq", "drivers"))
                 for m, deps in import_graph().items() if m.startswith("analysis")}
    assert {m: d for m, d in offenders.items() if d} == {}


def test_drivers_do_not_import_acq_and_the_ground_floor_imports_nothing_of_ours() -> None:
    graph = import_graph()
    assert {m: sorted(d) for m, d in graph.items() if m.startswith("drivers") and any(
        i.split(".")[0] == "acq" for i in d)} == {}
    assert {m: sorted(d) for m, d in graph.items() if m.startswith("acqcore") and any(
        i.split(".")[0] != "acqcore" for i in d)} == {}


def test_the_catalogue_and_the_file_readers_do_not_import_drivers() -> None:
    graph = import_graph()
    users = ("acq.monitoring.catalogue", "acq.monitoring.catalogue_db", "acq.monitoring.catalogue_backends",
             "acq.offline.csvtable", "acq.offline.import_files")
    assert {m: sorted(i for i in graph[m] if i.startswith("drivers")) for m in users} == {m: [] for m in users}


def test_outside_analysis_only_its_face_is_imported() -> None:
    offenders = {m: sorted(i for i in deps if i.startswith("analysis."))
                 for m, deps in import_graph().items() if not m.startswith("analysis")}
    assert {m: d for m, d in offenders.items() if d} == {}


def test_no_import_cycles() -> None:
    """Imports at module level, inside functions and under ``if TYPE_CHECKING:``."""
    assert _cycles(import_graph()) == []


def test_the_checker_finds_a_cycle_and_a_reverse_import() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert _cycles(graph) == [["a", "b", "c"]]
    assert "drivers.sim.bench" in _imports(ROOT / "tests" / "test_canopen.py")
    spans = _imports(ROOT / "analysis" / "stream_spans.py")  # from analysis import encoder: the module, not the face
    assert "analysis.encoder" in spans and "analysis" not in spans
    assert "acq.monitoring.batch" in _imports(ROOT / "acq" / "ui" / "display.py")  # under if TYPE_CHECKING


#: The modules that know the session file's HDF5 layout (``acq/recording/layout.py`` describes it).
SESSION_FILE_MODULES = {f"acq/recording/{name}.py" for name in ("layout", "writer", "reader", "repair", "session")}


def test_only_the_session_file_modules_read_root_attributes() -> None:
    """Outside the session file's modules session metadata is read through the typed ``Session.meta``."""
    readers = sorted(name for p in (ROOT / "acq").rglob("*.py") if (name := p.relative_to(ROOT).as_posix())
                     not in SESSION_FILE_MODULES
                     and any(isinstance(n, ast.Attribute) and n.attr == "attrs" for n in ast.walk(ast.parse(p.read_text()))))
    assert readers == []


#: Libraries that draw or talk to a person; with ``acq.ui`` itself, what only ``acq.ui`` may import.
PRESENTATION = ("rich", "click", "pyqtgraph", "PySide6", "shiboken6", "matplotlib")

#: ``python -m acq`` and the console script start the user interface: they may import ``acq.ui`` (nothing else).
ENTRY = ("acq.__main__", "acq.entry")

#: Modules outside ``acq.ui`` that still hold a presentation part beside their computation (a click command or
#: option, a rich table or progress bar, a figure drawn lazily) and what of it they import. Issue #15 item 2
#: splits them; the list only shrinks — a module that loses its presentation part leaves it.
MIXED: dict[str, list[str]] = {}


def presentation_imports() -> dict[str, list[str]]:
    """Module outside ``acq.ui`` → the presentation it imports (imports that run)."""
    found: dict[str, list[str]] = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            name = _module_name(path)
            if name == "acq.ui" or name.startswith("acq.ui."):
                continue
            uses: set[str] = set()
            for imported in _imports(path, type_only=False):
                top = imported.split(".")[0]
                if top in PRESENTATION:
                    uses.add(top)
                elif (imported == "acq.ui" or imported.startswith("acq.ui.")) and name not in ENTRY:
                    uses.add("acq.ui")
            if uses:
                found[name] = sorted(uses)
    return found


def test_presentation_lives_in_the_ui_package() -> None:
    """Computation apart from presentation: rich, click, Qt, matplotlib and ``acq.ui`` only in ``acq.ui``."""
    assert presentation_imports() == MIXED
