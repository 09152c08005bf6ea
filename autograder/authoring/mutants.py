"""Mutation testing of the hidden suites: how many deliberate bugs in each solution stub they catch.

``python -m autograder mutants ID`` (or ``make mutants ID=<id>``) takes each stub's solution, makes
small wrong versions of it (mutants), grades each with that stub's hidden tests and runs its public
check on it, and writes per stub: mutants, killed by the suite, killed by the public check, and the
survivors with their diffs (``build/mutants/<id>/report.md`` and ``report.json``).

The mutator is this module's own, on Python's ``ast``: mutmut and cosmic-ray mutate importable module
files and run a test command per mutant, while a stub lives in a notebook cell and is graded through
the sandboxed grader, which is slow to start (a fresh interpreter, the reference solution) and must
be reused across mutants. Operators (each applied at one place at a time, inside the solution
region only): arithmetic swapped (+/-, * and /, ** to *), comparisons flipped or loosened, a unary
minus dropped, ``not`` dropped, ``and``/``or`` and ``&``/``|`` swapped, integer constants off by
one and float constants changed, ``axis``/``dim`` arguments moved, reductions swapped (sum/mean,
max/min, argmax/argmin), slice bounds shifted by one, and ``torch.where``/``np.where`` replaced by
its first branch (a dropped mask).

A mutant is *killed* when the stub loses points or its public check fails. A survivor is either a
gap in the suite (add a test) or equivalent to the solution: list it with its reason in
``autograder/suites/<id>/equivalent_mutants.json`` as ``{"<stub>": {"<mutant id>": "<reason>"}}``;
the kill rate counts only the mutants not listed there.
"""
from __future__ import annotations

import ast
import contextlib
import copy
import difflib
import io
import json
import multiprocessing
import random
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Iterator

import nbformat

from autograder.core import course
from autograder.core.notebook import read_notebook

MARKERS = ("### BEGIN SOLUTION", "### END SOLUTION")
EQUIVALENT_FILE = "equivalent_mutants.json"
PUBLIC_CHECK_SECONDS = 60.0

_BINOP_SWAPS = {ast.Add: ast.Sub, ast.Sub: ast.Add, ast.Mult: ast.Div, ast.Div: ast.Mult, ast.Pow: ast.Mult,
                ast.FloorDiv: ast.Div, ast.BitAnd: ast.BitOr, ast.BitOr: ast.BitAnd, ast.MatMult: ast.Mult}
_CMP_SWAPS = {ast.Lt: ast.LtE, ast.LtE: ast.Lt, ast.Gt: ast.GtE, ast.GtE: ast.Gt, ast.Eq: ast.NotEq,
              ast.NotEq: ast.Eq, ast.Is: ast.IsNot, ast.IsNot: ast.Is, ast.In: ast.NotIn, ast.NotIn: ast.In}
_REDUCTIONS = {"sum": "mean", "mean": "sum", "max": "min", "min": "max", "argmax": "argmin", "argmin": "argmax",
               "maximum": "minimum", "minimum": "maximum", "amax": "amin", "amin": "amax", "logsumexp": "max"}
_AXIS_KEYWORDS = {"axis", "dim"}


@dataclass
class Mutant:
    """One wrong version of a stub: where and how it differs from the solution."""
    stub: str
    id: str
    operator: str
    line: int
    source: str
    diff: str


@dataclass
class MutantOutcome:
    id: str
    operator: str
    line: int
    suite_score: float | None = None
    max_score: float | None = None
    killed_by_suite: bool = False
    killed_by_check: bool = False
    check_message: str = ""
    suite_messages: list[str] = field(default_factory=list)
    equivalent: str | None = None
    diff: str = ""

    @property
    def killed(self) -> bool:
        return self.killed_by_suite or self.killed_by_check


# --------------------------------------------------------------------------- making mutants
def _solution_lines(cell_source: str) -> tuple[str, set[int]]:
    """The stub's source without the markers, and the (1-based) lines that were inside the solution region."""
    out, inside, region = [], False, set()
    for line in cell_source.splitlines():
        if line.strip() == MARKERS[0]:
            inside = True
            continue
        if line.strip() == MARKERS[1]:
            inside = False
            continue
        out.append(line)
        if inside:
            region.add(len(out))
    return "\n".join(out) + "\n", region


