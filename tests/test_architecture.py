"""The import structure, read from the source (ast), not from a running interpreter.

* no import circle between the modules of ``pipeline``, ``drivers`` and ``station``
  (imports inside functions count: a late import is still a dependency);
* no circle between their subpackages either (``station.session``, ``station.qa``,
  ``station.store``, ``pipeline.models``, ...; a top-level module is one of its own): a
  package that imports another is not imported by it, by any way round, late imports counted;
* the layers point one way: ``pipeline`` imports neither ``drivers`` nor ``station``,
  ``drivers`` does not import ``station``;
* no private name (``_x``) is imported from another module;
* nothing outside ``station.cli`` imports it: the command line parses, calls and prints, so
  no other module can need what it holds;
* an import inside a function (a late import) of one of these packages is there to defer a
  dependency, and says which: ``# defers NAME, ...`` on its line or the line above, each NAME a
  module (``scipy``, ``importlib.metadata``, ``pipeline.select``) that the importing module does
  not load itself when it is imported (its module-level imports, followed through the project's
  modules; its packages' ``__init__`` included, ``if TYPE_CHECKING:`` blocks left out). A late
  import that defers nothing belongs at the top of the module.

The checker itself is tested on a small made-up tree, so that a broken checker
cannot pass the real one.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("pipeline", "drivers", "station")
LAYERS = {"pipeline": set(), "drivers": {"pipeline"}, "station": {"pipeline", "drivers"}}
"""Which other packages each package may import."""


def module_names(root: Path, packages=PACKAGES) -> dict[str, Path]:
    """``{dotted module name: file}`` of every module of ``packages`` under ``root``."""
    out = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def imports_of(name: str, path: Path) -> Iterator[tuple[str, str | None, int]]:
    """``(module imported, name imported from it or None, line)`` of every import in a module."""
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, None, node.lineno
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            for alias in node.names:
                yield module, alias.name, node.lineno


def import_graph(root: Path, packages=PACKAGES) -> tuple[dict[str, set[str]], list[str]]:
    """Edges between the modules of ``packages`` and the private-name imports found."""
    modules = module_names(root, packages)
    graph: dict[str, set[str]] = {m: set() for m in modules}
    private = []
    for name, path in modules.items():
        for module, imported, line in imports_of(name, path):
            target = f"{module}.{imported}" if imported and f"{module}.{imported}" in modules else module
            if target in modules and target != name:
                graph[name].add(target)
            internal = module.split(".")[0] in packages
            if internal and imported and imported.startswith("_") and not imported.startswith("__"):
                private.append(f"{path.relative_to(root)}:{line}: {name} imports {imported} from {module}")
    return graph, private


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _imported(name: str, path: Path, node: ast.Import | ast.ImportFrom) -> list[str]:
    """The modules an import statement may load (``from m import x``: ``m`` and ``m.x``)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    if node.level:
        base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        base = base[: len(base) - (node.level - 1)]
        module = ".".join(base + ([node.module] if node.module else []))
    else:
        module = node.module or ""
    return [module, *(f"{module}.{alias.name}" for alias in node.names)]


def split_imports(name: str, path: Path) -> tuple[list[ast.stmt], list[ast.stmt]]:
    """(module-level imports, imports inside functions) of a module; ``if TYPE_CHECKING:`` blocks
    are neither (they never run)."""
    top: list[ast.stmt] = []
    late: list[ast.stmt] = []

    def walk(body: list[ast.stmt], in_function: bool) -> None:
        for node in body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                (late if in_function else top).append(node)
            elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                walk(node.body, True)
            elif isinstance(node, ast.If) and _is_type_checking(node.test):
                walk(node.orelse, in_function)
            else:
                for part in ("body", "orelse", "finalbody", "handlers", "cases"):
                    sub = getattr(node, part, None)
                    if isinstance(sub, list):
                        walk([n for n in sub if isinstance(n, ast.AST)], in_function)

    walk(ast.parse(path.read_text(encoding="utf-8"), str(path)).body, False)
    return top, late


