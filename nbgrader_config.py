"""nbgrader configuration: this repository is an nbgrader course.

Instructor notebooks live in ``solutions/<id>/<id>.ipynb`` and the generated
student notebooks in ``assignments/<id>/<id>.ipynb`` (``make assignments``).
"""
import os

c = get_config()  # noqa: F821  (injected by nbgrader)

# The folder of this file, absolute: nbgrader would take "." from wherever it runs, with a warning from each
# of its apps at every command.
c.CourseDirectory.root = os.path.dirname(os.path.abspath(__file__))
c.CourseDirectory.source_directory = "solutions"
c.CourseDirectory.release_directory = "assignments"
c.CourseDirectory.db_url = "sqlite:///.nbgrader/gradebook.db"
# Student copies are written straight into assignments/<id>/, not release/<course_id>/<id>/.
c.CourseDirectory.course_id = ""
c.ClearSolutions.code_stub = {"python": "# YOUR CODE HERE\nraise NotImplementedError()"}
c.ClearSolutions.text_stub = "YOUR ANSWER HERE"
c.ClearOutput.enabled = True

# Late submissions (autograder/outputs/late.py): nbgrader's late-submission plugin, which nbgrader-sync and
# export apply to each submission past its deadline (the assignment's due date, or a student's extension from
# extensions.csv). No penalty as shipped; e.g. percent = 10 and cap_percent = 50: a tenth of the score per day
# begun, at most half of it. LatePenalty.points = 1 takes a point per period instead.
c.AssignLatePenalties.plugin_class = "autograder.outputs.late.LatePenalty"
c.LatePenalty.per = "day"
c.LatePenalty.percent = 0.0
c.LatePenalty.cap_percent = 100.0
c.LatePenalty.grace_minutes = 0.0

# formgrader's Generate and Autograde buttons would delete what a synced course relies on (the student
# notebooks; the notebooks formgrader shows) and Autograde would run student code outside the sandbox:
# both are refused before they touch a file (autograder/outputs/formgrader_guard.py, docs/instructors.md).
# Generate only from formgrader: `make assignments` runs `nbgrader generate_assignment` itself.
c.NbGraderAPI.GenerateAssignment.exporter_class = "autograder.outputs.formgrader_guard.GenerateRefused"
c.Autograde.exporter_class = "autograder.outputs.formgrader_guard.AutogradeRefused"

# Validate (the notebook toolbar's button, and `nbgrader validate`) runs every code cell at the FAST budget and
# fails on any cell that raises or writes to stderr: the public checks, not only nbgrader's graded test cells
# (this course has none), decide (rlcourse/student_lab.py). The student release ships the same settings.
from rlcourse.student_lab import configure_validate  # noqa: E402

configure_validate(c)
