"""An instructor's typo in a command is an error that names it, before any grading, never a grade."""
from __future__ import annotations

import pytest

from autograder.__main__ import main
from conftest import REPO

SAMPLE = REPO / "autograder/samples/hw0_setup/complete.ipynb"


def test_a_notebook_that_does_not_exist_is_an_error_not_a_zero(tmp_path):
    with pytest.raises(SystemExit, match="no such notebook or folder"):
        main(["grade", "hw0_setup", str(tmp_path / "alcie.ipynb"), "--out", str(tmp_path / "out")])
    assert not (tmp_path / "out").exists(), "nothing is written for a path that is not there"


@pytest.mark.parametrize("command", [["grade", "hw0_setup", str(SAMPLE)], ["batch", "hw0_setup", str(SAMPLE.parent)],
                                     ["demo"]])
def test_an_out_that_is_a_file_is_refused_at_once(tmp_path, capsys, command):
    taken = tmp_path / "gradebook.csv"
    taken.write_text("kept\n")
    with pytest.raises(SystemExit) as stopped:
        main([*command, "--out", str(taken)])
    assert stopped.value.code == 2 and "is a file; --out names the folder" in capsys.readouterr().err
    assert taken.read_text() == "kept\n"


@pytest.mark.parametrize("jobs, why", [("0", "at least 1"), ("-2", "at least 1"), ("two", "not a whole number")])
def test_jobs_must_be_a_positive_whole_number(tmp_path, capsys, jobs, why):
    with pytest.raises(SystemExit):
        main(["batch", "hw0_setup", str(SAMPLE.parent), "--out", str(tmp_path / "out"), "--jobs", jobs])
    assert why in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_export_from_a_folder_that_is_not_a_course_says_so_and_writes_nothing(tmp_path, capsys):
    with pytest.raises(SystemExit):
        main(["export", "--out", str(tmp_path / "grades.csv"), "--course", str(tmp_path / "nowhere")])
    assert "is not a folder" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit, match="no nbgrader gradebook"):
        main(["export", "--out", str(tmp_path / "grades.csv"), "--course", str(tmp_path / "empty")])
    assert not (tmp_path / "grades.csv").exists() and not any((tmp_path / "empty").iterdir()), "and makes no gradebook"


@pytest.mark.parametrize("command, why", [
    (["run", "nowhere.ipynb"], "no such notebook"),
    (["run", str(REPO / "solutions/hw0_setup/hw0_setup.ipynb"), "-p", "FAST"], "NAME=VALUE"),
    (["samples", "hw9"], "unknown or ungradable assignment 'hw9'"),
    (["prairielearn", "hw1_imitation", "--question-files", "/nonexistent/pl-course"], "needs --image <account>/"),
])
def test_authoring_commands_name_the_mistake(command, why):
    with pytest.raises(SystemExit, match=why):
        main(command)
