"""The package's structure (DESIGN.md "Layers", STYLE.md "Structure"; issue 13): an acyclic
import graph, no private name taken from another module, every third-party import declared,
`cj.kernels` reachable after `import caustics_jax`, one version source.

Read from the source with `tools/import_graph.py` (AST, imports inside functions included),
so no JAX work runs here.
"""

from __future__ import annotations

import ast
import importlib.metadata
import importlib.util
import pathlib
import re
import subprocess
import sys
import tomllib
import types

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "caustics_jax"


def _load_tool():
    spec = importlib.util.spec_from_file_location("import_graph", ROOT / "tools" / "import_graph.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses resolve their annotations through sys.modules
    spec.loader.exec_module(module)
    return module


import_graph = _load_tool()
MODULES = import_graph.build(PACKAGE)
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def test_the_package_import_graph_is_acyclic():
    assert len(MODULES) > 40  # the whole package was read
    assert import_graph.find_cycles(MODULES) == []


def test_no_module_imports_a_private_name_of_another_module():
    offenders = [f"{m.path.relative_to(ROOT)}:{line}: {name} of {target}"
                 for m in MODULES.values() for line, target, name in m.private]
    assert offenders == []


def test_every_import_points_down_the_layers():
    """docs/map.md "Layers": a module imports its own unit and lower layers only (runtime at
    the bottom, the public API on top), imports inside functions included."""
    assert import_graph.layer_violations(MODULES) == []
    units = {import_graph.unit(n) for n in MODULES}
    assert {"runtime", "math", "curve", "surface", "accel", "solvers", "transport", "kernels", "testing",
            "export", "shaders", "app", ""} <= units


def test_the_layer_check_fails_on_an_upward_import_in_a_planted_package(tmp_path):
    """An import from a low layer into a higher one (no cycle anywhere), one between two
    units of one layer, and a unit with no layer are each reported."""
    pkg = tmp_path / "pkg"
    for sub in ("math", "solvers", "curve", "surface", "extra"):
        (pkg / sub).mkdir(parents=True)
        (pkg / sub / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("from .solvers import walk\n")
    (pkg / "math" / "conic.py").write_text("def f():\n    from ..solvers.walk import g\n    return g\n")
    (pkg / "solvers" / "walk.py").write_text("def g():\n    return 1\n")
    (pkg / "curve" / "arcs.py").write_text("from ..surface import mesh\n")
    (pkg / "surface" / "mesh.py").write_text("")
    (pkg / "extra" / "x.py").write_text("from ..math import conic\n")
    modules = import_graph.build(pkg)
    assert import_graph.find_cycles(modules) == []
    problems = import_graph.layer_violations(modules)
    assert problems == ["pkg.curve.arcs:1: imports pkg.surface.mesh ('surface' is not below 'curve')",
                        "pkg.extra.x:1: unit 'extra' has no layer",
                        "pkg.math.conic:2: imports pkg.solvers.walk ('solvers' is not below 'math')"]


def test_the_package_root_holds_at_most_eight_modules():
    """The layers are folders: the root keeps the public API and a few modules at most."""
    root = sorted(p.name for p in PACKAGE.glob("*.py"))
    assert len(root) <= 8, root


#: Lines a module named for the walk may hold (issue 32: the walk's method, not its scheduling).
WALK_MODULE_LINES = 500


def test_every_module_named_for_the_walk_reads_within_500_lines():
    """`solvers/walk*.py` and the GLSL `walk*.glsl`: the paper's section, its scheduling in
    the runtime (`runtime.lane_solver`)."""
    files = sorted((ROOT / "caustics_jax").rglob("*walk*.*"))
    files = [f for f in files if f.suffix in (".py", ".glsl")]
    assert len(files) >= 4, files  # walk.py, walk_start.py, walk_steps.py, walk.glsl
    long = {f.relative_to(ROOT).as_posix(): n for f in files
            if (n := len(f.read_text().splitlines())) > WALK_MODULE_LINES}
    assert not long, long


def test_no_public_name_of_a_package_hides_one_of_its_modules():
    """`cj.start_points` is a function and `caustics_jax.start_points` no module: a package's
    attribute named like one of its submodules must be that submodule (STYLE.md)."""
    import importlib

    hidden = []
    for name, mod in MODULES.items():
        if not mod.is_package:
            continue
        package = importlib.import_module(name)
        for sub in (p.stem for p in mod.path.parent.glob("*.py") if p.stem != "__init__"):
            obj = getattr(package, sub, None)
            if obj is not None and not (isinstance(obj, types.ModuleType) and obj.__name__ == f"{name}.{sub}"):
                hidden.append(f"{name}.{sub}")
        for sub in (p.parent.name for p in mod.path.parent.glob("*/__init__.py")):
            obj = getattr(package, sub, None)
            if obj is not None and not isinstance(obj, types.ModuleType):
                hidden.append(f"{name}.{sub}")
    assert hidden == []


def test_the_package_source_holds_no_dated_notes():
    """Comments state contracts; measurements and their dates live in docs/ (STYLE.md)."""
    dated = re.compile(r"\b20[0-9]{2}-[0-9]{2}-[0-9]{2}\b")
    hits = [f"{p.relative_to(ROOT)}:{i}" for p in sorted(PACKAGE.rglob("*.py"))
            for i, line in enumerate(p.read_text().splitlines(), 1) if dated.search(line)]
    assert hits == []


def test_the_public_api_is_a_sorted_flat_list():
    """`caustics_jax.__all__` is sorted, without duplicates, and every name resolves."""
    import caustics_jax

    names = list(caustics_jax.__all__)
    assert names == sorted(names, key=str.lower) and len(set(names)) == len(names)
    assert all(hasattr(caustics_jax, n) for n in names)


def test_the_checker_finds_a_cycle_and_private_imports_in_a_planted_package(tmp_path):
    """The two rules above can fail: a package with `a -> b -> a` (the second import inside a
    function), `from .a import _helper`, and `a._helper` through a module alias."""
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("from .a import f\n")
    (pkg / "a.py").write_text("from . import b\n\ndef f():\n    return b.g()\n\ndef _helper():\n    pass\n")
    (pkg / "b.py").write_text("def g():\n    from .a import _helper\n    return _helper\n")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "c.py").write_text("from .. import a\nfrom .._private_module import public\n\n"
                                      "x = a._helper\n")
    (pkg / "_private_module.py").write_text("public = 1\n")
    modules = import_graph.build(pkg)
    assert import_graph.find_cycles(modules) == [["pkg.a", "pkg.b"]]
    private = sorted((m.name, target, name) for m in modules.values() for _, target, name in m.private)
    assert private == [("pkg.b", "pkg.a", "_helper"), ("pkg.sub.c", "pkg.a", "_helper")]
    assert set(modules["pkg.sub.c"].imports) == {"pkg.a", "pkg._private_module"}
    assert import_graph.main(["--root", str(pkg)]) == 1


def _distribution(requirement: str) -> str:
    """PEP 503 normalised distribution name of a requirement string."""
    name = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement).group(1)
    return re.sub(r"[-_.]+", "-", name).lower()


