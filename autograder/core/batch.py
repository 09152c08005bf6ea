"""Grade a folder of submissions in parallel, resumably, into per-submission folders and a gradebook.

Accepted layouts of the input folder: a flat folder of notebooks; nbgrader's
``submitted/<student>/<assignment>/`` (the folder itself or the course root that
holds it); an unzipped Gradescope export (one folder per submission). Each
entry of the folder is one submission, named by its file or folder name.
"""
from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import os
import re
import stat
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator

from autograder.core import course
from autograder.core.grader import Grader
from autograder.core.intake import NotebookError, read_code_cells, walk_notebooks, walk_tree
from autograder.core.notebook import UNTOUCHED_MARK, find_stubs
from autograder.core.results import GRADER_ERROR, UNGRADABLE, GradeResult, GraderError
from autograder.core.store import RESULT_NAME, archive_results, atomic_write, load_result, notebook_digest, save_result

Writer = Callable[[GradeResult, Path], None]
"""Renders one result into its submission's folder (``autograder.outputs.files.render_files``); called in the
grading process, before the core records the result, so it must be a module-level function."""
Progress = Callable[[Iterable, int, str], Iterator]
"""Wraps the finished gradings (items, total, description) to show progress; the core shows none itself."""

GRADEBOOK_NAME = "gradebook.csv"
MANIFEST_PATTERN = "_batch-{k}-of-{n}.json"
"""What a batch (``1-of-1``) or one shard of one graded: the assignment, the suite version, the submissions.
The ``_`` keeps it apart from the submissions' folders (their safe names never start with one)."""


@dataclass(frozen=True)
class Shard:
    """Shard ``k`` of ``n`` (1-based): the submissions whose name hashes to ``k``, for N copies of one command."""
    k: int = 1
    n: int = 1

    @classmethod
    def parse(cls, text: str) -> "Shard":
        """``"K/N"`` with 1 <= K <= N."""
        match = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
        if not match or not 1 <= int(match[1]) <= int(match[2]):
            raise ValueError(f"a shard is K/N with 1 <= K <= N (shard 2 of 3 is 2/3), not {text!r}")
        return cls(int(match[1]), int(match[2]))

    def owns(self, name: str) -> bool:
        """Whether submission ``name`` (its safe name) falls in this shard: a hash of the name, so every
        copy of the command splits a folder the same way, whatever order it lists the folder in."""
        return int.from_bytes(hashlib.sha256(name.encode()).digest()[:8], "big") % self.n == self.k - 1

    @property
    def gradebook_name(self) -> str:
        return GRADEBOOK_NAME if self.n == 1 else f"gradebook-{self.k}-of-{self.n}.csv"

    @property
    def manifest_name(self) -> str:
        return MANIFEST_PATTERN.format(k=self.k, n=self.n)


@dataclass
class Entry:
    name: str
    notebook: Path | None
    note: str = ""
    problem: str = ""
    missing: bool = False
    """nbgrader's layout, and the student's folder lacks this assignment: not a submission at all."""
    handed_in: Path | None = None
    """Where a submission with nothing to grade (``problem``) was found, to notice when it changes."""

    def digest(self) -> str:
        """What this entry holds now, as a result records it (``notebook_sha256``): the notebook's digest, or for a
        submission with nothing to grade, ``folder:`` and a digest of what it holds."""
        if self.notebook is not None:
            return _digest(self.notebook)
        return "folder:" + _contents_digest(self.handed_in) if self.handed_in is not None else ""


def _contents_digest(path: Path, limit: int = 1000) -> str:
    """A digest of what ``path`` holds (names, kinds, sizes and the bytes of regular files), no link followed."""
    digest = hashlib.sha256()
    try:
        top = os.lstat(path)
    except OSError:
        return ""
    items = [(path, top)]
    if stat.S_ISDIR(top.st_mode):
        for folder, dirs, files in walk_tree(path, []):
            for name in sorted(dirs + files):
                try:
                    items.append((Path(folder) / name, os.lstat(Path(folder) / name)))
                except OSError:
                    pass
            if len(items) > limit:
                break
    for item, st in items[:limit]:
        digest.update(f"{item.relative_to(path)}\0{stat.S_IFMT(st.st_mode)}\0{st.st_size}\0".encode("utf-8", "surrogateescape"))
        try:
            if stat.S_ISREG(st.st_mode) and st.st_size <= MAX_DIGESTED_BYTES:
                digest.update(notebook_digest(item).encode())  # a SHA-256 of the file's bytes
            elif stat.S_ISLNK(st.st_mode):
                digest.update(os.fsencode(os.readlink(item)))
        except OSError:  # unreadable: its name, kind and size stand for it
            pass
    return digest.hexdigest()


