"""Command line of the course tools: ``python -m autograder <command> ...``.

  grade ID NOTEBOOK --out DIR        grade one submission; per-stub summary, results.json, feedback.md
  batch ID FOLDER --out DIR --jobs N grade a folder (resumable), write gradebook.csv
        [--shard K/N]                only the submissions of shard K of N (one copy per machine)
  batch ID1,ID2 FOLDER --out DIR     several assignments in one pool (start-up once), each into DIR/ID/;
  batch --all FOLDER --out DIR       every assignment handed in (nbgrader's submitted/<student>/<id>/)
  merge ID SHARD_DIR ... --out DIR   join the shards of a batch into one gradebook (refuses a mismatch)
  prairielearn ID [--root /grade]    grade as PrairieLearn's external grader (results/results.json);
        [--question-files DIR]       or write the question's files for a PrairieLearn course
        [--timeout SECONDS]
  demo                               grade the sample submissions of every assignment (the README's main job)
  gradescope ID [--out ZIP] [--visibility V]   build the Gradescope autograder bundle
  run NOTEBOOK [-p NAME=VALUE ...]   execute a notebook with parameters under a time budget
  assignments [ID ...]               regenerate student notebooks from solutions/ (nbgrader)
  student-release OUT                build the student-only tree
  samples ID                         regenerate the sample submissions of an assignment
  permissions [--root DIR] [--no-environment] [--assignment ID]   in a grading container: file modes that wall
                                     the hidden files
                                     off a worker run without namespaces (the Gradescope and PrairieLearn routes)
  new ID [--title TEXT]              write a new assignment's two-stub skeleton (notebook, suite, samples)
  mutants ID [--stub S] [--max-per-stub N]   grade mutants of each solution stub (autograder/authoring/mutants.py)
  nbgrader-sync, feedback, export, regrade, results-diff, class-report   the term after batch
                                     (autograder/outputs/cli.py)
"""
from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path


def _cmd_grade(args: argparse.Namespace) -> int:
    from autograder.core import course
    from autograder.core.batch import choose_notebook, notebooks_in
    from autograder.core.grader import Grader
    from autograder.outputs.text import plain
    from autograder.outputs.terminal import summary_lines
    from autograder.outputs.files import write_outputs
    from autograder.core.results import GraderError
    from autograder.outputs.checkout import require_one_checkout

    course.check_assignment(args.assignment)
    require_one_checkout()
    if not args.notebook.exists() and not args.notebook.is_symlink():  # a typo, not a submission to mark 0
        raise SystemExit(f"{args.notebook}: no such notebook or folder")
    entry = None
    if args.notebook.is_dir() and not args.notebook.is_symlink():  # a submission folder: pick as batch would
        notebooks, skipped = notebooks_in(args.notebook)
        entry = choose_notebook(args.notebook.name, notebooks, args.assignment, course.stub_names(args.assignment),
                                skipped)
    # The notebook, those beside it (classmates', if the instructor keeps them together) and the output folder
    # are hidden from the sandbox wherever they lie.
    folder = args.notebook if entry is not None else args.notebook.parent
    hide = [args.out, folder] if folder.resolve() != course.release_notebook(args.assignment).parent.resolve() else \
        [args.out, *(p for p in folder.glob("*.ipynb") if p.name != f"{args.assignment}.ipynb")]
    try:
        grader = Grader(args.assignment, hide=hide)
    except GraderError as err:
        return _grader_failed(str(err))
    try:
        if entry is not None and entry.notebook is None:  # nothing to grade: the submission's problem, recorded
            result = grader.ungradable(args.notebook.name, entry.problem)
        else:  # a link, a device or a non-notebook comes back as ungradable, with the reason
            result = grader.grade(entry.notebook if entry else args.notebook)
    finally:
        grader.close()
    if not result.has_score:
        return _grader_failed(result.error)
    if entry is not None and entry.note:
        result.notes.insert(0, entry.note)
    write_outputs(result, args.out)
    _warn_isolation(result.isolation)
    print("\n".join(summary_lines(result)))
    print(f"wrote {plain(str(args.out / 'results.json'))} and {plain(str(args.out / 'feedback.md'))}")
    return 0


