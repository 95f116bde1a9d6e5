"""A bounded cache shared by threads, each value made once even when two threads ask at once.

The position coding's searches of one chart (one per reconstruction, side by side in threads,
:mod:`sidql.codec.position_coding`) code the same plans at the same steps more than once (the
densest and the sparsest plan are every reconstruction's): the codes depend on the values, the
keyframes and the step only. They share one :class:`SharedCache`: a value is made by the first
thread that asks for it while any other waits for it, then kept, the least recently used
dropped first beyond a byte limit. What a caller gets never depends on the timing, only how much
is made twice.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable


class SharedCache:
    """Values by key, at most ``limit`` bytes (``size(value)``) and at least the last ``keep``."""

    def __init__(self, limit: int, size: Callable[[object], int], keep: int = 2):
        self.limit, self.size, self.keep = limit, size, keep
        self.items: OrderedDict = OrderedDict()
        self.held = 0
        self.lock = threading.Lock()
        self.pending: dict = {}  # key -> Event of the thread making it

    def get(self, key: Hashable, make: Callable[[], object]):
        """The value of ``key``: kept, or ``make()`` (by this thread, or by another that was
        already making it)."""
        while True:
            with self.lock:
                if key in self.items:
                    self.items.move_to_end(key)
                    return self.items[key]
                made = self.pending.get(key)
                if made is None:
                    self.pending[key] = made = threading.Event()
                    break
            made.wait()  # another thread makes it; then look again (it may have failed)
        try:
            value = make()
            with self.lock:
                self.items[key] = value
                self.held += self.size(value)
                while len(self.items) > self.keep and self.held > self.limit:
                    self.held -= self.size(self.items.popitem(last=False)[1])
        finally:
            with self.lock:
                del self.pending[key]
            made.set()
        return value
