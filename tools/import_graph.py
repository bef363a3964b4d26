"""The import graph of the `caustics_jax` package, read from the source (AST, nothing imported).

Prints a Markdown section: a mermaid graph (one node per module, one arrow per import of
another package module, imports inside functions included) and the same edges as a table,
with the first paragraph of each module's docstring (what it is for).
Exits non-zero, after naming the offenders on stderr, when the graph has a cycle or when a
module imports a private name (leading underscore, not a dunder) of another module, either
as `from X import _name` or as an attribute `X._name` of an imported module. Private
*modules* (`_version.py`, `solvers/_solve.py`) are the optimistix layout and may be
imported; their private names may not. It also exits non-zero when an import points up the
layer order `LAYERS` (docs/map.md "Layers"): each module belongs to the top-level unit of
the package it sits in (`caustics_jax.math.conic` to `math`), and may import its own unit
and units of lower layers only.

Run from the repository root: `python tools/import_graph.py [--root caustics_jax]`.
`tests/test_architecture.py` loads this file and checks the same rules.
"""

from __future__ import annotations

import argparse
import ast
import pathlib
import sys
from dataclasses import dataclass, field

ROOT = pathlib.Path(__file__).resolve().parents[1]


@dataclass
class Module:
    """One source file of the package: its dotted name, path and what it imports."""

    name: str
    path: pathlib.Path
    is_package: bool
    #: package modules imported, with the line of each import
    imports: dict[str, int] = field(default_factory=dict)
    #: `(line, target module, name)` for every private name taken from another module
    private: list[tuple[int, str, str]] = field(default_factory=list)
    #: `(line, top-level name, at module level)` for every import from outside the package
    external: list[tuple[int, str, bool]] = field(default_factory=list)
    #: first paragraph of the module docstring, on one line ("" without one)
    summary: str = ""


#: The package's layers, bottom first (docs/map.md "Layers"). A unit is a sub-package or a
#: root module of the package; "" is the package's own `__init__` (the public API, on top).
#: A module may import its own unit and the units of lower layers; units of one layer are
#: independent of each other. `scenes` is the root name of `surface.scenes` (`cj.scenes`).
LAYERS: tuple[tuple[str, ...], ...] = (
    ("_version", "runtime"),
    ("math",),
    ("curve", "surface"),
    ("accel",),
    ("solvers",),
    ("transport", "kernels"),
    ("testing",),
    ("export",),
    ("shaders",),
    ("app",),
    ("scenes",),
    ("",),
)


def is_private(name: str) -> bool:
    """A leading underscore that is not a dunder."""
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def discover(package_dir: pathlib.Path) -> dict[str, Module]:
    """Every `.py` file under `package_dir`, by dotted module name."""
    base = package_dir.parent
    modules = {}
    for path in sorted(package_dir.rglob("*.py")):
        parts = list(path.relative_to(base).with_suffix("").parts)
        is_package = parts[-1] == "__init__"
        if is_package:
            parts = parts[:-1]
        name = ".".join(parts)
        modules[name] = Module(name, path, is_package)
    return modules


def _resolve(mod: Module, node: ast.ImportFrom) -> str:
    """The absolute module name of a `from ... import` statement."""
    if node.level == 0:
        return node.module or ""
    package = mod.name.split(".") if mod.is_package else mod.name.split(".")[:-1]
    if node.level > 1:
        package = package[: len(package) - (node.level - 1)]
    return ".".join(package + ([node.module] if node.module else []))


def _module_level(tree: ast.Module) -> set[int]:
    """`id`s of the import statements executed on import (not inside a def or a class body's
    methods): top level, and inside top-level `if`/`try`/`with` blocks."""
    out, stack = set(), list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out.add(id(node))
        elif isinstance(node, (ast.If, ast.Try, ast.With)):
            for name in ("body", "orelse", "finalbody", "handlers"):
                stack.extend(getattr(node, name, []))
        elif isinstance(node, ast.ExceptHandler):
            stack.extend(node.body)
    return out


