"""The instructor's outputs: what happens to a batch's results after grading.

This room depends on the grading core (it reads what ``batch`` writes and calls
``run_batch`` to regrade) and the core never imports it. Its modules:

- :mod:`~autograder.outputs.batch_output`: reading a batch's output folder (one
  ``result.json`` per submission) and its archived earlier runs;
- :mod:`~autograder.outputs.gradebook`: recording a batch in the course's
  nbgrader gradebook (``nbgrader.api.Gradebook``) and placing each submission
  where nbgrader's formgrader opens it, written answers waiting for a grade;
- :mod:`~autograder.outputs.feedback`: students' feedback once written answers
  are graded (Markdown, and nbgrader's own HTML);
- :mod:`~autograder.outputs.export`: the final grades of a course, one CSV;
- :mod:`~autograder.outputs.regrade`: regrading after a suite is fixed, keeping
  the earlier results readable, and the per-student difference;
- :mod:`~autograder.outputs.cli`: their ``python -m autograder`` commands.
"""
