"""formgrader's two buttons that would undo a course graded by this kit, refused before they touch a file.

In a course recorded by ``nbgrader-sync``, two of formgrader's buttons are traps:

- *Generate* (``NbGraderAPI.generate_assignment``) runs nbgrader's ``GenerateAssignment`` with
  ``force``: it deletes ``assignments/<id>/`` (the student notebooks the grader reads its trusted
  setup cells from) and then fails on the gradebook the sync wrote. This course generates its
  student notebooks with ``python -m autograder assignments`` (``make assignments``) instead.
- *Autograde* (``NbGraderAPI.autograde``) runs nbgrader's ``Autograde`` with ``force``: it deletes
  ``autograded/<student>/<id>/``, the notebook the sync placed for formgrader, and then executes
  the student's notebook in a Jupyter kernel, outside the sandbox. This course grades with
  ``python -m autograder batch`` and records the results with ``nbgrader-sync``.

Both converters build their exporter (``BaseConverter.exporter_class``, a configurable trait) after
finding the notebooks and before deciding what to delete, so the course's ``nbgrader_config.py``
names one of the exporters below for them: building it raises with the reason and what to run
instead, nbgrader's ``capture_log`` hands that to formgrader as a failed action, and nothing on disk
has changed. *Generate* is refused only when formgrader (``NbGraderAPI``) asks, so ``nbgrader
generate_assignment`` from the command line, which ``make assignments`` runs, still works;
*Autograde* is refused everywhere (formgrader and ``nbgrader autograde``).
"""
from __future__ import annotations

from nbconvert.exporters import NotebookExporter

GENERATE_REFUSED = (
    "Refused by this course's nbgrader_config.py: formgrader's Generate would delete assignments/<id>/ (the student "
    "notebooks the autograder reads) and then fail on the synced gradebook. Nothing was changed. Regenerate student "
    "notebooks with `make assignments` (python -m autograder assignments ID) instead.")
AUTOGRADE_REFUSED = (
    "Refused by this course's nbgrader_config.py: nbgrader's Autograde would delete the notebook formgrader shows "
    "(autograded/<student>/<id>/) and run the student's code outside the sandbox. Nothing was changed. Grade with "
    "`python -m autograder batch ID FOLDER --out DIR` (or `regrade`), then `python -m autograder nbgrader-sync`.")


class RefusedAction(RuntimeError):
    """A formgrader (or nbgrader) action this course refuses; the message says what to run instead."""


class _RefusingExporter(NotebookExporter):
    """An exporter that cannot be built: the converter that asks for it stops before it changes anything."""

    refusal = ""

    def __init__(self, *args, **kwargs):  # noqa: D107 - refuses by design
        parent = kwargs.get("parent")
        if parent is not None and getattr(parent, "log", None) is not None:
            parent.log.error(self.refusal)  # formgrader shows the action's log beside its error
        raise RefusedAction(self.refusal)


class GenerateRefused(_RefusingExporter):
    refusal = GENERATE_REFUSED


class AutogradeRefused(_RefusingExporter):
    refusal = AUTOGRADE_REFUSED

