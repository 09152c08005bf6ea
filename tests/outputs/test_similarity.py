"""Similar stub code (autograder/outputs/similarity.py): disguised copies are flagged, honest solutions are not.

Submissions are hw1_imitation notebooks built here from the student release (no grading needed):
the solution, a copy of it with every local name renamed and comments added in cells put in the
reverse order, a copy with all four functions in one cell in reverse order (its grading metadata
gone, matched by name), an honest rewrite of the four stubs, and two untouched notebooks.
"""
from __future__ import annotations

import hashlib
import re
from pathlib import Path

import nbformat
import pytest

from autograder.core import course
from autograder.outputs.class_report import write_class_report
from autograder.outputs.similarity import (NEVER_A_GRADE, StubCode, joined_stubs, read_stub_code, release_code,
                                           similar_pairs)
from autograder.outputs.files import write_gradebook, write_outputs
from autograder.core.results import GradeResult, StubResult
from autograder.core.results import TestOutcome as Outcome

ASSIGNMENT = "hw1_imitation"
STUB_END = "    # YOUR CODE HERE\n    raise NotImplementedError()"

REWRITE = {  # an honest rewrite of hw1's four stubs: the same task, written another way
"bc_loss": '''
    mean = policy(obs)
    sigma = policy.log_std.exp()
    per_dim = (actions - mean) ** 2 / (2 * sigma ** 2) + torch.log(sigma) + 0.5 * np.log(2 * np.pi)
    return torch.mean(torch.sum(per_dim, dim=1))
''',
"train_bc": '''
    generator = np.random.default_rng(seed)
    n = len(obs)
    X = torch.tensor(np.asarray(obs, dtype=np.float32))
    Y = torch.tensor(np.asarray(actions, dtype=np.float32))
    perm = generator.permutation(n)
    held_out = int(round(val_fraction * n))
    val_idx, train_idx = perm[:held_out], perm[held_out:]
    opt = torch.optim.Adam(policy.parameters(), lr=lr)
    train_losses, val_losses = [], []
    for epoch in range(n_epochs):
        idx = train_idx[generator.permutation(len(train_idx))]
        weighted = []
        for chunk in np.array_split(idx, max(1, int(np.ceil(len(idx) / batch_size)))):
            opt.zero_grad()
            l = bc_loss(policy, X[chunk], Y[chunk])
            l.backward()
            opt.step()
            weighted.append(float(l) * len(chunk))
        train_losses.append(sum(weighted) / max(1, len(idx)))
        if held_out == 0:
            val_losses.append(float("nan"))
        else:
            with torch.no_grad():
                val_losses.append(float(bc_loss(policy, X[val_idx], Y[val_idx])))
    return {"train": train_losses, "val": val_losses}
''',
"relabel_with_expert": '''
    states = np.asarray(obs, dtype=np.float32)
    lead = states.shape[:-1]
    flat = states.reshape((-1, states.shape[-1]))
    out = np.asarray(expert.act(flat)).astype(np.float32)
    return out.reshape(*lead, out.shape[-1])
''',
"dagger": '''
    gen = np.random.default_rng(seed)
    data = AggregatedDataset(demo_obs, demo_actions)
    history = {"returns": np.zeros(n_iterations), "dataset_sizes": np.zeros(n_iterations, dtype=np.int64)}
    for it, beta in enumerate(beta_schedule[:n_iterations]):
        behaviour = MixturePolicy(expert.act, policy.act, beta, gen)
        eps = rollout(behaviour, env_id, episodes_per_iter, seed=seed + it * episodes_per_iter)
        states = eps.obs[eps.mask]
        data.add(states, relabel_with_expert(expert, states))
        train_bc(policy, data.obs, data.actions, seed=seed + it, **train_kwargs)
        history["returns"][it] = eps.returns.mean()
        history["dataset_sizes"][it] = len(data)
    history["obs"], history["actions"] = data.obs, data.actions
    return policy, history
''',
}

