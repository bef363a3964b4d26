"""MkDocs hooks of the documentation site (mkdocs.yml; `make docs`).

- API pages, generated at build time so that every public name has one: a page per
  public module, with a mkdocstrings `::: module.name` block for each name of the
  module's `__all__` (a whole-module block where a module has no `__all__`). A name added
  to an `__all__` appears on the next build without editing anything here.
- After the build, every name of every documented `__all__` must have its anchor on its
  API page (`id="module.name"`), or the build fails.
- A figures page: every PNG of figures/ and the guides that embed it.
- The guides link their figures as `../figures/NAME.png` (correct on GitHub, where
  docs/ sits beside figures/); on the site the figures live under `docs/figures`
  (a link to `../figures`), so those links are rewritten to `figures/NAME.png`.
"""

from __future__ import annotations

import importlib
import re
import types
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

# (page, module, title, how): "names" documents each name of __all__, "module" the module.
API_PAGES = (
    ("caustics_jax", "caustics_jax", "The public API (`import caustics_jax as cj`)", "names"),
    ("scenes", "caustics_jax.surface.scenes", "Scenes", "module"),
    ("solvers", "caustics_jax.solvers", "Solvers", "names"),
    ("transport", "caustics_jax.transport", "Transport: D factor, irradiance, photons", "names"),
    ("kernels", "caustics_jax.kernels", "Real-time pipeline kernels", "names"),
    ("export", "caustics_jax.export", "Shader reference data", "names"),
    ("testing", "caustics_jax.testing", "Testing: the numpy float64 oracle and planted paths", "names"),
    ("compare", "caustics_jax.app.compare", "The solver comparison job", "module"),
    ("progress", "caustics_jax.runtime.progress", "Progress bars", "module"),
)
PAGE_OF_MODULE = {module: page for page, module, _, _ in API_PAGES}


def _page(module_name: str, title: str, how: str) -> str:
    module = importlib.import_module(module_name)
    lines = [f"# {title}", "", f"`{module_name}`", ""]
    if how == "module" or not hasattr(module, "__all__"):
        lines += [f"::: {module_name}", "    options:", "      show_root_heading: false", ""]
        return "\n".join(lines)
    doc = (module.__doc__ or "").strip()
    if doc:
        lines += [doc, ""]
    for name in module.__all__:
        obj = getattr(module, name)
        if isinstance(obj, types.ModuleType):
            page = PAGE_OF_MODULE.get(obj.__name__)
            target = f"[{obj.__name__}]({page}.md)" if page else f"`{obj.__name__}`"
            if page is None:  # a submodule without a page of its own: its docstring here
                lines += [f"::: {obj.__name__}", "    options:", "      members: false", ""]
            else:
                lines += [f"## `{name}`", "", f"The module {target}.", ""]
        elif name == "__version__":
            lines += ["## `__version__`", "", f"The package version, `{obj}` at this build.", ""]
        else:
            lines += [f"::: {module_name}.{name}", ""]
    return "\n".join(lines)


def _index() -> str:
    rows = "\n".join(f"| [{module}]({page}.md) | {title} |" for page, module, title, _ in API_PAGES)
    return ("# API reference\n\nGenerated from the docstrings at build time (mkdocstrings): every name of "
            "each module's `__all__` has an entry.\n\n| module | contents |\n|---|---|\n" + rows + "\n")


def _figures(docs_dir: Path) -> str:
    """A gallery of every figure in figures/, each with the guides that embed it."""
    guides = {p.name: p.read_text() for p in sorted(docs_dir.glob("*.md"))}
    lines = ["# Figures", "", "Every figure the experiments and `make demo` write into `figures/`, with the "
             "guides that discuss it (`make figures` regenerates them).", ""]
    for png in sorted((docs_dir / "figures").glob("*.png")):
        cited = [f"[{name[:-3]}]({name})" for name, text in guides.items() if f"figures/{png.name}" in text]
        lines += [f"## {png.stem}", "", f"![{png.stem}](figures/{png.name})", "",
                  ("Discussed in " + ", ".join(cited) + ".") if cited else "", ""]
    return "\n".join(lines)


def on_files(files, config):
    files.append(File.generated(config, "figures.md", content=_figures(Path(config["docs_dir"]))))
    files.append(File.generated(config, "api/index.md", content=_index()))
    for page, module, title, how in API_PAGES:
        files.append(File.generated(config, f"api/{page}.md", content=_page(module, title, how)))
    return files


_FIGURE_LINK = re.compile(r"\]\(\.\./figures/")


def on_page_markdown(markdown, page, config, files):
    if page.file.src_uri.count("/") == 0:  # top-level guides: docs/NAME.md
        return _FIGURE_LINK.sub("](figures/", markdown)
    return markdown


def on_post_build(config):
    missing = []
    for page, module_name, _, how in API_PAGES:
        module = importlib.import_module(module_name)
        if how != "names" or not hasattr(module, "__all__"):
            continue
        html = (Path(config["site_dir"]) / "api" / f"{page}.html").read_text()
        missing += [f"{module_name}.{name}" for name in module.__all__
                    if name != "__version__" and not isinstance(getattr(module, name), types.ModuleType)
                    and f'id="{module_name}.{name}"' not in html]
    if missing:
        raise PluginError(f"API pages lack an entry for {missing}")
