"""The searches' shared cache (sidql.codec.shared_cache): each value made once however many
threads ask at once, the byte limit kept, a failure not cached."""

from __future__ import annotations

import threading
import time

import pytest

from sidql.codec.shared_cache import SharedCache


def test_a_value_asked_for_by_many_threads_at_once_is_made_once():
    cache = SharedCache(1000, size=lambda v: 1)
    made, start = [], threading.Barrier(8)

    def make():
        made.append(1)
        time.sleep(0.05)  # long enough for every other thread to ask meanwhile
        return "v"

    got = []

    def ask():
        start.wait()
        got.append(cache.get("k", make))

    threads = [threading.Thread(target=ask) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert got == ["v"] * 8 and len(made) == 1


def test_the_least_recently_used_go_first_beyond_the_limit_but_the_last_two_stay():
    cache = SharedCache(10, size=lambda v: v)
    for k in "abc":
        cache.get(k, lambda: 4)
    assert list(cache.items) == ["b", "c"] and cache.held == 8  # a dropped: 12 > 10
    cache.get("b", lambda: pytest.fail("b is kept"))
    cache.get("d", lambda: 4)
    assert list(cache.items) == ["b", "d"]  # c was the least recently used
    big = SharedCache(1, size=lambda v: v)
    big.get("x", lambda: 5)
    big.get("y", lambda: 5)
    assert list(big.items) == ["x", "y"]  # over the limit, but the last two stay


def test_a_failure_is_raised_and_not_kept():
    cache = SharedCache(10, size=lambda v: 1)
    with pytest.raises(ZeroDivisionError):
        cache.get("k", lambda: 1 / 0)
    assert cache.get("k", lambda: 3) == 3 and not cache.pending
