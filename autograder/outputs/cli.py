"""The instructor's term after ``batch``, as ``python -m autograder`` commands:

  nbgrader-sync ID FOLDER --results DIR   record a batch in the nbgrader gradebook, notebooks placed for formgrader
  feedback ID --results DIR [--html]      feedback.md (and nbgrader's HTML) with the hand-given scores and comments
           [--zip DIR]                    and one zip per student (and one of them all) to upload to an LMS
  export [--out CSV] [--long]             the course's final grades, one CSV (student x assignment), late rule and
         [--format plain|canvas|moodle]   extensions applied; or Canvas's or Moodle's gradebook import
  regrade ID FOLDER --out DIR [--only N]  regrade after a suite fix; earlier results kept in DIR/_previous/
  results-diff OLD NEW                    per submission, what changed between two result folders
  class-report ID [FOLDER] --results DIR  item analysis (and, given FOLDER, similar stub code, names as pseudonyms)

Each takes ``--course ROOT``, the nbgrader course (its ``nbgrader_config.py``, gradebook and
``autograded/`` folder); the default is this repository. A command that grades (``regrade``) first
checks that the sandbox would import this checkout's code (:mod:`autograder.outputs.checkout`).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _course_folder(text: str) -> Path:
    if not Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text} is not a folder (the nbgrader course: its nbgrader_config.py, "
                                         "gradebook and autograded/)")
    return Path(text)


def _course(p: argparse.ArgumentParser) -> None:
    p.add_argument("--course", type=_course_folder, default=None,
                   help="the nbgrader course folder (default: this repository, whose nbgrader_config.py it reads)")


def _cmd_sync(args: argparse.Namespace) -> int:
    from autograder.outputs.gradebook import course_directory, sync

    report = sync(args.assignment, args.folder, args.results, args.course)
    print("\n".join(report.lines(args.assignment, course_directory(args.course).db_url)))
    for line in report.warnings():
        print(line, file=sys.stderr)
    return 0


GRADER_FAULT_EXIT = 3
"""The exit status when the grader failed on some submission (as ``batch``'s)."""


def _cmd_feedback(args: argparse.Namespace) -> int:
    from autograder.outputs.feedback import write_feedback

    done = write_feedback(args.assignment, args.results, args.course, html=args.html, zip_dir=args.zip)
    print(f"wrote {len(done.written)} feedback.md file(s)" + (" and nbgrader's feedback HTML" if args.html else "")
          + (f", e.g. {done.written[0]}" if done.written else ""))
    if done.zips:
        print(f"wrote {len(done.zips) - 1} per-student zip(s) in {done.zips[0].parent} and {done.zips[-1]}")
    for line in done.warnings():
        print(line, file=sys.stderr)
    return GRADER_FAULT_EXIT if done.not_graded else 0


def _cmd_export(args: argparse.Namespace) -> int:
    from autograder.outputs.export import export
    from autograder.outputs.gradebook import course_directory
    from autograder.outputs.text import plain

    database = course_directory(args.course).db_url.removeprefix("sqlite:///")
    if database.startswith("/") and not Path(database).exists():  # export would make an empty one there
        raise SystemExit(f"no nbgrader gradebook at {database}, so nothing to export (is --course the course "
                         "folder?); record a batch there first: python -m autograder nbgrader-sync ID FOLDER --results DIR")
    done = export(args.out, args.course, long=args.long, fmt=args.format, roster=args.roster,
                  extensions=args.extensions, lms_columns=args.lms_columns)
    grades = done.grades
    print(f"wrote {args.out} ({args.format}{', long' if args.long else ''}): "
          f"{len({g.student_id for g in grades})} student(s), {len({g.assignment for g in grades})} assignment(s); "
          f"late rule: {done.rule}")
    for g in grades:
        if g.extended or g.seconds_late > 0:
            print(f"  {g.assignment} {plain(g.student_id)}: {plain(g.note)}")
    for line in done.problems:
        print(f"warning: {line}", file=sys.stderr)
    waiting = sum(g.waiting for g in grades)
    if waiting:
        print(f"warning: {waiting} written answer(s) are not graded yet and count 0 (formgrader lists them)",
              file=sys.stderr)
    failed = [g for g in grades if g.not_recorded]
    if failed:
        print(f"warning: the grader failed on {len(failed)} submission(s), so their latest grading is not in the "
              f"gradebook (an empty cell where nothing was recorded before): "
              + ", ".join(f"{g.assignment} {plain(g.student_id)}" for g in failed[:20])
              + "; grade them again (batch or regrade), then nbgrader-sync, then export", file=sys.stderr)
        return GRADER_FAULT_EXIT
    return 0


def _cmd_regrade(args: argparse.Namespace) -> int:
    from autograder.outputs.checkout import require_one_checkout
    from autograder.outputs.regrade import change_lines, regrade
    from autograder.outputs.text import plain

    require_one_checkout()
    done = regrade(args.assignment, args.folder, args.out, args.only or None, jobs=args.jobs, course_root=args.course)
    print("\n".join(change_lines(done.changes, done.written, done.hand_stubs)))
    print(f"earlier results: {done.archive}" + ("; gradebook updated (hand-given scores and comments kept)"
                                                if done.synced else "; not recorded in a gradebook yet"))
    for line in done.sync_warnings:
        print(line, file=sys.stderr)
    if done.grader_errors:
        print(f"the grader failed on {len(done.grader_errors)} submission(s): "
              f"{', '.join(plain(n) for n in done.grader_errors[:20])}; they have no score (and were not recorded "
              "in the gradebook). Fix the grader and run the same command again.", file=sys.stderr)
        return GRADER_FAULT_EXIT
    return 0


def _cmd_diff(args: argparse.Namespace) -> int:
    from autograder.outputs.batch_output import read_results
    from autograder.outputs.regrade import diff_lines

    print("\n".join(diff_lines(read_results(args.old), read_results(args.new))))
    return 0


def _cmd_class_report(args: argparse.Namespace) -> int:
    from autograder.core import course
    from autograder.outputs.class_report import REPORT_DIR, write_class_report

    course.check_assignment(args.assignment)
    out = args.out or args.results / REPORT_DIR
    report = write_class_report(args.assignment, args.results, out, args.folder, args.threshold, args.jobs,
                                names=args.names, course_root=args.course)
    errors = report.table.grader_errors
    print(f"wrote {out / 'report.html'} and {out / 'report.md'}: {len(report.table.names)} submission(s) with a score"
          + (f"; {len(errors)} left out because the grader failed on them: {', '.join(errors[:20])}" if errors
             else "; the grader failed on none"))
    if report.similarity is not None:
        print(f"similar stub code: {len(report.similarity.pairs)} pair(s) flagged among "
              f"{report.similarity.compared} compared (grades unchanged)")
    return 0


def add_commands(sub: argparse._SubParsersAction) -> None:
    """Register this room's commands on ``python -m autograder``'s sub-parsers."""
    p = sub.add_parser("nbgrader-sync", help="record a batch in the nbgrader gradebook for formgrader")
    p.add_argument("assignment")
    p.add_argument("folder", type=Path, help="the submissions folder the batch graded")
    p.add_argument("--results", type=Path, required=True, help="the batch's --out folder")
    _course(p)
    p.set_defaults(fn=_cmd_sync)
    p = sub.add_parser("feedback", help="feedback with the hand-given scores and comments")
    p.add_argument("assignment")
    p.add_argument("--results", type=Path, required=True, help="the batch's --out folder (synced)")
    p.add_argument("--html", action="store_true", help="also run nbgrader generate_feedback")
    p.add_argument("--zip", type=Path, default=None, metavar="DIR",
                   help="also write DIR/ID/<student>.zip per student and DIR/ID-feedback.zip, for an LMS")
    _course(p)
    p.set_defaults(fn=_cmd_feedback)
    p = sub.add_parser("export", help="the course's final grades as one CSV")
    p.add_argument("--out", type=Path, default=Path("grades.csv"))
    p.add_argument("--long", action="store_true", help="one row per student and assignment (plain format)")
    p.add_argument("--format", choices=("plain", "canvas", "moodle"), default="plain",
                   help="plain (this kit's columns), canvas (Canvas's gradebook import) or moodle (Moodle's CSV import)")
    p.add_argument("--roster", type=Path, default=None,
                   help="the roster CSV (default: the course's roster.csv): Canvas's IDs and sections")
    p.add_argument("--extensions", type=Path, default=None,
                   help="per-student deadlines, CSV student_id,assignment,deadline (default: the course's extensions.csv)")
    p.add_argument("--lms-columns", type=Path, default=None, metavar="CSV",
                   help="assignment,column: each assignment's column name in the LMS (e.g. 'Homework 0 (87568490)')")
    _course(p)
    p.set_defaults(fn=_cmd_export)
    p = sub.add_parser("regrade", help="regrade a batch (or some of it), keeping the earlier results")
    p.add_argument("assignment")
    p.add_argument("folder", type=Path)
    p.add_argument("--out", type=Path, required=True, help="the batch's --out folder")
    p.add_argument("--only", nargs="+", metavar="NAME", help="regrade only these submissions")
    p.add_argument("--jobs", type=int, default=2)
    _course(p)
    p.set_defaults(fn=_cmd_regrade)
    p = sub.add_parser("results-diff", help="what changed between two result folders")
    p.add_argument("old", type=Path)
    p.add_argument("new", type=Path)
    p.set_defaults(fn=_cmd_diff)
    p = sub.add_parser("class-report", help="item analysis and similar stub code of a graded batch")
    p.add_argument("assignment")
    p.add_argument("folder", type=Path, nargs="?", default=None,
                   help="the submissions folder the batch graded: also list pairs with similar stub code")
    p.add_argument("--results", type=Path, required=True, help="the batch's --out folder")
    p.add_argument("--out", type=Path, default=None, help="report folder (default DIR/_class_report)")
    p.add_argument("--threshold", type=float, default=None,
                   help="flag a pair when each shares at least this fraction of its stub code (default 0.6)")
    p.add_argument("--jobs", type=int, default=2, help="notebooks read at once (each in its own process)")
    p.add_argument("--names", action="store_true",
                   help="show submissions' names in the similarity part (default: pseudonyms, as formgrader hides names)")
    _course(p)
    p.set_defaults(fn=_cmd_class_report)