MAX_DIGESTED_BYTES = 64 * 1024**2
"""Files larger than this count by their size only in a submission's digest."""


_PLAIN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._@-]{0,99}")
_RESERVED = re.compile(r"gradebook", re.IGNORECASE)
"""Names of the batch folder's own files (``gradebook*.csv``); its other files start with ``_``."""
HASH_MARK = "+"
"""Joins a made-safe name to the digest of the name it came from; no name kept as it is contains it."""


def safe_name(name: str) -> str:
    """The folder name of submission ``name``, from that name alone (so no classmate's name can change it).

    A plain name (letters, digits, ``._@-``, at most 100 characters, not the batch's own ``gradebook*``) is
    kept as it is; any other is made safe and marked with a digest of the original: ``alice smith`` becomes
    ``alice_smith+3f9a61c2``, which no plain name can equal (plain names have no ``+``).
    """
    if _PLAIN.fullmatch(name) and not name.endswith(".") and not _RESERVED.match(name):
        return name
    base = re.sub(r"[^A-Za-z0-9._@-]+", "_", name).strip("._-")[:60] or "submission"
    digest = hashlib.sha256(name.encode("utf-8", "surrogateescape")).hexdigest()[:8]
    return f"{base}{HASH_MARK}{digest}"


def unique_safe_names(names: list[str]) -> list[str]:
    """:func:`safe_name` of each name: unique by construction (distinct names give distinct safe names,
    case-sensitively), the same on every run and whatever else the folder holds."""
    return [safe_name(n) for n in names]


def notebooks_in(folder: Path) -> tuple[list[Path], list[str]]:
    """The notebooks of a submission folder, found without following links, and what was skipped (why)."""
    return walk_notebooks(folder)


SEVERAL_NOTEBOOKS = "several notebooks were submitted"
"""How the note of a submission with several notebooks starts (the batch's summary names those submissions)."""


def choose_notebook(name: str, notebooks: list[Path], assignment: str, expected: list[str],
                    skipped: list[str] = ()) -> Entry:
    """The notebook to grade among a submission's ``notebooks``; ``skipped`` are the files left out (links)."""
    skipped_note = ("left out: " + "; ".join(skipped[:5]) + (f" and {len(skipped) - 5} more" if len(skipped) > 5 else "")
                    if skipped else "")
    if not notebooks:
        return Entry(name, None, problem="no notebook (.ipynb) in this submission"
                     + (f" ({skipped_note})" if skipped_note else ""))
    if len(notebooks) == 1:
        return Entry(name, notebooks[0], note=skipped_note)

    def mtime(path: Path) -> float:
        try:
            return os.lstat(path).st_mtime
        except OSError:
            return 0.0

    def progress(path: Path) -> tuple[int, int, bool, float]:
        """Stubs done (found and no longer raising NotImplementedError), stubs found, named after the assignment,
        modified last: students who work in a copy (``hw0_setup-Copy1.ipynb``) hand in the released file too.
        A notebook over :data:`MAX_WEIGHED_BYTES` is ranked by its name and time only."""
        try:
            found = find_stubs(read_code_cells(path, cap=MAX_WEIGHED_BYTES)[0], expected)[0]
        except (NotebookError, GraderError):
            return (-1, -1, path.stem == assignment, mtime(path))
        done = sum(UNTOUCHED_MARK not in m.source for m in found.values())
        return (done, len(found), path.stem == assignment, mtime(path))

    # Every run of a batch chooses again, so a folder of a thousand notebooks must not cost minutes each time:
    # only the likeliest few are opened (the assignment's name first, then the newest).
    weighed = sorted(notebooks, key=lambda p: (p.stem == assignment, mtime(p)), reverse=True)[:MAX_WEIGHED]
    chosen = max(weighed, key=progress)
    others = [p.name for p in notebooks if p != chosen]
    listed = ", ".join(others[:5]) + (f" and {len(others) - 5} more" if len(others) > 5 else "")
    how = ("the one with the most stubs done" if len(weighed) == len(notebooks) else
           f"the one with the most stubs done among the {MAX_WEIGHED} newest (the assignment's name first)")
    note = f"{SEVERAL_NOTEBOOKS}; graded {chosen.name}, {how} (not {listed})"
    return Entry(name, chosen, note=note + (f"; {skipped_note}" if skipped_note else ""))