GRADER_FAULT_EXIT = 3
"""The exit status when the grader itself failed (2 is argparse's, for a bad command line)."""


def _grader_failed(reason: str) -> int:
    from autograder.outputs.text import plain

    print(f"NOT GRADED: the grader itself failed, so no score was written.\n  {plain(reason)}\n"
          "This is not the submission's fault. Check the course set-up (`make test` runs the grader's own "
          "tests), fix it, then grade again.", file=sys.stderr)
    return GRADER_FAULT_EXIT


def _warn_isolation(level: str) -> None:
    if level == "none":
        print("warning: no namespaces available here; the sandbox uses resource limits only (isolation is partial)",
              file=sys.stderr)


def _listed(names: list[str], shown: int = 20) -> str:
    """Names for a line of the batch's report: the first ``shown``, made inert, and how many more."""
    from autograder.outputs.text import listed, plain

    return listed([plain(n) for n in names], shown)


def _cmd_batch(args: argparse.Namespace) -> int:
    from autograder.core.batch import (SEVERAL_NOTEBOOKS, Shard, assignment_folder, assignments_in, handed_in_anew,
                                       missing_submissions, stray_files)
    from autograder.core import course
    from autograder.core.results import GRADED, GRADER_ERROR, UNGRADABLE
    from autograder.outputs.files import grade_folder
    from autograder.outputs.text import plain

    try:
        shard = Shard.parse(args.shard) if args.shard else Shard()
    except ValueError as err:
        raise SystemExit(str(err)) from err
    if args.all:  # batch --all FOLDER --out DIR: the folder came first
        if args.folder is not None:
            raise SystemExit("batch --all takes the folder only: python -m autograder batch --all FOLDER --out DIR")
        args.folder = Path(args.assignment)
        ids = assignments_in(args.folder)
        if not ids:
            raise SystemExit(f"no gradable assignment was handed in under {args.folder}")
    else:
        if args.folder is None:
            raise SystemExit("batch needs a folder of submissions: python -m autograder batch ID FOLDER --out DIR")
        ids = [i.strip() for i in args.assignment.split(",") if i.strip()]
    several = args.all or len(ids) > 1
    if several:  # one pool for them all: the grader's start-up once, each assignment into --out/<id>/
        by_assignment = grade_folder(ids, args.folder, args.out, jobs=args.jobs, shard=shard)
    else:
        by_assignment = {ids[0]: grade_folder(ids[0], args.folder, args.out, jobs=args.jobs, shard=shard)}
    every = [r for results in by_assignment.values() for r in results]
    _warn_isolation("none" if any(r.isolation == "none" for r in every) else "full")
    for assignment, results in by_assignment.items():
        out = args.out / assignment if several else args.out
        count = {status: sum(r.status == status for r in results) for status in (GRADED, UNGRADABLE, GRADER_ERROR)}
        print((f"{assignment}: " if several else "")
              + f"{len(results)} submissions ({count[GRADED]} graded, {count[UNGRADABLE]} ungradable, "
              f"{count[GRADER_ERROR]} not graded because the grader failed); gradebook: {out / shard.gradebook_name}"
              + (f"\nshard {shard.k} of {shard.n}: join the shards with python -m autograder merge"
                 if shard.n > 1 and not several else ""))
        folder = assignment_folder(args.folder, assignment) if several else args.folder
        missing = [m for m in missing_submissions(folder, assignment) if shard.owns(m)]
        if missing:
            print(f"{len(missing)} student folder(s) hold no {assignment}/ (not handed in; not graded, not in the "
                  f"gradebook): {_listed(missing)}")
        anew = handed_in_anew(out, shard)
        if anew:
            print(f"{len(anew)} submission(s) were handed in again after they were graded, so were graded again "
                  f"(the earlier results are kept in {out / '_previous'}): {_listed(anew)}")
        version = course.suite_version(assignment)
        older = [r.submission for r in results if r.suite_version and r.suite_version != version]
        if older:
            state = ("so the gradebook mixes two suites" if len(older) < len(results) else
                     "every result in the gradebook: none is by this version")
            print(f"{len(older)} result(s) were graded by an earlier version of {assignment}'s suite, {state}: "
                  f"python -m autograder regrade {assignment} {shlex.quote(str(args.folder))} --out "
                  f"{shlex.quote(str(out))} grades them "
                  f"all with this one, keeping the earlier results: {_listed(older)}", file=sys.stderr)
        unreadable = [r.submission for r in results if r.status == UNGRADABLE]
        if unreadable:
            print(f"{len(unreadable)} submission(s) could not be graded (0 in the gradebook, whose reason column says "
                  f"why): {_listed(unreadable)}")
        several_notebooks = [r.submission for r in results if any(n.startswith(SEVERAL_NOTEBOOKS) for n in r.notes)]
        if several_notebooks:
            print(f"{len(several_notebooks)} submission(s) held several notebooks, and the one with the most stubs "
                  f"done was graded (each one's feedback names it): {_listed(several_notebooks)}")
        wrong = [r.submission for r in results if r.wrong_notebook]
        if wrong:
            print(f"{len(wrong)} submission(s) define none of {assignment}'s stubs (graded 0; another assignment's "
                  f"notebook?): {_listed(wrong)}: the gradebook's reason column says what each seems to be")
        stray = [f for f in stray_files(folder) if shard.owns(f)]
        if stray:
            print(f"{len(stray)} file(s) beside the submissions are not notebooks (.ipynb), so not graded and not in "
                  f"the gradebook: {_listed(stray)}")
    if shard.n > 1 and several:
        print(f"shard {shard.k} of {shard.n}: join each assignment's shards with python -m autograder merge")
    failed = [r for r in every if r.status == GRADER_ERROR]
    if failed:
        print(f"the grader failed on {len(failed)} submission(s), e.g. {plain(failed[0].submission)}: "
              f"{plain(failed[0].error or '')}\n"
              "their rows have status grader_error and no score; fix the grader and run the same command again "
              "to grade just those", file=sys.stderr)
        return GRADER_FAULT_EXIT
    return 0


