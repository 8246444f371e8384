"""Issue 22's figures of a checkout, read from its source (ast): one path for each idea.

Usage::

    .venv/bin/python benchmarks/architecture.py [CHECKOUT ...]

For each checkout (default: this one) a Markdown table of what issue 22 counts, nothing run:

* the parts of ``station/`` (each top-level file or folder one part) and the import arrows between
  them (late imports, inside functions, counted: they are dependencies too); the parts that
  import each other by some way round (circles) and the arrows inside them, the layers the rest
  stands on (a part one layer above everything it imports), and the arrows that exist only
  through late imports;
* the default t = 30 spelled in code (a default, a keyword, an option's default, a field);
* function-level imports of the project's own modules and how many say what they defer;
* error classes of ``station``, how many are HarpErrors, the unrelated error bases; the error classes
  of ``station``, ``drivers`` and ``pipeline`` outside HarpError and how many say why
  (``tests/station/test_errors.py``'s checker); prints on stderr, and those not said through
  ``station.cli.say`` and how many say why; ``EXIT_*`` constants defined, literal non-zero returns of the
  command modules;
* process pools made, modules that assemble a focus setting's profile (``Calibration.profile``),
  places that write a selection reason;
* modules over 700 lines and the lines of code of ``pipeline``, ``drivers`` and ``station``.

Compare two commits with ``git worktree add --detach /tmp/before COMMIT`` and both paths as arguments.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from tests.station.test_errors import errors_outside_harp_error, stderr_prints  # noqa: E402  (the same)
from tests.test_architecture import cycles, module_names  # noqa: E402  (this checkout's, for any checkout)

BUILTIN_ERRORS = {"Exception", "RuntimeError", "ValueError", "OSError", "KeyError", "TypeError", "LookupError"}


def imports(name: str, path: Path, tree: ast.AST) -> list[tuple[str, bool, ast.stmt]]:
    """``(module imported, inside a function, node)`` of every import of a module."""
    late_nodes = {
        id(n)
        for fn in ast.walk(tree)
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
        for n in ast.walk(fn)
        if isinstance(n, (ast.Import, ast.ImportFrom))
    }
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, id(node) in late_nodes, node) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            out += [(f"{module}.{a.name}", id(node) in late_nodes, node) for a in node.names]
    return out


def part_of(module: str) -> str | None:
    """The part of ``station`` a module is in (its top-level file or folder), or None."""
    bits = module.split(".")
    return bits[1] if bits[0] == "station" and len(bits) > 1 else None


def layers(graph: dict[str, set[str]], groups: list[set[str]]) -> int:
    """Layers of the parts, a circle counted as one part."""
    rep = {v: min(g) for g in groups for v in g}
    dag: dict[str, set[str]] = defaultdict(set)
    for a, bs in graph.items():
        dag[rep.get(a, a)] |= {rep.get(b, b) for b in bs} - {rep.get(a, a)}
    height: dict[str, int] = {}

    def h(v: str) -> int:
        if v not in height:
            height[v] = 1 + max((h(w) for w in dag[v]), default=0)
        return height[v]

    return max((h(v) for v in {rep.get(v, v) for v in graph}), default=0)


def is_t30(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and node.value == 30 and type(node.value) is int


def t30_places(tree: ast.AST) -> int:
    """The default t = 30 spelled in code."""
    n = 0
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            args = node.args.posonlyargs + node.args.args
            n += sum(
                is_t30(d)
                for a, d in zip(args[len(args) - len(node.args.defaults) :], node.args.defaults)
                if a.arg == "t"
            )
            n += sum(is_t30(d) for a, d in zip(node.args.kwonlyargs, node.args.kw_defaults) if a.arg == "t" and d)
        elif isinstance(node, ast.Call):
            n += sum(k.arg == "t" and is_t30(k.value) for k in node.keywords)
            if node.args and isinstance(node.args[0], ast.Constant) and node.args[0].value == "--t":
                n += sum(k.arg == "default" and is_t30(k.value) for k in node.keywords)
        elif isinstance(node, ast.Dict):
            n += sum(
                isinstance(k, ast.Constant) and k.value == "t" and is_t30(v) for k, v in zip(node.keys, node.values)
            )
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None:
            v = node.value
            if isinstance(v, ast.Call) and v.args:
                v = v.args[0]
            n += node.target.id in ("t", "DEFAULT_T") and is_t30(v)
        elif isinstance(node, ast.Assign) and is_t30(node.value):
            n += any(isinstance(t, ast.Name) and t.id in ("t", "DEFAULT_T") for t in node.targets)
    return n


def figures(root: Path) -> list[tuple[str, str]]:
    mods = module_names(root)
    trees = {m: ast.parse(p.read_text(encoding="utf-8"), str(p)) for m, p in mods.items()}
    texts = {m: p.read_text(encoding="utf-8").splitlines() for m, p in mods.items()}
    rel = {m: str(p.relative_to(root)) for m, p in mods.items()}

    def resolve(target: str) -> str | None:
        while target and target not in mods:
            target = target.rpartition(".")[0]
        return target or None

    # the parts of station and their arrows
    parts = {part_of(m) for m in mods if part_of(m)}
    graph: dict[str, set[str]] = {p: set() for p in parts}
    top_only: dict[str, set[str]] = {p: set() for p in parts}
    late_nodes: dict[int, tuple[str, ast.stmt]] = {}  # import statements, not names
    for m, tree in trees.items():
        for target, late, node in imports(m, mods[m], tree):
            t = resolve(target)
            if t is None or t == m:
                continue
            if late:
                late_nodes[id(node)] = (m, node)
            a, b = part_of(m), part_of(t)
            if a and b and a != b:
                graph[a].add(b)
                if not late:
                    top_only[a].add(b)
    late_n, late_files = len(late_nodes), {m for m, _ in late_nodes.values()}
    late_said = sum(
        any("# defers" in ln for ln in texts[m][max(0, node.lineno - 2) : node.lineno])
        for m, node in late_nodes.values()
    )
    arrows = sum(len(v) for v in graph.values())
    groups = [set(c) for c in cycles(graph)]
    inside = sum(1 for a, bs in graph.items() for b in bs for g in groups if a in g and b in g)
    late_arrows = sum(len(graph[a] - top_only[a]) for a in graph)
    hidden = cycles(graph) != cycles(top_only)

    t30 = {rel[m]: k for m, t in trees.items() if (k := t30_places(t))}
    bases: dict[str, set[str]] = {}  # station's classes and the names of their bases
    for m, tree in trees.items():
        if m.startswith("station"):
            for node in ast.walk(tree):
                if isinstance(node, ast.ClassDef):
                    names = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
                    bases[node.name] = bases.get(node.name, set()) | names

    def under(cls: str, root: set[str], seen: frozenset = frozenset()) -> bool:
        names = bases.get(cls, set())
        return bool(names & root) or any(under(b, root, seen | {cls}) for b in names if b in bases and b not in seen)

    errors = [c for c in bases if under(c, BUILTIN_ERRORS)]
    harp_errors = sum(c == "HarpError" or under(c, {"HarpError"}) for c in errors)
    roots = sorted(c for c in errors if c != "HarpError" and not under(c, {"HarpError"}) and bases[c] & BUILTIN_ERRORS)
    roots += ["HarpError"] if "HarpError" in bases else []
    stderr = harp_prints = sayings = exits = literal_returns = pools = 0
    builders, reasons = set(), 0
    for m, tree in trees.items():
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                f = node.func
                fname = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if m.startswith("station") and fname == "print":
                    on_stderr = any(
                        k.arg == "file" and isinstance(k.value, ast.Attribute) and k.value.attr == "stderr"
                        for k in node.keywords
                    )
                    stderr += on_stderr
                    first = ast.unparse(node.args[0]) if node.args else ""
                    harp_prints += on_stderr and first[first.find("'") + 1 :].startswith(("harp", "{prog}", "{_prog"))
                if m.startswith("station.cli") and fname in ("say", "warn") and isinstance(f, ast.Name):
                    sayings += m != "station.cli.say"
                if m.startswith("station") and fname in ("ProcessPoolExecutor", "Pool", "get_context"):
                    pools += 1
                if (
                    m.startswith("station")
                    and fname == "profile"
                    and isinstance(f, ast.Attribute)
                    and any(k.arg == "provenance" for k in node.keywords)
                ):
                    builders.add(rel[m])
            elif isinstance(node, (ast.Assign, ast.AnnAssign)):
                targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                exits += any(isinstance(t, ast.Name) and t.id.startswith("EXIT_") for t in targets) and isinstance(
                    node.value, ast.Constant
                )
            elif isinstance(node, ast.Return) and m.startswith("station.cli"):
                v = node.value
                literal_returns += isinstance(v, ast.Constant) and type(v.value) is int and v.value != 0
            elif isinstance(node, ast.Dict) and m.startswith("station"):
                keys = [k.value for k in node.keys if isinstance(k, ast.Constant)]
                if "reason" in keys:
                    v = node.values[keys.index("reason")] if None not in node.keys else None
                    said = ast.unparse(v) if v is not None else ""
                    reasons += "folds" in keys or "given" in said or "configuration" in said
    sources = {rel[m]: "\n".join(texts[m]) for m in mods}
    unexplained, explained = errors_outside_harp_error(sources)
    as_is = [stderr_prints(s, r) for r, s in sources.items() if r.startswith("station/") and r != "station/cli/say.py"]
    prints_bare, prints_said = sum(len(u) for u, _ in as_is), sum(len(e) for _, e in as_is)
    sizes = {rel[m]: len(texts[m]) for m in mods}
    big = sorted((f"{p} {n}" for p, n in sizes.items() if n > 700), key=lambda s: -int(s.rsplit(" ", 1)[1]))
    return [
        ("station: parts (top-level files and folders)", str(len(parts))),
        ("station: arrows between parts (late imports counted)", str(arrows)),
        ("station: circles of parts", "; ".join(" <-> ".join(sorted(g)) for g in groups) or "none"),
        ("station: arrows inside circles", str(inside)),
        ("station: layers (a circle one part)", str(layers(graph, groups))),
        (
            "station: arrows only through late imports",
            f"{late_arrows} (a circle hidden by them: {'yes' if hidden else 'no'})",
        ),
        ("default t = 30 spelled in code", f"{sum(t30.values())} in {len(t30)} files ({', '.join(sorted(t30))})"),
        (
            "function-level imports of the project's modules",
            f"{late_n} in {len(late_files)} files, {late_said} say what they defer",
        ),
        ("station error classes", f"{len(errors)}, {harp_errors} of them HarpErrors"),
        ("station error bases (a class on a built-in base, not a HarpError)", f"{len(roots)} ({', '.join(roots)})"),
        (
            "error classes of station, drivers, pipeline outside HarpError",
            f"{len(unexplained) + len(explained)}, {len(explained)} say why",
        ),
        ("station print(..., file=sys.stderr)", f"{stderr}, {harp_prints} of them 'harp X: ...' by hand"),
        (
            "station prints on stderr outside station.cli.say",
            f"{prints_bare + prints_said}, {prints_said} say why",
        ),
        ("station/cli lines said by station.cli.say (say, warn)", str(sayings)),
        ("EXIT_* constants defined", str(exits)),
        ("literal non-zero returns in station/cli", str(literal_returns)),
        ("process pools made in station", str(pools)),
        ("modules assembling a focus setting's profile", f"{len(builders)} ({', '.join(sorted(builders))})"),
        ("dicts writing a selection reason", str(reasons)),
        ("modules over 700 lines", ", ".join(big) or "none"),
        ("lines in pipeline, drivers, station", str(sum(sizes.values()))),
        ("lines in station", str(sum(n for p, n in sizes.items() if p.startswith("station")))),
    ]


def _name(root: Path) -> str:
    """The checkout's commit (short), else its folder's name."""
    got = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return got.stdout.strip() or root.name


def main(argv: list[str]) -> None:
    roots = [Path(a).resolve() for a in argv] or [REPO]
    rows = [figures(r) for r in roots]
    print("| figure | " + " | ".join(_name(r) for r in roots) + " |")
    print("|:---|" + "---|" * len(roots))
    for i, (what, _) in enumerate(rows[0]):
        print(f"| {what} | " + " | ".join(r[i][1] for r in rows) + " |")


if __name__ == "__main__":
    main(sys.argv[1:])
