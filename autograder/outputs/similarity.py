"""Pairs of submissions whose stub code is suspiciously alike, for an instructor to look at; never a grade.

Only the code of the stub cells is compared (matched as grading matches them, by
:func:`autograder.core.notebook.find_stubs` on what :func:`autograder.core.intake.read_code_cells` read safely
in a child process), joined in the assignment's stub order, so moving cells around changes nothing.
Fingerprints come from ``copydetect`` (winnowing over Pygments tokens, as MOSS does): names become
one placeholder and comments, docstrings and whitespace are dropped before hashing, so renaming
variables, reordering functions and adding comments leave a copy's fingerprints in place; the
k-grams are hashed by a fixed function, so a report is the same on every run. Every fingerprint of
the released notebook's code (the stub skeletons, the setup cells, the public checks) is
boilerplate and never counts, so an untouched stub matches nothing.
"""
from __future__ import annotations

import hashlib
import html
import re
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from copydetect import compare_files
from copydetect.utils import filter_code, get_token_coverage, highlight_overlap, winnow
from pygments.lexers import PythonLexer
from pygments.token import String

from autograder.core import course
from autograder.core.batch import discover
from autograder.core.intake import NotebookError, read_code_cells
from autograder.core.notebook import find_stubs, read_notebook
from autograder.core.results import GraderError

NOISE_TOKENS = 25
"""Matches shorter than this many filtered characters are ignored (copydetect's ``noise_t``)."""
GUARANTEE_TOKENS = 30
"""Matches at least this long are always found (copydetect's ``guarantee_t``); the winnowing window follows."""
THRESHOLD = 0.6
"""A pair is flagged when both submissions share at least this fraction of their own fingerprinted code."""
MIN_SHARED = 60
"""...and the shared fragments cover at least this many filtered characters (a few short lines never flag)."""
MAX_STUB_CHARS = 20_000
"""A stub's code is compared up to this many characters (the longest solution stub cell has about 3,000): cells
padded to the grader's 1 MB cap would otherwise cost seconds of tokenising and hashing, and every comparison
with them more."""
NEVER_A_GRADE = ("This list never changes a grade. Similar code is a reason to read two submissions side by side, "
                 "not evidence of copying: short stubs, the lecture's formulas and shared starter code make honest "
                 "solutions alike.")


@dataclass
class StubCode:
    """One submission's stub code as compared: ``code`` (empty when nothing was read) and why, if so."""

    name: str
    code: str
    problem: str = ""


@dataclass
class Pair:
    """Two flagged submissions: the fraction of each one's code found in the other, and where (slices)."""

    a: str
    b: str
    similarity_a: float
    similarity_b: float
    shared: int
    slices_a: np.ndarray
    slices_b: np.ndarray


def without_docstrings(source: str) -> str:
    """``source`` without its docstrings (a triple-quoted string opening a line, Pygments' ``String.Doc``) and
    the indented lines they leave blank. The release's docstrings are boilerplate, but a match that starts
    or ends beside one would mark the whole docstring on the side-by-side page (a string is one token)."""
    kept = "".join(text for kind, text in PythonLexer().get_tokens(source) if kind not in String.Doc)
    return re.sub(r"(?m)^[ \t]+\n", "", kept)


def compared_part(source: str) -> str:
    """The first :data:`MAX_STUB_CHARS` of ``source`` once its comment lines and the comments ending lines without
    quotes are dropped (a fast regex, before the cap): padding a copied stub with 20,000 characters of comments
    otherwise pushed its code past the cap, and the copy went unflagged."""
    source = re.sub(r"(?m)^[ \t]*#.*(?:\n|$)", "", source)
    source = re.sub(r"(?m)^([^'\"#\n]*?)[ \t]*#.*$", r"\1", source)
    return source[:MAX_STUB_CHARS]


def joined_stubs(sources: dict[str, str], stubs: list[str]) -> str:
    """The stub sources in the assignment's order, docstrings left out, each under a comment naming it
    (comments are not compared); a cell matched for several stubs (one cell defining them all) is shown once."""
    seen: set[str] = set()
    parts = []
    for stub in stubs:
        source = sources.get(stub)
        if source is not None and source not in seen:
            seen.add(source)
            parts.append(f"# ---- {stub}\n{without_docstrings(source).rstrip()}\n")
    return "\n".join(parts)


def _read_one(name: str, notebook: Path | None, problem: str, stubs: list[str]) -> StubCode:
    if notebook is None:
        return StubCode(name, "", problem or "no notebook")
    try:
        nb, _ = read_code_cells(notebook)
    except (NotebookError, GraderError) as err:
        return StubCode(name, "", f"could not read the notebook: {err}")
    found, _ = find_stubs(nb, stubs)
    return StubCode(name, joined_stubs({s: compared_part(m.source) for s, m in found.items() if not m.problem},
                                       stubs))


def read_stub_code(assignment: str, folder: Path, jobs: int = 2) -> list[StubCode]:
    """Each submission's stub code, named as ``batch`` names it (so it matches the result folders)."""
    stubs = course.stub_names(assignment)
    entries = discover(folder, assignment, stubs)
    with ThreadPoolExecutor(max(jobs, 1)) as pool:  # each read runs in its own child process
        return list(pool.map(lambda e: _read_one(e.name, e.notebook, e.problem, stubs), entries))


def release_code(assignment: str) -> str:
    """The boilerplate that never counts as shared: every code cell of the student release, and its stubs joined
    as a submission's are (an untouched stub's end followed by the next one's start is not in the release)."""
    nb = read_notebook(course.release_notebook(assignment))
    stubs = course.stub_names(assignment)
    skeletons = {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
                 if c.cell_type == "code" and c.metadata.get("nbgrader", {}).get("grade_id") in stubs}
    return "\n".join([*(without_docstrings(c.source) for c in nb.cells if c.cell_type == "code"),
                      joined_stubs(skeletons, stubs)])


