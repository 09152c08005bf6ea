"""Record a batch in the course's nbgrader gradebook, so that formgrader grades the written answers.

After ``python -m autograder batch ID FOLDER --out DIR``, :func:`sync` (``python -m autograder
nbgrader-sync ID FOLDER --results DIR``) writes, through ``nbgrader.api.Gradebook`` only:

- the assignment's structure: one notebook named after the assignment, a grade cell for each
  stub (``cell_type`` code, worth the points its hidden tests carry) and for each written
  answer (markdown, worth its nbgrader ``points``), each also a solution cell so a grader can
  leave a comment on it;
- per submission: the student (the name the submission was handed in under, its folder's name in
  ``submitted/`` or its notebook's stem, not the safe name ``batch`` filed it under: see
  :func:`submission_ids`; for a Gradescope export, each submitter named in ``submission_metadata.yml``;
  an id that cannot be a folder name as it is, such as one with a control character, is recorded under
  its safe name and named in a warning), the submission with its time when the layout records
  one (nbgrader's ``timestamp.txt``, Gradescope's ``:created_at:``), the autograder's score of
  each stub as the grade's ``auto_score`` and the tests' outcomes as its ``auto_comment``;
  a written answer left as released (or a submission with no notebook, or one missing from another
  assignment's notebook handed in by mistake) gets ``auto_score`` 0, any other written answer waits for a
  person (``needs_manual_grade``);
- the submitted notebook, placed at ``autograded/<student>/<assignment>/<assignment>.ipynb``
  of the nbgrader course, where formgrader opens it (see :func:`formgrader_notebook`).

Running it again updates the same rows (nbgrader's ``update_or_create_*`` and ``find_*``), never
adds a second submission, and never writes ``manual_score``, ``extra_credit`` or
``manual_comment``: what a person gave in formgrader stays as it was, and a grade a person set
keeps ``needs_manual_grade`` as formgrader left it, but for one case: when the text of a cell a person
graded changed since (the notebook placed for formgrader before differs from the one placed now: the
student handed in again), its grade is marked as needing a grade again, and the sync names the student
and the cell (:attr:`SyncReport.reread`) on every run until a person grades it. A grader error (no score) changes nothing
of its submission in the gradebook: its student is listed (created if new, with no submission) and
the course's ``.nbgrader/autograder_not_recorded.json`` names it until a later sync records it, so
``export`` leaves that grade empty and says why instead of showing a 0.

A student's names and e-mail already in the gradebook (imported from the roster with ``nbgrader db
student import roster.csv``) are kept: the sync only fills in what is empty.
"""
from __future__ import annotations

import html
import json
import os
import re
import sys
import unicodedata
import warnings
from dataclasses import dataclass, field
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path

import nbformat

from autograder.core import course
from autograder.core.batch import Entry, discover, safe_name, submissions_folder
from autograder.core.notebook import NotebookError, find_stubs, manual_cells, read_notebook, read_submission
from autograder.outputs.batch_output import STUDENTS_NAME, read_results, read_students
from autograder.core.store import atomic_write
from autograder.outputs.text import listed, markdown_text, plain
from autograder.core.results import GRADED, GRADER_ERROR, GradeResult, GraderError

GRADESCOPE_METADATA = "submission_metadata.yml"
NOT_RECORDED_NAME = ".nbgrader/autograder_not_recorded.json"
"""In the course root: ``{assignment: {student id: why}}``, the submissions whose latest grading the sync could not
record (the grader failed on them); read by ``export``."""
MISSING_CELL = "(No cell with this id was found in the submission; the answer may be elsewhere in the notebook.)"


@dataclass
class WrittenAnswer:
    grade_id: str
    points: float
    released: str
    """The cell's text in the student notebook ("YOUR ANSWER HERE"): an answer still equal to it is unanswered."""


@dataclass
class Submitter:
    student_id: str
    first_name: str | None = None
    last_name: str | None = None
    email: str | None = None


