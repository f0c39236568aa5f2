"""The collector's full passes, timed from a gc callback and reported from the loop.

A gc callback runs inside whatever allocation set the collection off, on any thread, with
that thread's locks held — a library thread in the middle of logging, say, holding a handler's
lock or a queue's mutex. A callback that logs or takes a lock there can wait for a lock its own
thread holds, forever. So `GcWatch` only reads the clock and stores numbers in its own
attributes (each store is one atomic bytecode under the GIL); the event loop reads them with
`take()` and does the logging.
"""

from __future__ import annotations

import time


class GcWatch:
    """Times generation-2 (full) collections; register the instance in `gc.callbacks`."""

    def __init__(self, slow_s: float):
        self.slow_s = slow_s
        self.full = 0  # full passes seen
        self.slow = 0  # of those, slower than slow_s
        self.longest_s = 0.0  # the longest slow pass since the last take()
        self._start: float | None = None
        self._taken = 0

    def __call__(self, phase: str, info: dict) -> None:
        """The gc callback: no lock, no logging, nothing shared but its own numbers."""
        if info.get("generation") != 2:
            return
        now = time.perf_counter()
        if phase == "start":
            self._start = now
            return
        start, self._start = self._start, None
        if start is None:
            return
        took = now - start
        self.full += 1
        if took > self.slow_s:
            self.slow += 1
            self.longest_s = max(self.longest_s, took)

    @property
    def pending(self) -> bool:
        """Slow passes not yet taken."""
        return self.slow != self._taken

    def take(self) -> tuple[int, float]:
        """On the loop: (slow passes since the last take, the longest of them in s). A pass
        that ends on another thread during the take is counted at the next one."""
        slow = self.slow
        new, self._taken = slow - self._taken, slow
        longest, self.longest_s = self.longest_s, 0.0
        return new, longest