class _Sites(ast.NodeVisitor):
    """Every (node path, operator) a mutation can apply to, inside the solution region."""

    def __init__(self, region: set[int]) -> None:
        self.region, self.sites, self.path = region, [], []

    def generic_visit(self, node: ast.AST) -> None:
        for name, value in ast.iter_fields(node):
            if isinstance(value, list):
                for i, item in enumerate(value):
                    if isinstance(item, ast.AST):
                        self.path.append((name, i))
                        self.visit(item)
                        self.path.pop()
            elif isinstance(value, ast.AST):
                self.path.append((name, None))
                self.visit(value)
                self.path.pop()

    def visit(self, node: ast.AST) -> None:
        if getattr(node, "lineno", None) in self.region:
            for op in _operators(node):
                self.sites.append((tuple(self.path), op, node.lineno))
        self.generic_visit(node)


def _operators(node: ast.AST) -> Iterator[str]:
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "where"
            and len(node.args) == 3):
        yield "mask:where->first branch"
    if isinstance(node, ast.BinOp) and type(node.op) in _BINOP_SWAPS:
        yield f"binop:{type(node.op).__name__}->{_BINOP_SWAPS[type(node.op)].__name__}"
    elif isinstance(node, ast.Compare) and len(node.ops) == 1 and type(node.ops[0]) in _CMP_SWAPS:
        yield f"compare:{type(node.ops[0]).__name__}->{_CMP_SWAPS[type(node.ops[0])].__name__}"
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.Not, ast.Invert)):
        yield f"unary:drop {type(node.op).__name__}"
    elif isinstance(node, ast.BoolOp):
        yield "boolop:swap and/or"
    elif isinstance(node, ast.Constant) and type(node.value) in (int, float):
        yield "constant:+1" if type(node.value) is int else "constant:changed"
    elif isinstance(node, ast.keyword) and node.arg in _AXIS_KEYWORDS:
        yield f"axis:{node.arg} moved"
    elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _REDUCTIONS:
        yield f"reduction:{node.func.attr}->{_REDUCTIONS[node.func.attr]}"
    elif isinstance(node, ast.Slice):
        if node.lower is not None:
            yield "slice:lower+1"
        if node.upper is not None:
            yield "slice:upper+1"



def _plus_one(expr: ast.expr) -> ast.expr:
    return ast.BinOp(left=expr, op=ast.Add(), right=ast.Constant(1))


def _apply(node: ast.AST, op: str) -> ast.AST:
    """The mutated replacement of ``node`` for operator ``op``."""
    node = copy.deepcopy(node)
    kind = op.split(":")[0]
    if kind == "binop":
        node.op = _BINOP_SWAPS[type(node.op)]()
    elif kind == "compare":
        node.ops = [_CMP_SWAPS[type(node.ops[0])]()]
    elif kind == "unary":
        return node.operand
    elif kind == "boolop":
        node.op = ast.Or() if isinstance(node.op, ast.And) else ast.And()
    elif kind == "constant":
        v = node.value
        node.value = v + 1 if type(v) is int else (1.0 if v == 0.0 else v * 2.0)
    elif kind == "axis":
        v = node.value
        if isinstance(v, ast.Constant) and type(v.value) is int:
            node.value = ast.Constant(0 if v.value == -1 else -1)
        elif isinstance(v, ast.UnaryOp) and isinstance(v.op, ast.USub):
            node.value = ast.Constant(0)
        else:
            node.value = _plus_one(v)
    elif kind == "reduction":
        node.func.attr = _REDUCTIONS[node.func.attr]
    elif op == "slice:lower+1":
        node.lower = _plus_one(node.lower)
    elif op == "slice:upper+1":
        node.upper = _plus_one(node.upper)
    elif kind == "mask":
        return node.args[1]
    return node


def _replace(tree: ast.AST, path: tuple, op: str) -> ast.AST:
    tree = copy.deepcopy(tree)
    parent, last = None, None
    node = tree
    for name, index in path:
        parent, last = node, (name, index)
        node = getattr(node, name) if index is None else getattr(node, name)[index]
    new = _apply(node, op)
    name, index = last
    if index is None:
        setattr(parent, name, new)
    else:
        getattr(parent, name)[index] = new
    return ast.fix_missing_locations(tree)


