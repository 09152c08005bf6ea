"""Batch grading: the folder layouts, the gradebook, and resuming after a kill."""
from __future__ import annotations

import pytest

import csv
import re
import os
import shutil
import signal
import subprocess
import sys
import time

from autograder.core.batch import discover
from conftest import REPO

pytestmark = pytest.mark.slow  # end-to-end: make test-fast leaves it out, make test and CI run it

SAMPLES = REPO / "autograder/samples/hw0_setup"
EXPECTED = ["discounted_returns", "episode_returns"]


def test_layouts_are_recognised(tmp_path):
    flat = tmp_path / "flat"
    flat.mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", flat / "alice.ipynb")
    nbg = tmp_path / "course" / "submitted" / "bob" / "hw0_setup"
    nbg.mkdir(parents=True)
    shutil.copy(SAMPLES / "partial.ipynb", nbg / "hw0_setup.ipynb")
    export = tmp_path / "export"
    (export / "submission_101").mkdir(parents=True)
    (export / "submission_metadata.yml").write_text("{}")
    shutil.copy(SAMPLES / "complete.ipynb", export / "submission_101" / "work.ipynb")
    shutil.copy(SAMPLES / "untouched.ipynb", export / "submission_101" / "scratch.ipynb")
    (export / "submission_102").mkdir()

    assert [(e.name, e.notebook.name) for e in discover(flat, "hw0_setup", EXPECTED)] == [("alice", "alice.ipynb")]
    assert [(e.name, e.notebook.name) for e in discover(tmp_path / "course", "hw0_setup", EXPECTED)] == \
        [("bob", "hw0_setup.ipynb")]
    entries = {e.name: e for e in discover(export, "hw0_setup", EXPECTED)}
    assert entries["submission_101"].notebook.name == "work.ipynb"  # the one with the most stubs found
    assert "several notebooks" in entries["submission_101"].note
    assert entries["submission_102"].notebook is None and "no notebook" in entries["submission_102"].problem


def test_a_student_who_worked_in_a_copy_is_graded_from_the_copy(tmp_path):
    """Erin handed in the released hw0_setup.ipynb untouched and her work in hw0_setup-Copy1.ipynb: the copy, with
    more stubs done, is graded (before, the file named after the assignment always won: 0 points, said only in
    her feedback). Where both have as many stubs done, the one named after the assignment is graded."""
    erin = tmp_path / "class" / "erin"
    erin.mkdir(parents=True)
    shutil.copy(SAMPLES / "untouched.ipynb", erin / "hw0_setup.ipynb")
    shutil.copy(SAMPLES / "complete.ipynb", erin / "hw0_setup-Copy1.ipynb")
    finn = tmp_path / "class" / "finn"
    finn.mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", finn / "hw0_setup.ipynb")
    shutil.copy(SAMPLES / "complete.ipynb", finn / "hw0_setup-Copy1.ipynb")
    os.utime(finn / "hw0_setup.ipynb", (0, 0))  # older: the name decides a tie before the time does
    entries = {e.name: e for e in discover(tmp_path / "class", "hw0_setup", EXPECTED)}
    assert entries["erin"].notebook.name == "hw0_setup-Copy1.ipynb"
    assert "the one with the most stubs done (not hw0_setup.ipynb)" in entries["erin"].note
    assert entries["finn"].notebook.name == "hw0_setup.ipynb"


