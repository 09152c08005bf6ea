"""nbgrader configuration: this repository is an nbgrader course.

Instructor notebooks live in ``solutions/<id>/<id>.ipynb`` and the generated
student notebooks in ``assignments/<id>/<id>.ipynb`` (``make assignments``).
"""
c = get_config()  # noqa: F821  (injected by nbgrader)

c.CourseDirectory.root = "."
c.CourseDirectory.source_directory = "solutions"
c.CourseDirectory.release_directory = "assignments"
c.CourseDirectory.db_url = "sqlite:///.nbgrader/gradebook.db"
# Student copies are written straight into assignments/<id>/, not release/<course_id>/<id>/.
c.CourseDirectory.course_id = ""
c.ClearSolutions.code_stub = {"python": "# YOUR CODE HERE\nraise NotImplementedError()"}
c.ClearSolutions.text_stub = "YOUR ANSWER HERE"
c.ClearOutput.enabled = True