@dataclass
class Fingerprint:
    """What ``copydetect.compare_files`` reads of a document: its winnowed k-gram hashes and where they are."""

    filtered_code: str
    offsets: np.ndarray
    hashes: set[int]
    hash_idx: dict[int, list[int]]
    k: int
    token_coverage: int


def kgram_hashes(text: str, k: int) -> np.ndarray:
    """A 64-bit hash of every k-character window of ``text``, the same in every process.

    copydetect hashes with Python's ``hash``, which is salted per process: the winnowed fingerprints, so the
    figures, would change from one run of the report to the next.
    """
    return np.array([int.from_bytes(hashlib.blake2b(text[i:i + k].encode(), digest_size=8).digest(), "little",
                                    signed=True) for i in range(len(text) - k + 1)], dtype=np.int64)


def fingerprint(code: str, boilerplate: np.ndarray | None = None, window: int | None = None) -> Fingerprint:
    """Tokenise ``code`` as Python with copydetect's filter (names to one letter, no comments or spacing), hash its
    k-grams, winnow them (copydetect's robust winnowing) and drop those in ``boilerplate``."""
    window = GUARANTEE_TOKENS - NOISE_TOKENS + 1 if window is None else window
    filtered, offsets = filter_code(code, "submission.py", "python")
    all_hashes = kgram_hashes(filtered, NOISE_TOKENS)
    hashes, idx = winnow(all_hashes, window, remove_duplicates=False) if len(all_hashes) else (all_hashes, all_hashes)
    if boilerplate is not None and len(boilerplate):
        keep = ~np.isin(hashes, boilerplate)
        hashes, idx = hashes[keep], idx[keep]
    where: dict[int, list[int]] = {}
    for h, i in zip(hashes.tolist(), idx.tolist()):
        where.setdefault(h, []).append(i)
    coverage = int(get_token_coverage(where, NOISE_TOKENS, len(filtered)))
    return Fingerprint(filtered, offsets, set(where), where, NOISE_TOKENS, coverage)


def boilerplate_hashes(code: str) -> np.ndarray:
    """Every k-gram hash of ``code`` (no winnowing), as copydetect takes boilerplate."""
    return np.array(sorted(fingerprint(code, window=1).hashes), dtype=np.int64)


def similar_pairs(codes: list[StubCode], boilerplate: str, threshold: float = THRESHOLD,
                  min_shared: int = MIN_SHARED) -> tuple[list[Pair], list[tuple[str, str, float, float]]]:
    """The flagged pairs, most similar first, and every compared pair's similarities (for the record).

    Submissions whose stub code has no fingerprint left once the boilerplate is removed (untouched
    stubs, say) are compared with nothing.
    """
    skip = boilerplate_hashes(boilerplate)
    prints = [(c.name, fingerprint(c.code, skip)) for c in codes if c.code.strip()]
    prints = [(name, fp) for name, fp in prints if fp.token_coverage > 0]
    flagged, scores = [], []
    for i, (name_a, fp_a) in enumerate(prints):
        for name_b, fp_b in prints[i + 1:]:
            if not fp_a.hashes & fp_b.hashes:
                scores.append((name_a, name_b, 0.0, 0.0))
                continue
            shared, (sim_a, sim_b), (slices_a, slices_b) = compare_files(fp_a, fp_b)
            scores.append((name_a, name_b, float(sim_a), float(sim_b)))
            if min(sim_a, sim_b) >= threshold and shared >= min_shared:
                flagged.append(Pair(name_a, name_b, float(sim_a), float(sim_b), int(shared), slices_a, slices_b))
    flagged.sort(key=lambda p: (-min(p.similarity_a, p.similarity_b), p.a, p.b))
    return flagged, scores


def _marked(code: str, slices: np.ndarray) -> str:
    if slices.size == 0:
        return html.escape(code)
    shown, _ = highlight_overlap(code, slices, "<mark>", "</mark>", escape_html=True)
    return shown


PAIR_STYLE = ("body{font-family:system-ui,sans-serif;margin:1.5em}.cols{display:flex;gap:1em}"
              ".cols>div{flex:1;min-width:0}pre{background:#f6f6f6;padding:.6em;overflow-x:auto;font-size:.85em}"
              "mark{background:#ffd54f}.note{border-left:4px solid #888;padding-left:.8em;color:#333}")


def pair_page(assignment: str, pair: Pair, code_a: str, code_b: str) -> str:
    """A self-contained HTML page: both submissions' stub code side by side, the shared fragments marked."""
    a, b = html.escape(pair.a), html.escape(pair.b)
    return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(assignment)}: {a} and {b}</title>"
            f"<style>{PAIR_STYLE}</style></head><body><h1>{html.escape(assignment)}: {a} and {b}</h1>"
            f"<p class='note'>{html.escape(NEVER_A_GRADE)}</p>"
            f"<p>{pair.similarity_a:.0%} of {a}'s compared code is found in {b}'s; {pair.similarity_b:.0%} of "
            f"{b}'s in {a}'s. Marked: the fragments they share once the released notebook's code is set aside "
            "(names, comments and spacing are ignored when matching, so a marked fragment may read differently "
            "on each side).</p><div class='cols'>"
            f"<div><h2>{a}</h2><pre>{_marked(code_a, pair.slices_a)}</pre></div>"
            f"<div><h2>{b}</h2><pre>{_marked(code_b, pair.slices_b)}</pre></div>"
            "</div><p><a href='../report.html'>back to the class report</a></p></body></html>")