def test_killed_batch_resumes_and_grades_each_submission_once(open_tmp):
    folder, out = open_tmp / "in", open_tmp / "out"
    folder.mkdir()
    kinds = ["complete", "partial", "untouched", "broken_syntax"]
    for i in range(12):
        shutil.copy(SAMPLES / f"{kinds[i % 4]}.ipynb", folder / f"student{i:02d}.ipynb")
    (folder / "empty_folder_submission").mkdir()
    command = [sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out", str(out), "--jobs", "2"]
    first = subprocess.Popen(command, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while len(list(out.glob("*/result.json"))) < 4 and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.2)
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    done_before = {p.parent.name: p.stat().st_mtime_ns for p in out.glob("*/result.json")}
    assert 4 <= len(done_before) < 13, "the kill should land halfway"
    assert not (out / "gradebook.csv").exists()

    second = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert second.returncode == 0, second.stderr[-2000:]
    rows = list(csv.DictReader((out / "gradebook.csv").open()))
    names = [r["submission"] for r in rows]
    assert sorted(names) == sorted([f"student{i:02d}" for i in range(12)] + ["empty_folder_submission"])
    assert len(set(names)) == len(names)
    for name, mtime in done_before.items():  # finished before the kill: not graded again
        assert (out / name / "result.json").stat().st_mtime_ns == mtime
    by_name = {r["submission"]: r for r in rows}
    assert by_name["student00"]["score"] == "8" and by_name["student01"]["score"] == "5"
    assert by_name["empty_folder_submission"]["status"] == "ungradable"
    assert not list(out.rglob("*.tmp")), "no half-written files are left behind"


def test_names_are_made_safe_then_unique_the_same_on_every_run(tmp_path):
    folder = tmp_path / "flat"
    folder.mkdir()
    for name in ("alice smith", "alice_smith", "alice_smith-2", "Bob", "bob", "ça va"):
        shutil.copy(SAMPLES / "complete.ipynb", folder / f"{name}.ipynb")
    first = [e.name for e in discover(folder, "hw0_setup", EXPECTED)]
    assert first == [e.name for e in discover(folder, "hw0_setup", EXPECTED)], "names must not change between runs"
    assert len(set(first)) == 6, f"every submission keeps its own folder and row: {first}"
    kept = {"alice_smith", "alice_smith-2", "Bob", "bob"}
    assert kept <= set(first), "a plain name is kept as it is"
    made = sorted(set(first) - kept)
    assert [n.split("+")[0] for n in made] == ["a_va", "alice_smith"] and all(len(n.split("+")[1]) == 8 for n in made)


def test_no_crafted_name_takes_a_classmates_folder_or_the_batchs_own_files(tmp_path):
    """A name is made safe from itself alone: adding a crafted file never moves a classmate's result, and no
    submission's folder can be the gradebook (issue 35)."""
    from autograder.core.batch import safe_name

    honest = ["alice", "alice smith", "bob.jones", "Zoë"]
    alone = {n: safe_name(n) for n in honest}
    crafted = ["alice ", " alice", "alice_smith", f"{alone['alice smith']}", "alice_smith+00000000", "ALICE",
               "gradebook.csv", "Gradebook-1-of-2.csv", "_batch-1-of-1.json", "_previous", ".alice", "alice.",
               "zo\udceb", "x" * 300, "merged"]
    folder = tmp_path / "class"
    folder.mkdir()
    for name in honest + crafted:
        try:
            shutil.copy(SAMPLES / "partial.ipynb", folder / f"{name}.ipynb")
        except OSError:
            pass
    names = {e.notebook.stem: e.name for e in discover(folder, "hw0_setup", EXPECTED)}
    assert {n: names[n] for n in honest} == alone, "a classmate's crafted name moved an honest result"
    assert len(set(names.values())) == len(names), "two submissions share a folder"
    for name in names.values():
        assert not re.fullmatch(r"gradebook.*\.csv", name, re.I) and not name.startswith(("_", ".")), name
        assert "/" not in name
        assert len(name) <= 100 and name.encode("utf-8")


def test_a_student_who_skipped_the_assignment_is_missing_not_graded_from_another_notebook(tmp_path):
    """nbgrader's layout: a folder without ``<student>/<assignment>/`` is no submission (issue 36)."""
    from autograder.core.batch import missing_submissions

    submitted = tmp_path / "course" / "submitted"
    (submitted / "ann" / "hw0_setup").mkdir(parents=True)
    (submitted / "ann" / "hw1b_multimodal").mkdir(parents=True)
    shutil.copy(SAMPLES / "complete.ipynb", submitted / "ann" / "hw0_setup" / "hw0_setup.ipynb")
    shutil.copy(SAMPLES / "complete.ipynb", submitted / "ann" / "hw1b_multimodal" / "hw1b_multimodal.ipynb")
    (submitted / "ben" / "hw1b_multimodal").mkdir(parents=True)   # handed in hw1b only
    shutil.copy(SAMPLES / "partial.ipynb", submitted / "ben" / "hw1b_multimodal" / "hw1b_multimodal.ipynb")
    (submitted / "cat" / "hw0_setup").mkdir(parents=True)          # hw0's folder holds a misplaced notebook
    shutil.copy(REPO / "assignments/hw1b_multimodal/hw1b_multimodal.ipynb", submitted / "cat" / "hw0_setup")
    (submitted / "eve" / "hw0_setup").mkdir(parents=True)          # hw0's work saved under another assignment's name
    shutil.copy(SAMPLES / "partial.ipynb", submitted / "eve" / "hw0_setup" / "hw1_imitation.ipynb")
    (submitted / "dan").mkdir()                                      # a stray notebook outside any folder
    shutil.copy(SAMPLES / "complete.ipynb", submitted / "dan" / "hw0_setup.ipynb")
    for root in (tmp_path / "course", submitted):
        entries = {e.name: e for e in discover(root, "hw0_setup", EXPECTED)}
        assert set(entries) == {"ann", "cat", "eve"}, "ben and dan handed in no hw0_setup/ folder"
        assert entries["ann"].notebook.name == "hw0_setup.ipynb"
        assert entries["cat"].notebook is None and "another assignment's notebook" in entries["cat"].problem
        assert entries["eve"].notebook.name == "hw1_imitation.ipynb" and not entries["eve"].problem, \
            "its name is another assignment's, but it defines hw0's stubs: it is graded"
        assert missing_submissions(root, "hw0_setup") == ["ben", "dan"]
    assert missing_submissions(tmp_path / "course", "hw1b_multimodal") == ["cat", "dan", "eve"]
    flat = tmp_path / "flat"
    flat.mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", flat / "alice.ipynb")
    assert missing_submissions(flat, "hw0_setup") == []


def test_the_batch_names_the_missing_and_writes_no_row_for_them(open_tmp):
    submitted = open_tmp / "course" / "submitted"
    (submitted / "ann" / "hw0_setup").mkdir(parents=True)
    shutil.copy(SAMPLES / "partial.ipynb", submitted / "ann" / "hw0_setup" / "hw0_setup.ipynb")
    (submitted / "ben" / "hw1_imitation").mkdir(parents=True)
    shutil.copy(SAMPLES / "complete.ipynb", submitted / "ben" / "hw1_imitation" / "hw0_setup.ipynb")
    out = open_tmp / "out"
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", "hw0_setup", str(open_tmp / "course"),
                           "--out", str(out), "--jobs", "1"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "1 student folder(s) hold no hw0_setup/" in done.stdout and "ben" in done.stdout
    rows = list(csv.DictReader((out / "gradebook.csv").open()))
    assert [r["submission"] for r in rows] == ["ann"]
    assert not (out / "ben").exists()
    import json
    assert json.loads((out / "_batch-1-of-1.json").read_text())["missing"] == ["ben"]


def test_one_zipped_folder_does_not_make_a_class_nbgrader_layout(tmp_path):
    export = tmp_path / "export"
    for name in ("s1", "s2", "s3"):
        (export / name).mkdir(parents=True)
        shutil.copy(SAMPLES / "partial.ipynb", export / name / "work.ipynb")
    (export / "s3" / "hw0_setup").mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", export / "s3" / "hw0_setup" / "hw0_setup.ipynb")
    assert sorted(e.name for e in discover(export, "hw0_setup", EXPECTED)) == ["s1", "s2", "s3"]


def test_what_a_folder_of_notebooks_holds_besides_this_assignments_work_is_named(open_tmp, tmp_path):
    """In one batch: a notebook in capitals is graded; a file that is not a notebook is named and not graded;
    another assignment's notebook (or one with every stub cell deleted) is graded 0 as before, and the batch, the
    gradebook's reason column, the feedback and result.json say what it seems to be."""
    import nbformat

    from autograder.core.batch import stray_files
    from autograder.core.store import load_result

    flat = open_tmp / "flat"
    flat.mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", flat / "alice.IPYNB")
    shutil.copy(SAMPLES / "partial.ipynb", flat / "bob.ipynb")
    (flat / "carol.py").write_text("def discounted_returns(r, g): ...\n")
    (flat / ".DS_Store").write_bytes(b"\0")
    (flat / "dan").mkdir()
    shutil.copy(SAMPLES / "complete.ipynb", flat / "dan" / "HW0_SETUP.IPYNB")
    shutil.copy(REPO / "autograder/samples/hw1_imitation/complete.ipynb", flat / "erin.ipynb")
    shutil.copy(SAMPLES / "untouched.ipynb", flat / "fay.ipynb")
    blank = nbformat.read(str(SAMPLES / "complete.ipynb"), 4)
    blank.cells = [c for c in blank.cells if c.metadata.get("nbgrader", {}).get("grade_id") not in EXPECTED]
    nbformat.write(blank, str(flat / "gus.ipynb"))
    assert stray_files(flat) == ["carol.py"]
    assert {e.name: e.notebook.name for e in discover(flat, "hw0_setup", EXPECTED)} == \
        {"alice": "alice.IPYNB", "bob": "bob.ipynb", "dan": "HW0_SETUP.IPYNB", "erin": "erin.ipynb",
         "fay": "fay.ipynb", "gus": "gus.ipynb"}
    out = open_tmp / "out"
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", "hw0_setup", str(flat), "--out", str(out),
                           "--jobs", "2"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "1 file(s) beside the submissions are not notebooks (.ipynb)" in done.stdout and "carol.py" in done.stdout
    assert "2 submission(s) define none of hw0_setup's stubs" in done.stdout and "erin, gus" in done.stdout
    rows = {r["submission"]: r for r in csv.DictReader((out / "gradebook.csv").open())}
    assert sorted(rows) == ["alice", "bob", "dan", "erin", "fay", "gus"]
    assert rows["alice"]["score"] == rows["alice"]["max_score"] == rows["dan"]["score"]
    assert rows["erin"]["score"] == "0" and rows["erin"]["status"] == "graded"
    assert "hw1_imitation's" in rows["erin"]["reason"]
    assert "is it this assignment's notebook?" in rows["gus"]["reason"] and "hw1" not in rows["gus"]["reason"]
    assert rows["fay"]["reason"] == rows["bob"]["reason"] == "", "a notebook with its stubs: nothing to say"
    assert "hw1\\_imitation's" in (out / "erin" / "feedback.md").read_text()
    assert "hw1_imitation's" in load_result(out / "erin").wrong_notebook
    from autograder.outputs.terminal import summary_lines
    assert "hw1_imitation's" in summary_lines(load_result(out / "erin"))[1], "grade's summary says it too"


def _batch(folder, out, jobs: int) -> subprocess.CompletedProcess:
    """``python -m autograder batch hw0_setup FOLDER --out OUT``, which must succeed."""
    done = subprocess.run([sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out", str(out),
                           "--jobs", str(jobs)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return done


def test_a_notebook_handed_in_again_is_graded_again_and_an_older_suites_results_are_named(open_tmp):
    """Run again after a student handed in anew, the batch grades that notebook (not the recorded result of the
    earlier one), keeps the earlier result in _previous/, and says so; a third run grades nothing. Results of an
    earlier suite version are named with the regrade command; a result recorded before digests is kept."""
    import json

    flat = open_tmp / "flat"
    flat.mkdir()
    shutil.copy(SAMPLES / "untouched.ipynb", flat / "alice.ipynb")
    shutil.copy(SAMPLES / "partial.ipynb", flat / "bob.ipynb")
    shutil.copy(SAMPLES / "partial.ipynb", flat / "cy.ipynb")
    out = open_tmp / "out"

    def batch() -> subprocess.CompletedProcess:
        return _batch(flat, out, jobs=2)

    def scores() -> dict[str, str]:
        return {r["submission"]: r["score"] for r in csv.DictReader((out / "gradebook.csv").open())}

    batch()
    assert scores() == {"alice": "0", "bob": "5", "cy": "5"}
    record = out / "cy" / "result.json"
    older = json.loads(record.read_text())
    older["notebook_sha256"] = ""                       # as recorded before digests: taken as it is
    record.write_text(json.dumps(older))
    shutil.copy(SAMPLES / "complete.ipynb", flat / "alice.ipynb")
    shutil.copy(SAMPLES / "complete.ipynb", flat / "cy.ipynb")
    again = batch()
    assert "1 submission(s) were handed in again after they were graded" in again.stdout and "alice" in again.stdout
    assert scores() == {"alice": "8", "bob": "5", "cy": "5"}
    kept = [p for p in (out / "_previous").iterdir() if p.is_dir()]
    assert len(kept) == 1 and json.loads((kept[0] / "alice" / "result.json").read_text())["stubs"][0]["tests"]
    assert "graded again" in (out / "alice" / "feedback.md").read_text()
    bob = json.loads((out / "bob" / "result.json").read_text())
    bob["suite_version"] = "an-earlier-one"
    (out / "bob" / "result.json").write_text(json.dumps(bob))
    third = batch()
    assert "handed in again" not in third.stdout and len(list((out / "_previous").iterdir())) == 1
    assert "1 result(s) were graded by an earlier version of hw0_setup's suite" in third.stderr and "bob" in third.stderr


def test_a_submission_with_nothing_to_grade_is_graded_once_it_holds_a_notebook(open_tmp):
    """Dave handed in another assignment's notebook and Nina a .py file: both ungradable. Once each hands in this
    assignment's notebook, the next run grades them (before, their results had no digest and were kept for good,
    still naming the removed file); a run after that grades nothing again. A result recorded before such results
    had a digest is graded again too when the submission now holds a notebook."""
    import json

    folder = open_tmp / "class"  # a folder per student (not nbgrader's layout, whose folders are named by assignment)
    for student in ("dave", "nina", "olga"):
        (folder / student).mkdir(parents=True)
    shutil.copy(REPO / "autograder/samples/hw1_imitation/complete.ipynb", folder / "dave" / "hw1_imitation.ipynb")
    (folder / "nina" / "hw0_setup.py").write_text("print('my answers')\n")
    (folder / "olga" / "notes.txt").write_text("forgot the notebook\n")
    out = open_tmp / "out"

    def batch() -> subprocess.CompletedProcess:
        return _batch(folder, out, jobs=1)

    def rows() -> dict[str, dict]:
        return {r["submission"]: r for r in csv.DictReader((out / "gradebook.csv").open())}

    first = batch()
    assert "3 submission(s) could not be graded" in first.stdout and "dave, nina, olga" in first.stdout, first.stdout
    assert {n: r["status"] for n, r in rows().items()} == {"dave": "ungradable", "nina": "ungradable", "olga": "ungradable"}
    olga = json.loads((out / "olga" / "result.json").read_text())
    olga["notebook_sha256"] = ""  # as recorded before ungradable results had a digest
    (out / "olga" / "result.json").write_text(json.dumps(olga))
    (folder / "dave" / "hw1_imitation.ipynb").unlink()
    for student in ("dave", "nina", "olga"):
        shutil.copy(SAMPLES / "complete.ipynb", folder / student / "hw0_setup.ipynb")
    again = batch()
    assert "3 submission(s) were handed in again" in again.stdout, again.stdout
    assert {n: (r["status"], r["score"]) for n, r in rows().items()} == \
        {"dave": ("graded", "8"), "nina": ("graded", "8"), "olga": ("graded", "8")}
    assert "hw1_imitation" not in rows()["dave"]["reason"]
    assert "handed in again" not in batch().stdout, "nothing changed since: nothing graded again"


def test_a_submission_nested_a_thousand_folders_deep_is_its_own_problem_only(tmp_path):
    """Red team C: a folder about 990 levels deep made discover raise RecursionError (Python 3.11's os.walk
    recurses per level), and the batch graded no one. The walk is iterative and stops at MAX_WALK_DEPTH levels,
    so a notebook that deep is not found (and the feedback says why), and the classmate beside it is graded."""
    from autograder.core.batch import _contents_digest
    from autograder.core.intake import MAX_WALK_DEPTH

    subs = tmp_path / "subs"
    shutil.copy(SAMPLES / "complete.ipynb", (subs / "ann").mkdir(parents=True) or subs / "ann" / "hw0_setup.ipynb")
    deep = subs / "zed"
    deep.mkdir()
    levels = 1000
    fd = os.open(deep, os.O_RDONLY)
    try:                                                   # made relative to each level, so paths stay short
        for _ in range(levels):
            os.mkdir("d", dir_fd=fd)
            inner = os.open("d", os.O_RDONLY, dir_fd=fd)
            os.close(fd)
            fd = inner
        with open(os.open("hw0_setup.ipynb", os.O_WRONLY | os.O_CREAT, 0o600, dir_fd=fd), "wb") as f:
            f.write((SAMPLES / "complete.ipynb").read_bytes())
    finally:
        os.close(fd)
    try:
        entries = {e.name: e for e in discover(subs, "hw0_setup", EXPECTED)}
        assert entries["ann"].notebook is not None
        assert entries["zed"].notebook is None and f"more than {MAX_WALK_DEPTH} levels deep" in entries["zed"].problem
        assert _contents_digest(deep) == _contents_digest(deep), "the digest walks it too, without recursion"
    finally:  # pytest's own clean-up of old temporary folders recurses per level too: take the chain down here
        fds = [os.open(deep, os.O_RDONLY)]
        for _ in range(levels):
            fds.append(os.open("d", os.O_RDONLY, dir_fd=fds[-1]))
        os.unlink("hw0_setup.ipynb", dir_fd=fds[-1])
        for parent in reversed(fds[:-1]):
            os.close(fds.pop())
            os.rmdir("d", dir_fd=parent)
        os.close(fds.pop())


def test_choosing_among_many_notebooks_opens_only_the_likeliest_few(tmp_path, monkeypatch):
    """Red team C: 1,000 notebooks in one folder made every batch run open each of them (52 s a rerun, against
    0.4 s). At most MAX_WEIGHED are opened, the assignment's name first, then the newest."""
    from autograder.core import batch

    folder = tmp_path / "ann"
    folder.mkdir()
    for k in range(30):
        shutil.copy(SAMPLES / "untouched.ipynb", folder / f"scratch{k:02d}.ipynb")
        os.utime(folder / f"scratch{k:02d}.ipynb", (1_000_000 + k, 1_000_000 + k))
    shutil.copy(SAMPLES / "complete.ipynb", folder / "final.ipynb")
    os.utime(folder / "final.ipynb", (2_000_000, 2_000_000))
    opened = []
    real = batch.read_code_cells
    monkeypatch.setattr(batch, "read_code_cells", lambda path, **kw: opened.append(path) or real(path, **kw))
    notebooks, skipped = batch.notebooks_in(folder)
    entry = batch.choose_notebook("ann", notebooks, "hw0_setup", EXPECTED, skipped)
    assert entry.notebook.name == "final.ipynb" and len(opened) == batch.MAX_WEIGHED
    assert "among the 10 newest" in entry.note


def test_an_unreadable_notebook_has_a_stable_digest_so_it_is_not_graded_again_every_run(tmp_path, monkeypatch):
    """Red team C (by reading): as a normal user, a mode-000 notebook had an empty digest, so every run of the batch
    archived its result and graded it again. Its digest now stands on its size, time and inode (root reads any
    file, so the unreadable case is made here by the digest function failing)."""
    from autograder.core import batch

    path = tmp_path / "alice.ipynb"
    shutil.copy(SAMPLES / "complete.ipynb", path)

    def refuse(p, cap=0):
        raise PermissionError(13, "Permission denied", str(p))

    monkeypatch.setattr(batch, "notebook_digest", refuse)
    first = batch._digest(path)
    assert first.startswith("unreadable:") and batch._digest(path) == first
    os.utime(path, ns=(1, 1))
    assert batch._digest(path) != first, "a changed file has another digest"


def test_a_notebook_and_a_folder_of_one_name_are_one_submission(tmp_path):
    """Red team D: alice.ipynb beside a folder alice/ were graded into one result folder, the last written winning,
    and every later run graded both again. They are one submission, graded from the notebook with most stubs done."""
    flat = tmp_path / "flat"
    (flat / "alice").mkdir(parents=True)
    shutil.copy(SAMPLES / "untouched.ipynb", flat / "alice.ipynb")
    shutil.copy(SAMPLES / "complete.ipynb", flat / "alice" / "hw0_setup.ipynb")
    shutil.copy(SAMPLES / "partial.ipynb", flat / "bob.ipynb")
    entries = discover(flat, "hw0_setup", EXPECTED)
    assert [e.name for e in entries] == ["alice", "bob"]
    assert entries[0].notebook == flat / "alice" / "hw0_setup.ipynb" and "2 times under this name" in entries[0].note


def test_a_notebook_only_in_checkpoints_is_named_in_the_reason(tmp_path):
    """Red team D: an upload whose only notebook was in .ipynb_checkpoints/ got "no notebook" and nothing more."""
    from autograder.core.batch import choose_notebook, notebooks_in

    (tmp_path / "up" / ".ipynb_checkpoints").mkdir(parents=True)
    shutil.copy(SAMPLES / "complete.ipynb", tmp_path / "up" / ".ipynb_checkpoints" / "hw0_setup-checkpoint.ipynb")
    notebooks, skipped = notebooks_in(tmp_path / "up")
    entry = choose_notebook("up", notebooks, "hw0_setup", EXPECTED, skipped)
    assert entry.notebook is None and ".ipynb_checkpoints/ holds 1 notebook(s)" in entry.problem
