"""One way to run a batch of independent tasks: in this process, a local process pool, or Ray.

``run_batch(fn, items, workers=K, ray=None | "local" | ADDRESS)`` calls ``fn(item)`` for every item
and returns one :class:`Outcome` per item, in input order: its result, or the error it raised
(``"Type: message"``) — a failed task costs only its own item. A tqdm bar counts finished tasks.

Ray (``pip install sidql[ray]``) is imported lazily, only when asked for: ``ray="local"`` starts a
local runtime with ``workers`` CPUs; any other string is a cluster address (``ray://host:10001`` or
``auto`` on a cluster node). ``fn`` and the items travel to the workers by value (pickled), results
come back by value; so tasks that read input files need the same paths on every node, and the
caller (the driver) writes the outputs.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from typing import Any

from tqdm import tqdm

from sim.errors import SidqlError

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

    Args:
        fn: a picklable (module-level) function.
        workers: worker processes (default: CPU cores; 1 runs in this process); for Ray: the
            local runtime's CPU count (ignored for a cluster, which has its own).
        ray: None (process pool), ``"local"`` or a cluster address.
    """
    items = list(items)
    out: list[Outcome | None] = [None] * len(items)
    bar = tqdm(total=len(items), desc=desc, unit="task", disable=not progress)
    if ray is not None:
        _run_ray(fn, items, out, bar, workers, ray)
    else:
        workers = workers or min(len(items), os.cpu_count() or 1) or 1
        if workers == 1:
            for i, item in enumerate(items):
                out[i] = _call(fn, item)
                bar.update()
        else:
            with ProcessPoolExecutor(
                max_workers=workers, initializer=_init_worker, initargs=(os.getpid(),)
            ) as pool:
                futures = {pool.submit(_call, fn, item): i for i, item in enumerate(items)}
                for fut in as_completed(futures):
                    i = futures[fut]
                    try:
                        out[i] = fut.result()
                    except Exception as e:  # the worker died (not an error inside fn): the
                        out[i] = Outcome(items[i], error=one_line(e))  # pool fails what is left
                    bar.update()
    bar.close()
    return out  # type: ignore[return-value]


def _run_ray(fn, items, out, bar, workers, address) -> None:
    import ray  # lazy: an optional extra, and slow to import

    started = False
    if not ray.is_initialized():
        if address == "local":
            ray.init(num_cpus=workers or os.cpu_count(), include_dashboard=False,
                     log_to_driver=False)  # fmt: skip
        else:
            ray.init(address=address, log_to_driver=False)
        started = True
    try:
        remote = ray.remote(_call)
        fn_ref = ray.put(fn)
        pending = {remote.remote(fn_ref, item): i for i, item in enumerate(items)}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                i = pending.pop(ref)
                try:
                    out[i] = ray.get(ref)
                except Exception as e:  # the worker died (not an error inside fn)
                    out[i] = Outcome(items[i], error=one_line(e))
                bar.update()
    finally:
        if started:
            ray.shutdown()