def analyse(modules: dict[str, Module], package: str) -> None:
    """Fill each module's `imports`, `private` and `external` from its source."""
    for mod in modules.values():
        tree = ast.parse(mod.path.read_text(), filename=str(mod.path))
        mod.summary = " ".join((ast.get_docstring(tree) or "").split("\n\n")[0].split())
        top = _module_level(tree)
        aliases: dict[str, str] = {}  # local name -> package module it is bound to

        def add(target: str, line: int, mod=mod) -> None:
            if target != mod.name and target in modules:
                mod.imports.setdefault(target, line)

        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                for a in node.names:
                    root = a.name.split(".")[0]
                    if root != package:
                        mod.external.append((node.lineno, root, id(node) in top))
                        continue
                    add(a.name, node.lineno)
                    aliases[a.asname or root] = a.name if a.asname else root
            elif isinstance(node, ast.ImportFrom):
                source = _resolve(mod, node)
                root = source.split(".")[0]
                if node.level == 0 and root != package:
                    if root != "__future__":
                        mod.external.append((node.lineno, root, id(node) in top))
                    continue
                for a in node.names:
                    sub = f"{source}.{a.name}"
                    if sub in modules:  # `from . import walk`: a module, not a name
                        add(sub, node.lineno)
                        aliases[a.asname or a.name] = sub
                    else:
                        add(source, node.lineno)
                        if is_private(a.name) and source != mod.name:
                            mod.private.append((node.lineno, source, a.name))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in aliases and is_private(node.attr)):
                target = aliases[node.value.id]
                if f"{target}.{node.attr}" not in modules and target != mod.name:
                    mod.private.append((node.lineno, target, node.attr))


def find_cycles(modules: dict[str, Module]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in modules[v].imports:
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
                out.append(sorted(comp))

    sys.setrecursionlimit(max(1000, 10 * len(modules)))
    for v in sorted(modules):
        if v not in index:
            visit(v)
    return out


def unit(name: str) -> str:
    """The top-level unit of a dotted module name: `pkg.math.conic` -> `math`, `pkg` -> ""."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 else ""


def layer_violations(modules: dict[str, Module], layers=LAYERS) -> list[str]:
    """`module:line: imports target` for every import that does not point down `layers`
    (into the importer's own unit or a lower layer), and for every unit `layers` lacks."""
    rank = {u: i for i, layer in enumerate(layers) for u in layer}
    out = []
    for name, mod in sorted(modules.items()):
        for target, line in sorted(mod.imports.items()):
            a, b = unit(name), unit(target)
            if a not in rank or b not in rank:
                out.append(f"{name}:{line}: unit {(a if a not in rank else b)!r} has no layer")
            elif a != b and rank[b] >= rank[a]:
                out.append(f"{name}:{line}: imports {target} ({b!r} is not below {a!r})")
    return out


def build(package_dir: pathlib.Path = ROOT / "caustics_jax") -> dict[str, Module]:
    """Discover and analyse the package at `package_dir`."""
    modules = discover(package_dir)
    analyse(modules, package_dir.name)
    return modules


def markdown(modules: dict[str, Module], package: str) -> str:
    """The graph as a mermaid block, with each subpackage drawn as one node (its modules'
    imports merged), and as a table of every module (module, what it is for, package modules
    it imports)."""

    def short(name: str) -> str:
        return name[len(package) + 1:] if name != package else package

    def group(name: str) -> str:
        parts = name.split(".")
        return ".".join(parts[:2]) if len(parts) > 2 or modules[name].is_package else name

    def node_id(name: str) -> str:
        return name.replace(".", "_")

    nodes = sorted({group(n) for n in modules})
    edges = sorted({(group(n), group(t)) for n, m in modules.items() for t in m.imports if group(n) != group(t)})
    lines = ["```mermaid", "graph LR"]
    for name in nodes:
        label = f"{short(name)}/" if modules[name].is_package and name != package else short(name)
        label = f"{package} (public API)" if name == package else label
        lines.append(f'    {node_id(name)}["{label}"]')
    lines += [f"    {node_id(a)} --> {node_id(b)}" for a, b in edges]
    lines += ["```", "", "| module | what it is for (docstring) | imports (within the package) |", "|---|---|---|"]
    for name in sorted(modules):
        targets = ", ".join(f"`{short(t)}`" for t in sorted(modules[name].imports)) or "(none)"
        summary = modules[name].summary.replace("|", "\\|") or "(no docstring)"
        lines.append(f"| `{short(name)}` | {summary} | {targets} |")
    n_edges = sum(len(m.imports) for m in modules.values())
    lines += ["", f"{len(modules)} modules, {n_edges} import edges (imports inside functions included); "
              f"the mermaid graph draws each subpackage (`name/`) as one node, {len(nodes)} nodes and "
              f"{len(edges)} edges."]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=str(ROOT / "caustics_jax"), help="the package directory")
    args = parser.parse_args(argv)
    package_dir = pathlib.Path(args.root).resolve()
    modules = build(package_dir)
    print(markdown(modules, package_dir.name))
    status = 0
    for comp in find_cycles(modules):
        print(f"import cycle: {' <-> '.join(comp)}", file=sys.stderr)
        status = 1
    for problem in layer_violations(modules):
        print(f"layer order: {problem}", file=sys.stderr)
        status = 1
    for mod in modules.values():
        for line, target, name in mod.private:
            print(f"{mod.path}:{line}: private name {name!r} of {target}", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    sys.exit(main())
