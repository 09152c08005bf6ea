"""The instructor's term after batch: nbgrader gradebook sync, formgrader, feedback, final grades, regrades.

Fast tests use the fixture course's assignment ``fx`` (four stubs worth 3, 2, 1 and 1 points, and a
written answer ``q_why`` worth 2) with results written directly; the slow one runs the whole term
end to end: batch, sync, formgrader over HTTP, a fixed suite, regrade, feedback and export.
"""
from __future__ import annotations

import csv
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import nbformat
import pytest
from nbconvert.filters.markdown import markdown2html

from autograder.outputs import export, feedback, gradebook, regrade
from autograder.outputs.batch_output import PREVIOUS_DIR, read_results, read_students
from autograder.outputs.text import markdown_text
from autograder.outputs.files import write_outputs
from autograder.core.results import GRADED, GRADER_ERROR, UNGRADABLE, GradeResult, StubResult
from autograder.core.results import TestOutcome as Outcome
from conftest import FIXTURE_COURSE, REPO

POINTS = {"scaled_sum": 3.0, "Counter": 2.0, "mean_of": 1.0, "double_scaled": 1.0}
RELEASE = FIXTURE_COURSE / "assignments" / "fx" / "fx.ipynb"


def graded(name: str, passed: set[str], points: dict[str, float] = POINTS) -> GradeResult:
    """A result in which the stubs in ``passed`` earned all their points and the others none."""
    stubs = [StubResult(s, [Outcome(f"{s} is right", s, p, s in passed, "" if s in passed else f"{s} <b>is</b> off")])
             for s, p in points.items()]
    return GradeResult("fx", name, stubs, [("q_why", 2.0)], status=GRADED)


def submission(path: Path, answer: str | None = "YOUR ANSWER HERE", drop: tuple[str, ...] = ()) -> Path:
    """The released fx notebook with a written answer (None: the answer cell deleted) and cells dropped."""
    nb = nbformat.read(str(RELEASE), as_version=4)
    cells = []
    for cell in nb.cells:
        gid = cell.metadata.get("nbgrader", {}).get("grade_id")
        if gid in drop or (gid == "q_why" and answer is None):
            continue
        if gid == "q_why":
            cell.source = answer
        cells.append(cell)
    nb.cells = cells
    path.parent.mkdir(parents=True, exist_ok=True)
    nbformat.write(nb, str(path))
    return path


@pytest.fixture(scope="module")
def empty_gradebook(tmp_path_factory) -> Path:
    """A new nbgrader gradebook, made once: nbgrader runs alembic for each new one (seconds)."""
    root = tmp_path_factory.mktemp("template")
    shutil.copy(REPO / "nbgrader_config.py", root / "nbgrader_config.py")
    gradebook.open_gradebook(gradebook.course_directory(root)).close()
    return root / ".nbgrader" / "gradebook.db"


@pytest.fixture
def new_course(tmp_path, empty_gradebook) -> Path:
    """An nbgrader course folder laid out as this repository configures it, with an empty gradebook."""
    root = tmp_path / "course"
    (root / ".nbgrader").mkdir(parents=True)
    shutil.copy(REPO / "nbgrader_config.py", root / "nbgrader_config.py")
    shutil.copy(empty_gradebook, root / ".nbgrader" / "gradebook.db")
    return root


@pytest.fixture
def term(fixture_course, tmp_path, new_course):
    """Three flat submissions of fx graded (results written as batch writes them), and an empty nbgrader course."""
    folder, out = tmp_path / "submissions", tmp_path / "results"
    submission(folder / "alice.ipynb", "The max cancels in the ratio: <script>alert(1)</script> $a<b$.")
    submission(folder / "bob.ipynb", "Because.")
    submission(folder / "carol.ipynb")
    write_outputs(graded("alice", set(POINTS)), out / "alice")
    write_outputs(graded("bob", {"scaled_sum"}), out / "bob")
    write_outputs(graded("carol", set()), out / "carol")
    return folder, out, new_course


