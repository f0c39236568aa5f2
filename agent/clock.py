"""The one source of time: a monotonic clock the agent, the simulator and tests share.

Everything that waits for a moment in time asks the clock (`sleep_until`) instead of calling
asyncio.sleep with a relative delay, so schedules run against absolute deadlines and a test can
substitute virtual time.
"""

from __future__ import annotations

import asyncio

from drivers.values import Clock

__all__ = ["Clock", "LoopClock", "VirtualClock"]


class LoopClock:
    """The running event loop's monotonic clock (time.monotonic on every platform we use)."""

    def now(self) -> float:
        return asyncio.get_running_loop().time()

    async def sleep_until(self, deadline: float) -> None:
        delay = deadline - self.now()
        # asyncio.sleep(0) still yields, so a late caller lets other tasks run.
        await asyncio.sleep(max(0.0, delay))


class VirtualClock:
    """Virtual time for tests and faster-than-real-time simulation.

    sleep_until jumps time to the deadline plus `lateness(deadline)` — a callable that models
    how late a real loop wakes (default: on time) — and yields once to the loop.
    """

    def __init__(self, start: float = 0.0, lateness=None):
        self._now = start
        self._lateness = lateness or (lambda deadline: 0.0)

    def now(self) -> float:
        return self._now

    def advance(self, seconds: float) -> None:
        self._now += seconds

    async def sleep_until(self, deadline: float) -> None:
        if deadline > self._now:
            self._now = deadline + self._lateness(deadline)
        await asyncio.sleep(0)