def test_every_third_party_import_is_a_declared_dependency():
    """Imports run on `import caustics_jax` need a `[project] dependencies` entry; an import
    inside a function (lazy) may instead come from an optional extra. Import names map to
    distributions through the installed metadata (`jaxlib` is its own distribution, ...)."""
    required = {_distribution(r) for r in PYPROJECT["project"]["dependencies"]}
    optional = {_distribution(r) for extra in PYPROJECT["project"].get("optional-dependencies", {}).values()
                for r in extra}
    providers = importlib.metadata.packages_distributions()
    problems = []
    for mod in MODULES.values():
        for line, name, at_import in mod.external:
            if name in sys.stdlib_module_names:
                continue
            dists = {_distribution(d) for d in providers.get(name, [])}
            where = f"{mod.path.relative_to(ROOT)}:{line}: {name}"
            if not dists:
                problems.append(f"{where}: no installed distribution provides it")
            elif not dists & required and (at_import or not dists & optional):
                problems.append(f"{where} ({', '.join(sorted(dists))}) is not declared"
                                + ("" if at_import else " in the dependencies or an extra"))
    assert problems == []
    seen = {name for m in MODULES.values() for _, name, _ in m.external} - set(sys.stdlib_module_names)
    assert {"jax", "numpy", "equinox", "optimistix", "jaxtyping", "scipy", "trimesh"} <= seen