def grades_of(root: Path, student: str) -> dict[str, object]:
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        nb = gb.find_submission_notebook("fx", "fx", student)
        return {g.name: (g.auto_score, g.manual_score, g.needs_manual_grade) for g in nb.grades}


def give(root: Path, student: str, cell: str, score: float | None = None, comment: str | None = None) -> None:
    """What formgrader's score box and comment box write (through the same Gradebook rows)."""
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        if score is not None:
            grade = gb.find_grade(cell, "fx", "fx", student)
            grade.manual_score, grade.needs_manual_grade = score, False
        if comment is not None:
            gb.find_comment(cell, "fx", "fx", student).manual_comment = comment
        gb.db.commit()


def test_sync_records_automatic_scores_and_keeps_what_people_gave(term):
    folder, out, root = term
    report = gradebook.sync("fx", folder, out, root)
    assert sorted(s for _, s in report.recorded) == ["alice", "bob", "carol"] and not report.skipped
    assert grades_of(root, "alice") == {"scaled_sum": (3, None, False), "Counter": (2, None, False),
                                        "mean_of": (1, None, False), "double_scaled": (1, None, False),
                                        "q_why": (None, None, True)}
    assert grades_of(root, "bob")["Counter"] == (0, None, False)
    assert grades_of(root, "carol")["q_why"] == (0, None, False), "an answer left as released is worth 0, not pending"
    give(root, "bob", "q_why", 1.5, "Half of it: say why the maximum cancels.")
    give(root, "bob", "Counter", 1.0, "Partial credit: the idea is there.")
    give(root, "alice", "q_why", 2.0)

    write_outputs(graded("bob", {"scaled_sum", "mean_of"}), out / "bob")  # a regrade changed bob's mean_of
    again = gradebook.sync("fx", folder, out, root)
    assert again.kept == 5 and again.waiting == 0  # bob's two scores and two comments, alice's score
    bob = grades_of(root, "bob")
    assert bob["q_why"] == (None, 1.5, False) and bob["Counter"] == (0, 1.0, False)
    assert bob["mean_of"] == (1, None, False)
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        assert len(gb.assignment_submissions("fx")) == 3 and len(gb.students) == 3
        assert gb.find_comment("q_why", "fx", "fx", "bob").manual_comment.startswith("Half of it")
        assert "mean_of is right (1/1)" in gb.find_comment("mean_of", "fx", "fx", "bob").auto_comment
        shown = markdown2html(gb.find_comment("Counter", "fx", "fx", "bob").auto_comment)  # as nbgrader's feedback HTML
        assert "Counter &lt;b&gt;is&lt;/b&gt; off" in shown and "<b>" not in shown
        assert gb.find_submission("fx", "bob").score == 3 + 1 + 1 + 1.5
    assert json.loads((out / "_students.json").read_text()) == {"alice": ["alice"], "bob": ["bob"], "carol": ["carol"]}


