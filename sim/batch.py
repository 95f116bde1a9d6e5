"""One way to run a batch of independent tasks: in this process, a local process pool, or Ray.

``run_batch(fn, items, workers=K, ray=None | "local" | ADDRESS)`` calls ``fn(item)`` for every item
and returns one :class:`Outcome` per item, in input order: its result, or the error it raised
(``"Type: message"``) — a failed task costs only its own item. A tqdm bar counts finished tasks.
``iter_batch`` (same arguments) yields each outcome as its task finishes, keeping a bounded
window of tasks in flight, so a caller that stores results as they arrive holds a bounded amount
of memory however long the batch.

Ray (``pip install sidql[ray]``) is imported lazily, only when asked for: ``ray="local"`` starts a
local runtime with ``workers`` CPUs; any other string is a cluster address (``ray://host:10001`` or
``auto`` on a cluster node). ``fn`` and the items travel to the workers by value (pickled), results
come back by value; so tasks that read input files need the same paths on every node, and the
caller (the driver) writes the outputs.

A large object that many items share (a subject's physics model) goes into them wrapped in
:class:`Shared`: on Ray it is stored once in the object store and each worker fetches and
unpickles it once (:func:`shared_value`), not with every task; elsewhere it travels as it is.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

from tqdm import tqdm

from sim.errors import ArgumentTypeError, SidqlError, UsageError

PARENT_POLL_S = 0.2  # how often a pool worker checks that its parent is alive
#: Held by a task while it writes a file; a worker whose parent died waits for it before exiting,
#: so no half-written temporary file is left behind.
WRITE_LOCK = threading.Lock()


@dataclass
class Outcome:
    """The result of one task, or its error (exactly one is set)."""

    item: Any
    result: Any = None
    error: str | None = None
    bad_input: bool = False

    @property
    def ok(self) -> bool:
        return self.error is None


ERROR_CHARS = 300  # a failure is listed in one line of a summary: longer messages are cut


def one_line(e: BaseException) -> str:
    """``"Type: message"`` of an exception on one line of at most :data:`ERROR_CHARS` characters
    (a library's message can hold whole arrays)."""
    text = " ".join(f"{type(e).__name__}: {e}".split())
    return text if len(text) <= ERROR_CHARS else text[: ERROR_CHARS - 3] + "..."


def _call(fn: Callable, item) -> Outcome:
    try:
        return Outcome(item, result=fn(item))
    except SidqlError as e:  # bad input (a file, a name, a target): listed, the others go on
        return Outcome(item, error=str(e), bad_input=True)
    except Exception as e:  # a bug in one task must not cost the others; report it with its type
        return Outcome(item, error=one_line(e))


def _call_away(fn: Callable, item) -> Outcome:
    """:func:`_call` in a worker: the outcome comes back without its item (the driver has it
    and puts it back), so a task's inputs do not travel twice."""
    outcome = _call(fn, item)
    outcome.item = None
    return outcome


def _init_worker(parent_pid: int) -> None:
    """Pool initializer: one compute thread per worker (the pool's processes already fill the
    cores; a library's own thread pool in each would oversubscribe them), then :func:`_watch_parent`."""
    for var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
        os.environ[var] = "1"  # read by torch / BLAS when this worker first imports them
    torch = sys.modules.get("torch")  # already imported by the parent (fork): set it; never import
    if torch is not None:
        torch.set_num_threads(1)
    _watch_parent(parent_pid)


def _watch_parent(parent_pid: int) -> None:
    """Pool initializer: a daemon thread ends this worker when its parent process goes away.

    A parent killed by SIGKILL cannot tell its workers; without this they would finish the queued
    work and then wait for more forever. The check is the parent pid changing (the worker was
    re-parented); the thread takes the write lock first, so no half-written temporary is left.
    """
    ppid = os.getppid()  # the parent itself (fork, spawn) or a forkserver that dies with it

    def parent_alive() -> bool:
        if os.getppid() != ppid:
            return False
        if ppid != parent_pid:
            try:
                os.kill(parent_pid, 0)
            except ProcessLookupError:
                return False
            except PermissionError:
                pass
        return True

    def watch():
        while parent_alive():
            time.sleep(PARENT_POLL_S)
        with WRITE_LOCK:
            os._exit(1)

    threading.Thread(target=watch, name="watch-parent", daemon=True).start()


def check_batch_arguments(fn, workers) -> None:
    """A callable ``fn`` and ``workers`` None or a whole number >= 1, else a UsageError kind."""
    if not callable(fn):
        raise ArgumentTypeError(f"fn must be callable; got {type(fn).__name__}")
    if workers is not None and (
        isinstance(workers, bool) or not isinstance(workers, int) or workers < 1
    ):
        raise UsageError(f"workers must be a whole number >= 1; got {workers!r}")


def run_batch(
    fn: Callable,
    items: Sequence,
    *,
    workers: int | None = None,
    ray: str | None = None,
    desc: str = "tasks",
    progress: bool = True,
) -> list[Outcome]:
    """``fn(item)`` for every item (see the module docstring); outcomes in input order.

    Holds every result until the last task ends: for batches whose results are small or few. A
    batch whose results are large (clips) uses :func:`iter_batch` and stores each as it arrives.

    Args:
        fn: a picklable (module-level) function.
        workers: worker processes (default: CPU cores; 1 runs in this process); for Ray: the
            local runtime's CPU count (ignored for a cluster, which has its own).
        ray: None (process pool), ``"local"`` or a cluster address.
    """
    check_batch_arguments(fn, workers)
    items = list(items)
    out: list[Outcome | None] = [None] * len(items)
    for i, outcome in iter_batch(
        fn, items, workers=workers, ray=ray, desc=desc, progress=progress, total=len(items)
    ):
        out[i] = outcome
    return out  # type: ignore[return-value]


def iter_batch(
    fn: Callable,
    items: Iterable,
    *,
    workers: int | None = None,
    ray: str | None = None,
    desc: str = "tasks",
    progress: bool = True,
    total: int | None = None,
    in_flight: int | None = None,
) -> Iterator[tuple[int, Outcome]]:
    """``(position, Outcome)`` of ``fn(item)`` for every item, as the tasks finish.

    ``items`` is read lazily (it may be a generator, even an endless one: stop iterating and the
    tasks still running are cancelled) and at most ``in_flight`` tasks are submitted and not yet
    yielded (default: twice the workers or the cluster's CPUs), so the memory this process holds
    is bounded by the window, not by the batch: the caller stores each result as it arrives.
    Waiting is on the window only, so a batch of n tasks costs O(n * window), never O(n^2).

    Args:
        total: number of items, for the progress bar (None: unknown).
        others: as :func:`run_batch`.
    """
    check_batch_arguments(fn, workers)
    bar = tqdm(total=total, desc=desc, unit="task", disable=not progress)
    try:
        if ray is not None:
            source = _run_ray(fn, iter(items), workers, ray, in_flight)
        else:
            workers = workers or os.cpu_count() or 1
            if workers == 1:
                source = ((i, _call(fn, item)) for i, item in enumerate(items))
            else:
                source = _run_pool(fn, iter(items), workers, in_flight or 2 * workers)
        for i, outcome in source:
            bar.update()
            yield i, outcome
    finally:
        bar.close()


def _new_pool(workers: int) -> ProcessPoolExecutor:
    return ProcessPoolExecutor(
        max_workers=workers, initializer=_init_worker, initargs=(os.getpid(),)
    )


def _run_pool(fn, items: Iterator, workers: int, in_flight: int):
    """Tasks in a process pool, a window of ``in_flight`` at a time. A worker that dies outright
    (a segfault, the OOM killer) breaks the pool: the tasks then in flight are failed items, and
    a fresh pool takes the rest."""
    pool = None
    pending: dict = {}  # future -> (position, item, its pool)
    position = 0
    try:
        while True:
            if pool is None:
                pool = _new_pool(workers)
            while len(pending) < in_flight:  # keep the window full, reading items lazily
                item = next(items, _END)
                if item is _END:
                    break
                try:
                    fut = pool.submit(_call_away, fn, item)
                except BrokenProcessPool:  # broke since the last wait: a fresh pool takes it
                    pool.shutdown(wait=True, cancel_futures=True)
                    pool = _new_pool(workers)
                    fut = pool.submit(_call_away, fn, item)
                pending[fut] = (position, item, pool)
                position += 1
            if not pending:
                return
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                i, item, its_pool = pending.pop(fut)
                try:
                    outcome = fut.result()
                    outcome.item = item
                except Exception as e:  # the worker died (not an error inside fn)
                    outcome = Outcome(item, error=one_line(e))
                    if isinstance(e, BrokenProcessPool) and its_pool is pool:
                        pool.shutdown(wait=True, cancel_futures=True)
                        pool = None  # the rest of the window fails with it; a new pool follows
                yield i, outcome
    finally:  # also when the caller stops early: queued tasks are cancelled, running ones end
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


_END = object()


class Shared:
    """A large object several items of one batch hold (read it with :func:`shared_value`).

    Pickled for a Ray task, it becomes a reference to one copy in Ray's object store, made the
    first time it is sent; a worker fetches and unpickles it once and keeps it for the next
    tasks (the last :data:`SHARED_CACHE` of them). Pickled any other way (a process pool), it
    carries its value.
    """

    def __init__(self, value):
        self.value = value
        self._ref = None

    def __reduce__(self):
        if not _SENDING_TO_RAY:
            return Shared, (self.value,)
        if self._ref is None:
            import ray  # lazy: an optional extra, and slow to import

            self._ref = ray.put(self.value)
        return _shared_from_ref, ([self._ref],)  # nested in a list: Ray does not fetch it


def shared_value(x):
    """The value of a :class:`Shared` (anything else: itself)."""
    return x.value if isinstance(x, Shared) else x


#: How many :class:`Shared` values a Ray worker keeps between tasks.
SHARED_CACHE = 8
_SENDING_TO_RAY = False  # set while this driver submits a Ray task (see Shared.__reduce__)
_WORKER_SHARED: dict = {}  # in a Ray worker: object ref id -> Shared, oldest first


def _shared_from_ref(box) -> Shared:
    """In a Ray worker: the :class:`Shared` whose value is stored at ``box[0]``, fetched once."""
    ref = box[0]
    key = ref.hex()
    out = _WORKER_SHARED.pop(key, None)
    if out is None:
        import ray  # lazy: an optional extra, and slow to import

        out = Shared(ray.get(ref))
        while len(_WORKER_SHARED) >= SHARED_CACHE:
            _WORKER_SHARED.pop(next(iter(_WORKER_SHARED)))
    _WORKER_SHARED[key] = out  # most recently used last
    return out


class RayConnectionError(ConnectionError):
    """This process could not join the Ray cluster named by its address (the message says how)."""


def _ray_connect(ray, address: str, workers: int | None) -> None:
    """Start a local runtime (``address == "local"``) or join the cluster at ``address``."""
    if address == "local":
        ray.init(num_cpus=workers or os.cpu_count(), include_dashboard=False,
                 log_to_driver=False)  # fmt: skip
        return
    try:
        ray.init(address=address, log_to_driver=False)
    except Exception as e:  # Ray raises ConnectionError, RuntimeError or its own kinds
        text = " ".join(str(e).split())
        hint = ""
        if "auth" in text.lower() or "token" in text.lower() or not os.environ.get("RAY_AUTH_MODE"):
            hint = (
                "; a cluster started by 'ray start --head' (Ray >= 2.59) requires token "
                "authentication: export RAY_AUTH_MODE=token and the cluster's token "
                "(RAY_AUTH_TOKEN, RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token) here and on every "
                "node; see docs/synthetic.md, 'A Ray cluster'"
            )
        raise RayConnectionError(
            f"cannot join the Ray cluster at {address}: {text[:200]}{hint}"
        ) from None


@contextmanager
def ray_session(address: str | None, workers: int | None = None):
    """Within the block, batches on Ray share one connection (``address`` as :func:`run_batch`'s
    ``ray``; None: nothing is started): a command that runs several batches starts or joins
    Ray once, and leaves it on exit."""
    if address is None:
        yield
        return
    import ray  # lazy: an optional extra, and slow to import

    if ray.is_initialized():
        yield
        return
    _ray_connect(ray, address, workers)
    try:
        yield
    finally:
        ray.shutdown()


def _run_ray(fn, items: Iterator, workers, address, in_flight):
    import ray  # lazy: an optional extra, and slow to import

    started = False
    if not ray.is_initialized():
        _ray_connect(ray, address, workers)
        started = True
    pending: list = []  # the window of running tasks' object refs
    where: dict = {}  # object ref -> (position, item)
    try:
        if in_flight is None:
            in_flight = max(4, 2 * int(ray.cluster_resources().get("CPU", 1)))
        remote = ray.remote(_call_away)
        fn_ref = ray.put(fn)  # shipped once, not with every task
        position = 0
        while True:
            while len(pending) < in_flight:
                item = next(items, _END)
                if item is _END:
                    break
                ref = _submit(remote, fn_ref, item)
                pending.append(ref)
                where[ref] = (position, item)
                position += 1
            if not pending:
                return
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                i, item = where.pop(ref)
                try:
                    outcome = ray.get(ref)
                    outcome.item = item
                except Exception as e:  # the worker died (not an error inside fn)
                    outcome = Outcome(item, error=one_line(e))
                yield i, outcome
    finally:
        for ref in pending:  # the caller stopped early: the rest is not needed
            ray.cancel(ref)
        if started:
            ray.shutdown()


def _submit(remote, fn_ref, item):
    """``remote.remote(fn_ref, item)`` with the :class:`Shared` values in ``item`` sent by
    reference (Ray pickles a task's arguments while it is submitted)."""
    global _SENDING_TO_RAY
    _SENDING_TO_RAY = True
    try:
        return remote.remote(fn_ref, item)
    finally:
        _SENDING_TO_RAY = False