def make_mutants(stub: str, cell_source: str) -> list[Mutant]:
    """Every single-site mutant of a stub cell (whose solution region is marked), deduplicated by source."""
    source, region = _solution_lines(cell_source)
    tree = ast.parse(source)
    finder = _Sites(region)
    finder.visit(tree)
    original = ast.unparse(tree)
    seen, out = {original}, []
    for path, op, line in finder.sites:
        try:
            mutated = ast.unparse(_replace(tree, path, op))
            compile(mutated, "<mutant>", "exec")
        except (SyntaxError, ValueError, TypeError, AttributeError):
            continue
        if mutated in seen:
            continue
        seen.add(mutated)
        diff = "\n".join(l for l in difflib.unified_diff(original.splitlines(), mutated.splitlines(), lineterm="", n=0)
                         if not l.startswith(("---", "+++", "@@")))
        text = source.splitlines()[line - 1].split("  #")[0].strip()
        mutant_id = f"{op} @ {text[:70]}"
        count = sum(m.id.startswith(mutant_id) for m in out)
        out.append(Mutant(stub, mutant_id + (f" #{count + 1}" if count else ""), op, line, mutated, diff))
    return out


# --------------------------------------------------------------------------- public checks
def _notebook_parts(assignment: str) -> tuple[list[tuple[str, str]], dict[str, str]]:
    """The solution notebook's code cells in order, as (kind, source) with kind "stub:<name>", "check:<name>" or
    "cell" (parameters with FAST = True, setup, experiments), and the stub cells by name."""
    cells, stubs = [], {}
    for cell in read_notebook(course.solution_notebook(assignment)).cells:
        if cell.cell_type != "code":
            continue
        meta, tags = cell.metadata.get("nbgrader", {}), cell.metadata.get("tags", [])
        grade_id = meta.get("grade_id", "")
        if "parameters" in tags:
            cells.append(("cell", cell.source + "\nFAST = True"))
        elif grade_id.startswith("check_"):
            cells.append((f"check:{grade_id[len('check_'):]}", cell.source))
        elif meta.get("solution") and grade_id:
            stubs[grade_id] = cell.source
            cells.append((f"stub:{grade_id}", _solution_lines(cell.source)[0]))
        else:
            cells.append(("cell", cell.source))
    return cells, stubs


def _run_check(namespace: dict, mutant_source: str, check: str, queue) -> None:
    try:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            exec(compile(mutant_source, "<mutant>", "exec"), namespace)
            exec(compile(check, "<public check>", "exec"), namespace)
        queue.put("")
    except BaseException as err:  # noqa: BLE001 - any failure of the check kills the mutant
        queue.put(f"{type(err).__name__}: {str(err)[:200]}")


def _in_child(namespace: dict, source: str, check: str) -> str:
    """Run ``source`` then ``check`` in a forked copy of ``namespace``: "" when the check passes, else why not."""
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_run_check, args=(namespace, source, check, queue))
    child.start()
    child.join(PUBLIC_CHECK_SECONDS)
    if child.is_alive():
        child.kill()
        child.join()
        return f"the public check did not finish in {PUBLIC_CHECK_SECONDS:.0f} s"
    return queue.get() if not queue.empty() else f"the public check's process died (exit {child.exitcode})"


def run_public_checks(assignment: str, mutants_by_stub: dict[str, list[Mutant]], log=print) -> dict[tuple[str, str], str | None]:
    """Each mutant's public-check outcome: None (no usable check), "" (passes) or the failure.

    The solution notebook runs once in order, as a student's would (FAST = True, experiments included, so a
    check finds the data an earlier cell loaded); at each stub's check cell, a forked copy of the namespace
    runs each of its mutants and then the check. A check the solution itself fails here counts for nothing.
    """
    import matplotlib
    import torch

    matplotlib.use("Agg")
    torch.set_num_threads(1)  # no thread pool in the parent, so the forked children cannot deadlock on one
    cells, _ = _notebook_parts(assignment)
    namespace: dict = {}
    out: dict[tuple[str, str], str | None] = {}
    wanted = {f"check:{stub}" for stub, mutants in mutants_by_stub.items() if mutants}
    last = max((i for i, (kind, _) in enumerate(cells) if kind in wanted), default=-1)
    for kind, source in cells[:last + 1]:       # nothing after the last check that is needed
        if kind.startswith("check:"):
            stub = kind.split(":", 1)[1]
            mutants = mutants_by_stub.get(stub, [])
            if mutants:
                usable = _in_child(namespace, "", source) == ""
                if not usable:
                    log(f"{assignment}: the public check of {stub} fails on the solution here; not counted")
                for m in mutants:
                    out[(stub, m.id)] = _in_child(namespace, m.source, source) if usable else None
        try:
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                exec(compile(source, f"<{kind}>", "exec"), namespace)
        except Exception as err:  # noqa: BLE001 - a failing experiment must not stop the run
            log(f"{assignment}: a {kind} cell failed while running the solution notebook: {type(err).__name__}: {err}")
    return out