def _cmd_merge(args: argparse.Namespace) -> int:
    from autograder.outputs.merge import merge

    results = merge(args.assignment, args.shards, args.out)
    print(f"merged {len(results)} submissions into {args.out / 'gradebook.csv'}")
    return 0


def _cmd_prairielearn(args: argparse.Namespace) -> int:
    from autograder.outputs.prairielearn import question_files, run

    if args.question_files is not None:
        if not args.image:
            raise SystemExit("--question-files needs --image <account>/rlcourse-grader:<term>, the grading image you "
                             "built from docker/grader/Dockerfile and pushed to Docker Hub, where PrairieLearn pulls "
                             "it from (docs/instructors.md, PrairieLearn)")
        for path in question_files(args.assignment, args.question_files, image=args.image, timeout=args.timeout):
            print(f"wrote {path}")
        return 0
    return run(args.assignment, args.root)


def _cmd_run(args: argparse.Namespace) -> int:
    from autograder.authoring.nbrun import parse_value, run_notebook

    if not Path(args.notebook).is_file():
        raise SystemExit(f"{args.notebook}: no such notebook")
    malformed = [item for item in args.parameter if "=" not in item]
    if malformed:
        raise SystemExit(f"-p takes NAME=VALUE (e.g. -p FAST=True), not {malformed[0]!r}")
    parameters = dict(item.split("=", 1) for item in args.parameter)
    report = run_notebook(args.notebook, {k: parse_value(v) for k, v in parameters.items()}, timeout=args.timeout,
                          until_first_stub=args.until_first_stub, output=args.output)
    print(report.describe(args.notebook))
    return 0 if report.ok else 1