MAX_WEIGHED = 10
"""At most this many of a submission's notebooks are opened to choose the one to grade."""
MAX_WEIGHED_BYTES = 8 * 1024**2
"""A notebook over this size is not opened to choose among several (it is ranked by name and time)."""


def grade_upload(assignment: str, folder: Path, hide: list[Path] = ()) -> GradeResult:
    """Grade the one submission uploaded into ``folder``, as a hosted grader (Gradescope, PrairieLearn) lays it out.

    The notebook is chosen as :func:`choose_notebook` chooses; links in the upload are named, never followed.
    Raises :class:`GraderError` when the grader cannot be built; a fault while grading comes back as a result
    of status ``grader_error``.
    """
    notebooks, skipped = notebooks_in(folder)
    entry = choose_notebook("submission", notebooks, assignment, course.stub_names(assignment), skipped)
    grader = Grader(assignment, hide=hide)
    try:
        if entry.notebook is None:
            return grader.ungradable("submission", entry.problem)
        result = grader.grade(entry.notebook, name=entry.notebook.name)
    finally:
        grader.close()
    if entry.note:
        result.notes.insert(0, entry.note)
    return result.make_encodable()


def _nbgrader_layout(folder: Path, assignment: str) -> bool:
    """Whether ``folder`` (already ``submitted/`` if the course root was given) is nbgrader's
    ``<student>/<assignment>/`` layout: its name says so, or it holds folders only (no notebook, no Gradescope
    metadata) and at least half of them hold an assignment's folder, so that one student's zipped folder
    cannot turn a class into it."""
    if folder.name == "submitted":
        return True
    if (folder / "submission_metadata.yml").exists() or any(folder.glob("*.ipynb")):
        return False  # a Gradescope export, or a flat folder of notebooks (some of them students' folders)
    known = set(course.assignment_ids()) | {assignment}
    students = _student_folders(folder)
    with_assignments = sum(any((child / name).is_dir() for name in known) for child in students)
    return bool(students) and 2 * with_assignments >= len(students)


def _student_folders(folder: Path) -> list[Path]:
    return [c for c in sorted(folder.iterdir()) if not c.name.startswith(".") and c.is_dir() and not c.is_symlink()]


def submissions_folder(folder: Path) -> Path:
    """The folder whose entries are the submissions: ``folder``, or its ``submitted/`` (nbgrader's course root)."""
    folder = Path(folder)
    if not folder.is_dir():
        raise SystemExit(f"{folder} is not a folder of submissions")
    return folder / "submitted" if (folder / "submitted").is_dir() else folder


def missing_submissions(folder: Path, assignment: str) -> list[str]:
    """The students of nbgrader's layout who handed in no ``<assignment>/`` folder (their folder holds
    other assignments only): they are not graded, recorded or counted, only named. Empty in other layouts."""
    folder = submissions_folder(folder)
    if not _nbgrader_layout(folder, assignment):
        return []
    return [c.name for c in _student_folders(folder) if not os.path.lexists(c / assignment)]


def stray_files(folder: Path) -> list[str]:
    """The files handed in beside the submissions that are not notebooks (``alice.py``, ``bob.zip``): a submission
    is a notebook or a folder, so these are not graded, recorded or counted, only named."""
    folder = submissions_folder(folder)
    return [c.name for c in sorted(folder.iterdir()) if not c.name.startswith(".") and c.suffix.lower() != ".ipynb"
            and c.name != "submission_metadata.yml" and stat.S_ISREG(os.lstat(c).st_mode)]