def test_the_placed_notebook_shows_the_graded_cells_and_no_student_html(term):
    folder, out, root = term
    nb = nbformat.read(str(folder / "alice.ipynb"), as_version=4)
    nb.cells[2].outputs = [nbformat.v4.new_output("display_data", {"text/html": "<script>steal()</script>"})]
    nb.cells.append(nbformat.v4.new_raw_cell("<img src=x onerror=steal()>"))
    nb.metadata["widgets"] = {"application/vnd.jupyter.widget-state+json": {"state": {}}}
    for cell in nb.cells:  # a student who lost every cell's metadata: stubs are found by the names they define
        cell.metadata = {}
    counter = next(i for i, c in enumerate(nb.cells) if c.source.startswith("class Counter"))
    mean_of = next(c for c in nb.cells if c.source.startswith("def mean_of"))
    nb.cells[counter].source += "\n\n" + mean_of.source  # two stubs in one cell
    nb.cells.remove(mean_of)
    nbformat.write(nb, str(folder / "alice.ipynb"))
    gradebook.sync("fx", folder, out, root)
    placed = nbformat.read(str(root / "autograded" / "alice" / "fx" / "fx.ipynb"), as_version=4)
    graded_cells = {c.metadata["nbgrader"]["grade_id"]: c for c in placed.cells if "nbgrader" in c.metadata}
    assert {k: c.metadata["nbgrader"]["points"] for k, c in graded_cells.items()} == {**POINTS, "q_why": 2.0}
    assert graded_cells["Counter"].source.startswith("class Counter") and "def mean_of" in graded_cells["Counter"].source
    assert graded_cells["mean_of"].source == "# `mean_of` is defined in the cell of `Counter` above."
    assert graded_cells["scaled_sum"].source.startswith("def scaled_sum")
    assert graded_cells["q_why"].source == gradebook.MISSING_CELL  # no cell carries q_why's id any more
    assert all(c.metadata["nbgrader"]["grade"] and c.metadata["nbgrader"]["solution"] for c in graded_cells.values())
    text = "".join(c.source for c in placed.cells if c.cell_type == "markdown")
    assert "<script" not in text and "<img" not in text and "&lt;img" in text and "$a<b$" in text  # math as written
    assert not any(c.get("outputs") for c in placed.cells if c.cell_type == "code")
    assert set(placed.metadata) <= {"kernelspec", "language_info"}
    assert placed.cells[0].source.startswith("**Automatic score: 7 / 7**")
    assert grades_of(root, "alice")["q_why"] == (None, None, True), "a missing answer cell waits for a person"


@pytest.mark.parametrize("answer, shown", [
    ("<script>steal()</script> since $a<b$ and $$c<d$$", "since $a&lt;b$ and $$c&lt;d$$"),  # math as MathJax reads it
    ("[my plot](javascript:steal()) and [more]( jav&#x61;script:steal())", "[my plot](javascript:steal())"),
    ("[r]: javascript:steal()\n\nsee [r]", "[r]: javascript:steal()"),
    ("[notes](https://example.org/n) and ![fig](figure.png)", '<a href="https://example.org/n">notes</a>'),
    ("\\$<img src=x onerror=steal()>$", "&lt;img src=x onerror=steal()&gt;"),  # not math: every < escaped
    ("`a$` <img src=x onerror=steal()> `$b`", "&lt;img src=x onerror=steal()&gt;"),
])
def test_student_markdown_renders_inert_in_formgrader(answer, shown):
    rendered = markdown2html(gradebook._inert(answer))  # the filter formgrader's template applies
    assert shown in rendered
    assert "<script" not in rendered and "onerror=" not in rendered.replace("&lt;img src=x onerror=", "")
    assert 'href="javascript' not in rendered.replace(" ", "")


def test_a_gradescope_export_records_each_submitter_and_knows_who_was_late(fixture_course, tmp_path, new_course):
    folder, out, root = tmp_path / "export", tmp_path / "results", new_course
    submission(folder / "submission_101" / "work.ipynb", "Because.")
    submission(folder / "submission_102" / "fx.ipynb")
    (folder / "submission_metadata.yml").write_text("""\
submission_101:
  :submitters:
  - :name: Ada Lovelace
    :sid: '1815'
    :email: ada@example.edu
  - :name: Charles Babbage
    :sid: '1791'
    :email: cb@example.edu
  :created_at: 2026-03-01 09:00:00.000000000 +00:00
submission_102:
  :submitters:
  - :name: "=HYPERLINK(1)"
    :email: late@example.edu
  :created_at: 2026-03-03 09:00:00.000000000 +00:00
""")
    write_outputs(graded("submission_101", {"scaled_sum"}), out / "submission_101")
    write_outputs(GradeResult("fx", "submission_102", [], [("q_why", 2.0)], error="no notebook", status=UNGRADABLE),
                  out / "submission_102")
    gradebook.sync("fx", folder, out, root)
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        assert sorted(s.id for s in gb.students) == ["1791", "1815", "late@example.edu"]
        assert gb.find_student("1815").last_name == "Lovelace" and gb.find_student("1815").first_name == "Ada"
        gb.update_or_create_assignment("fx", duedate="2026-03-02 00:00:00 UTC")
    assert grades_of(root, "late@example.edu")["q_why"] == (0, None, False), "no notebook: nothing to grade by hand"
    grades = {(g.student_id, g.assignment): g for g in export.export(tmp_path / "long.csv", root, long=True).grades}
    assert grades["1815", "fx"].late == "no" and grades["late@example.edu", "fx"].late == "yes"
    assert grades["1791", "fx"].automatic == 3 and grades["1791", "fx"].waiting == 1
    rows = list(csv.DictReader((tmp_path / "long.csv").open()))
    assert [r["student_id"] for r in rows] == ["1791", "1815", "late@example.edu"]
    export.export(tmp_path / "wide.csv", root)
    wide = list(csv.DictReader((tmp_path / "wide.csv").open()))
    assert wide[2]["last_name"] == "'=HYPERLINK(1)", "a name that a spreadsheet would run is written as text"
    assert [r["fx late"] for r in wide] == ["no", "no", "yes"]