def _cmd_demo(args: argparse.Namespace) -> int:
    from autograder.authoring.demo import run_demo

    return run_demo(args.out, jobs=args.jobs)



def _cmd_assignments(args: argparse.Namespace) -> int:
    from autograder.authoring.release import generate_assignments
    from autograder.authoring.samples import write_samples
    from autograder.core import course

    ids = args.ids or course.assignment_ids()
    generate_assignments(ids)
    for assignment in ids:  # the samples are the release with its stubs filled in: kept in step with it
        if (course.samples_dir(assignment) / "expected.json").exists():
            write_samples(assignment)
            print(f"regenerated {course.samples_dir(assignment)} (the samples `make demo` grades)")
    return 0


def _cmd_student_release(args: argparse.Namespace) -> int:
    from autograder.authoring.release import build_student_release

    print(f"student release written to {build_student_release(args.out)}")
    return 0


def _cmd_permissions(args: argparse.Namespace) -> int:
    from autograder.core.course import REPO, set_container_permissions

    changed = set_container_permissions(args.root or REPO, environment=not args.no_environment,
                                        assignment=args.assignment)
    print(f"{len(changed)} file modes changed under {args.root or REPO}" + (" (and its virtual environment)"
                                                                          if not args.no_environment else "")
          + (f" for grading {args.assignment}" if args.assignment else ""))
    return 0


def _cmd_samples(args: argparse.Namespace) -> int:
    from autograder.authoring.samples import write_samples
    from autograder.core import course

    course.check_assignment(args.assignment)
    for path in write_samples(args.assignment):
        print(path)
    return 0


def _cmd_new(args: argparse.Namespace) -> int:
    from autograder.authoring.new import create

    for path in create(args.assignment, args.title):
        print(f"wrote {path}")
    print(f"next: replace the two stubs in solutions/{args.assignment}/, then `python -m autograder assignments "
          f"{args.assignment}`, `python -m autograder samples {args.assignment}` and `python -m "
          f"autograder.authoring.limits {args.assignment}` (CONTRIBUTING.md)")
    return 0


def _cmd_mutants(args: argparse.Namespace) -> int:
    from autograder.authoring.mutants import command

    return command(args.assignment, args.stub or None, args.max_per_stub, args.seed, args.out)


def _out_folder(text: str) -> Path:
    """``--out``: a folder, made if missing; an existing file there is refused at once, not after the grading."""
    path = Path(text)
    if path.exists() and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file; --out names the folder to write into")
    return path