# --------------------------------------------------------------------------- the suite
def stub_tests(assignment: str) -> dict[str, list[str]]:
    """The hidden test functions of each stub, read from the suite's decorators."""
    out: dict[str, list[str]] = {}
    for path in sorted(course.suite_dir(assignment).glob("test_*.py")):
        for node in ast.parse(path.read_text()).body:
            if not isinstance(node, ast.FunctionDef):
                continue
            for deco in node.decorator_list:
                if (isinstance(deco, ast.Call) and getattr(deco.func, "id", "") == "stub" and deco.args
                        and isinstance(deco.args[0], ast.Constant)):
                    out.setdefault(deco.args[0].value, []).append(node.name)
    return out


def _stub_grader(assignment: str):
    """A Grader whose suite runs can be narrowed to some tests (``only``), so a mutant pays only for its stub's."""
    from autograder.core.grader import Grader

    class StubGrader(Grader):
        only: list[str] = []

        def _run_suite(self, plugin, *extra):  # noqa: ANN001 - the Grader's own signature
            if self.only and "--collect-only" not in extra:
                extra = (*extra, "-k", " or ".join(self.only))
            return super()._run_suite(plugin, *extra)

    return StubGrader(assignment)


def equivalent_mutants(assignment: str) -> dict[str, dict[str, str]]:
    path = course.suite_dir(assignment) / EQUIVALENT_FILE
    return json.loads(path.read_text()) if path.is_file() else {}


def run_mutants(assignment: str, stubs: list[str] | None = None, max_per_stub: int | None = None,
                seed: int = 0, out: Path | None = None, log=print) -> dict[str, list[MutantOutcome]]:
    """Grade every mutant (or a seeded sample of ``max_per_stub`` per stub) and write the report."""
    from autograder.authoring.samples import _with_stubs, solution_sources

    course.check_assignment(assignment)
    out = out or course.REPO / "build" / "mutants" / assignment
    out.mkdir(parents=True, exist_ok=True)
    solved = solution_sources(assignment)
    _, stub_cells = _notebook_parts(assignment)
    tests = stub_tests(assignment)
    equivalent = equivalent_mutants(assignment)
    grader = _stub_grader(assignment)
    results: dict[str, list[MutantOutcome]] = {}
    chosen, totals = {}, {}
    for stub in stubs or list(solved):
        mutants = make_mutants(stub, stub_cells[stub])
        totals[stub] = len(mutants)
        if max_per_stub is not None and len(mutants) > max_per_stub:
            mutants = sorted(random.Random(f"{seed}:{stub}").sample(mutants, max_per_stub), key=lambda m: m.line)
        chosen[stub] = mutants
    checked = run_public_checks(assignment, chosen, log)
    try:
        for stub, mutants in chosen.items():
            total = totals[stub]
            grader.only = tests.get(stub, [])
            results[stub] = []
            for k, mutant in enumerate(mutants, 1):
                start = time.monotonic()
                outcome = MutantOutcome(mutant.id, mutant.operator, mutant.line, diff=mutant.diff,
                                        equivalent=equivalent.get(stub, {}).get(mutant.id))
                message = checked.get((stub, mutant.id))
                outcome.killed_by_check = bool(message)
                outcome.check_message = message or ""
                with tempfile.TemporaryDirectory() as tmp:
                    path = Path(tmp) / "mutant.ipynb"
                    nbformat.write(_with_stubs(assignment, {**solved, stub: mutant.source}), str(path))
                    result = grader.grade(path)
                if result.has_score:
                    mine = next((s for s in result.stubs if s.name == stub), None)
                    if mine is not None:
                        outcome.suite_score, outcome.max_score = mine.score, mine.max_score
                        outcome.killed_by_suite = mine.score < mine.max_score
                        outcome.suite_messages = [t.message[:200] for t in mine.tests if not t.passed]
                else:
                    outcome.suite_messages = [f"grader error: {result.error}"]
                results[stub].append(outcome)
                log(f"{assignment} {stub} [{k}/{len(mutants)} of {total}] {'killed' if outcome.killed else 'SURVIVED'}"
                    f" ({time.monotonic() - start:.1f} s) {mutant.id}")
            write_report(assignment, results, out, {s: totals[s] for s in results}, max_per_stub)
    finally:
        grader.close()
    return results