def test_export_totals_are_automatic_plus_written_and_agree_with_nbgrader(term, tmp_path):
    from nbgrader.plugins.export import CsvExportPlugin

    folder, out, root = term
    gradebook.sync("fx", folder, out, root)
    give(root, "alice", "q_why", 2.0)
    give(root, "bob", "q_why", 0.5)
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        gb.add_student("dave", first_name="Dave")  # enrolled, never submitted
        CsvExportPlugin(to=str(tmp_path / "nbgrader.csv")).export(gb)
    grades = export.export(tmp_path / "grades.csv", root).grades
    rows = {r["student_id"]: r for r in csv.DictReader((tmp_path / "grades.csv").open())}
    expected = {"alice": (7, 2), "bob": (3, 0.5), "carol": (0, 0), "dave": (0, 0)}
    for student, (auto, written) in expected.items():
        row = rows[student]
        assert (float(row["fx automatic"]), float(row["fx written"])) == (auto, written)
        assert float(row["fx"]) == auto + written
        assert float(row["course total"]) == auto + written
    theirs = {r["student_id"]: float(r["score"]) for r in csv.DictReader((tmp_path / "nbgrader.csv").open())}
    assert theirs == {g.student_id: g.total for g in grades}
    assert rows["alice"]["fx late"] == "", "no due date: lateness unknown"


def test_results_of_two_suite_versions_are_refused(term):
    folder, out, root = term
    write_outputs(graded("bob", {"scaled_sum"}, {**POINTS, "mean_of": 2.0}), out / "bob")
    with pytest.raises(SystemExit, match="mean_of.*different versions"):
        gradebook.sync("fx", folder, out, root)


def test_a_grader_error_changes_nothing_in_the_gradebook(term):
    folder, out, root = term
    gradebook.sync("fx", folder, out, root)
    write_outputs(GradeResult("fx", "bob", [], [], error="sandbox did not start", status=GRADER_ERROR), out / "bob")
    report = gradebook.sync("fx", folder, out, root)
    assert [name for name, _ in report.skipped] == ["bob"]
    assert grades_of(root, "bob")["scaled_sum"] == (3, None, False)