@dataclass
class SyncReport:
    recorded: list[tuple[str, str]] = field(default_factory=list)
    """``(submission, student)`` pairs written to the gradebook."""
    placed: list[Path] = field(default_factory=list)
    skipped: list[tuple[str, str]] = field(default_factory=list)
    """``(submission, why)`` for each submission not recorded."""
    kept: int = 0
    """Scores and comments given by a person, left as they were."""
    waiting: int = 0
    """Written answers that wait for a person's grade."""
    reread: list[tuple[str, str]] = field(default_factory=list)
    """``(student, cell)`` for each score a person gave whose cell's text changed since (a notebook handed in
    again): marked as needing a grade again (nbgrader's ``needs_manual_grade``) until a person grades it."""
    unusable_ids: list[tuple[str, str, str]] = field(default_factory=list)
    """``(student id, id recorded instead, why)`` for each student id that cannot be a gradebook id as it is."""
    other_suite: dict[str, str] = field(default_factory=dict)
    """``{submission: suite version}`` for each recorded result graded by a version of the suite other than the
    current one (a result that records no version is not counted)."""
    earlier_ids: list[tuple[str, str]] = field(default_factory=list)
    """``(id recorded by an earlier sync, student id now)``: the safe name an earlier version of this sync recorded
    a student under, still holding a submission (export lists it as a student of its own)."""
    claimed: list[tuple[str, str, list[str]]] = field(default_factory=list)
    """``(student id, submission recorded, other submissions naming that id)``: one gradebook row per student, so a
    student named by several submissions (a Gradescope export where two list the same SID) gets the newest only."""
    suite_now: str = ""
    regrade_command: str = ""

    def lines(self, assignment: str, gradebook: str) -> list[str]:
        out = [f"{assignment}: {len(self.recorded)} submission(s) recorded in {gradebook}, "
               f"{len(self.placed)} notebook(s) placed for formgrader; {self.waiting} written answer(s) wait for a "
               f"grade; {self.kept} score(s) or comment(s) given by a person kept as they were"]
        out += [f"  not recorded: {name}: {why}" for name, why in self.skipped]
        return out

    def warnings(self) -> list[str]:
        """What the instructor must act on, one line each (the command prints them on stderr)."""
        out = [f"warning: student id {ascii(raw)} {why}, so it was recorded as {ascii(used)}, which matches no "
               f"roster entry: rename the student's folder (or their id in the roster), then sync again"
               for raw, used, why in self.unusable_ids]
        out += [f"warning: an earlier sync recorded {plain(student)}'s submission under {ascii(old)}, which export "
                f"lists as a student of its own: remove it (nbgrader db student remove {ascii(old)} --force, from the "
                f"course root), then sync again" for old, student in self.earlier_ids]
        if self.other_suite:
            names = sorted(self.other_suite)
            out.append(f"warning: {len(names)} result(s) recorded here were graded by another version of the suite "
                       f"({', '.join(sorted(set(self.other_suite.values())))}; the current one is {self.suite_now}): "
                       f"{listed([plain(n) for n in names])}. Their scores are the old suite's; regrade them all, "
                       f"which records the new ones: {self.regrade_command}")
        for student, kept, others in self.claimed:
            out.append(f"warning: student {plain(student)} is named by {len(others) + 1} submissions: recorded "
                       f"{plain(kept)} (the newest where the times are known, else the last by name), not "
                       f"{listed([plain(o) for o in others])}. Check the export's submitters, then sync again.")
        if self.reread:
            cells = listed([f"{plain(s)}: {plain(c)}" for s, c in self.reread], 30)
            out.append(f"warning: {len(self.reread)} score(s) given by hand are of a cell whose text changed since "
                       f"(the notebook was handed in again): {cells}. They are marked as needing a grade again in "
                       "formgrader, and export counts the earlier score until a person grades them.")
        return out


# ------------------------------------------------------------------ the nbgrader course

def course_directory(root: Path | None = None):
    """nbgrader's ``CourseDirectory`` for the course at ``root`` (default: this repository), read from its
    ``nbgrader_config.py``, with the root and a relative SQLite ``db_url`` made absolute under ``root``
    (the configuration names them relative to the folder nbgrader is started in)."""
    from nbgrader.coursedir import CourseDirectory
    from traitlets.config import Config
    from traitlets.config.loader import PyFileConfigLoader

    root = Path(root or course.REPO).resolve()
    config = Config()
    if (root / "nbgrader_config.py").is_file():
        config = PyFileConfigLoader("nbgrader_config.py", path=str(root)).load_config()
        config.CourseDirectory.pop("root", None)  # relative to the folder nbgrader starts in: set below
    coursedir = CourseDirectory(config=config)
    coursedir.root = str(root)
    prefix = "sqlite:///"
    if coursedir.db_url.startswith(prefix) and not coursedir.db_url.startswith(prefix + "/"):
        database = root / coursedir.db_url[len(prefix):]
        database.parent.mkdir(parents=True, exist_ok=True)
        coursedir.db_url = prefix + str(database)
    return coursedir


def open_gradebook(coursedir):
    """The course's ``nbgrader.api.Gradebook`` (a context manager that closes it)."""
    from nbgrader.api import Gradebook

    with_nbgrader_path()  # a new gradebook runs alembic
    return Gradebook(coursedir.db_url, coursedir.course_id)


