"""A worker and the grader share one CPU while a lent object's round trips come quickly, and only then."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from autograder.core import pairing
from conftest import REPO

pytestmark = pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="pinning to one CPU of one changes nothing")

CELL = '''
import time

def looks(env, n, pause=0.0, then=0):
    seen = [env.look() for _ in range(n)]
    start = time.monotonic()
    while time.monotonic() - start < pause:  # computing, no messages
        pass
    return seen + [env.look() for _ in range(then)]
'''


class Probe:
    """A lent object that reports, from the grader, where the grader's thread and the worker may run."""

    def __init__(self, pid: int) -> None:
        self.pid = pid

    def look(self) -> list[list[int]]:
        return [sorted(os.sched_getaffinity(0)), sorted(os.sched_getaffinity(self.pid))]


@pytest.fixture(scope="module")
def session():
    from autograder.core import course
    from autograder.core.session import Cell, Session
    from autograder.core.supervisor import Zygote
    from autograder.sandbox.config import Limits, SpawnConfig

    zygote = Zygote(["numpy"])
    session = Session(zygote, [Cell("probe", CELL, stub="looks")], SpawnConfig(course.sandbox_view(()), Limits()))
    session.start()
    assert session.status["probe"].ok, session.status["probe"].message
    try:
        worker = session.worker.pid
        os.sched_setaffinity(worker, os.sched_getaffinity(worker))  # allowed only where pinning it is
    except PermissionError:
        session.close()
        zygote.close()
        pytest.skip("this grader may not set its worker's CPUs (no CAP_SYS_NICE, and the worker is another uid): "
                    "nothing is pinned, test_without_the_right_to_pin_nothing_is_pinned_and_grading_goes_on checks that")
    yield session
    session.close()
    zygote.close()


def looks(session, n: int, **kwargs) -> list[list[list[int]]]:
    from autograder.core.session import Lend, Namespace

    probe = Probe(session.worker.pid)
    return Namespace(session, "student").looks(Lend(probe, ("look",), ()), n, **kwargs)


def pinned(look: list[list[int]]) -> bool:
    grader, worker = look
    return len(grader) == 1 and grader == worker


@pytest.fixture
def patient(monkeypatch):
    """No release for a quiet worker: on a loaded machine a worker may wait more than 2 ms for its CPU between two
    callbacks, which lets the pair go (as it should) and would make the tests below depend on the load."""
    from autograder.core import session as session_module

    monkeypatch.setattr(session_module, "IDLE_SECONDS", 10.0)


def test_quick_round_trips_share_the_graders_cpu_and_both_are_let_go_after(session, patient):
    everywhere = sorted(os.sched_getaffinity(0))
    worker_before = sorted(os.sched_getaffinity(session.worker.pid))
    seen = looks(session, 3 * pairing.PAIR_AFTER)
    assert not any(pinned(look) for look in seen[:pairing.PAIR_AFTER - 1]), "a few callbacks are not pinned"
    assert all(pinned(look) for look in seen[pairing.PAIR_AFTER - 1:]), seen
    assert sorted(os.sched_getaffinity(0)) == everywhere, "the grader's thread runs anywhere again"
    assert sorted(os.sched_getaffinity(session.worker.pid)) == worker_before, "and so does the worker"


def test_a_worker_that_computes_between_messages_is_let_go(session, monkeypatch):
    from autograder.core import session as session_module

    # The release rule with a longer quiet time and pause than the grader's 2 ms: on a loaded machine a worker
    # may wait for its CPU for milliseconds between two quick callbacks (tens of busy loops on 2 cores did).
    monkeypatch.setattr(session_module, "IDLE_SECONDS", 0.25)
    seen = looks(session, 2 * pairing.PAIR_AFTER, pause=1.0, then=pairing.PAIR_AFTER - 1)
    assert pinned(seen[2 * pairing.PAIR_AFTER - 1])
    assert not any(pinned(look) for look in seen[2 * pairing.PAIR_AFTER:]), "released when it went quiet, not re-pinned"


def test_pinned_pairs_are_let_go_now_and_then_for_the_scheduler_to_choose_again(session, patient, monkeypatch):
    monkeypatch.setattr(pairing, "REPAIR_EVERY", 5)
    seen = [pinned(look) for look in looks(session, 4 * pairing.PAIR_AFTER)]
    first = pairing.PAIR_AFTER - 1
    assert seen[first:first + 5] == [True] * 5
    assert seen[first + 5:first + 5 + pairing.PAIR_AFTER] == [False] * pairing.PAIR_AFTER
    assert seen[first + 5 + pairing.PAIR_AFTER], "pinned again after as many quick callbacks"


def test_a_pair_whose_worker_is_gone_lets_the_grader_go():
    pair = pairing.CpuPair(os.getpid())
    everywhere = os.sched_getaffinity(0)
    for _ in range(pairing.PAIR_AFTER):
        pair.callback()
    assert pair.pinned and len(os.sched_getaffinity(0)) == 1
    pair.pid = 2**22 + 12345  # no such process: restoring its mask fails quietly
    pair.release()
    assert not pair.pinned and os.sched_getaffinity(0) == everywhere


WITHOUT_RIGHT = """
import json, os
from autograder.core import course
from autograder.core.session import Cell, Lend, Namespace, Session
from autograder.core.supervisor import Zygote
from autograder.sandbox.config import Limits, SpawnConfig

class Probe:
    def look(self):
        return sorted(os.sched_getaffinity(0))

zygote = Zygote(["numpy"])
session = Session(zygote, [Cell("probe", CELL, stub="looks")], SpawnConfig(course.sandbox_view(()), Limits()))
session.start()
seen = Namespace(session, "student").looks(Lend(Probe(), ("look",), ()), 64)
print(json.dumps({"seen": seen, "pinnings": session.pair.pinnings, "isolation": session.isolation}))
session.close()
zygote.close()
"""


def test_without_the_right_to_pin_nothing_is_pinned_and_grading_goes_on():
    """A grader whose root lacks CAP_SYS_NICE (a container's default set) may not set the CPUs of a worker that
    runs as another uid: the round trips still run, on any CPU."""
    if os.geteuid() != 0 or not shutil.which("setpriv"):
        pytest.skip("needs root and setpriv to drop one capability")
    done = subprocess.run(["setpriv", "--bounding-set=-sys_nice", "--inh-caps=-sys_nice", "--", sys.executable, "-c",
                           f"CELL = {CELL!r}\n" + WITHOUT_RIGHT], cwd=REPO, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    out = json.loads(done.stdout.splitlines()[-1])
    everywhere = sorted(os.sched_getaffinity(0))
    assert out["pinnings"] == 0 and out["seen"] == [everywhere] * 64, out