def _other_assignments_only(notebooks: list[Path], assignment: str, chosen: Path | None, expected: list[str]) -> str:
    """A problem to report when every notebook submitted is named after another assignment and the one chosen
    defines none of this assignment's stubs (this assignment's work saved under another name is graded), else ``""``."""
    others = set(course.assignment_ids()) - {assignment}
    if notebooks and all(p.stem in others for p in notebooks):
        try:
            if chosen is not None and find_stubs(read_code_cells(chosen)[0], expected)[0]:
                return ""
        except (NotebookError, GraderError):
            pass
        names = ", ".join(sorted({p.name for p in notebooks})[:5])
        return (f"the submission holds only another assignment's notebook ({names}), not {assignment}.ipynb: "
                "was it handed in to the wrong assignment?")
    return ""


def _merge_same_names(entries: list[Entry], assignment: str, expected: list[str]) -> list[Entry]:
    """One entry per name: ``alice.ipynb`` beside a folder ``alice/`` (or ``alice.IPYNB``) is one student who handed
    in twice, graded from the notebook :func:`choose_notebook` picks among them, with a note; two entries of one
    name would share a result folder, the last written winning and every later run grading both again."""
    by_name: dict[str, list[Entry]] = {}
    for entry in entries:
        by_name.setdefault(entry.name, []).append(entry)
    merged = []
    for name, same in by_name.items():
        if len(same) == 1:
            merged.append(same[0])
            continue
        notebooks = [e.notebook for e in same if e.notebook is not None]
        if not notebooks:
            merged.append(same[0])
            continue
        entry = choose_notebook(name, notebooks, assignment, expected)
        twice = f"handed in {len(same)} times under this name (a notebook and a folder, say)"
        entry.note = f"{entry.note}; {twice}" if entry.note else f"{twice}; graded {entry.notebook.name}"
        merged.append(entry)
    return merged


def discover(folder: Path, assignment: str, expected: list[str]) -> list[Entry]:
    """One entry per submission in ``folder`` (see the module docstring for the layouts).

    Nothing a student submitted is followed if it is a link: a submission that is one, or a
    notebook that is not a regular file, is listed with its reason and graded as nothing. In
    nbgrader's layout a student without this assignment's folder has no entry at all
    (:func:`missing_submissions` names them); a notebook is only ever taken from ``<student>/<assignment>/``.
    """
    folder = submissions_folder(folder)
    nbgrader = _nbgrader_layout(folder, assignment)
    entries = []
    for child in sorted(folder.iterdir()):
        if child.name.startswith(".") or child.name in ("submission_metadata.yml",):
            continue
        mode = os.lstat(child).st_mode
        notebook = child.suffix.lower() == ".ipynb"  # alice.IPYNB too
        if stat.S_ISLNK(mode):
            if notebook or child.is_dir():
                stem = child.stem if notebook else child.name
                entries.append(Entry(stem, None, problem=f"{child.name} is a symbolic link: the grader does not follow links",
                                     handed_in=child))
        elif notebook and not stat.S_ISDIR(mode):
            if stat.S_ISREG(mode):
                entries.append(Entry(child.stem, child))
            else:
                entries.append(Entry(child.stem, None, problem=f"{child.name} is not a regular file: it was not read",
                                     handed_in=child))
        elif stat.S_ISDIR(mode):
            inner = child / assignment
            if os.path.islink(inner):
                entries.append(Entry(child.name, None, problem=f"{child.name}/{assignment} is a symbolic link: "
                                                               "the grader does not follow links", handed_in=inner))
                continue
            if nbgrader and not inner.is_dir():
                entries.append(Entry(child.name, None, missing=True))
                continue
            where = inner if inner.is_dir() else child
            try:
                notebooks, skipped = notebooks_in(where)
                entry = choose_notebook(child.name, notebooks, assignment, expected, skipped)
                problem = _other_assignments_only(notebooks, assignment, entry.notebook, expected)
            except (OSError, RecursionError, ValueError) as err:  # one odd folder is its student's problem only
                entry = Entry(child.name, None)
                problem = f"the submission's folder could not be searched ({type(err).__name__})"
            entry = Entry(child.name, None, note=entry.note, problem=problem) if problem else entry
            if entry.notebook is None:
                entry.handed_in = where
            entries.append(entry)
    entries = _merge_same_names(entries, assignment, expected)
    # Names are made unique over every student folder, handed in or not, so they never shift when one hands in.
    for entry, name in zip(entries, unique_safe_names([e.name for e in entries])):
        entry.name = name
    return [e for e in entries if not e.missing]