def test_feedback_carries_automatic_and_hand_given_scores_and_comments(term):
    folder, out, root = term
    gradebook.sync("fx", folder, out, root)
    give(root, "bob", "q_why", 1.5, "Say *why* the [max](http://x) cancels.")
    give(root, "bob", "Counter", 1.0, "Close.")
    done = feedback.write_feedback("fx", out, root)
    assert len(done.written) == 3
    assert done.pending == [("alice", "q_why")], "alice's answer waits for a grade: the feedback says so"
    assert "alice: q_why" in done.warnings()[0]
    text = (root / "feedback" / "bob" / "fx" / "feedback.md").read_text()
    assert "**Automatic score: 3 / 7**" in text and "Counter <b>is</b> off" not in text
    assert "- `q_why`: 1.5 / 2" in text
    assert f"*comment:* {markdown_text('Say *why* the [max](http://x) cancels.')}" in text
    assert "*why*" not in text and "[max](" not in text, "a grader's comment is shown as text, not as Markdown"
    assert "- `Counter`: 1 / 2 (the tests gave 0)" in text
    assert "**Total: 4 (stubs) + 1.5 (written) = 5.5 / 9**" in text
    alice = (root / "feedback" / "alice" / "fx" / "feedback.md").read_text()
    assert "- `q_why`: not graded yet (2 point(s))" in alice and "(1 written answer(s) not graded yet)" in alice
    carol = (root / "feedback" / "carol" / "fx" / "feedback.md").read_text()
    assert "- `q_why`: 0 / 2 (left unanswered)" in carol


def test_regrade_comparison_and_archive(term):
    folder, out, root = term
    before = read_results(out)
    kept = regrade.archive(out, ["bob"])
    write_outputs(graded("bob", {"scaled_sum", "mean_of"}), out / "bob")
    assert kept.parent == out / PREVIOUS_DIR
    assert read_results(kept)["bob"].score == 3, "the earlier result stays readable"
    changes = regrade.compare(before, read_results(out))
    changed = [(c.submission, c.before, c.after, c.stubs) for c in changes if c.changed]
    assert changed == [("bob", 3, 4, [("mean_of", 0, 1)])]
    lines = regrade.change_lines(changes, {"alice": 2.0, "bob": 1.5, "carol": 0.0})
    bob = next(line for line in lines if line.startswith("bob"))
    assert "3 → 4" in bob and "4.5 → 5.5" in bob and "mean_of 0 → 1" in bob
    assert lines[-1] == "1 of 3 submission(s) changed"
    assert "alice" in read_results(out) and "alice" not in read_results(kept)


# ------------------------------------------------------------------ the whole term, end to end

def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Formgrader:
    """nbgrader's formgrader, headless, on a loopback port, in the nbgrader course folder."""

    def __init__(self, root: Path, env: dict[str, str]):
        self.url, self.token = f"http://127.0.0.1:{_free_port()}", "term-test-token"
        jupyter = Path(sys.executable).parent / "jupyter"
        self.log = (root.parent / "formgrader.log").open("w")
        self.process = subprocess.Popen(
            [str(jupyter), "server", "--no-browser", "--allow-root", "--ip=127.0.0.1",
             f"--port={self.url.rsplit(':', 1)[1]}", f"--IdentityProvider.token={self.token}",
             f"--ServerApp.root_dir={root}"],
            cwd=root, env={**env, "JUPYTER_RUNTIME_DIR": str(root.parent / "runtime")},
            stdout=self.log, stderr=subprocess.STDOUT)
        deadline = time.monotonic() + 120
        while True:
            try:
                self.get("/formgrader/api/status")
                return
            except OSError:
                if self.process.poll() is not None or time.monotonic() > deadline:
                    self.close()
                    log = (root.parent / "formgrader.log").read_text()
                    raise AssertionError(f"formgrader did not start: {log[-2000:]}")
                time.sleep(0.5)

    def request(self, path: str, data: dict | None = None) -> str:
        request = urllib.request.Request(self.url + path, headers={"Authorization": f"token {self.token}"},
                                         data=None if data is None else json.dumps(data).encode(),
                                         method="GET" if data is None else "PUT")
        with urllib.request.urlopen(request, timeout=60) as response:
            return response.read().decode()

    def get(self, path: str):
        return self.request(path)

    def api(self, path: str, data: dict | None = None):
        return json.loads(self.request("/formgrader/api/" + path, data))

    def close(self) -> None:
        self.process.terminate()
        try:
            self.process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.process.kill()
        self.log.close()


