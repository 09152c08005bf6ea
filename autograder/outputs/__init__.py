"""The instructor's outputs: everything a grading becomes for people, and the term after a batch.

This room depends on the grading core (it receives each result from ``core.batch.run_batch`` through a
writer callback, and reads the records the core keeps) and the core never imports it
(``tests/test_layers.py`` checks the arrows). Its modules:

- :mod:`~autograder.outputs.text`: student text made inert for every medium (terminal, Markdown, plain
  text, CSV); every writer here goes through it;
- :mod:`~autograder.outputs.files`: a submission's ``results.json`` and ``feedback.md``, the batch's
  ``gradebook.csv``, and :func:`~autograder.outputs.files.grade_folder` (the batch with these writers);
- :mod:`~autograder.outputs.terminal`: the per-stub summary and the progress bar;
- :mod:`~autograder.outputs.gradescope` and :mod:`~autograder.outputs.prairielearn`: the hosted graders'
  bundles, questions and entry points;
- :mod:`~autograder.outputs.batch_output`: reading a batch's output folder and its archived runs;
- :mod:`~autograder.outputs.gradebook`: recording a batch in the course's nbgrader gradebook and placing
  each submission where formgrader opens it; :mod:`~autograder.outputs.formgrader_guard` keeps
  formgrader's destructive buttons from running;
- :mod:`~autograder.outputs.feedback`: students' feedback, with hand grades once written answers are graded;
- :mod:`~autograder.outputs.export`, :mod:`~autograder.outputs.late`: final grades for an LMS, late rules;
- :mod:`~autograder.outputs.merge`, :mod:`~autograder.outputs.regrade`: shards joined, regrading after a
  suite is fixed;
- :mod:`~autograder.outputs.class_report`, :mod:`~autograder.outputs.similarity`: item analysis and
  similar stub code;
- :mod:`~autograder.outputs.checkout`: refusing a venv whose sandbox would run another checkout;
- :mod:`~autograder.outputs.cli`: the term's ``python -m autograder`` commands.
"""
