"""Join the shards of a batch into one gradebook: ``python -m autograder merge ID SHARD_DIR ... --out DIR``.

``batch --shard K/N`` grades the submissions whose name hashes to K, so N copies of one command (a
Slurm job array, a Kubernetes indexed Job, GNU parallel over ssh) grade a class between them. Each
copy writes its submissions' folders, a gradebook ``gradebook-K-of-N.csv`` and a manifest
``_batch-K-of-N.json`` (assignment, suite version, the digest of the folder's names, its submissions),
into one shared folder or one folder each. The merge refuses, with the reason, rather than write a
gradebook that is not the class's:

- shards of another assignment, of another N, of a different folder of submissions, or graded by
  a different version of the suite (a result's own version is checked too, not only the manifest's);
- a shard missing, given twice, or not finished (a submission it owns has no result yet);
- a submission claimed by two shards.

It copies the submissions' folders into ``--out`` (unless they are there already) and writes
``gradebook.csv`` over them all, exactly as one unsharded ``batch`` would have.
"""
from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

from autograder.core import course
from autograder.core.batch import GRADEBOOK_NAME, MANIFEST_PATTERN
from autograder.outputs.batch_output import read_result
from autograder.core.store import atomic_write
from autograder.outputs.files import write_gradebook
from autograder.core.results import GradeResult

MERGED_NAME = "_merged.json"


class MergeRefused(SystemExit):
    """The shards given do not make one class's gradebook; the message says why."""


@dataclass
class ShardOutput:
    folder: Path
    manifest: dict

    @property
    def label(self) -> str:
        k, n = self.manifest["shard"]
        return f"shard {k}/{n} in {self.folder}"


def find_shards(folders: list[Path]) -> list[ShardOutput]:
    """Every shard manifest in the given folders (one shared folder may hold all N)."""
    shards = []
    for folder in folders:
        folder = Path(folder)
        if not folder.is_dir():
            raise MergeRefused(f"{folder} is not a folder")
        paths = sorted(folder.glob(MANIFEST_PATTERN.format(k="*", n="*")))
        if not paths:
            raise MergeRefused(f"{folder} holds no shard manifest (_batch-K-of-N.json): was it written by "
                               "`python -m autograder batch`?")
        for path in paths:
            try:
                shards.append(ShardOutput(folder, json.loads(path.read_text())))
            except (OSError, ValueError) as err:
                raise MergeRefused(f"{path} cannot be read: {err}") from err
    return shards


def check_shards(assignment: str, shards: list[ShardOutput]) -> None:
    """Refuse (:class:`MergeRefused`) unless the manifests are one complete, consistent split of one folder."""
    for key, what in (("assignment", "assignments"), ("suite_version", "versions of the suite"),
                      ("folder_digest", "folders of submissions")):
        values = {s.manifest.get(key) for s in shards}
        if len(values) > 1:
            listed = "; ".join(f"{s.label}: {s.manifest.get(key)}" for s in shards)
            raise MergeRefused(f"the shards were graded for different {what} ({listed}); regrade so that "
                               "every shard uses the same")
    if shards[0].manifest["assignment"] != assignment:
        raise MergeRefused(f"the shards grade {shards[0].manifest['assignment']}, not {assignment}")
    sizes = {s.manifest["shard"][1] for s in shards}
    if len(sizes) > 1:
        raise MergeRefused(f"the shards split the class in different ways (N = {sorted(sizes)})")
    n = sizes.pop()
    ks = [s.manifest["shard"][0] for s in shards]
    twice = sorted({k for k in ks if ks.count(k) > 1})
    missing = sorted(set(range(1, n + 1)) - set(ks))
    if twice:
        raise MergeRefused(f"shard(s) {', '.join(f'{k}/{n}' for k in twice)} given more than once")
    if missing:
        raise MergeRefused(f"shard(s) {', '.join(f'{k}/{n}' for k in missing)} missing: the merge would "
                           "lose their submissions")
    owners: dict[str, str] = {}
    for s in shards:
        for name in s.manifest["submissions"]:
            if name in owners:
                raise MergeRefused(f"{name} was graded by both {owners[name]} and {s.label}")
            owners[name] = s.label
    if len(owners) != shards[0].manifest["folder_submissions"]:
        raise MergeRefused(f"the shards hold {len(owners)} submissions, the folder {shards[0].manifest['folder_submissions']}")


def merge(assignment: str, folders: list[Path], out_dir: Path) -> list[GradeResult]:
    """Check the shards in ``folders``, gather their results into ``out_dir`` and write its gradebook."""
    course.check_assignment(assignment)
    shards = find_shards(folders)
    check_shards(assignment, shards)
    version = shards[0].manifest["suite_version"]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    results = []
    for shard in shards:
        for name in shard.manifest["submissions"]:
            source = shard.folder / name
            result = read_result(source)
            if result is None:
                raise MergeRefused(f"{shard.label} has not finished: {name} has no result yet (run the shard "
                                   "again: it grades only what is missing)")
            if result.suite_version != version:
                raise MergeRefused(f"{name} in {shard.label} was graded by suite version "
                                   f"{result.suite_version or '(unrecorded)'}, not {version}: regrade it")
            results.append(result)
    for shard in shards:  # only once everything checked: a refused merge writes nothing
        for name in shard.manifest["submissions"]:
            source, target = shard.folder / name, out_dir / name
            if source.resolve() != target.resolve():
                if target.exists():
                    shutil.rmtree(target)
                shutil.copytree(source, target, symlinks=True)
    write_gradebook(results, out_dir / GRADEBOOK_NAME, course.stub_names(assignment))
    atomic_write(out_dir / MERGED_NAME, json.dumps({
        "assignment": assignment, "suite_version": version, "submissions": len(results),
        "shards": [{"shard": s.manifest["shard"], "folder": str(s.folder)} for s in shards]}, indent=1))
    return results
