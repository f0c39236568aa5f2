"""Waiting for events in tests.

On a busy machine everything takes longer, so a wait ends when its event happens, not at a
wall-clock margin. Its only bound is the test's own budget: the test's pytest-timeout less a
reserve for teardown (`budget`, set for every test by the autouse fixture in conftest). A wait
still unfinished then fails naming what it waited for, where pytest-timeout itself would end
the whole run (thread method). Where a time is the claim, the test asserts it from the event's
own timestamp after the wait.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any

# The end of the current test's budget (time.monotonic()); None outside a test.
_deadline: list[float | None] = [None]
# Kept back from the test's pytest-timeout for its teardown (closing ports, the worker).
TEARDOWN_RESERVE = 0.2


def budget(timeout_s: float | None) -> None:
    """Start the current test's budget: `timeout_s` is its pytest-timeout (None: unbounded)."""
    _deadline[0] = None if not timeout_s else time.monotonic() + timeout_s * (1 - TEARDOWN_RESERVE)


async def until(
    predicate: Callable[[], Any], what: str, pause: Callable[[float], Awaitable[Any]] | None = None
) -> Any:
    """predicate()'s first truthy value, polled every 20 ms (`pause`: how to wait, such as
    Textual's pilot.pause); AssertionError naming `what` if the test's budget runs out."""
    wait = pause or asyncio.sleep
    while not (found := predicate()):
        deadline = _deadline[0]
        assert deadline is None or time.monotonic() < deadline, f"timed out waiting for {what}"
        await wait(0.02)
    return found


def until_sync(predicate: Callable[[], Any], what: str, pause_s: float = 0.05) -> Any:
    """`until` for a test without an event loop (a child process watched through /proc)."""
    while not (found := predicate()):
        deadline = _deadline[0]
        assert deadline is None or time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(pause_s)
    return found