def test_kernels_is_reachable_after_importing_the_package():
    """In a fresh interpreter: nothing else has imported `caustics_jax.kernels` there."""
    code = ("import types, caustics_jax as cj; assert isinstance(cj.kernels, types.ModuleType); "
            "print(cj.kernels.__name__)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "caustics_jax.kernels"


def test_the_version_is_written_once():
    """pyproject.toml reads it from `caustics_jax/_version.py`; the installed metadata agrees;
    no other module assigns a literal `__version__`."""
    import caustics_jax

    project = PYPROJECT["project"]
    assert "version" not in project and "version" in project["dynamic"]
    assert PYPROJECT["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "caustics_jax._version.__version__"}
    assert caustics_jax.__version__ == importlib.metadata.version("caustics_jax")
    writers = []
    for mod in MODULES.values():
        for node in ast.walk(ast.parse(mod.path.read_text())):
            if (isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
                    and any(isinstance(t, ast.Name) and t.id == "__version__" for t in node.targets)):
                writers.append(mod.name)
    assert writers == ["caustics_jax._version"]



def _defines(path: pathlib.Path, name: str) -> bool:
    """`name` is a top-level function, class, assignment or import of the module at `path`."""
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and node.name == name:
            return True
        if isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == name for t in targets):
                return True
        if isinstance(node, ast.ImportFrom) and any((a.asname or a.name) == name for a in node.names):
            return True
    return False


def test_every_name_in_the_code_map_exists():
    """docs/map.md names the one function of each formula: each `caustics_jax.module.name`
    is defined in that module's source, each `tests/...py[::test]` exists."""
    text = (ROOT / "docs" / "map.md").read_text()
    dotted = sorted(set(re.findall(r"`(caustics_jax(?:\.\w+)+)`", text)))
    tests = sorted(set(re.findall(r"`(tests/[\w/]+\.py)(?:::(\w+))?`", text)))
    assert len(dotted) > 80 and len(tests) > 20
    missing = []
    for name in dotted:
        if name in MODULES:
            continue
        module, attr = name.rsplit(".", 1)
        if module not in MODULES or not _defines(MODULES[module].path, attr):
            missing.append(name)
    for path, test in tests:
        if not (ROOT / path).exists() or (test and not _defines(ROOT / path, test)):
            missing.append(f"{path}::{test}" if test else path)
    assert missing == []


#: The sibling folder of the shared design documents: outside the repository.
OUTSIDE = "../" + "shared"


def _math_sections() -> set[str]:
    """Section numbers of docs/math.md: `## 2. ...` gives "2", `### 2.3 ...` gives "2.3"."""
    text = (ROOT / "docs" / "math.md").read_text()
    return set(re.findall(r"^#{2,3} (\d+(?:\.\d+)?)\.?\s", text, flags=re.M))


def test_every_math_citation_resolves_to_a_section_of_the_projects_math_reference():
    """The project stands on its own: every `math.md §N` in the package, the docs, the README,
    the tests and experiments names a section of docs/math.md, no file points at the
    sibling folder of shared documents a clone does not have, and every "seed NNN" cited in
    the package is in the bibliography."""
    sections = _math_sections()
    assert {str(n) for n in range(1, 9)} <= sections
    files = [*PACKAGE.rglob("*.py"), *PACKAGE.rglob("*.glsl"), *(ROOT / "docs").glob("*.md"), ROOT / "README.md",
             *(ROOT / "tests").rglob("*.py"), *(ROOT / "experiments").glob("*.py"), *(ROOT / "notebooks").glob("*.py")]
    cited, outside = set(), []
    for path in files:
        text = path.read_text()
        cited |= {(str(path.relative_to(ROOT)), n) for n in re.findall(r"math\.md ?§ ?(\d+(?:\.\d+)?)", text)}
        if OUTSIDE in text and path != pathlib.Path(__file__):
            outside.append(str(path.relative_to(ROOT)))
    assert len(cited) > 50
    assert sorted((f, n) for f, n in cited if n not in sections) == []
    assert outside == []
    assert "MATH.md" not in "".join(p.read_text() for p in PACKAGE.rglob("*.py"))
    bibliography = (ROOT / "docs" / "bibliography.md").read_text()
    seeds = {m for p in PACKAGE.rglob("*.py") for m in re.findall(r"seed (\d{3})", p.read_text())}
    assert seeds and all(f"| {s} |" in bibliography for s in seeds), seeds
