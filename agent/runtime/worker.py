"""The identification worker: one spawned process, started (and warmed up) with the agent, and
stopped without ever blocking the loop on it."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import multiprocessing
import os
import sys
from collections.abc import Callable
from concurrent.futures import Executor, ProcessPoolExecutor

from agent.ident import job as jobs

log = logging.getLogger(__name__)

# At shutdown, how long an identification in the worker may go on before the worker is killed.
WORKER_STOP_S = 2.0

# The worker's scheduling below the agent's: on a small flight computer the identification takes
# the CPU the agent (event loop, drivers, MAVSDK and radio threads) leaves over. SCHED_BATCH at
# nice +10 (Linux): the scheduler treats it as CPU-bound, so it never preempts a waking agent
# thread, and its nice weight gives it about a tenth of a busy core's time. Not SCHED_IDLE: a
# SCHED_IDLE process runs only when nothing else wants the CPU, so on a machine kept busy by
# other work the worker never finishes even its warm-up, identification stops, and the
# agent's shutdown waits for it for ever. Elsewhere: nice +10 alone.
WORKER_NICE = 10


def new_worker() -> ProcessPoolExecutor:
    """The identification worker: one process, spawned (no fork of a threaded process), its
    priority lowered and its numerics warmed up by `start_worker`."""
    context = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(1, mp_context=context, initializer=start_worker)


def start_worker() -> None:
    """The worker process's initializer: tie its life to the agent's, lower its priority, then
    warm up."""
    if sys.platform == "linux":
        _die_with_the_agent()
    with contextlib.suppress(OSError, AttributeError):  # not permitted, or not POSIX: go on
        os.nice(WORKER_NICE)
    with contextlib.suppress(OSError, AttributeError):  # not Linux: nice +10 alone
        os.sched_setscheduler(0, os.SCHED_BATCH, os.sched_param(0))
    jobs.warm()


def _die_with_the_agent() -> None:
    """Linux: the kernel kills the worker when the agent's thread that started it (the event
    loop's, the main thread) ends, even by SIGKILL; a `kill -9` of the agent otherwise leaves
    the worker, idle with its 130 MB, running forever."""
    import ctypes
    import signal

    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    if os.getppid() == 1:  # the agent died before the line above
        os._exit(0)


def processes(pool: Executor) -> list:
    """The pool's worker processes (none for a thread pool). Python < 3.14 has no public way
    to reach them."""
    return list((getattr(pool, "_processes", None) or {}).values())


async def stop_worker(pool: Executor) -> None:
    """Stop the worker without waiting on it for ever: an idle worker exits at once; one still
    identifying (or starved of CPU on a busy machine) is killed after WORKER_STOP_S — its
    window is lost either way at shutdown, and the loop must not block on it. Then the pool's
    manager thread, which notices the exit, is given WORKER_STOP_S to end."""
    running = processes(pool)
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    loop = asyncio.get_running_loop()

    async def wait(done: Callable[[], bool]) -> None:
        deadline = loop.time() + WORKER_STOP_S
        while not done() and loop.time() < deadline:
            await asyncio.sleep(0.05)

    try:
        await wait(lambda: not any(p.is_alive() for p in running))
    finally:  # the deadline, or cancelled while waiting
        for process in running:
            if process.is_alive():
                process.kill()
                log.warning("the identification worker did not stop in time: killed")
    await wait(lambda: not any(p.is_alive() for p in running))
    if manager is not None:
        await wait(lambda: not manager.is_alive())
