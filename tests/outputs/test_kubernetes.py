"""The Kubernetes manifests of docs/instructors.md (deploy/kubernetes/): valid Job and PersistentVolumeClaim
objects by the API's schema (a vendored subset), a ReadWriteMany volume mounted beside the image's kit, an indexed
Job whose indexes cover the shards, a merge Job over the same folder, and capabilities that are enough for the
sandbox's full isolation (tried here, as root, with exactly that capability set)."""
from __future__ import annotations

import copy
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import jsonschema
import pytest
import yaml

from conftest import REPO

DEPLOY = REPO / "deploy" / "kubernetes"
SCHEMA = json.loads((REPO / "tests/fixtures/schemas/kubernetes_job_pvc_v1.30.json").read_text())
MANIFESTS = ("pvc.yaml", "grade-job.yaml", "merge-job.yaml")
RUNTIME_DEFAULT_CAPABILITIES = ("CHOWN", "DAC_OVERRIDE", "FSETID", "FOWNER", "MKNOD", "NET_RAW", "SETGID", "SETUID",
                                "SETFCAP", "SETPCAP", "NET_BIND_SERVICE", "SYS_CHROOT", "KILL", "AUDIT_WRITE")
"""The capabilities containerd and Docker give a container by default (no SYS_ADMIN)."""


def load(name: str) -> dict:
    docs = [d for d in yaml.safe_load_all((DEPLOY / name).read_text()) if d is not None]
    assert len(docs) == 1, name
    return docs[0]


def errors(doc: dict) -> list[str]:
    schema = {"$schema": SCHEMA["$schema"], "$defs": SCHEMA["$defs"], **SCHEMA["kinds"][doc["kind"]]}
    return [f"{'/'.join(map(str, e.absolute_path))}: {e.message}"
            for e in jsonschema.Draft202012Validator(schema).iter_errors(doc)]


def container(doc: dict) -> dict:
    (only,) = doc["spec"]["template"]["spec"]["containers"]
    return only


@pytest.mark.parametrize("name", MANIFESTS)
def test_each_manifest_is_a_valid_object_of_its_kind(name):
    doc = load(name)
    assert doc["apiVersion"] == {"Job": "batch/v1", "PersistentVolumeClaim": "v1"}[doc["kind"]]
    assert errors(doc) == []


def test_the_schema_check_catches_what_the_api_server_refuses():
    job = load("grade-job.yaml")
    broken = copy.deepcopy(job)
    del broken["spec"]["template"]["spec"]["containers"]
    assert any("'containers' is a required property" in e for e in errors(broken))
    broken = copy.deepcopy(job)
    container(broken)["volumeMount"] = container(broken).pop("volumeMounts")
    assert any("volumeMount" in e for e in errors(broken))
    broken = copy.deepcopy(job)
    broken["spec"]["completions"] = "8"
    assert any("completions" in e for e in errors(broken))
    broken = copy.deepcopy(job)
    container(broken)["securityContext"]["capabilities"]["add"] = "SYS_ADMIN"
    assert any("capabilities" in e for e in errors(broken))
    pvc = load("pvc.yaml")
    pvc["spec"]["accessMode"] = pvc["spec"].pop("accessModes")
    assert errors(pvc)


def test_the_volume_is_readwritemany_and_mounted_beside_the_image_kit():
    pvc = load("pvc.yaml")
    assert pvc["spec"]["accessModes"] == ["ReadWriteMany"] and pvc["spec"]["resources"]["requests"]["storage"]
    kit = re.search(r"^WORKDIR (\S+)", (REPO / "docker/grader/Dockerfile").read_text(), re.M).group(1)
    for name in ("grade-job.yaml", "merge-job.yaml"):
        job = load(name)
        spec = job["spec"]["template"]["spec"]
        assert [v["persistentVolumeClaim"]["claimName"] for v in spec["volumes"]] == [pvc["metadata"]["name"]]
        box = container(job)
        assert box["workingDir"] == kit
        for mount in box["volumeMounts"]:
            inside = lambda a, b: a == b or a.startswith(b.rstrip("/") + "/")  # noqa: E731
            assert not inside(kit, mount["mountPath"]) and not inside(mount["mountPath"], kit), \
                f"{name}: {mount['mountPath']} would hide or sit in the image's {kit} (its .venv)"
        repo = {e["name"]: e["value"] for e in box["env"]}["RLCOURSE_REPO"]
        assert any(repo.startswith(m["mountPath"].rstrip("/") + "/") for m in box["volumeMounts"]), repo


def _batch_argv(job: dict) -> tuple[str, int, str]:
    command = container(job)["command"]
    assert command[:2] == ["bash", "-c"]
    script = command[2]
    found = re.fullmatch(r"exec \.venv/bin/python -m autograder batch (\S+) (\S+) --out (\S+) --jobs \d+ "
                         r"--shard \$\(\(JOB_COMPLETION_INDEX \+ 1\)\)/(\d+)", script)
    assert found, script
    return found.group(1), int(found.group(4)), found.group(3)


