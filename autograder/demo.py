"""The README's main job: grade every assignment's sample submissions and show the gradebooks."""
from __future__ import annotations

import csv
from pathlib import Path

from autograder import course
from autograder.batch import GRADEBOOK_NAME, run_batch
from autograder.report import FEEDBACK_NAME


def _table(path: Path) -> str:
    rows = list(csv.reader(path.open()))
    header, body = rows[0], rows[1:]
    keep = [i for i, h in enumerate(header) if h != "reason"]
    widths = [max(len(r[i]) for r in rows) for i in keep]
    line = lambda r: "  ".join(r[i].ljust(w) for i, w in zip(keep, widths))  # noqa: E731
    return "\n".join([line(header), line(["-" * w for w in widths] + [""] * len(header)), *map(line, body)])


def run_demo(out: Path, jobs: int = 2) -> int:
    """Batch-grade ``autograder/samples/<id>/`` for every assignment that has samples; print each gradebook."""
    ids = [i for i in course.assignment_ids() if course.samples_dir(i).is_dir() and course.suite_dir(i).is_dir()]
    if not ids:
        raise SystemExit("no assignment has sample submissions yet (python -m autograder samples ID)")
    for assignment in ids:
        target = Path(out) / assignment
        run_batch(assignment, course.samples_dir(assignment), target, jobs=jobs)
        print(f"\n{assignment}: gradebook {target / GRADEBOOK_NAME}\n")
        print(_table(target / GRADEBOOK_NAME))
        print(f"\nper-student feedback: {target}/<submission>/{FEEDBACK_NAME} "
              f"(e.g. {target / 'partial' / FEEDBACK_NAME}); Gradescope JSON beside it as results.json")
    return 0