def module_level_loads(root: Path, packages=PACKAGES) -> dict[str, set[str]]:
    """``{module: every module importing it loads}``: its module-level imports, the project's
    modules among them followed (their packages' ``__init__`` too); other names with their parents
    (``scipy.optimize`` -> ``scipy``, ``scipy.optimize``)."""
    modules = module_names(root, packages)
    direct: dict[str, set[str]] = {}
    for name, path in modules.items():
        names = {".".join(name.split(".")[:i]) for i in range(1, name.count(".") + 1)}
        for node in split_imports(name, path)[0]:
            for target in _imported(name, path, node):
                parts = target.split(".")
                names |= {".".join(parts[:i]) for i in range(1, len(parts) + 1)}
        direct[name] = names
    loads: dict[str, set[str]] = {}
    for name in modules:
        seen: set[str] = set()
        stack = [name]
        while stack:
            m = stack.pop()
            if m in seen:
                continue
            seen.add(m)
            stack += [t for t in direct.get(m, ()) if t in modules and t not in seen]
            seen |= {t for t in direct.get(m, ()) if t not in modules}
        loads[name] = seen
    return loads


DEFERS = re.compile(r"#\s*defers\s+([\w.]+(?:\s*,\s*[\w.]+)*)")


def late_import_problems(root: Path, packages=PACKAGES) -> list[str]:
    """Late imports of the project's modules that do not say what they defer (``# defers NAME, ...``
    on the line or the line above), or that name a module the importing module loads itself."""
    modules = module_names(root, packages)
    loads = module_level_loads(root, packages)
    out = []
    for name, path in modules.items():
        lines = path.read_text(encoding="utf-8").splitlines()
        for node in split_imports(name, path)[1]:
            if not any(t.split(".")[0] in packages for t in _imported(name, path, node)):
                continue
            where = f"{path.relative_to(root)}:{node.lineno}"
            above = lines[node.lineno - 2].strip() if node.lineno > 1 else ""
            said = DEFERS.search(lines[node.lineno - 1]) or (DEFERS.search(above) if above.startswith("#") else None)
            if not said:
                out.append(f"{where}: a late import that does not say what it defers ('# defers NAME')")
                continue
            loaded = sorted(n.strip() for n in said.group(1).split(",") if n.strip() in loads[name])
            if loaded:
                out.append(f"{where}: {name} loads {', '.join(loaded)} itself: the late import defers nothing")
    return out


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def subpackage(module: str) -> str:
    """The subpackage a module belongs to: its first two names (``station.session.run`` ->
    ``station.session``; a top-level module, ``station.profile``, is its own)."""
    return ".".join(module.split(".")[:2])


def subpackage_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The import graph between subpackages (:func:`subpackage`) of a module graph."""
    out: dict[str, set[str]] = {}
    for a, targets in graph.items():
        out.setdefault(subpackage(a), set())
        for b in targets:
            out.setdefault(subpackage(b), set())
            if subpackage(a) != subpackage(b):
                out[subpackage(a)].add(subpackage(b))
    return out


def layer_violations(graph: dict[str, set[str]]) -> list[str]:
    out = []
    for a, targets in graph.items():
        pa = a.split(".")[0]
        for b in sorted(targets):
            pb = b.split(".")[0]
            if pb != pa and pb not in LAYERS[pa]:
                out.append(f"{a} imports {b}")
    return out


def cli_importers(graph: dict[str, set[str]]) -> list[str]:
    """Modules outside ``station.cli`` that import one of its modules."""
    inside = lambda m: m == "station.cli" or m.startswith("station.cli.")  # noqa: E731
    return [
        f"{a} imports {b}"
        for a, targets in sorted(graph.items())
        if not inside(a)
        for b in sorted(targets)
        if inside(b)
    ]


@pytest.fixture(scope="module")
def real():
    return import_graph(REPO)


def test_no_import_circles(real):
    graph, _ = real
    assert len(graph) > 60 and sum(map(len, graph.values())) > 100  # the whole tree was read
    assert cycles(graph) == []


def test_no_circles_between_subpackages(real):
    """Issue 22 item 3: e.g. the session and the QA, or the configuration, the store and the profile,
    once imported each other (one way at module level, the other inside functions)."""
    graph, _ = real
    sub = subpackage_graph(graph)
    assert {"station.session", "station.qa", "station.store", "station.config"} <= set(sub)
    assert "station.session" in sub["station.qa"]  # edges between subpackages are seen
    assert cycles(sub) == []


def test_layers_point_one_way(real):
    graph, _ = real
    assert "pipeline.edgeset" in graph["pipeline.fit"]  # edges are seen
    assert layer_violations(graph) == []


def test_no_private_name_imported_across_modules(real):
    _, private = real
    assert private == []


def test_nothing_outside_the_command_line_imports_it(real):
    graph, _ = real
    assert "station.cli.export" in graph["station.cli.profile"]  # cli modules are seen
    assert cli_importers(graph) == []


def test_late_imports_say_what_they_defer_and_defer_it():
    """Issue 22 item 3: a late import of the project's own modules only where it defers a dependency."""
    assert late_import_problems(REPO) == []


