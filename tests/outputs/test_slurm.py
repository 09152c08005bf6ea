"""The Slurm route of docs/instructors.md, run for real: a single-node Slurm (Debian's slurm-wlm, with munge)
started for this test, a small class graded by deploy/slurm/submit.sh (the job array of grade_array.sh and the
merge that depends on it), and the merged gradebook compared with the unsharded batch's, row for row.

Needs root and the packages (``make setup`` installs them as root; ``apt-get install slurm-wlm munge``); skipped,
saying which is missing, otherwise. Every daemon it starts (munged, slurmctld, slurmd) has a private socket, ports,
state and pid files under a temporary folder, and is stopped by its pid at the end."""
from __future__ import annotations

import csv
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from conftest import REPO

pytestmark = pytest.mark.slow
SLURM = REPO / "deploy" / "slurm"
SAMPLES = REPO / "autograder" / "samples" / "hw0_setup"
KINDS = ("complete", "partial", "untouched", "broken_exception", "broken_syntax", "cheating")
TOOLS = ("munged", "slurmctld", "slurmd", "sbatch", "squeue", "scontrol", "sinfo", "setpriv")
SHARDS = 3
PATH = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/sbin"])
"""Where the daemons are (Debian puts them in /usr/sbin, which a user's PATH may lack)."""


def _why_not() -> str | None:
    if os.geteuid() != 0:
        return "needs root: slurmd runs jobs as root here and munged must start as the munge user"
    missing = [tool for tool in TOOLS if not shutil.which(tool, path=PATH)]
    if missing:
        return (f"{', '.join(missing)} not installed: apt-get install slurm-wlm munge (make setup does it when run as "
                "root)")
    try:
        import pwd

        pwd.getpwnam("munge")
    except KeyError:
        return "no munge user (Debian's munge package creates it)"
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(what: str, check, seconds: float, log: Path | None = None):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.5)
    tail = log.read_text()[-3000:] if log is not None and log.exists() else ""
    raise AssertionError(f"{what} did not happen in {seconds:.0f} s\n{tail}")