def with_nbgrader_path() -> None:
    """nbgrader runs ``alembic`` by name: put this environment's ``bin/`` first on ``PATH``."""
    bin_dir = str(Path(sys.executable).parent)
    if os.environ.get("PATH", "").split(os.pathsep)[0] != bin_dir:
        os.environ["PATH"] = bin_dir + os.pathsep + os.environ.get("PATH", "")


def read_not_recorded(root: Path) -> dict[str, dict[str, str]]:
    """The course's record of submissions the sync could not record (see :data:`NOT_RECORDED_NAME`)."""
    try:
        data = json.loads((Path(root) / NOT_RECORDED_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _write_not_recorded(root: Path, assignment: str, failed: dict[str, str], recorded: set[str]) -> None:
    data = read_not_recorded(root)
    kept = {s: why for s, why in data.get(assignment, {}).items() if s not in recorded}
    kept.update(failed)
    data[assignment] = kept
    if not kept:
        del data[assignment]
    if data or (Path(root) / NOT_RECORDED_NAME).exists():
        atomic_write(Path(root) / NOT_RECORDED_NAME, json.dumps(data, indent=1, sort_keys=True))


def keep_names(gb, person: Submitter) -> None:
    """The student in the gradebook, created if new; names and e-mail filled in only where empty there
    (the roster's, imported with ``nbgrader db student import``, are kept)."""
    from nbgrader.api import MissingEntry

    given = {k: v for k, v in (("first_name", person.first_name), ("last_name", person.last_name),
                               ("email", person.email)) if v is not None}
    try:
        student = gb.find_student(person.student_id)
    except MissingEntry:
        gb.update_or_create_student(person.student_id, **given)
        return
    empty = {k: v for k, v in given.items() if not getattr(student, k)}
    if empty:
        gb.update_or_create_student(person.student_id, **empty)


def id_problem(student_id: str) -> str | None:
    """Why ``student_id`` cannot be a gradebook id and a folder name of ``autograded/`` as it is, or None."""
    try:
        student_id.encode("utf-8")
    except UnicodeEncodeError:
        return "is not valid UTF-8"
    if not student_id or student_id in (".", "..") or "/" in student_id:
        return "is not a folder name"
    if any(unicodedata.category(c) in ("Cc", "Cf", "Cs", "Co", "Cn") for c in student_id):
        return "holds control or unassigned characters"
    if student_id != student_id.strip():
        return "begins or ends with white space"
    return None


def submission_ids(folder: Path) -> dict[str, str]:
    """Per submission name as ``batch`` makes it (``safe_name``), the name it was made from: the student's folder
    name in nbgrader's layout, a notebook's stem in a flat folder. The student id is that name, not the safe one
    (``Mallory Smith``, not ``Mallory_Smith+4daf2c6d``): it is the id in the roster and in ``submitted/``."""
    try:
        root = submissions_folder(Path(folder))
        children = list(root.iterdir())
    except (SystemExit, OSError):
        return {}
    out: dict[str, str] = {}
    for child in children:
        for name in (child.name, child.stem):
            out.setdefault(safe_name(name), name)
    return out


def _student_id(raw: str, report: SyncReport) -> str:
    """``raw`` as the gradebook's student id; when it cannot be one, its safe name, and a warning naming both."""
    why = id_problem(raw)
    if why is None:
        return raw
    used = safe_name(raw)
    if (raw, used, why) not in report.unusable_ids:
        report.unusable_ids.append((raw, used, why))
    return used


# ------------------------------------------------------------------ what the assignment holds

def written_answers(assignment: str) -> list[WrittenAnswer]:
    """The hand-graded answers of an assignment, from its student notebook, in order."""
    nb = read_notebook(course.release_notebook(assignment))
    released = {c.metadata.get("nbgrader", {}).get("grade_id"): c.source for c in nb.cells}
    return [WrittenAnswer(gid, points, released.get(gid, "")) for gid, points in manual_cells(nb)]


def stub_points(assignment: str, results: list[GradeResult]) -> dict[str, float]:
    """Each stub's points, in notebook order, as the graded results carry them.

    All results must come from one version of the suite: a stub worth different points in two
    results means some were graded before the suite changed, and they must be regraded first.
    """
    seen: dict[str, tuple[float, str]] = {}
    for result in results:
        if result.status != GRADED:
            continue
        for stub in result.stubs:
            if stub.name in seen and seen[stub.name][0] != stub.max_score:
                points, other = seen[stub.name]
                raise SystemExit(
                    f"`{stub.name}` is worth {stub.max_score:g} point(s) in {result.submission}'s result and "
                    f"{points:g} in {other}'s: these results come from different versions of {assignment}'s suite. "
                    f"Regrade them all with the same suite first (python -m autograder regrade {assignment} ...).")
            seen.setdefault(stub.name, (stub.max_score, result.submission))
    return {name: seen[name][0] for name in [*course.stub_names(assignment), *seen] if name in seen}


def register_assignment(gb, assignment: str, stubs: dict[str, float], written: list[WrittenAnswer]) -> None:
    """The assignment, its notebook and its graded cells in the gradebook (its due date, if set, is kept)."""
    gb.update_or_create_assignment(assignment)
    gb.update_or_create_notebook(assignment, assignment)
    for name, points in stubs.items():
        gb.update_or_create_grade_cell(name, assignment, assignment, max_score=points, cell_type="code")
        gb.update_or_create_solution_cell(name, assignment, assignment)
    for answer in written:
        gb.update_or_create_grade_cell(answer.grade_id, assignment, assignment, max_score=answer.points,
                                       cell_type="markdown")
        gb.update_or_create_solution_cell(answer.grade_id, assignment, assignment)


# ------------------------------------------------------------------ who submitted, and when

def gradescope_submitters(folder: Path) -> dict[str, tuple[list[Submitter], str | None]]:
    """From a Gradescope export's ``submission_metadata.yml``: per submission folder, its submitters
    (student id: the SID, else the e-mail, as written there) and its ``:created_at:`` time."""
    import yaml

    path = Path(folder) / GRADESCOPE_METADATA
    if not path.is_file():
        return {}
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    except (yaml.YAMLError, UnicodeDecodeError) as err:
        raise SystemExit(f"{path} cannot be read ({str(err)[:200]}); fix or remove it") from None
    out = {}
    for name, record in (data.items() if isinstance(data, dict) else []):
        record = record if isinstance(record, dict) else {}
        people = []
        for person in record.get(":submitters") or []:
            person = person if isinstance(person, dict) else {}
            raw = str(person.get(":sid") or person.get(":email") or "").strip()
            if raw:
                full = str(person.get(":name") or "").strip()
                first, _, last = full.rpartition(" ") if " " in full else ("", "", full)
                people.append(Submitter(raw, first or None, last or None,
                                        str(person.get(":email") or "") or None))
        created = record.get(":created_at")
        out[str(name)] = (people, str(created) if created else None)
    return out


def nbgrader_timestamp(entry: Entry, folder: Path) -> str | None:
    """The ``timestamp.txt`` nbgrader's ``collect`` writes beside a submitted notebook, if any."""
    if entry.notebook is None:
        return None
    for place in (entry.notebook.parent, Path(folder) / entry.name):
        stamp = place / "timestamp.txt"
        if stamp.is_file() and not stamp.is_symlink() and stamp.stat().st_size < 200:
            return stamp.read_text(encoding="utf-8", errors="replace").strip() or None
    return None


# ------------------------------------------------------------------ the notebook formgrader shows

_LINK_TARGET = re.compile(r"\]\(\s*([^)\s]*)")
_REFERENCE = re.compile(r"(?m)^( {0,3})(\[[^\]\n]+\]:[ \t]*)(\S*)")
_MATH = re.compile(r"(\$\$.+?\$\$|\$[^$\n]+\$)", re.S)
_SAFE_SCHEMES = {"http", "https", "mailto"}
_SHOWN_TAGS = {"p", "a", "em", "strong", "del", "code", "pre", "ul", "ol", "li", "blockquote", "hr", "br", "img",
               "h1", "h2", "h3", "h4", "h5", "h6", "table", "thead", "tbody", "tr", "th", "td"}
_SHOWN_ATTRIBUTES = {"href", "src", "alt", "title", "id", "class", "align", "style", "start"}


def _harmless_url(url: str) -> bool:
    """A link target with no scheme, or http(s) or mailto, read as a browser reads it (entities decoded,
    tabs and line breaks dropped): never ``javascript:`` and the like."""
    decoded = re.sub(r"[\x00-\x20\x7f]", "", html.unescape(url))
    scheme = re.match(r"([A-Za-z][A-Za-z0-9+.-]*):", decoded)
    return scheme is None or scheme.group(1).lower() in _SAFE_SCHEMES


def _no_scheme_links(text: str) -> str:
    """Links (inline and reference) whose target has a scheme other than http(s) or mailto, shown as text."""
    text = _LINK_TARGET.sub(lambda m: m.group(0) if _harmless_url(m.group(1)) else "]\\(" + m.group(0)[2:], text)
    return _REFERENCE.sub(
        lambda m: m.group(0) if _harmless_url(m.group(3)) else f"{m.group(1)}\\{m.group(2)}{m.group(3)}", text)


class _Elements(HTMLParser):
    """Whether HTML holds only the elements Markdown makes, with harmless links."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.inert = True

    def handle_starttag(self, tag, attrs):
        for name, value in attrs:
            if name not in _SHOWN_ATTRIBUTES or (name in ("href", "src") and not _harmless_url(value or "")) \
                    or (name == "style" and value and not re.fullmatch(r"text-align:\s*\w+;?", value)):
                self.inert = False
        self.inert &= tag in _SHOWN_TAGS

    handle_startendtag = handle_starttag


def _renders_inert(markdown: str) -> bool:
    """Whether nbconvert's Markdown renderer (the one formgrader's and nbgrader's feedback templates use)
    makes only Markdown's own elements of this text."""
    from nbconvert.filters.markdown import markdown2html

    elements = _Elements()
    elements.feed(markdown2html(markdown))
    elements.close()
    return elements.inert


def _inert(markdown: str) -> str:
    """Student Markdown that formgrader (and nbgrader's feedback HTML) renders as text where it could act.

    nbconvert passes raw HTML and any link scheme through: a script, an event handler or a
    ``javascript:`` link would run in the grader's browser with the grader's Jupyter session. Outside
    math, ``<`` is written ``&lt;`` (it shows as ``<``; nbconvert escapes math itself), and a link
    with another scheme is shown as its text. The result is rendered as formgrader renders it and
    checked to hold only Markdown's own elements; if it does not (math delimiters that the renderer
    reads otherwise than the split here), every ``<`` is escaped, math included.
    """
    parts = _MATH.split(markdown)
    candidate = _no_scheme_links("".join(p if i % 2 else p.replace("<", "&lt;") for i, p in enumerate(parts)))
    return candidate if _renders_inert(candidate) else _no_scheme_links(markdown.replace("<", "&lt;"))


def _graded(grade_id: str, points: float) -> dict:
    return {"grade": True, "solution": True, "locked": False, "points": points, "grade_id": grade_id,
            "schema_version": 3}


def formgrader_notebook(path: Path, result: GradeResult, stubs: dict[str, float],
                        written: list[WrittenAnswer]) -> tuple[nbformat.NotebookNode, dict[str, str]]:
    """The submitted notebook as formgrader should show it, and each written answer's state.

    Every cell keeps its source; outputs and all metadata but tags are dropped (the grader did not
    run them, and they are the student's HTML); Markdown and raw cells become inert Markdown
    (:func:`_inert`). The cell the grader graded for each stub (matched as ``find_stubs`` matches
    it) and the cell of each written answer (by ``grade_id``, the last one if several) carry
    nbgrader metadata, so formgrader shows a score box there; one that is missing, or a stub
    sharing another stub's cell, gets a cell of its own at the end, saying so. A first cell
    gives the automatic score and the grader's notes. States: ``answered``, ``unanswered`` (as
    released, or empty) or ``missing``.
    """
    nb, _ = read_submission(path)
    matched, _ = find_stubs(nb, list(stubs))
    stub_cell = {}
    written_cell = {}
    ids = {a.grade_id for a in written}
    for index, cell in enumerate(nb.cells):
        meta = cell.get("metadata", {}).get("nbgrader")
        gid = meta.get("grade_id") if isinstance(meta, dict) else None
        if cell.cell_type == "code":
            for name, match in matched.items():
                if cell.source == match.source:
                    stub_cell[name] = index
        elif cell.cell_type == "markdown" and gid in ids:
            written_cell[gid] = index
    cells = []
    notes = [markdown_text(n) for n in result.notes]
    cells.append(nbformat.v4.new_markdown_cell(
        f"**Automatic score: {result.score:g} / {result.max_score:g}** (the stubs' scores below come from "
        "the hidden tests; the written answers wait for yours)" + "".join(f"\n- note: {n}" for n in notes)))
    where: dict[int, tuple[str, str]] = {}
    shared = {}  # a stub defined in the cell of another: its score box gets a cell of its own
    for name, index in stub_cell.items():
        if index in where:
            shared[name] = where[index][1]
        else:
            where[index] = ("code", name)
    where.update({index: ("markdown", gid) for gid, index in written_cell.items()})
    points = {**stubs, **{a.grade_id: a.points for a in written}}
    for index, cell in enumerate(nb.cells):
        source = cell.get("source", "")
        tags = cell.get("metadata", {}).get("tags", [])
        if cell.cell_type == "code":
            new = nbformat.v4.new_code_cell(source)
        else:
            new = nbformat.v4.new_markdown_cell(_inert(source))
            if cell.cell_type == "markdown" and isinstance(cell.get("attachments"), dict):
                new.attachments = cell.attachments
        if isinstance(tags, list) and all(isinstance(t, str) for t in tags) and tags:
            new.metadata["tags"] = tags
        if index in where:
            new.metadata["nbgrader"] = _graded(where[index][1], points[where[index][1]])
        cells.append(new)
    for name in stubs:
        if name in shared:
            cell = nbformat.v4.new_code_cell(f"# `{name}` is defined in the cell of `{shared[name]}` above.")
        elif name not in stub_cell:
            cell = nbformat.v4.new_code_cell(f"# No cell defining `{name}` was found in the submission.")
        else:
            continue
        cell.metadata["nbgrader"] = _graded(name, stubs[name])
        cells.append(cell)
    states = {}
    for answer in written:
        if answer.grade_id not in written_cell:
            cell = nbformat.v4.new_markdown_cell(MISSING_CELL)
            cell.metadata["nbgrader"] = _graded(answer.grade_id, answer.points)
            cells.append(cell)
            states[answer.grade_id] = "missing"
            continue
        text = nb.cells[written_cell[answer.grade_id]].source.strip()
        states[answer.grade_id] = "unanswered" if text in ("", answer.released.strip()) else "answered"
    out = nbformat.v4.new_notebook(cells=cells)
    for key in ("kernelspec", "language_info"):
        if isinstance(nb.metadata.get(key), dict):
            out.metadata[key] = nb.metadata[key]
    return out, states


def _tests_comment(result: GradeResult, name: str) -> str:
    """The hidden tests' outcomes for one stub, as the grade's automatic comment."""
    if result.status != GRADED:
        return f"Not graded automatically: {_inert(_line(result.error or 'no notebook'))}"
    stub = next((s for s in result.stubs if s.name == name), None)
    if stub is None:
        return "No tests of this stub ran."
    lines = []  # Markdown: nbgrader's feedback HTML renders comments, and messages quote student text
    for test in stub.tests:
        if test.passed:
            lines.append(f"- ✓ {_inert(_line(test.name))} ({test.points:g}/{test.points:g})")
        else:
            lines.append(f"- ✗ {_inert(_line(test.name))} (0/{test.points:g}): {_inert(_line(test.message))}")
    return "\n".join(lines)


def _line(text: str) -> str:
    return plain(text).replace("\n", " ")


# ------------------------------------------------------------------ writing grades

def _rows(gb, assignment: str, student: str, timestamp: str | None):
    """The submission's notebook and its grade and comment rows, creating what is missing (a cell added to
    the assignment after the submission was first recorded gets its row here)."""
    from nbgrader import api

    try:
        submission = gb.find_submission(assignment, student)
        if timestamp is not None:
            gb.update_or_create_submission(assignment, student, timestamp=timestamp)
    except api.MissingEntry:
        with warnings.catch_warnings():  # nbgrader's add_submission builds rows before adding them: SAWarnings
            warnings.simplefilter("ignore")
            submission = gb.add_submission(assignment, student, **({"timestamp": timestamp} if timestamp else {}))
    notebook = gb.find_notebook(assignment, assignment)
    submitted = next((n for n in submission.notebooks if n.notebook_id == notebook.id), None)
    if submitted is None:
        submitted = api.SubmittedNotebook(notebook=notebook, assignment=submission)
        gb.db.add(submitted)
    grades = {g.cell_id: g for g in submitted.grades}
    comments = {c.cell_id: c for c in submitted.comments}
    for cell in notebook.grade_cells:
        if cell.id not in grades:
            grades[cell.id] = api.Grade(cell_id=cell.id, notebook=submitted)
            gb.db.add(grades[cell.id])
    for cell in notebook.solution_cells:
        if cell.id not in comments:
            comments[cell.id] = api.Comment(cell_id=cell.id, notebook=submitted)
            gb.db.add(comments[cell.id])
    gb.db.flush()
    by_name_grade = {cell.name: grades[cell.id] for cell in notebook.grade_cells}
    by_name_comment = {cell.name: comments[cell.id] for cell in notebook.solution_cells}
    return by_name_grade, by_name_comment


def graded_cell_texts(notebook: nbformat.NotebookNode) -> dict[str, str]:
    """Per graded cell (its nbgrader ``grade_id``) of a notebook placed for formgrader, the text shown there."""
    out = {}
    for cell in notebook.cells:
        meta = cell.get("metadata", {}).get("nbgrader")
        if isinstance(meta, dict) and meta.get("grade_id"):
            out[meta["grade_id"]] = cell.get("source", "").strip()
    return out


def changed_cells(place: Path, notebook: nbformat.NotebookNode) -> set[str]:
    """The graded cells whose text differs between the notebook placed at ``place`` before (what a person saw in
    formgrader) and ``notebook`` (about to replace it); none when nothing was placed before."""
    try:
        before = graded_cell_texts(nbformat.read(str(place), as_version=4))
    except (OSError, ValueError, KeyError):
        return set()
    after = graded_cell_texts(notebook)
    return {gid for gid in set(before) | set(after) if before.get(gid) != after.get(gid)}


def record_submission(gb, assignment: str, student: str, result: GradeResult, stubs: dict[str, float],
                      states: dict[str, str], timestamp: str | None, report: SyncReport,
                      changed: set[str] = frozenset()) -> None:
    """One student's submission: automatic scores and comments in, a person's scores and comments untouched, but
    a score a person gave to a cell in ``changed`` (its text differs from what they graded) marked as needing a
    grade again (nbgrader's ``needs_manual_grade``, which formgrader clears when a person saves a score)."""
    grades, comments = _rows(gb, assignment, student, timestamp)
    for name in sorted(changed):
        if name in grades and grades[name].manual_score is not None:
            grades[name].needs_manual_grade = True
    scores = {s.name: s.score for s in result.stubs} if result.status == GRADED else {}
    for name in stubs:
        grade, comment = grades[name], comments[name]
        grade.auto_score = float(scores.get(name, 0.0))
        comment.auto_comment = _tests_comment(result, name)
        if grade.manual_score is None:
            grade.needs_manual_grade = False
    for gid, state in states.items():
        grade = grades[gid]
        if grade.manual_score is not None:
            continue  # graded by a person: theirs to change
        # Another assignment's notebook has no answer to this question anywhere: nothing waits for a person.
        elsewhere = state == "missing" and bool(result.wrong_notebook)
        if elsewhere and gid in comments:
            comments[gid].auto_comment = f"Not answered: {_inert(_line(result.wrong_notebook))}"
        unanswered = state == "unanswered" or result.status != GRADED or elsewhere
        grade.auto_score = 0.0 if unanswered else None
        grade.needs_manual_grade = not unanswered
        report.waiting += not unanswered
    report.reread += [(student, name) for name, g in grades.items() if g.manual_score is not None
                      and g.needs_manual_grade]
    report.kept += sum(g.manual_score is not None or g.extra_credit is not None for g in grades.values())
    report.kept += sum(c.manual_comment is not None for c in comments.values())
    gb.db.commit()


def _submitters(entries: list[Entry], folder: Path, report: SyncReport
                ) -> dict[str, tuple[list[Submitter], str | None]]:
    """Per submission, its students (ids as the course knows them: see :func:`submission_ids`) and its time."""
    gradescope = gradescope_submitters(folder)
    original = submission_ids(folder)
    out = {}
    for entry in entries:
        people, created = gradescope.get(entry.name, ([], None))
        people = people or [Submitter(original.get(entry.name, entry.name))]
        for person in people:
            person.student_id = _student_id(person.student_id, report)
        out[entry.name] = (people, created or nbgrader_timestamp(entry, folder))
    return out


def _one_submission_per_student(people: dict[str, tuple[list[Submitter], str | None]], graded: set[str],
                                report: SyncReport) -> dict[str, str]:
    """For each student id that several graded submissions name, the submission recorded for it: the newest by
    its time where every one has a time, else the last by name; each such id is named in ``report.claimed``."""
    from nbgrader.utils import parse_utc

    by_student: dict[str, list[str]] = {}
    for name in sorted(people):
        if name in graded:
            for person in people[name][0]:
                by_student.setdefault(person.student_id, []).append(name)
    owner = {}
    for student, names in by_student.items():
        if len(names) < 2:
            continue
        try:
            times = [parse_utc(people[n][1]) if people[n][1] else None for n in names]
        except (ValueError, TypeError, OverflowError):
            times = [None]
        kept = max(zip(times, names))[1] if None not in times else names[-1]
        owner[student] = kept
        report.claimed.append((student, kept, [n for n in names if n != kept]))
    return owner


def sync(assignment: str, folder: Path, results_dir: Path, course_root: Path | None = None) -> SyncReport:
    """Record the batch in ``results_dir`` (graded from ``folder``) in the gradebook of the nbgrader course at
    ``course_root`` (default: this repository), and place each notebook for formgrader. See the module."""
    course.check_assignment(assignment)
    with_nbgrader_path()
    folder, results_dir = Path(folder), Path(results_dir)
    results = read_results(results_dir)
    entries = {e.name: e for e in discover(folder, assignment, course.stub_names(assignment))}
    stubs = stub_points(assignment, list(results.values()))
    written = written_answers(assignment)
    coursedir = course_directory(course_root)
    report = SyncReport(suite_now=course.suite_version(assignment),
                        regrade_command=f"python -m autograder regrade {assignment} {folder} --out {results_dir}")
    people = _submitters(list(entries.values()), folder, report)
    owner = _one_submission_per_student(people, {n for n, r in results.items() if r.status != GRADER_ERROR}, report)
    students: dict[str, list[str]] = {}
    failed: dict[str, str] = {}
    from nbgrader.api import MissingEntry

    with open_gradebook(coursedir) as gb:
        register_assignment(gb, assignment, stubs, written)
        for name in sorted(set(results) | set(entries)):
            result, entry = results.get(name), entries.get(name)
            if result is None:
                report.skipped.append((name, "not graded yet (run the batch again)"))
                continue
            if entry is None:
                report.skipped.append((name, f"graded, but no longer in {folder}"))
                continue
            if result.status == GRADER_ERROR:
                report.skipped.append((name, "the grader failed on it; run the batch again, then sync"))
                for person in people[name][0]:
                    keep_names(gb, person)
                    failed[person.student_id] = plain(result.error or "grader error")[:300]
                continue
            notebook, states = None, {a.grade_id: "unanswered" for a in written}
            if result.status == GRADED and entry.notebook is not None:
                try:
                    notebook, states = formgrader_notebook(entry.notebook, result, stubs, written)
                except (NotebookError, GraderError, OSError) as err:
                    report.skipped.append((name, f"its notebook cannot be read any more: {plain(str(err))}"))
                    continue
            submitters, timestamp = people[name]
            if result.suite_version and result.suite_version != report.suite_now:
                report.other_suite[name] = result.suite_version
            for person in submitters:
                if owner.get(person.student_id, name) != name:
                    continue  # a newer submission names this student too: it is theirs
                keep_names(gb, person)
                place = Path(coursedir.format_path(coursedir.autograded_directory, person.student_id,
                                                   assignment)) / f"{assignment}.ipynb"
                changed = changed_cells(place, notebook) if notebook is not None else set()
                record_submission(gb, assignment, person.student_id, result, stubs, states, timestamp, report,
                                  changed)
                report.recorded.append((name, person.student_id))
                if person.student_id != name and (name, person.student_id) not in report.earlier_ids:
                    try:
                        gb.find_submission(assignment, name)
                        report.earlier_ids.append((name, person.student_id))
                    except MissingEntry:
                        pass
                if notebook is not None:
                    atomic_write(place, nbformat.writes(notebook))
                    report.placed.append(place)
            students[name] = [p.student_id for p in submitters if owner.get(p.student_id, name) == name]
    _write_not_recorded(Path(coursedir.root), assignment, failed, {s for _, s in report.recorded})
    atomic_write(results_dir / STUDENTS_NAME, json.dumps({**read_students(results_dir), **students}, indent=1,
                                                         sort_keys=True))
    return report


# ------------------------------------------------------------------ stub scores a person changed

HandStubs = dict[str, tuple[float | None, float]]
"""Per stub a person changed in formgrader: ``(manual_score or None, extra_credit or 0)``."""


def synced_grades(assignment: str, results_dir: Path, course_root: Path | None = None) -> Iterator[tuple[str, list]]:
    """Per synced submission of ``results_dir``: its name and the grades of its first student's notebook in the
    course's gradebook (nothing before any sync)."""
    from nbgrader.api import MissingEntry

    students = read_students(results_dir)
    if not students:
        return
    with open_gradebook(course_directory(course_root)) as gb:
        for name, ids in students.items():
            try:
                submitted = gb.find_submission_notebook(assignment, assignment, ids[0])
            except (MissingEntry, IndexError):
                continue
            yield name, submitted.grades


def hand_stub_scores(assignment: str, results_dir: Path, course_root: Path | None = None) -> dict[str, HandStubs]:
    """Per synced submission of ``results_dir`` (its first student's grades), the stub scores a person changed
    in formgrader (a score or extra credit on a stub's cell); empty before any sync. ``export`` counts them."""
    out: dict[str, HandStubs] = {}
    for name, grades in synced_grades(assignment, results_dir, course_root):
        changed = {g.name: (g.manual_score, g.extra_credit or 0.0) for g in grades
                   if g.cell_type == "code" and (g.manual_score is not None or g.extra_credit)}
        if changed:
            out[name] = changed
    return out


def hand_stub_delta(stub_scores: dict[str, float], hand: HandStubs) -> float:
    """What the stub scores a person changed add to the automatic score ``sum(stub_scores)`` (as the gradebook
    counts a grade: the person's score where given, else the automatic one, plus extra credit)."""
    return sum((manual if manual is not None else stub_scores.get(stub, 0.0)) + extra - stub_scores.get(stub, 0.0)
               for stub, (manual, extra) in hand.items())
