"""rlcourse.progress: a tqdm bar for a person at a terminal, a few plain lines for a log."""
from __future__ import annotations

import io

import rlcourse.progress as progress_mod
from rlcourse.progress import progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_fast_loop_in_a_log_writes_at_most_a_few_lines():
    log = io.StringIO()
    assert sum(progress(range(1000), desc="rollout", stream=log)) == sum(range(1000))
    assert "\r" not in log.getvalue() and len(log.getvalue().splitlines()) <= 2


def test_a_slow_loop_in_a_log_writes_one_line_per_interval_and_a_last_one(monkeypatch):
    clock = iter(range(0, 10**6, 20))  # every read of the clock is 20 ms later: 1,000 steps take 20 s
    monkeypatch.setattr(progress_mod, "_clock", lambda: next(clock) / 1000)
    log = io.StringIO()
    for _ in progress(range(1000), desc="rollout Hopper-v5", stream=log, interval=5.0):
        pass
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and len(lines) == 5, lines
    assert lines[0].startswith("rollout Hopper-v5: 250/1000 (25%) after 5 s")
    assert lines[-1].startswith("rollout Hopper-v5: 1000/1000 (100%) finished in 20 s")


def test_a_loop_stopped_early_still_ends_its_log(monkeypatch):
    clock = iter(range(0, 10**6, 20))
    monkeypatch.setattr(progress_mod, "_clock", lambda: next(clock) / 1000)
    log = io.StringIO()
    for t in progress(range(1000), stream=log, interval=5.0):
        if t == 399:
            break
    assert log.getvalue().splitlines()[-1].startswith("400/1000 (40%) stopped after")


def test_a_terminal_gets_a_tqdm_bar_and_disable_silences_both():
    tty = Terminal()
    assert list(progress(range(50), desc="bar", stream=tty)) == list(range(50))
    assert "\r" in tty.getvalue() and "bar" in tty.getvalue()
    quiet = Terminal()
    assert list(progress(range(5), stream=quiet, disable=True)) == list(range(5)) and quiet.getvalue() == ""