DISGUISED = {  # the solution copied: every local name changed, comments added
"bc_loss": '''
    # compute the negative log likelihood
    ls = policy.log_std   # log sigma
    standardized = (actions - policy(obs)) * torch.exp(-ls)  # my z-scores

    nll = 0.5 * standardized**2 + ls + 0.5 * np.log(2 * np.pi)   # per dimension
    return nll.sum(dim=-1).mean()  # sum dims, average samples
''',
"train_bc": '''
    # set up a generator
    gen = np.random.default_rng(seed)
    X = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
    Y = torch.as_tensor(np.asarray(actions), dtype=torch.float32)
    perm = gen.permutation(len(X))   # random order
    num_val = int(round(val_fraction * len(X)))
    validation, training = perm[:num_val], perm[num_val:]
    opt = torch.optim.Adam(policy.parameters(), lr=lr)
    log = {"train": [], "val": []}
    # main loop
    for _ in range(n_epochs):
        mixed = gen.permutation(training)
        running = 0.0
        for s in range(0, len(mixed), batch_size):
            mb = mixed[s:s + batch_size]   # minibatch
            l = bc_loss(policy, X[mb], Y[mb])
            opt.zero_grad()
            l.backward()
            opt.step()
            running += l.item() * len(mb)
        log["train"].append(running / max(len(training), 1))
        with torch.no_grad():   # evaluation
            log["val"].append(bc_loss(policy, X[validation], Y[validation]).item() if num_val else float("nan"))
    return log
''',
"relabel_with_expert": '''
    o = np.asarray(obs, dtype=np.float32)  # to float32
    # ask the expert once for all states
    acts = np.asarray(expert.act(o.reshape(-1, o.shape[-1])), dtype=np.float32)
    return acts.reshape(o.shape[:-1] + acts.shape[-1:])
''',
"dagger": '''
    g = np.random.default_rng(seed)
    ds = AggregatedDataset(demo_obs, demo_actions)   # start from the demos
    rets, szs = [], []
    for k in range(n_iterations):
        mix = MixturePolicy(expert.act, policy.act, beta_schedule[k], g)
        eps = rollout(mix, env_id, episodes_per_iter, seed=seed + k * episodes_per_iter)
        states = eps.obs[eps.mask]   # only real steps
        ds.add(states, relabel_with_expert(expert, states))
        # retrain on everything
        train_bc(policy, ds.obs, ds.actions, seed=seed + k, **train_kwargs)
        rets.append(float(eps.returns.mean()))
        szs.append(len(ds))
    out = {"returns": np.array(rets), "dataset_sizes": np.array(szs, dtype=np.int64),
           "obs": ds.obs, "actions": ds.actions}
    return policy, out
''',
}


def release_cells() -> tuple[nbformat.NotebookNode, dict[str, str]]:
    nb = nbformat.read(str(course.release_notebook(ASSIGNMENT)), as_version=4)
    stubs = course.stub_names(ASSIGNMENT)
    return nb, {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
                if c.metadata.get("nbgrader", {}).get("grade_id") in stubs}


def solution_bodies() -> dict[str, str]:
    """The body of each stub in the instructor's solution (between its nbgrader markers)."""
    nb = nbformat.read(str(course.REPO / "solutions" / ASSIGNMENT / f"{ASSIGNMENT}.ipynb"), as_version=4)
    found = {}
    for cell in nb.cells:
        body = re.search(r"### BEGIN SOLUTION\n(.*?)\n\s*### END SOLUTION", cell.source, re.S)
        if body and cell.metadata.get("nbgrader", {}).get("grade_id"):
            found[cell.metadata["nbgrader"]["grade_id"]] = body.group(1)
    return found


def filled(bodies: dict[str, str]) -> dict[str, str]:
    """Each released stub cell with its body replaced."""
    _, cells = release_cells()
    assert all(STUB_END in source for source in cells.values())
    return {stub: source.replace(STUB_END, bodies[stub].strip("\n")) for stub, source in cells.items()}


def write(path: Path, sources: dict[str, str] | None = None, reverse: bool = False, one_cell: bool = False) -> None:
    """A submission made from the release: stub cells replaced, put in reverse order, or merged into one cell."""
    nb, cells = release_cells()
    sources = sources or {}
    stub_cells = [c for c in nb.cells if c.metadata.get("nbgrader", {}).get("grade_id") in cells]
    for cell in stub_cells:
        cell.source = sources.get(cell.metadata["nbgrader"]["grade_id"], cell.source)
    if reverse:
        slots = [i for i, c in enumerate(nb.cells) if c in stub_cells]
        for i, cell in zip(slots, reversed(stub_cells)):
            nb.cells[i] = cell
    if one_cell:
        nb.cells = [c for c in nb.cells if c not in stub_cells]
        nb.cells.append(nbformat.v4.new_code_cell("\n\n".join(reversed([sources[s] for s in cells]))))
    nbformat.write(nb, str(path))