# ------------------------------------------------------------------ worker processes

_grader: Grader | None = None
_grader_failure: str | None = None
_grader_of: str | None = None
"""The assignment this process's grader (or its failure to build) is for."""
_hide_by_assignment: dict[str, list[str]] | None = None
"""Set when this process grades several assignments: what each one hides; its grader is then built on demand."""


def _build(assignment: str, hide: list[str]) -> None:
    global _grader, _grader_failure, _grader_of
    if _grader is not None:  # one grader at a time: its zygote and reference go before the next is built
        _grader.close()
        _grader = None
    _grader_failure, _grader_of = None, assignment
    try:
        _grader = Grader(assignment, hide=[Path(h) for h in hide])
    except GraderError as err:  # every submission this process takes is then a grader error
        _grader_failure = str(err)


def _init(assignment: str, hide: list[str]) -> None:
    _build(assignment, hide)


def _init_many(hide_by_assignment: dict[str, list[str]]) -> None:
    """A process of a batch over several assignments: it imports the grader's modules once, and builds each
    assignment's grader when its first submission of that assignment comes (they come in assignment order)."""
    global _hide_by_assignment
    _hide_by_assignment = hide_by_assignment


def _finish(result: GradeResult, folder: Path, write: Writer | None) -> None:
    """Hand ``result`` to the writer, then record it: the record, written last, marks the submission done."""
    result.make_encodable()
    if write is not None:
        write(result, folder)
    save_result(result, folder)


def _grade_one(entry: Entry, out_dir: str, assignment: str, write: Writer | None) -> str:
    if _hide_by_assignment is not None and _grader_of != assignment:
        _build(assignment, _hide_by_assignment[assignment])
    if _grader is None:
        result = _unscored(assignment, entry, _grader_failure or "the grader could not be built", GRADER_ERROR)
    else:
        digest = _digest(entry.notebook)  # before grading: the record names the notebook that was read
        result = _grader.grade(entry.notebook, name=entry.name)
        result.notebook_sha256 = digest
    if entry.note:
        result.notes.insert(0, entry.note)
    _finish(result, Path(out_dir) / entry.name, write)
    return entry.name


def _load(out_dir: Path, name: str) -> GradeResult | None:
    return load_result(out_dir / name)


def _done(out_dir: Path, name: str) -> bool:
    """Graded (or ungradable) already; a grader error is retried on every run until it grades."""
    result = _load(out_dir, name)
    return result is not None and result.status != GRADER_ERROR


def _digest(path: Path | None) -> str:
    """The notebook's digest; for one the grader cannot read, one of its size, time and inode (stable while the
    file is, so an unreadable notebook is not graded again on every run)."""
    if path is None:
        return ""
    try:
        return notebook_digest(path)
    except OSError:
        try:
            st = os.lstat(path)
        except OSError:
            return ""
        return f"unreadable:{st.st_size}:{st.st_mtime_ns}:{st.st_ino}"


def _handed_in_anew(out_dir: Path, entries: list[Entry]) -> list[Entry]:
    """The entries whose recorded result graded another notebook than the one there now, or found nothing to grade
    where the submission now holds something else (a student who handed in again after the batch ran): their
    results are archived in ``_previous/`` and they are graded again, each with a note saying so. Graded results
    older than the recorded digest are taken as they are."""
    changed = []
    for e in entries:
        old = _load(out_dir, e.name)
        if old is None or old.status == GRADER_ERROR:
            continue
        if old.notebook_sha256:
            if old.notebook_sha256 != e.digest():
                changed.append((e, old))
        elif old.status == UNGRADABLE and (e.notebook is not None or (e.problem or None) != old.error):
            changed.append((e, old))  # recorded before such results had a digest: it holds something else now
    if not changed:
        return []
    kept = archive_results(out_dir, [e.name for e, _ in changed], [GRADEBOOK_NAME])
    for e, old in changed:
        score = f"{old.score:g}/{old.max_score:g}" if old.has_score else old.status
        what = "this notebook is not the one" if e.notebook is not None and old.notebook_sha256[:7] != "folder:" \
            else "the submission does not hold what it held when it was"
        note = (f"graded again: {what} graded before (that grading, {score}, is kept in "
                f"{kept.relative_to(out_dir).as_posix()}/)")
        e.note = f"{note}; {e.note}" if e.note else note
        (out_dir / e.name / RESULT_NAME).unlink(missing_ok=True)
    return [e for e, _ in changed]