def _jobs(text: str) -> int:
    try:
        jobs = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if jobs < 1:
        raise argparse.ArgumentTypeError("--jobs is the number of grading processes: at least 1")
    return jobs


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m autograder", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("grade", help="grade one submission")
    p.add_argument("assignment")
    p.add_argument("notebook", type=Path)
    p.add_argument("--out", type=_out_folder, required=True)
    p.set_defaults(fn=_cmd_grade)
    p = sub.add_parser("batch", help="grade a folder of submissions (of one assignment, or several at once)")
    p.add_argument("assignment", metavar="ID[,ID...]",
                   help="the assignment, or several separated by commas (graded in one pool: start-up paid once)")
    p.add_argument("folder", type=Path, nargs="?", help="the submissions (for several: nbgrader's layout, or ID/ each)")
    p.add_argument("--all", action="store_true",
                   help="every assignment handed in under the folder (batch --all FOLDER --out DIR); each into DIR/ID/")
    p.add_argument("--out", type=_out_folder, required=True)
    p.add_argument("--jobs", type=_jobs, default=2)
    p.add_argument("--shard", default=None, metavar="K/N",
                   help="grade only shard K of N (split by submission name); join shards with `merge`")
    p.set_defaults(fn=_cmd_batch)
    p = sub.add_parser("merge", help="join the shards of a batch into one gradebook")
    p.add_argument("assignment")
    p.add_argument("shards", type=Path, nargs="+", help="the shards' --out folders (or one folder they share)")
    p.add_argument("--out", type=_out_folder, required=True)
    p.set_defaults(fn=_cmd_merge)
    p = sub.add_parser("prairielearn", help="grade one submission as PrairieLearn's external grader")
    p.add_argument("assignment")
    p.add_argument("--root", type=Path, default=Path("/grade"), help="PrairieLearn's grading folder")
    p.add_argument("--question-files", type=Path, default=None, metavar="COURSE_DIR",
                   help="instead of grading, write the question's info.json, question.html and run.sh here")
    p.add_argument("--image", default=None, metavar="ACCOUNT/rlcourse-grader:TERM",
                   help="with --question-files (required there): the grading image you built and pushed to Docker Hub, "
                        "named in info.json")
    p.add_argument("--timeout", type=int, default=None, metavar="SECONDS",
                   help="the question's grading timeout (default: the submission's limit plus 60 s; at most 600)")
    p.set_defaults(fn=_cmd_prairielearn)
    p = sub.add_parser("demo", help="grade every assignment's sample submissions")
    p.add_argument("--out", type=_out_folder, default=Path("build/demo"))
    p.add_argument("--jobs", type=_jobs, default=2)
    p.set_defaults(fn=_cmd_demo)
    from autograder.outputs import gradescope

    gradescope.add_command(sub)  # gradescope ID [--out ZIP] [--visibility V]
    p = sub.add_parser("run", help="execute a notebook with parameters")
    p.add_argument("notebook", type=Path)
    p.add_argument("-p", "--parameter", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("--timeout", type=float, default=600)
    p.add_argument("--until-first-stub", action="store_true")
    p.add_argument("--output", type=Path, default=None, help="write the executed notebook here")
    p.set_defaults(fn=_cmd_run)
    p = sub.add_parser("assignments", help="regenerate student notebooks and the sample submissions made from them")
    p.add_argument("ids", nargs="*")
    p.set_defaults(fn=_cmd_assignments)
    p = sub.add_parser("student-release", help="build the student-only tree")
    p.add_argument("out", type=Path)
    p.set_defaults(fn=_cmd_student_release)
    p = sub.add_parser("samples", help="regenerate sample submissions")
    p.add_argument("assignment")
    p.set_defaults(fn=_cmd_samples)
    p = sub.add_parser("permissions", help="set the file modes a worker without namespaces needs (grading containers)")
    p.add_argument("--root", type=Path, default=None, help="the course checkout (default: the one being graded)")
    p.add_argument("--no-environment", action="store_true", help="leave the virtual environment's modes as they are")
    p.add_argument("--assignment", default=None, help="the assignment this container grades: the library modules "
                   "grading it does not need become readable by their owner only (a worker refuses otherwise)")
    p.set_defaults(fn=_cmd_permissions)
    p = sub.add_parser("new", help="write a new assignment's skeleton")
    p.add_argument("assignment")
    p.add_argument("--title", default="a new assignment")
    p.set_defaults(fn=_cmd_new)
    p = sub.add_parser("mutants", help="grade mutants of each solution stub with its hidden tests and public check")
    p.add_argument("assignment")
    p.add_argument("--stub", action="append", default=[], help="only this stub (repeatable)")
    p.add_argument("--max-per-stub", type=int, default=None, help="grade a seeded sample of at most N mutants per stub")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=None, help="report folder (default build/mutants/<id>)")
    p.set_defaults(fn=_cmd_mutants)
    from autograder.outputs.cli import add_commands

    add_commands(sub)
    args = parser.parse_args(argv)
    return args.fn(args)


if __name__ == "__main__":
    sys.exit(main())