def _stop(pid_file: Path) -> None:
    """Stop the daemon whose pid ``pid_file`` holds (one this test started), TERM first, then KILL."""
    try:
        pid = int(pid_file.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return
    try:
        os.kill(pid, signal.SIGTERM)
        for _ in range(40):
            os.kill(pid, 0)
            time.sleep(0.25)
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


@pytest.fixture(scope="module")
def cluster():
    """A one-node Slurm of this machine's CPUs, its environment for the clients (``SLURM_CONF``)."""
    why = _why_not()
    if why:
        pytest.skip(why)
    root = Path(tempfile.mkdtemp(prefix="rlcourse-slurm-", dir="/tmp"))
    root.chmod(0o755)
    keys, run = root / "munge", root / "munge-run"  # the key's folder private, the socket's open to all
    for folder, mode in ((keys, 0o700), (run, 0o755)):
        folder.mkdir()
        shutil.chown(folder, "munge", "munge")
        folder.chmod(mode)
    key = keys / "munge.key"
    key.write_bytes(os.urandom(1024))
    shutil.chown(key, "munge", "munge")
    key.chmod(0o400)
    munge_socket = run / "munge.socket"
    state = root / "slurm"
    (state / "state").mkdir(parents=True)
    (state / "spool").mkdir()
    host = socket.gethostname().split(".")[0]
    cpus = min(os.cpu_count() or 1, 2)
    conf = state / "slurm.conf"
    conf.write_text("\n".join([
        "ClusterName=rlcoursetest", f"SlurmctldHost={host}", "SlurmUser=root", "SlurmdUser=root",
        f"SlurmctldPort={_free_port()}", f"SlurmdPort={_free_port()}", "AuthType=auth/munge",
        f"AuthInfo=socket={munge_socket}", "CredType=cred/munge", "ProctrackType=proctrack/linuxproc",
        "TaskPlugin=task/none", "JobAcctGatherType=jobacct_gather/none", "AccountingStorageType=accounting_storage/none",
        "JobCompType=jobcomp/none", "MpiDefault=none", "SchedulerType=sched/backfill", "SelectType=select/cons_tres",
        "SelectTypeParameters=CR_CPU_Memory", "ReturnToService=2", "MinJobAge=3600",
        f"StateSaveLocation={state / 'state'}", f"SlurmdSpoolDir={state / 'spool'}",
        f"SlurmctldPidFile={state / 'slurmctld.pid'}", f"SlurmdPidFile={state / 'slurmd.pid'}",
        f"SlurmctldLogFile={state / 'slurmctld.log'}", f"SlurmdLogFile={state / 'slurmd.log'}",
        f"NodeName={host} CPUs={cpus} RealMemory=4000 State=UNKNOWN",
        "PartitionName=grading Nodes=ALL Default=YES MaxTime=INFINITE State=UP", ""]))
    env = dict(os.environ, SLURM_CONF=str(conf), PATH=PATH)
    pid_files = [run / "munged.pid", state / "slurmd.pid", state / "slurmctld.pid"]
    try:
        subprocess.run(["setpriv", "--reuid=munge", "--regid=munge", "--init-groups", "munged",
                        f"--key-file={key}", f"--socket={munge_socket}", f"--pid-file={run / 'munged.pid'}",
                        f"--log-file={keys / 'munged.log'}", f"--seed-file={keys / 'munged.seed'}"],
                       env=env, check=True, capture_output=True, timeout=60)
        _wait("munged's socket", munge_socket.exists, 30)
        for daemon in ("slurmctld", "slurmd"):
            subprocess.run([daemon, "-f", str(conf)], env=env, check=True, capture_output=True, timeout=60)
        _wait("the node to be idle", lambda: subprocess.run(["sinfo", "-h", "-o", "%T"], env=env, capture_output=True,
                                                              text=True).stdout.strip() == "idle",
              90, state / "slurmctld.log")
        yield env
    finally:
        for pid_file in pid_files:
            _stop(pid_file)
        shutil.rmtree(root, ignore_errors=True)


def _rows(path: Path) -> list[list[str]]:
    with path.open(newline="") as f:
        return list(csv.reader(f))


def _job_state(job: str, env: dict) -> str:
    shown = subprocess.run(["scontrol", "show", "job", job], env=env, capture_output=True, text=True).stdout
    states = re.findall(r"JobState=(\S+)", shown)
    return ",".join(states)


def test_the_docs_show_the_slurm_scripts_as_they_are():
    docs = (REPO / "docs/instructors.md").read_text()
    blocks = re.findall(r"```bash\n(.*?)```", docs, re.S)
    for name in ("grade_array.sh", "merge.sh", "submit.sh"):
        assert (SLURM / name).read_text() in blocks, f"docs/instructors.md does not show deploy/slurm/{name}"


def test_a_class_graded_as_a_job_array_and_merged_equals_the_unsharded_batch(cluster, tmp_path):
    work = Path(tempfile.mkdtemp(prefix="rlcourse-slurm-class-", dir="/tmp"))
    try:
        folder = work / "class"
        folder.mkdir()
        for i, kind in enumerate(KINDS):
            shutil.copy(SAMPLES / f"{kind}.ipynb", folder / f"student{i:02d}.ipynb")
        whole = subprocess.run([sys.executable, "-m", "autograder", "batch", "hw0_setup", str(folder), "--out",
                                str(work / "whole"), "--jobs", "1"], cwd=REPO, capture_output=True, text=True,
                               timeout=900)
        assert whole.returncode == 0, whole.stdout[-2000:] + whole.stderr[-2000:]

        out = work / "sharded"
        submitted = subprocess.run(
            ["bash", str(SLURM / "submit.sh"), "hw0_setup", str(folder), str(out), str(SHARDS), "--cpus-per-task=1",
             "--mem=1000", f"--output={work}/slurm-%j.out"],
            cwd=REPO, env=dict(cluster, COURSE=str(REPO), JOBS="1"), capture_output=True, text=True, timeout=120)
        assert submitted.returncode == 0, submitted.stderr
        array, merge = submitted.stdout.split()[-2:]
        _wait("the array and its merge to finish", lambda: not subprocess.run(
            ["squeue", "-h", "-j", f"{array},{merge}"], env=cluster, capture_output=True, text=True).stdout.strip(),
              1500)
        logs = "\n".join(p.read_text()[-1500:] for p in sorted(work.glob("slurm-*.out")))
        assert set(_job_state(array, cluster).split(",")) == {"COMPLETED"}, logs
        assert _job_state(merge, cluster) == "COMPLETED", logs
        assert sorted(p.name for p in out.glob("gradebook-*-of-*.csv")) == \
            [f"gradebook-{k}-of-{SHARDS}.csv" for k in range(1, SHARDS + 1)]
        merged, unsharded = _rows(out / "gradebook.csv"), _rows(work / "whole" / "gradebook.csv")
        assert merged == unsharded and len(merged) == len(KINDS) + 1
    finally:
        shutil.rmtree(work, ignore_errors=True)


def test_an_array_that_does_not_start_at_1_is_refused(cluster):
    """--array=0-2 would grade shards 0/3 (none), 1/3 and 2/3: the script refuses it before grading anything."""
    work = Path(tempfile.mkdtemp(prefix="rlcourse-slurm-bad-", dir="/tmp"))
    try:
        done = subprocess.run(["sbatch", "--parsable", "--array=0-2", "--cpus-per-task=1", "--mem=100",
                               f"--output={work}/slurm-%A_%a.out", str(SLURM / "grade_array.sh"), "hw0_setup",
                               str(work / "class"), str(work / "out")],
                              cwd=REPO, env=dict(cluster, COURSE=str(REPO)), capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        job = done.stdout.strip().split(";")[0]
        _wait("the refused array to end", lambda: not subprocess.run(["squeue", "-h", "-j", job], env=cluster,
                                                                     capture_output=True, text=True).stdout.strip(), 300)
        assert set(_job_state(job, cluster).split(",")) == {"FAILED"}
        assert "--array=1-N" in "".join(p.read_text() for p in work.glob("slurm-*.out"))
        assert not (work / "out").exists()
    finally:
        shutil.rmtree(work, ignore_errors=True)
