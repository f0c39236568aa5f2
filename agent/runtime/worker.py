"""The identification worker: one spawned process, started (and warmed up) with the agent, and
stopped without ever blocking the loop on it."""

from __future__ import annotations

import asyncio
import logging
import multiprocessing
from collections.abc import Callable
from concurrent.futures import Executor, ProcessPoolExecutor

from agent.ident import job as jobs

log = logging.getLogger(__name__)

# At shutdown, how long an identification in the worker may go on before the worker is killed.
WORKER_STOP_S = 2.0


def new_worker() -> ProcessPoolExecutor:
    """The identification worker: one process, spawned (no fork of a threaded process), its
    priority lowered and its numerics warmed up by `jobs.start_worker`."""
    context = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(1, mp_context=context, initializer=jobs.start_worker)


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
