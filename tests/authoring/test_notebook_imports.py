"""What the notebooks import is declared: every package a notebook or rlcourse imports is pinned in
pyproject.toml (and so in environment.yml, tests/test_packaging.py), not present by accident because
another package happens to require it."""
from __future__ import annotations

import ast
import importlib.metadata
import re
import sys
import tomllib

import nbformat

from conftest import REPO

# A distribution the notebooks need without importing it: the front end that draws ipywidgets in JupyterLab.
NEEDED_UNIMPORTED = {"jupyterlab-widgets"}


def _normal(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def imported_modules(source: str) -> set[str]:
    """Top-level names of the absolute imports anywhere in ``source`` (IPython magics and shell lines dropped)."""
    code = "\n".join(line for line in source.splitlines() if not line.lstrip().startswith(("%", "!")))
    found = set()
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.Import):
            found |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            found.add(node.module.split(".")[0])
    return found


def notebook_and_library_imports() -> dict[str, set[str]]:
    """Third-party module -> the notebooks and rlcourse files that import it."""
    where: dict[str, set[str]] = {}
    sources = [(nb.relative_to(REPO), "\n".join(c.source for c in nbformat.read(nb, as_version=4).cells
                                               if c.cell_type == "code"))
               for nb in sorted((REPO / "solutions").glob("*/*.ipynb"))]
    sources += [(f.relative_to(REPO), f.read_text()) for f in sorted((REPO / "rlcourse").rglob("*.py"))]
    for path, source in sources:
        for module in imported_modules(source) - set(sys.stdlib_module_names) - {"rlcourse"}:
            where.setdefault(module, set()).add(str(path))
    return where


def declared() -> set[str]:
    deps = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    return {_normal(re.match(r"[A-Za-z0-9_.-]+", d).group()) for d in deps}


def test_imported_modules_reads_nested_and_from_imports_but_not_relative_ones():
    source = "import a.b as c\nfrom d.e import f\nfrom . import g\n%matplotlib inline\ndef h():\n    import i\n"
    assert imported_modules(source) == {"a", "d", "i"}


def test_every_package_the_notebooks_and_rlcourse_import_is_a_declared_dependency():
    owners = importlib.metadata.packages_distributions()
    pins = declared()
    undeclared = {}
    for module, files in sorted(notebook_and_library_imports().items()):
        dists = {_normal(d) for d in owners.get(module, [])}
        if not dists & pins:
            undeclared[module] = (sorted(dists) or ["not installed"], sorted(files)[:3])
    assert not undeclared, f"imported but not in pyproject.toml's dependencies (module: distributions, importers): {undeclared}"
    assert {"ipywidgets", "ipython"} <= pins  # hw3's annotator and IPython.display
    assert NEEDED_UNIMPORTED <= pins