def _unscored(assignment: str, entry: Entry, reason: str, status: str) -> GradeResult:
    """A result with no tests run: ``ungradable`` (the submission's fault) or ``grader_error`` (ours)."""
    return GradeResult(assignment, entry.name, [], [], [entry.note] if entry.note else [], reason, status=status,
                       suite_version=course.suite_version(assignment))


def handed_in_anew(out_dir: Path, shard: Shard = Shard()) -> list[str]:
    """The submissions the last run of ``shard``'s batch into ``out_dir`` graded again because their notebook had
    changed since an earlier run graded it (from the batch's manifest; empty when there is none)."""
    try:
        return list(json.loads((Path(out_dir) / shard.manifest_name).read_text(encoding="utf-8"))["handed_in_anew"])
    except (OSError, ValueError, KeyError, TypeError):
        return []


def names_digest(names: list[str]) -> str:
    """One digest of a folder's submission names: shards that saw different folders are never merged."""
    return hashlib.sha256("\0".join(sorted(names)).encode()).hexdigest()[:16]


def write_manifest(out_dir: Path, assignment: str, shard: Shard, all_names: list[str], names: list[str],
                   missing: list[str] = (), handed_in_anew: list[str] = ()) -> None:
    manifest = {"assignment": assignment, "suite_version": course.suite_version(assignment),
                "shard": [shard.k, shard.n], "folder_submissions": len(all_names),
                "folder_digest": names_digest(all_names), "submissions": sorted(names),
                "missing": sorted(missing), "handed_in_anew": sorted(handed_in_anew)}
    out_dir.mkdir(parents=True, exist_ok=True)
    atomic_write(out_dir / shard.manifest_name, json.dumps(manifest, indent=1))


@dataclass(frozen=True)
class Batch:
    """One assignment's part of a batch: its submissions' folder, its output folder, its shard."""
    assignment: str
    folder: Path
    out_dir: Path
    shard: Shard = Shard()


def _prepare(batch: Batch, write: Writer | None) -> tuple[list[Entry], list[Entry]]:
    """Discover ``batch``'s submissions, write its manifest and the results of those with nothing to grade:
    its entries, and those still to grade."""
    out_dir, assignment, shard = Path(batch.out_dir), batch.assignment, batch.shard
    course.check_assignment(assignment)
    expected = course.stub_names(assignment)
    entries = discover(batch.folder, assignment, expected)
    all_names = [e.name for e in entries]
    entries = [e for e in entries if shard.owns(e.name)]
    anew = _handed_in_anew(out_dir, entries)
    write_manifest(out_dir, assignment, shard, all_names, [e.name for e in entries],
                   [m for m in missing_submissions(batch.folder, assignment) if shard.owns(m)], [e.name for e in anew])
    todo = [e for e in entries if e.notebook is not None and not _done(out_dir, e.name)]
    for e in entries:
        if e.notebook is None and not _done(out_dir, e.name):
            result = _unscored(assignment, e, e.problem, UNGRADABLE)
            result.notebook_sha256 = e.digest()
            _finish(result, out_dir / e.name, write)
    return entries, todo


def _hide(batch: Batch) -> list[str]:
    """Classmates' notebooks and the results are hidden from the sandbox even inside a released folder."""
    return [str(Path(batch.folder).resolve()), str(Path(batch.out_dir).resolve())]


def _grade(tasks: list[tuple[Batch, Entry]], write: Writer | None, jobs: int, progress: Progress | None,
           description: str, initializer: Callable, initargs: tuple) -> None:
    """Grade every (batch, entry) in a pool of ``jobs`` processes, retrying what a dying process left undone."""
    todo = list(tasks)
    attempts = 0
    while todo and attempts < 3:
        attempts += 1
        try:
            with ProcessPoolExecutor(max(1, jobs), mp_context=mp.get_context("spawn"), initializer=initializer,
                                     initargs=initargs) as pool:
                futures = {pool.submit(_grade_one, e, str(b.out_dir), b.assignment, write): (b, e) for b, e in todo}
                finished = as_completed(futures)
                if progress is not None:
                    finished = progress(finished, len(futures), description)
                for future in finished:
                    batch, entry = futures[future]
                    try:
                        future.result()
                    except BrokenProcessPool:
                        raise
                    except Exception as err:  # noqa: BLE001 - a grader bug must not drop the submission, nor grade it
                        _finish(_unscored(batch.assignment, entry, f"internal grader error: {err}", GRADER_ERROR),
                                Path(batch.out_dir) / entry.name, write)
        except BrokenProcessPool:
            pass  # a grading process died; the finished results are on disk, retry the rest
        todo = [(b, e) for b, e in todo if _load(Path(b.out_dir), e.name) is None]
    for batch, e in todo:
        _finish(_unscored(batch.assignment, e, "the grading process died repeatedly on this submission", GRADER_ERROR),
                Path(batch.out_dir) / e.name, write)