def test_the_indexed_job_grades_every_shard_once():
    job = load("grade-job.yaml")
    assignment, n, _ = _batch_argv(job)
    assert job["spec"]["completionMode"] == "Indexed" and job["spec"]["completions"] == n
    assert job["spec"]["parallelism"] <= n
    script = container(job)["command"][2].replace("exec .venv/bin/python", "echo")
    shards = [subprocess.run(["bash", "-c", script], env={"JOB_COMPLETION_INDEX": str(i), "PATH": os.environ["PATH"]},
                             capture_output=True, text=True, check=True).stdout.split("--shard ")[1].strip()
              for i in range(n)]
    assert shards == [f"{k}/{n}" for k in range(1, n + 1)]
    assert (REPO / "autograder/suites" / assignment).is_dir()


def test_the_merge_job_joins_the_grading_jobs_folder():
    assignment, _, out = _batch_argv(load("grade-job.yaml"))
    merge = load("merge-job.yaml")
    assert container(merge)["command"] == [".venv/bin/python", "-m", "autograder", "merge", assignment, out, "--out", out]
    assert merge["spec"]["template"]["spec"]["restartPolicy"] == "Never"
    assert container(merge)["securityContext"]["capabilities"] == {"drop": ["ALL"]}


def test_the_docs_show_the_manifests_as_they_are():
    docs = (REPO / "docs/instructors.md").read_text()
    blocks = re.findall(r"```yaml\n(.*?)```", docs, re.S)
    for name in MANIFESTS:
        assert (DEPLOY / name).read_text() in blocks, f"docs/instructors.md does not show deploy/kubernetes/{name}"


def _bounding_set() -> set[str]:
    with open("/proc/self/status") as f:
        mask = int(next(line for line in f if line.startswith("CapBnd:")).split()[1], 16)
    names = subprocess.run(["capsh", f"--decode={mask:x}"], capture_output=True, text=True).stdout if \
        shutil.which("capsh") else ""
    return {c.strip().upper().removeprefix("CAP_") for c in names.split("=", 1)[-1].split(",") if c.strip()}


def _grade_with(capabilities: list[str], out: Path, expect: int = 0):
    """The result of grading hw0's partial sample with this bounding set; its error output if ``expect`` is a
    grader fault's exit status."""
    caps = ",".join(f"+{c.lower()}" for c in capabilities)
    done = subprocess.run(["setpriv", f"--bounding-set=-all,{caps}", "--inh-caps=-all", "--",
                           str(REPO / ".venv/bin/python"), "-m", "autograder", "grade", "hw0_setup",
                           str(REPO / "autograder/samples/hw0_setup/partial.ipynb"), "--out", str(out)],
                          cwd=REPO, capture_output=True, text=True, timeout=600)
    assert done.returncode == expect, done.stderr[-2000:]
    return json.loads((out / "result.json").read_text()) if expect == 0 else done.stderr


@pytest.mark.slow
def test_the_manifests_capabilities_give_the_sandbox_full_isolation(tmp_path):
    """As root, with exactly the capabilities the grading Job adds (all others gone), the sandbox builds its
    namespaces (isolation "full"); with a container runtime's default set (no SYS_ADMIN) it falls back to "none",
    where it grades only a course whose file modes wall off the hidden files. Seccomp and AppArmor are the
    cluster's: not tried here."""
    if os.geteuid() != 0 or not shutil.which("setpriv") or not shutil.which("capsh"):
        pytest.skip("needs root, setpriv and capsh (util-linux, libcap2-bin) to run the grader with a capability set")
    added = container(load("grade-job.yaml"))["securityContext"]["capabilities"]
    assert added["drop"] == ["ALL"]
    missing = (set(added["add"]) | set(RUNTIME_DEFAULT_CAPABILITIES)) - _bounding_set()
    if missing:
        pytest.skip(f"this machine's own bounding set lacks {sorted(missing)}")
    full = _grade_with(added["add"], tmp_path / "manifest")
    assert full["isolation"] == "full" and full["error"] is None
    score = lambda r: sum(t["points"] for s in r["stubs"] for t in s["tests"] if t["passed"])  # noqa: E731
    assert score(full) == 5
    # Without SYS_ADMIN there is no view: the worker becomes a uid of its own, and refuses to start while the
    # modes of this checkout let it read the hidden suites (tests/sandbox/test_no_namespaces_as_root.py grades
    # a course walled by `python -m autograder permissions` this way).
    if any(os.stat(REPO / p).st_mode & 0o005 for p in ("solutions", "autograder/suites")):
        refused = _grade_with(list(RUNTIME_DEFAULT_CAPABILITIES), tmp_path / "runtime-default", expect=3)
        assert "autograder permissions" in refused