BUGGY_MEAN_TEST = "check_scalar(got, float(np.median(values)))  # a suite bug: the median, not the mean"


@pytest.mark.slow
def test_a_term_batch_formgrader_regrade_feedback_and_final_grades(open_tmp, monkeypatch):
    """Three students submit fx through nbgrader's submitted/ folder; the suite has a bug (mean_of is checked
    against the median), fixed after hand grading; the class is regraded; the hand-given scores survive."""
    from autograder.core import course

    source = open_tmp / "fixture"  # a copy of the fixture course, whose suite this test fixes mid-term
    shutil.copytree(FIXTURE_COURSE, source, ignore=shutil.ignore_patterns("samples", "__pycache__"))
    shutil.copy(REPO / "nbgrader_config.py", source / "nbgrader_config.py")
    suite = source / "autograder" / "suites" / "fx" / "test_fx.py"
    fixed = suite.read_text()
    assert "check_scalar(got, reference.mean_of(values))" in fixed
    suite.write_text(fixed.replace("check_scalar(got, reference.mean_of(values))", BUGGY_MEAN_TEST))
    for path in [source, *source.rglob("*")]:
        path.chmod(0o755 if path.is_dir() else 0o644)
    monkeypatch.setattr(course, "REPO", source)
    env = {**os.environ, "RLCOURSE_REPO": str(source),
           "PATH": str(Path(sys.executable).parent) + os.pathsep + os.environ.get("PATH", "")}
    root = open_tmp / "course"
    root.mkdir()
    shutil.copy(REPO / "nbgrader_config.py", root / "nbgrader_config.py")
    solution = {c.metadata["nbgrader"]["grade_id"]: re.sub(r"\s*### (BEGIN|END) SOLUTION\n?", "\n", c.source)
                for c in nbformat.read(str(source / "solutions/fx/fx.ipynb"), as_version=4).cells
                if "nbgrader" in c.metadata}
    submitted = root / "submitted"
    for student, stubs, answer in [("alice", list(POINTS), "The max cancels in the ratio."),
                                   ("bob", ["scaled_sum"], "Because."), ("carol", [], None)]:
        nb = nbformat.read(str(source / "assignments/fx/fx.ipynb"), as_version=4)
        for cell in nb.cells:
            gid = cell.metadata.get("nbgrader", {}).get("grade_id")
            if gid in stubs:
                cell.source = solution[gid]
            elif gid == "q_why" and answer:
                cell.source = answer
        (submitted / student / "fx").mkdir(parents=True)
        nbformat.write(nb, str(submitted / student / "fx" / "fx.ipynb"))
    (submitted / "bob" / "fx" / "timestamp.txt").write_text("2026-03-02 10:00:00.000000 UTC")
    for path in [open_tmp, *root.rglob("*")]:
        path.chmod(0o777 if path.is_dir() else 0o644)
    out = open_tmp / "results"

    def cli(*args: str) -> str:
        done = subprocess.run([sys.executable, "-m", "autograder", *args], env=env, cwd=REPO, capture_output=True,
                              text=True, timeout=600)
        assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-3000:]
        return done.stdout

    cli("batch", "fx", str(root), "--out", str(out))
    assert {n: r.score for n, r in read_results(out).items()} == {"alice": 6, "bob": 3, "carol": 0}
    synced = cli("nbgrader-sync", "fx", str(root), "--results", str(out), "--course", str(root))
    assert "3 submission(s) recorded" in synced
    with gradebook.open_gradebook(gradebook.course_directory(root)) as gb:
        gb.update_or_create_assignment("fx", duedate="2026-03-01 23:59:00 UTC")

    server = Formgrader(root, env)
    try:
        listed = {s["student"]: s for s in server.api("submitted_notebooks/fx/fx")}
        assert set(listed) == {"alice", "bob", "carol"}
        page = server.get(f"/formgrader/submissions/{listed['bob']['id']}/")
        for stub, points in POINTS.items():  # a score box on each stub, out of its points, as formgrader draws it
            assert f'id="{stub}" style="width: 4em;" type="number"/> / {points}' in page
        assert 'id="q_why" style="width: 4em;" type="number"/> / 2.0' in page
        assert "Automatic score: 3 / 7" in page
        grades = {g["name"]: g for g in server.api(f"grades?submission_id={listed['bob']['id']}")}
        assert {k: g["auto_score"] for k, g in grades.items() if k in POINTS} == {
            "scaled_sum": 3.0, "Counter": 0.0, "mean_of": 0.0, "double_scaled": 0.0}  # the scores the page fills in
        assert grades["q_why"]["auto_score"] is None and grades["q_why"]["needs_manual_grade"]
        comments = {c["name"]: c for c in server.api(f"comments?submission_id={listed['bob']['id']}")}
        assert "not implemented yet" in comments["Counter"]["auto_comment"]
        for student, score, comment in [("bob", 1.0, "Half: why does it cancel?"), ("alice", 2.0, "Exactly.")]:
            sid = listed[student]["id"]
            grade = next(g for g in server.api(f"grades?submission_id={sid}") if g["name"] == "q_why")
            note = next(c for c in server.api(f"comments?submission_id={sid}") if c["name"] == "q_why")
            assert server.api(f"grade/{grade['id']}", {"manual_score": score})["manual_score"] == score
            server.api(f"comment/{note['id']}", {"manual_comment": comment})
    finally:
        server.close()

    suite.write_text(fixed)  # the suite is fixed mid-term: alice's correct mean_of was marked wrong
    # (regrading alice alone is refused now: the class would be graded by two suites; test_term_lms.py checks it)
    shown = cli("regrade", "fx", str(root), "--out", str(out), "--course", str(root))
    alice_line = next(line for line in shown.splitlines() if line.startswith("alice"))
    assert "6 → 7" in alice_line and "mean_of 0 → 1" in alice_line and "8 → 9" in alice_line, shown
    assert "1 of 3 submission(s) changed" in shown
    archived = [p for p in (out / PREVIOUS_DIR).iterdir() if p.is_dir()]
    assert len(archived) == 1 and read_results(archived[0])["alice"].score == 6
    assert "mean_of 0 → 1" in cli("results-diff", str(archived[0]), str(out))
    assert read_students(out) == {"alice": ["alice"], "bob": ["bob"], "carol": ["carol"]}
    assert grades_of(root, "alice")["mean_of"] == (1, None, False)
    assert grades_of(root, "alice")["q_why"] == (None, 2.0, False)
    assert grades_of(root, "bob")["q_why"] == (None, 1.0, False)

    cli("feedback", "fx", "--results", str(out), "--course", str(root), "--html")
    bob = (root / "feedback/bob/fx/feedback.md").read_text()
    assert "- `q_why`: 1 / 2" in bob and markdown_text("Half: why does it cancel?") in bob and "= 4 / 9**" in bob
    html = (root / "feedback/bob/fx/fx.html").read_text()
    assert "Half: why does it cancel?" in html and "Score: 4.0 / 9.0" in html

    cli("export", "--out", str(open_tmp / "grades.csv"), "--course", str(root))
    rows = {r["student_id"]: r for r in csv.DictReader((open_tmp / "grades.csv").open())}
    assert {s: (float(r["fx automatic"]), float(r["fx written"]), float(r["fx"])) for s, r in rows.items()} == {
        "alice": (7, 2, 9), "bob": (3, 1, 4), "carol": (0, 0, 0)}
    assert rows["bob"]["fx late"] == "yes" and rows["alice"]["fx late"] == ""
    done = subprocess.run([str(Path(sys.executable).parent / "nbgrader"), "export", "--to", str(open_tmp / "nb.csv")],
                          cwd=root, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    theirs = {r["student_id"]: float(r["score"]) for r in csv.DictReader((open_tmp / "nb.csv").open())}
    assert theirs == {s: float(r["fx"]) for s, r in rows.items()}