def test_the_late_import_checker_sees_what_it_must(tmp_path):
    for rel, text in {
        "pipeline/__init__.py": "",
        "pipeline/heavy.py": "import scipy.optimize\n",
        "pipeline/light.py": "import json\n",
        "pipeline/uses.py": (
            "import numpy\nfrom pipeline import light\n"
            "def a():\n    from pipeline import heavy  # defers scipy\n"
            "def b():\n    # defers scipy.optimize\n    from pipeline.heavy import thing\n"
            "def c():\n    from pipeline import light\n"
            "def d():\n    from pipeline.heavy import other  # defers numpy\n"
            "def e():\n    import numpy.linalg  # not the project's: not checked\n"
        ),
        "pipeline/typed.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import yaml\n"
        "def f():\n    from pipeline import heavy  # defers yaml\n",
    }.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    loads = module_level_loads(tmp_path, ("pipeline",))
    assert {"json", "pipeline.light", "numpy", "pipeline"} <= loads["pipeline.uses"]  # followed, packages too
    assert "scipy" not in loads["pipeline.uses"] and {"scipy", "scipy.optimize"} <= loads["pipeline.heavy"]
    assert "yaml" not in loads["pipeline.typed"]
    assert late_import_problems(tmp_path, ("pipeline",)) == [
        "pipeline/uses.py:9: a late import that does not say what it defers ('# defers NAME')",
        "pipeline/uses.py:11: pipeline.uses loads numpy itself: the late import defers nothing",
    ]


def test_the_checker_sees_what_it_must(tmp_path):
    for rel, text in {
        "pipeline/__init__.py": "",
        "pipeline/a.py": "from pipeline.b import thing\n",
        "pipeline/b.py": "def f():\n    from pipeline import a\n    from . import c\n",
        "pipeline/c.py": "from station.x import _hidden\n",
        "drivers/__init__.py": "",
        "station/__init__.py": "",
        "station/x.py": "import drivers\n_hidden = 1\n",
        "station/cli/__init__.py": "from station.cli import y\n",
        "station/cli/y.py": "from station import x\n",
        "station/z.py": "def f():\n    from station.cli.y import g\n",
        "station/p/__init__.py": "",
        "station/p/a.py": "from station.q.b import thing\n",
        "station/q/__init__.py": "",
        "station/q/b.py": "def f():\n    from station.p import c\n",
        "station/p/c.py": "",
    }.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    graph, private = import_graph(tmp_path)
    assert graph["pipeline.b"] == {"pipeline.a", "pipeline.c"}  # late and relative imports count
    assert cycles(graph) == [["pipeline.a", "pipeline.b"]]
    assert layer_violations(graph) == ["pipeline.c imports station.x"]
    assert private == ["pipeline/c.py:1: pipeline.c imports _hidden from station.x"]
    assert cli_importers(graph) == ["station.z imports station.cli.y"]
    # station.p.a -> station.q.b -> station.p.c is no circle of modules (above), but one of subpackages
    assert ["station.p", "station.q"] in cycles(subpackage_graph(graph))