# --------------------------------------------------------------------------- the report
def summarise(outcomes: list[MutantOutcome]) -> dict[str, float]:
    counted = [o for o in outcomes if not o.equivalent]
    by_suite = sum(o.killed_by_suite for o in counted)
    return {"mutants": len(outcomes), "equivalent": len(outcomes) - len(counted), "killed_by_suite": by_suite,
            "killed_by_check": sum(o.killed_by_check for o in counted),
            "survivors": sum(not o.killed_by_suite for o in counted),
            "suite_kill_rate": by_suite / len(counted) if counted else 1.0}


def write_report(assignment: str, results: dict[str, list[MutantOutcome]], out: Path,
                 totals: dict[str, int], max_per_stub: int | None) -> Path:
    """``report.json`` and ``report.md``: per stub the counts, and every survivor of the suite with its diff."""
    data = {stub: {"made": totals.get(stub, len(o)), **summarise(o), "outcomes": [asdict(x) for x in o]}
            for stub, o in results.items()}
    (out / "report.json").write_text(json.dumps(data, indent=1) + "\n")
    lines = [f"# Mutants of {assignment}", "",
             f"Each mutant is one small change to a solution stub, graded with that stub's hidden tests "
             f"and its public check{f' (a seeded sample of at most {max_per_stub} per stub)' if max_per_stub else ''}.",
             "Kill rates count the mutants not listed as equivalent.", "",
             "| stub | made | graded | equivalent | killed by the suite | killed by the public check | suite survivors | suite kill rate |",
             "|---|---|---|---|---|---|---|---|"]
    for stub, d in data.items():
        lines.append(f"| `{stub}` | {d['made']} | {d['mutants']} | {d['equivalent']} | {d['killed_by_suite']} | "
                     f"{d['killed_by_check']} | {d['survivors']} | {d['suite_kill_rate']:.0%} |")
    counted = [o for outs in results.values() for o in outs if not o.equivalent]
    if counted:
        lines.append(f"| all | {sum(totals.values())} | {sum(len(o) for o in results.values())} | "
                     f"{sum(d['equivalent'] for d in data.values())} | {sum(o.killed_by_suite for o in counted)} | "
                     f"{sum(o.killed_by_check for o in counted)} | {sum(not o.killed_by_suite for o in counted)} | "
                     f"{sum(o.killed_by_suite for o in counted) / len(counted):.0%} |")
    for stub, outs in results.items():
        survivors = [o for o in outs if not o.killed_by_suite and not o.equivalent]
        if survivors:
            lines += ["", f"## Survivors of `{stub}`", ""]
            for o in survivors:
                caught = "caught by the public check" if o.killed_by_check else "not caught by the public check either"
                lines += [f"- `{o.id}` (line {o.line}; {caught})", "", "```diff", o.diff, "```", ""]
    path = out / "report.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def main_line(results: dict[str, list[MutantOutcome]]) -> str:
    counted = [o for outs in results.values() for o in outs if not o.equivalent]
    killed = sum(o.killed_by_suite for o in counted)
    return (f"{killed} of {len(counted)} non-equivalent mutants killed by the suite "
            f"({killed / len(counted):.0%})" if counted else "no mutants")



def command(assignment: str, stubs: list[str] | None, max_per_stub: int | None, seed: int, out: Path | None) -> int:
    """The ``mutants`` command: run, print where the report is, and the overall kill rate."""
    results = run_mutants(assignment, stubs, max_per_stub, seed, out)
    folder = out or course.REPO / "build" / "mutants" / assignment
    print(f"{assignment}: {main_line(results)}; report: {folder / 'report.md'}")
    return 0
