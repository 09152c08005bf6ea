"""The reference's answers kept across submissions: only plain-data calls, decoded afresh for every caller."""
from __future__ import annotations

import numpy as np

from autograder.core.session import LocalTransport, Namespace, ReferenceCache
from autograder.suite import lend


def _reference(calls: list[str]) -> dict:
    def total(x, scale=1.0):
        calls.append("total")
        return {"sum": x.sum() * scale, "copy": x.copy()}

    def draw(rng):
        calls.append("draw")
        return rng.normal()

    return {"total": total, "draw": draw}


def test_a_plain_call_is_computed_once_and_each_caller_gets_its_own_copy():
    calls: list[str] = []
    cache = ReferenceCache()
    namespace = _reference(calls)
    first = Namespace(LocalTransport(namespace, cache=cache), "reference").total(np.arange(4.0), scale=2.0)
    second = Namespace(LocalTransport(namespace, cache=cache), "reference").total(np.arange(4.0), scale=2.0)
    assert calls == ["total"] and cache.hits == 1
    assert first["sum"] == second["sum"] == 12.0 and first["copy"] is not second["copy"]
    np.testing.assert_array_equal(second["copy"], np.arange(4.0))
    Namespace(LocalTransport(namespace, cache=cache), "reference").total(np.arange(4.0), scale=3.0)
    Namespace(LocalTransport(namespace, cache=cache), "reference").total(np.arange(5.0), scale=2.0)
    assert calls == ["total"] * 3, "other arguments are another question"


def test_a_call_given_an_object_is_never_kept():
    calls: list[str] = []
    cache = ReferenceCache()
    namespace = _reference(calls)
    draws = [Namespace(LocalTransport(namespace, cache=cache), "reference").draw(lend(np.random.default_rng(0), methods=["normal"]))
             for _ in range(2)]
    assert calls == ["draw", "draw"] and not cache.answers, "a generator's state must advance as it would"
    assert draws[0] == draws[1]


def test_without_a_cache_or_over_its_size_nothing_is_kept():
    calls: list[str] = []
    namespace = _reference(calls)
    for _ in range(2):
        Namespace(LocalTransport(namespace), "reference").total(np.ones(3))
    small = ReferenceCache(max_bytes=10)
    for _ in range(2):
        Namespace(LocalTransport(namespace, cache=small), "reference").total(np.ones(3))
    assert calls == ["total"] * 4 and not small.answers
    assert ReferenceCache.key({"op": "call", "target": "helpers.x", "args": []}, []) is None
    assert ReferenceCache.key({"op": "eval", "expr": "1"}, []) is None
