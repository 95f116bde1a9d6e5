"""sim.batch.run_batch: order, isolation of failures, same results in-process and in a pool."""

from __future__ import annotations

import operator
import os
import sys

import pytest

from sim.batch import ERROR_CHARS, run_batch
from sim.errors import MotionDataError, UnknownNameError


def _work(x: int) -> int:
    if x == 3:
        raise MotionDataError("f.amc", 7, "bad frame")
    if x == 5:
        raise ZeroDivisionError("boom")
    if x == 6:
        raise UnknownNameError("kind", "jump", ("track", "fall"))
    return x * x


@pytest.mark.parametrize("workers", [1, 2])
def test_failures_cost_only_their_item_and_order_is_kept(workers):
    out = run_batch(_work, range(8), workers=workers, progress=False)
    assert [o.item for o in out] == list(range(8))
    assert [o.result for o in out if o.ok] == [x * x for x in range(8) if x not in (3, 5, 6)]
    bad = {o.item: o for o in out if not o.ok}
    assert set(bad) == {3, 5, 6}
    assert bad[6].bad_input and bad[6].error == "unknown kind 'jump'; known: track, fall"
    assert bad[3].bad_input and "f.amc" in bad[3].error and "bad frame" in bad[3].error
    assert not bad[5].bad_input and bad[5].error.startswith("ZeroDivisionError")


def test_empty_batch():
    assert run_batch(_work, [], workers=2, progress=False) == []


def _noisy(x: int) -> int:
    raise TypeError("bad arguments:\n" + "0., " * 500)


def test_a_failure_is_listed_on_one_short_line():
    (o,) = run_batch(_noisy, [1], workers=1, progress=False)
    assert "\n" not in o.error and len(o.error) <= ERROR_CHARS
    assert o.error.startswith("TypeError: bad arguments: 0., 0.,") and o.error.endswith("...")


def _dies(x: int) -> int:
    if x == 2:
        import os

        os._exit(3)  # a worker killed outright (a segfault in MuJoCo, the OOM killer)
    return x


def test_a_dead_pool_worker_is_a_failed_item_not_a_crash_of_the_batch():
    out = run_batch(_dies, range(4), workers=2, progress=False)
    assert [o.item for o in out] == list(range(4))
    assert not out[2].ok and "BrokenProcessPool" in out[2].error
    assert all(o.result == o.item for o in out if o.ok)


def _threads(_: int) -> tuple:
    import os
    import sys

    torch = sys.modules.get("torch")
    return os.environ.get("OMP_NUM_THREADS"), torch.get_num_threads() if torch else None


def test_a_pool_worker_computes_on_one_thread():
    """The pool's processes fill the cores: each worker's libraries get one thread (no
    oversubscription), also torch when the parent had imported it before the pool started."""
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        out = run_batch(_threads, range(2), workers=2, progress=False)
    finally:
        torch.set_num_threads(before)
    for o in out:
        assert o.ok, o.error
        omp, torch_threads = o.result
        assert omp == "1" and torch_threads in (1, None)


def _square(x: int) -> int:
    return x * x


def _lazy(n: int, pulled: list):
    for i in range(n):
        pulled.append(i)
        yield i


@pytest.mark.parametrize("workers", [1, 2])
def test_items_are_read_lazily_with_a_bounded_window_in_flight(workers):
    """iter_batch yields results as tasks finish and never holds more than its window of
    submitted-but-unyielded tasks, so a caller storing each result holds bounded memory; an
    endless item stream is fine, and stopping early stops the reading."""
    from sim.batch import iter_batch

    pulled: list = []
    seen = {}
    for i, o in iter_batch(_square, _lazy(40, pulled), workers=workers, in_flight=3,
                           progress=False):  # fmt: skip
        seen[i] = o.result
        assert len(pulled) - len(seen) <= 3
    assert seen == {i: i * i for i in range(40)}
    pulled.clear()
    for k, _ in enumerate(iter_batch(_square, _lazy(10**9, pulled), workers=workers,
                                     in_flight=3, progress=False)):  # fmt: skip
        if k == 4:
            break
    assert len(pulled) <= 5 + 3


def test_on_ray_items_are_read_lazily_with_a_bounded_window_in_flight():
    pytest.importorskip("ray")
    from sim.batch import iter_batch

    pulled: list = []
    seen = {}
    for i, o in iter_batch(operator.neg, _lazy(12, pulled), workers=2, ray="local", in_flight=2,
                           progress=False):  # fmt: skip
        seen[i] = o.result
        assert len(pulled) - len(seen) <= 2
    assert seen == {i: -i for i in range(12)}


def _dies_slowly(x: int) -> int:
    import time

    time.sleep(0.05)  # long enough for the pool to notice the death before the batch ends
    return _dies(x)


def test_after_a_dead_worker_a_fresh_pool_takes_the_rest():
    """A worker killed outright fails the tasks of its pool then in flight; the items after them
    run in a fresh pool."""
    out = run_batch(_dies_slowly, range(24), workers=2, progress=False)
    assert not out[2].ok
    assert all(o.ok and o.result == o.item for o in out[-8:])
    assert sum(not o.ok for o in out) <= 12


_COUNT = "SIDQL_TEST_UNPICKLED"  # in each process's environment: _Counted unpickled so often


class _Counted:
    """A payload that counts, in the process that unpickles it, how often that happens."""

    def __init__(self, data):
        self.data = data

    def __reduce__(self):
        return _counted, (self.data,)


def _counted(data):
    os.environ[_COUNT] = str(int(os.environ.get(_COUNT, "0")) + 1)
    return _Counted(data)


def _reads_shared(item):
    from sim.batch import shared_value

    k, shared = item
    return os.getpid(), int(os.environ.get(_COUNT, "0")), k + int(shared_value(shared).data.sum())


def test_on_ray_a_shared_value_reaches_each_worker_once():
    """Items holding one Shared payload: on Ray each worker unpickles it once (not once per
    task); in a process pool and in this process the same results, the payload by value; the
    items do not travel back with the outcomes (each outcome still names its item)."""
    ray = pytest.importorskip("ray")
    import numpy as np

    from sim.batch import Shared, run_batch

    shared = Shared(_Counted(np.ones(50_000)))
    items = [(k, shared) for k in range(12)]
    want = [k + 50_000 for k in range(12)]
    for workers in (1, 2):  # first: by value (Ray's pickling-by-value below changes this module)
        out = run_batch(_reads_shared, items, workers=workers, progress=False)
        assert [o.result and o.result[2] for o in out] == want, [o.error for o in out][:2]
        assert all(o.item is item for o, item in zip(out, items, strict=True))
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers lack tests/
    assert int(os.environ.get(_COUNT, "0")) == 0  # outcomes come back without their items
    out = run_batch(_reads_shared, items, workers=2, ray="local", progress=False)
    assert [o.result[2] for o in out] == want, [o.error for o in out]
    per_worker = {}
    for pid, seen, _ in (o.result for o in out):
        per_worker[pid] = max(per_worker.get(pid, 0), seen)
    assert set(per_worker.values()) == {1}, [o.result[:2] for o in out]  # once per worker
