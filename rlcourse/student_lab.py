"""The student's JupyterLab: a Validate button that runs the public checks, and no instructor menus.

nbgrader is installed with the course, so every notebook's toolbar has nbgrader's **Validate**. As
shipped, Validate only looks at nbgrader's graded test cells, which this course has none of (its
hidden tests live with the grader), so it would praise a notebook whose stubs still raise; and it
cuts every cell off after 30 s. ``configure_validate`` sets nbgrader's own options so that it tells
the truth: every code cell counts (``Validator.validate_all``), so a public check that fails, a stub
that raises, or a warning on stderr is reported with its message; the notebook runs at its ``FAST``
budget (``FAST = True`` added to the cell tagged ``parameters``, as papermill injects parameters), so
Validate answers in about a minute; and no cell is cut off before ``CELL_TIMEOUT`` seconds.

``python -m rlcourse.student_lab`` hides nbgrader's instructor entries (Formgrader, Create
Assignment, and the exchange's assignment and course lists, which this course does not use) with
JupyterLab's own ``jupyter labextension disable`` (what nbgrader's installation guide says; its
function, called in this process), in this Python environment (``--user``: in the user's Jupyter config instead), and turns
their server extensions off in the same place through Jupyter Server's config manager (nbgrader
0.9.6's ``jupyter server extension disable`` refuses them: it cannot validate the module).
Validate stays.
"""
from __future__ import annotations

import argparse
from pathlib import Path

CELL_TIMEOUT = 600
"""Seconds one cell may run under Validate before nbgrader stops it (every FAST cell takes far less)."""

HIDDEN_LAB_PLUGINS = (
    "@jupyter/nbgrader:formgrader",
    "@jupyter/nbgrader:create-assignment",
    "@jupyter/nbgrader:assignment-list",
    "@jupyter/nbgrader:course-list",
    "@jupyter/nbgrader:menu",
)
"""nbgrader's JupyterLab plugins a student has no use for: all but ``validate-assignment``."""

HIDDEN_SERVER_EXTENSIONS = (
    "nbgrader.server_extensions.formgrader",
    "nbgrader.server_extensions.assignment_list",
    "nbgrader.server_extensions.course_list",
)
"""The server halves of those plugins (Create Assignment has none)."""

VALIDATE_FAILED = (
    "VALIDATION FAILED ON {num_failed} CELL(S) when the notebook ran at its FAST budget. Each is shown "
    "below: a public check that fails, a stub that still raises NotImplementedError, a warning, or a "
    "written answer left empty. Fix them before you submit; the grader's hidden tests are stricter "
    "than the public checks.\n"
)


def inject_fast(cell, cell_index: int = 0, **_) -> None:
    """nbclient's ``on_cell_start`` hook: run the cell tagged ``parameters`` with ``FAST = True`` after it."""
    if cell.get("cell_type") == "code" and "parameters" in cell.get("metadata", {}).get("tags", []):
        cell["source"] = cell["source"].rstrip("\n") + "\nFAST = True  # added by Validate\n"


def configure_validate(c) -> None:
    """Set nbgrader's Validator and Execute options on the traitlets config ``c`` (an nbgrader_config.py)."""
    c.Validator.validate_all = True
    c.Validator.failed_warning = VALIDATE_FAILED
    c.Execute.timeout = CELL_TIMEOUT
    c.Execute.on_cell_start = inject_fast


def hide_instructor_entries(user: bool = False) -> Path:
    """Disable nbgrader's instructor plugins and their server extensions; return the config folder written."""
    from jupyter_core.paths import ENV_CONFIG_PATH, jupyter_config_dir
    from jupyter_server.config_manager import BaseJSONConfigManager

    from jupyterlab.commands import disable_extension  # what `jupyter labextension disable` runs

    for plugin in HIDDEN_LAB_PLUGINS:
        disable_extension(plugin, level="user" if user else "sys_prefix")
    folder = Path(jupyter_config_dir() if user else ENV_CONFIG_PATH[0])
    BaseJSONConfigManager(config_dir=str(folder)).update(
        "jupyter_server_config", {"ServerApp": {"jpserver_extensions": dict.fromkeys(HIDDEN_SERVER_EXTENSIONS, False)}})
    return folder


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m rlcourse.student_lab", description=__doc__.split("\n\n")[0])
    parser.add_argument("--user", action="store_true",
                        help="write the user's Jupyter config (JUPYTER_CONFIG_DIR) instead of this environment's")
    args = parser.parse_args(argv)
    hide_instructor_entries(user=args.user)
    print("JupyterLab: nbgrader's instructor entries hidden; Validate runs the public checks at FAST")


if __name__ == "__main__":
    main()