def run_batch(assignment: str, folder: Path, out_dir: Path, *, write: Writer | None = None, jobs: int = 2,
              progress: Progress | None = None, shard: Shard = Shard()) -> list[GradeResult]:
    """Grade every submission (of ``shard``) not yet graded in ``out_dir``; the results of them all, by name.

    Each result is handed to ``write`` (if given) and recorded in ``out_dir/<name>/result.json``; a shard
    writes its own manifest, so N shards may share one ``out_dir`` on a shared disk or each have their own.
    The gradebook is the writers' (``autograder.outputs.files.grade_folder`` writes one).
    """
    batch = Batch(assignment, Path(folder), Path(out_dir), shard)
    entries, todo = _prepare(batch, write)
    if todo:
        _grade([(batch, e) for e in todo], write, jobs, progress, f"grading {assignment}", _init,
               (assignment, _hide(batch)))
    return [r for e in entries if (r := _load(batch.out_dir, e.name)) is not None]


def run_batches(batches: list[Batch], *, write: Writer | None = None, jobs: int = 2,
                progress: Progress | None = None) -> dict[str, list[GradeResult]]:
    """:func:`run_batch` for several assignments in one pool of processes: each process imports the grader
    once (the start-up a batch per assignment pays again for each), and builds an assignment's grader when
    the first of its submissions comes; submissions go in assignment order, so that is about once each.
    The results of each assignment, by assignment."""
    if len({b.assignment for b in batches}) != len(batches):
        raise ValueError("each assignment once in a batch of several")
    prepared = [(b, *_prepare(b, write)) for b in batches]
    tasks = [(b, e) for b, _, todo in prepared for e in todo]
    if tasks:
        names = [b.assignment for b in batches if any(t[0] is b for t in tasks)]
        _grade(tasks, write, jobs, progress, "grading " + ", ".join(names), _init_many,
               ({b.assignment: _hide(b) for b in batches},))
    return {b.assignment: [r for e in entries if (r := _load(b.out_dir, e.name)) is not None]
            for b, entries, _ in prepared}


def assignment_folder(folder: Path, assignment: str) -> Path:
    """Where ``assignment``'s submissions lie in a batch over several: ``folder/<assignment>/`` when it holds
    notebooks (whatever ``folder`` is called: nbgrader never puts a notebook straight in a student's folder);
    else nbgrader's layout holds every assignment (``submitted/<student>/<assignment>/``), so ``folder`` itself."""
    folder = Path(folder)
    inner = submissions_folder(folder)
    if (folder / assignment).is_dir() and any((folder / assignment).glob("*.ipynb")):
        return folder / assignment  # notebooks in <assignment>/, even in a folder called submitted/
    if inner.name == "submitted" or (_nbgrader_layout(inner, assignment) and not (folder / assignment).is_dir()):
        return folder
    if (folder / assignment).is_dir():
        return folder / assignment
    raise SystemExit(f"{folder} is neither nbgrader's layout (submitted/<student>/<assignment>/) nor holds a folder "
                     f"{assignment}/ of submissions")


def assignments_in(folder: Path) -> list[str]:
    """The gradable assignments that some student handed in, in nbgrader's layout under ``folder`` (or with a
    folder of their own in it), in course order."""
    folder = Path(folder)
    inner = submissions_folder(folder)
    gradable = [a for a in course.assignment_ids() if course.suite_dir(a).is_dir()]
    students = _student_folders(inner)
    return [a for a in gradable if (folder / a).is_dir() or any((s / a).is_dir() for s in students)]
