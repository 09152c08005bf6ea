"""The grader's rooms and their arrows (DESIGN.md, "How the grader grows"), read from every import's AST.

The rooms are the sub-packages of ``autograder``. Outputs and authoring depend on the core, the core on
the sandbox's protocol, and nothing points the other way: the sandbox imports nothing of the grader, the
core none of the outputs, the authoring tools or the CLI, the suites only ``autograder.suite``, the
course library (``rlcourse``) nothing of the grader, and no module anywhere imports the tests.
"""
from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

FORBIDDEN: dict[str, tuple[str, ...]] = {
    "autograder.sandbox": ("autograder.core", "autograder.outputs", "autograder.authoring", "autograder.suite",
                           "autograder.suites", "autograder.__main__"),
    "autograder.core": ("autograder.outputs", "autograder.authoring", "autograder.suites", "autograder.__main__"),
    "autograder.suite": ("autograder.outputs", "autograder.authoring", "autograder.__main__"),
    "rlcourse": ("autograder",),
}
"""Room (a module prefix) -> module prefixes it may not import. Every module is also barred from ``tests``."""
SUITES_MAY_IMPORT = ("autograder.suite",)
"""A hidden suite reaches the grader only through its public face."""


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports(path: Path, root: Path) -> list[tuple[int, str]]:
    """(line, module) of every import in ``path``: statements (relative ones resolved), and calls of
    ``importlib.import_module`` or ``__import__`` with a literal name."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = module_name(path, root).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([base] if base else []))
            found += [(node.lineno, f"{base}.{alias.name}" if base else alias.name) for alias in node.names]
            found.append((node.lineno, base))
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str):
            func = node.func
            name = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if name in ("import_module", "__import__"):
                found.append((node.lineno, node.args[0].value))
    return found


def _within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def forbidden_arrows(root: Path) -> list[str]:
    """Every import under ``root`` (a checkout) that breaks the design, as ``file:line: room -> module``."""
    bad = []
    files = [p for folder in ("autograder", "rlcourse") if (root / folder).is_dir()
             for p in sorted((root / folder).rglob("*.py")) if "__pycache__" not in p.parts]
    for path in files:
        name = module_name(path, root)
        for line, target in imports(path, root):
            where = f"{path.relative_to(root)}:{line}: {name} -> {target}"
            if _within(target, "tests") or (target == "conftest" and not _within(name, "autograder.suites")):
                bad.append(where)  # a suite's own conftest.py is the suite's, not the project's tests
            elif _within(name, "autograder.suites"):
                if _within(target, "autograder") and not any(_within(target, ok) for ok in SUITES_MAY_IMPORT) \
                        and target != "autograder":
                    bad.append(where)
            else:
                for room, barred in FORBIDDEN.items():
                    if _within(name, room) and any(_within(target, b) for b in barred):
                        bad.append(where)
    return bad


def test_every_arrow_points_the_way_the_design_says():
    assert len(list((REPO / "autograder").rglob("*.py"))) > 40
    assert forbidden_arrows(REPO) == []


def test_the_rooms_are_folders():
    rooms = {p.name for p in (REPO / "autograder").iterdir() if (p / "__init__.py").is_file()}
    assert {"sandbox", "core", "outputs", "authoring"} <= rooms
    loose = sorted(p.name for p in (REPO / "autograder").glob("*.py"))
    assert loose == ["__init__.py", "__main__.py", "suite.py"], "modules belong in a room, not at the top"


def _plant(tmp_path: Path, module: str, source: str) -> Path:
    root = tmp_path / "checkout"
    path = root / Path(*module.split(".")).with_suffix(".py")
    for folder in [path.parent, *path.parent.parents]:
        if folder == root:
            break
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "__init__.py").touch()
    path.write_text(source)
    return root


def test_a_planted_forbidden_import_is_caught(tmp_path):
    cases = {
        ("autograder.core.grader", "from autograder.outputs.files import write_outputs\n"): "autograder.outputs",
        ("autograder.core.batch", "from ..outputs import text\n"): "autograder.outputs.text",
        ("autograder.core.batch", "import importlib\nimportlib.import_module('autograder.authoring.demo')\n"):
            "autograder.authoring.demo",
        ("autograder.sandbox.worker", "def f():\n    from autograder.core import session\n"): "autograder.core",
        ("autograder.suites.hw0.test_x", "from autograder.core.session import Lend\n"): "autograder.core.session",
        ("rlcourse.nets", "import autograder.outputs.text\n"): "autograder.outputs.text",
        ("autograder.outputs.files", "from tests.conftest import x\n"): "tests.conftest",
    }
    for n, ((module, source), target) in enumerate(cases.items()):
        root = _plant(tmp_path / str(n), module, source)
        found = forbidden_arrows(root)
        assert any(f"-> {target}" in line for line in found), (module, source, found)
    allowed = {("autograder.outputs.files", "from autograder.core.batch import run_batch\n"),
               ("autograder.suites.hw0.test_x", "from autograder.suite import stub\n"),
               ("autograder.core.batch", '"""Writers live in autograder.outputs."""\n')}
    for n, (module, source) in enumerate(allowed):
        assert forbidden_arrows(_plant(tmp_path / f"ok{n}", module, source)) == [], source
