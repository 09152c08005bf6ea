"""Shipped datasets, verified against ``datasets/MANIFEST.json`` on every load.

Each entry of the MANIFEST records a file's sha256, size, the exact command that
made it and its seed (plus free-form ``info``, e.g. an expert's measured
return). Loaders refuse a missing, truncated or altered file with a message
that names the file and the fix; nothing is ever downloaded. The scripts in
``datasets/scripts/`` record what they write with :func:`record`, so the command
is the one that was run, argument for argument.

Command line::

    python -m rlcourse.data check                # verify every file
    python -m rlcourse.data add FILE --command "..." --seed 0 [--info key=value ...]
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
import sys
from pathlib import Path
from typing import Any, Sequence

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DATASETS = Path(os.environ.get("RLCOURSE_DATASETS", REPO / "datasets"))
MANIFEST_NAME = "MANIFEST.json"


class DatasetError(RuntimeError):
    """A shipped file is missing, truncated, altered or not listed in the MANIFEST."""


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def read_manifest(root: Path = DATASETS) -> dict[str, dict[str, Any]]:
    """The MANIFEST's entries, keyed by path relative to ``root``."""
    path = root / MANIFEST_NAME
    if not path.exists():
        raise DatasetError(f"{path} is missing: restore it with `git checkout -- {path.name}`")
    return json.loads(path.read_text())["files"]


def _write_manifest(entries: dict[str, dict[str, Any]], root: Path) -> None:
    tmp = root / (MANIFEST_NAME + ".tmp")
    tmp.write_text(json.dumps({"files": dict(sorted(entries.items()))}, indent=2) + "\n")
    tmp.replace(root / MANIFEST_NAME)


def verify(name: str, root: Path = DATASETS) -> Path:
    """Check ``name`` (relative to ``datasets/``) against the MANIFEST and return its path."""
    entries = read_manifest(root)
    if name not in entries:
        raise DatasetError(f"datasets/{name} is not listed in datasets/{MANIFEST_NAME}; known files: "
                           + ", ".join(sorted(entries)))
    entry, path = entries[name], root / name
    fix = f"regenerate it with `{entry['command']}` or restore it with `git checkout -- datasets/{name}`"
    if not path.exists():
        raise DatasetError(f"datasets/{name} is missing: {fix}")
    size = path.stat().st_size
    if size != entry["size"]:
        kind = "truncated" if size < entry["size"] else "longer than recorded"
        raise DatasetError(f"datasets/{name} is {kind} ({size} bytes, MANIFEST says {entry['size']}): {fix}")
    if _sha256(path) != entry["sha256"]:
        raise DatasetError(f"datasets/{name} has been altered (its sha256 differs from the MANIFEST's): {fix}")
    return path


def info(name: str, root: Path = DATASETS) -> dict[str, Any]:
    """The MANIFEST entry of ``name`` (sha256, size, command, seed, info)."""
    return read_manifest(root)[name]


def load_npz(name: str, root: Path = DATASETS) -> dict[str, np.ndarray]:
    """A verified ``.npz`` as a dict of arrays (``allow_pickle=False``)."""
    with np.load(verify(name, root), allow_pickle=False) as data:
        return {key: data[key] for key in data.files}


def load_json(name: str, root: Path = DATASETS) -> Any:
    """A verified JSON file."""
    return json.loads(verify(name, root).read_text())


def load_policy(name: str, root: Path = DATASETS):
    """A verified policy file (see :func:`rlcourse.nets.save_policy`)."""
    from rlcourse.nets import load_policy as _load

    return _load(verify(name, root))


def add(path: str | Path, command: str, seed: int | None, info_: dict[str, Any] | None = None,
        root: Path = DATASETS) -> dict[str, Any]:
    """Record (or refresh) ``path`` in the MANIFEST with its checksum, size, command and seed."""
    path = Path(path).resolve()
    name = path.relative_to(root.resolve()).as_posix()
    entries = read_manifest(root) if (root / MANIFEST_NAME).exists() else {}
    entries[name] = {"sha256": _sha256(path), "size": path.stat().st_size, "command": command,
                     "seed": seed, "info": info_ or {}}
    _write_manifest(entries, root)
    return entries[name]


def script_command(script: str | Path, argv: Sequence[str] | None = None) -> str:
    """The command that runs ``script`` with the arguments ``argv`` (default: this process's, ``sys.argv[1:]``),
    as typed in the repository root: ``python datasets/scripts/make_items.py --seed 0``, quoted by ``shlex.join``."""
    path = Path(script).resolve()
    shown = path.relative_to(REPO).as_posix() if path.is_relative_to(REPO) else str(path)
    return "python " + shlex.join([shown, *(sys.argv[1:] if argv is None else argv)])


def record(path: str | Path, script: str | Path, argv: Sequence[str] | None = None, *, seed: int | None,
           info: dict[str, Any] | None = None, root: Path = DATASETS) -> dict[str, Any]:
    """Record ``path`` in the MANIFEST as made by running ``script`` with ``argv`` (see :func:`script_command`).

    A script calls ``record(out, __file__, argv, seed=args.seed, info=...)`` with the ``argv`` its parser read
    (``None`` when it read the command line), so the MANIFEST holds the exact command, not a summary of it.
    """
    return add(path, script_command(script, argv), seed, info, root)


def remove(name: str, root: Path = DATASETS) -> None:
    """Drop ``name`` from the MANIFEST (after its file was deleted on purpose)."""
    entries = read_manifest(root)
    entries.pop(name, None)
    _write_manifest(entries, root)


def check_all(root: Path = DATASETS) -> list[str]:
    """Problems with every listed file (empty when all verify); also flags unlisted data files."""
    problems = []
    entries = read_manifest(root)
    for name in sorted(entries):
        try:
            verify(name, root)
        except DatasetError as err:
            problems.append(str(err))
    shipped = {p.relative_to(root).as_posix() for p in root.rglob("*")
               if p.is_file() and p.suffix in {".npz", ".pt", ".json", ".npy"} and p.name != MANIFEST_NAME
               and not p.name.startswith("ckpt_")}  # training snapshots (datasets/experts/<env>/<run>/) are not shipped
    for name in sorted(shipped - set(entries)):
        problems.append(f"datasets/{name} is not listed in the MANIFEST: add it with `python -m rlcourse.data add`")
    return problems


def _parse_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m rlcourse.data", description="Verify or record shipped datasets.")
    sub = parser.add_subparsers(dest="cmd", required=True)
    sub.add_parser("check", help="verify every file in the MANIFEST")
    add_p = sub.add_parser("add", help="record a file in the MANIFEST")
    add_p.add_argument("file")
    add_p.add_argument("--command", required=True, help="the command that regenerates the file")
    add_p.add_argument("--seed", type=int, default=None)
    add_p.add_argument("--info", nargs="*", default=[], metavar="KEY=VALUE")
    args = parser.parse_args(argv)
    if args.cmd == "add":
        extra = dict(item.split("=", 1) for item in args.info)
        entry = add(args.file, args.command, args.seed, {k: _parse_value(v) for k, v in extra.items()})
        print(f"recorded {args.file}: {entry['size']} bytes, sha256 {entry['sha256'][:12]}…")
        return 0
    problems = check_all()
    for problem in problems:
        print(problem, file=sys.stderr)
    n = len(read_manifest())
    print(f"{n - len([p for p in problems if 'not listed' not in p])}/{n} files verified"
          + ("" if not problems else f"; {len(problems)} problem(s)"))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