@pytest.fixture(scope="module")
def class_folder(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("similarity") / "submissions"
    folder.mkdir()
    write(folder / "solution.ipynb", filled(solution_bodies()))
    write(folder / "renamed_commented_reordered.ipynb", filled(DISGUISED), reverse=True)
    write(folder / "one_cell_reversed.ipynb", filled(DISGUISED), one_cell=True)
    write(folder / "honest_rewrite.ipynb", filled(REWRITE))
    write(folder / "untouched_1.ipynb")
    write(folder / "untouched_2.ipynb")
    return folder


COPIES = {("renamed_commented_reordered", "solution"), ("one_cell_reversed", "solution"),
          ("one_cell_reversed", "renamed_commented_reordered")}


def test_disguised_copies_are_flagged_and_honest_solutions_are_not(class_folder):
    codes = read_stub_code(ASSIGNMENT, class_folder)
    assert {c.name for c in codes} == {p.stem for p in class_folder.glob("*.ipynb")}
    assert not any(c.problem for c in codes)
    one_cell = next(c for c in codes if c.name == "one_cell_reversed")
    assert all(f"def {stub}(" in one_cell.code for stub in course.stub_names(ASSIGNMENT))
    flagged, scores = similar_pairs(codes, release_code(ASSIGNMENT))
    assert {tuple(sorted((p.a, p.b))) for p in flagged} == COPIES
    assert all(min(p.similarity_a, p.similarity_b) > 0.9 for p in flagged)
    honest = {tuple(sorted((a, b))): (x, y) for a, b, x, y in scores if "honest_rewrite" in (a, b)}
    assert set(honest) == {("honest_rewrite", n) for n in ("one_cell_reversed", "renamed_commented_reordered",
                                                           "solution")}  # untouched ones have nothing to compare
    assert all(max(x, y) < 0.5 for x, y in honest.values()), honest


def test_the_release_is_boilerplate_so_untouched_stubs_match_nothing():
    _, cells = release_cells()
    stubs = course.stub_names(ASSIGNMENT)
    untouched = [StubCode(f"u{i}", joined_stubs(cells, stubs)) for i in range(3)]
    flagged, scores = similar_pairs(untouched, release_code(ASSIGNMENT), threshold=0.0, min_shared=0)
    assert flagged == [] and scores == []


def fake_result(name: str) -> GradeResult:
    return GradeResult(ASSIGNMENT, name, [StubResult(s, [Outcome(f"{s} works", s, 1.0, name == "solution")])
                                          for s in course.stub_names(ASSIGNMENT)], [], [])


def test_the_report_lists_pairs_with_side_by_side_pages_and_changes_no_grade(class_folder, tmp_path):
    results = tmp_path / "results"
    names = sorted(p.stem for p in class_folder.glob("*.ipynb"))
    for name in names:
        write_outputs(fake_result(name), results / name)
    write_gradebook([fake_result(n) for n in names], results / "gradebook.csv")
    before = {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in results.rglob("*") if p.is_file()}
    write_class_report(ASSIGNMENT, results, submissions=class_folder)
    assert before == {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in before}
    page = (results / "_class_report" / "report.html").read_text()
    assert page.count("side by side</a>") == len(COPIES) and NEVER_A_GRADE.split(".")[0] in page
    pairs = sorted((results / "_class_report" / "similarity").glob("pair-*.html"))
    assert len(pairs) == len(COPIES)
    side = pairs[0].read_text()
    assert NEVER_A_GRADE.split(".")[0] in side and side.count("<mark>") >= 2 and "<script" not in side
    assert "&gt;" in side  # the code is escaped (a `->` annotation), never pasted raw


def test_a_padded_stub_cell_is_compared_up_to_the_cap(tmp_path):
    from autograder.outputs.similarity import MAX_STUB_CHARS

    folder = tmp_path / "submissions"
    folder.mkdir()
    padded = filled(solution_bodies())
    padded["bc_loss"] += "\n" + "x = 1  # padding\n" * 50_000  # about 850 KB, under the grader's 1 MB cell cap
    write(folder / "padded.ipynb", padded)
    (code,) = read_stub_code(ASSIGNMENT, folder)
    assert not code.problem and "def dagger(" in code.code
    assert len(code.code) < len(course.stub_names(ASSIGNMENT)) * (MAX_STUB_CHARS + 100)


def test_a_copy_padded_with_comments_past_the_cap_is_still_flagged(class_folder, tmp_path):
    """Red team C: 20,000 characters of comments at the top of each copied stub cell pushed its code past the
    cap, and a verbatim copy went unflagged. Comments go before the cap."""
    folder = tmp_path / "submissions"
    folder.mkdir()
    write(folder / "solution.ipynb", filled(solution_bodies()))
    padding = "# " + "notes " * 3_400 + "\n"                            # about 20,000 characters of comment lines
    padded = {stub: padding + "\n".join("# " + "x" * 80 for _ in range(10)) + "\n" + source
              for stub, source in filled(solution_bodies()).items()}
    write(folder / "padded_copy.ipynb", padded)
    flagged, _ = similar_pairs(read_stub_code(ASSIGNMENT, folder), release_code(ASSIGNMENT))
    assert [tuple(sorted((p.a, p.b))) for p in flagged] == [("padded_copy", "solution")]


HW0_REWRITE = {"discounted_returns": '''
    r = np.asarray(rewards, dtype=float)
    out = np.zeros_like(r)
    running = np.zeros(r.shape[0])
    for t in range(r.shape[1] - 1, -1, -1):
        running = r[:, t] + gamma * running
        out[:, t] = running
    return out
''', "episode_returns": '''
    done = np.asarray(dones, dtype=bool)
    returns, total = [], 0.0
    for r, d in zip(np.asarray(rewards, dtype=float), done):
        total += r
        if d:
            returns.append(total)
            total = 0.0
    return np.array(returns, dtype=float)
'''}
HW0_COPY = {"discounted_returns": '''
    R = np.asarray(rewards, dtype=float)  # as floats
    n = R.shape[-1]
    a, b = np.arange(n)[:, None], np.arange(n)[None, :]
    M = np.where(a >= b, float(gamma) ** np.maximum(a - b, 0), 0.0)
    return R @ M  # matrix of discounts
''', "episode_returns": '''
    rw = np.asarray(rewards, dtype=float)
    idx = np.flatnonzero(np.asarray(dones, dtype=bool))  # episode ends
    cum = np.cumsum(rw)[idx]
    return np.diff(cum, prepend=0.0)
'''}


def test_short_stubs_a_renamed_copy_is_flagged_and_an_honest_rewrite_is_not():
    """hw0's two stubs are a few lines each, where honest solutions are most alike."""
    stubs = course.stub_names("hw0_setup")
    nb = nbformat.read(str(course.release_notebook("hw0_setup")), as_version=4)
    cells = {c.metadata["nbgrader"]["grade_id"]: c.source for c in nb.cells
             if c.metadata.get("nbgrader", {}).get("grade_id") in stubs}
    solution = nbformat.read(str(course.REPO / "solutions/hw0_setup/hw0_setup.ipynb"), as_version=4)
    bodies = {c.metadata["nbgrader"]["grade_id"]: re.search(r"### BEGIN SOLUTION\n(.*?)\n\s*### END SOLUTION",
                                                            c.source, re.S).group(1)
              for c in solution.cells if c.metadata.get("nbgrader", {}).get("grade_id") in stubs}
    codes = [StubCode(name, joined_stubs({s: cells[s].replace(STUB_END, b[s].strip("\n")) for s in stubs}, stubs))
             for name, b in [("solution", bodies), ("copy", HW0_COPY), ("rewrite", HW0_REWRITE)]]
    flagged, scores = similar_pairs(codes, release_code("hw0_setup"))
    assert [(p.a, p.b) for p in flagged] == [("solution", "copy")]
    assert all(max(x, y) < 0.5 for a, b, x, y in scores if "rewrite" in (a, b)), scores
