"""Code that runs at arbitrary points — the gc callback, and the callbacks digi-xbee and MAVSDK
make on their own threads — must never take a lock or log (docs/hardening.md, *Reliability*):
it runs inside whatever the interrupted thread was doing, with that thread's locks held.

Bad input tried: a full garbage collection forced at every Python call a logging thread makes
(inside the logging handler, inside the log queue's put), each one slow, while another thread
logs beside it — the agent's execution log used to deadlock on exactly this (the gc callback
logged from inside the queue's put, whose mutex its own thread held); and each callback run
under a profiler that records every lock acquired and every logging call it makes.
"""

from __future__ import annotations

import asyncio
import gc
import json
import logging
import sys
import threading
import time

import pytest
from digi.xbee.models.address import XBee16BitAddress, XBee64BitAddress
from digi.xbee.packets.common import ReceivePacket
from mavsdk.plugins.mavlink_direct import MavlinkMessage

from agent.clock import VirtualClock
from agent.config import Config, Recorder
from agent.logs import JsonLinesHandler, LogWriter
from agent.runtime import Agent
from agent.runtime.health import GcWatch
from drivers.autopilot.driver import MessageSeam
from drivers.xbee.driver import PacketSeam

# A thread that logs while collecting is deadlocked when no full collection has ended for this
# long: each line here runs dozens of full collections, about 15 ms each on a quiet machine,
# several times that on a loaded machine or beside a second test worker, and a deadlocked thread
# never ends one again. Judged by progress, not by the whole run's time, which grows with the
# process's objects and the machine's load. Below the suite's 120 s per-test timeout, so a
# stuck thread fails with this test's own message.
DEADLOCK_S = 60.0
# The whole logging run may take longer than a per-test timeout allows on a loaded machine,
# while every collection still ends: the test's own bound (pytest-timeout's marker).
LOGGING_RUN_S = 600
# One line each way: the deadlock this guards against (the callback logging inside the queue's
# put, whose mutex its own thread holds) comes on the first line the library thread logs, and
# each line costs dozens of full collections of the worker's whole heap (about 35 s late in
# the suite, 113 s for three).
LINES = 1


def _collect_at_every_call(frame, event, arg):
    """A profile hook: a full collection at each Python function the thread enters."""
    if event == "call":
        gc.collect()


@pytest.fixture
def execution_log(tmp_path):
    writer = LogWriter(tmp_path)
    handle = writer.open("0001_exec_x.jsonl")
    handler = JsonLinesHandler(writer, handle)
    logger = logging.getLogger("test.arbitrary")
    logger.addHandler(handler)
    logger.propagate = False
    yield logger, writer
    logger.removeHandler(handler)
    logger.propagate = True
    writer.close()


def _full_collections() -> int:
    return gc.get_stats()[2]["collections"]


def _wait_while_collecting(finished: threading.Event) -> None:
    """Until `finished`; fails when no full collection has ended for DEADLOCK_S meanwhile (the
    collecting thread is stuck, not slow)."""
    seen, since = _full_collections(), time.monotonic()
    while not finished.wait(1.0):
        now = _full_collections()
        if now != seen:
            seen, since = now, time.monotonic()
        assert time.monotonic() - since < DEADLOCK_S, (
            "the logging thread deadlocked in a gc callback"
        )


def _log_while_collecting(execution_log, callback, lines, beside=()) -> list[str]:
    """Log `lines` from a library-like thread that runs a full collection at every Python call
    it makes, and `beside` from this thread meanwhile, with `callback` in gc.callbacks; the
    execution log's messages afterwards. Fails if the thread deadlocks."""
    logger, writer = execution_log
    finished = threading.Event()

    def library_thread() -> None:  # a library logging from its own thread, as digi-xbee does
        sys.setprofile(_collect_at_every_call)
        try:
            for line in lines:
                logger.warning(line)
        finally:
            sys.setprofile(None)
            finished.set()

    gc.callbacks.append(callback)
    try:
        thread = threading.Thread(target=library_thread, name="library", daemon=True)
        thread.start()
        for line in beside:
            logger.warning(line)
        _wait_while_collecting(finished)
        thread.join()
    finally:
        gc.callbacks.remove(callback)
    writer.close()
    text = (writer.directory / "0001_exec_x.jsonl").read_text()
    return [json.loads(line)["message"] for line in text.splitlines()]


@pytest.mark.timeout(LOGGING_RUN_S)
def test_a_slow_full_collection_inside_the_log_path_neither_deadlocks_nor_logs(execution_log):
    watch = GcWatch(slow_s=0.0)  # every full pass counts as slow: the callback's worst path
    library = [f"library line {k}" for k in range(LINES)]
    loop = [f"loop line {k}" for k in range(LINES)]  # the loop thread logs beside it
    messages = _log_while_collecting(execution_log, watch, library, loop)
    assert sorted(messages) == sorted(library + loop)
    # Every forced pass was timed and counted; none of them logged (the loop reports them).
    assert watch.slow >= LINES * 10
    assert watch.full == watch.slow
    slow, longest = watch.take()
    assert slow == watch.slow
    assert longest > 0
    assert watch.take() == (0, 0.0)


class _TrackedLock:
    """A lock that notes each acquisition made while `_watching` is on in its thread."""

    def __init__(self, inner, name: str):
        self._inner, self._name = inner, name

    def acquire(self, *args, **kwargs):
        if getattr(_watching, "on", False):
            _watching.seen.append(self._name)
        return self._inner.acquire(*args, **kwargs)

    def release(self):
        return self._inner.release()

    def locked(self):
        return self._inner.locked()

    __enter__ = acquire

    def __exit__(self, *exc):
        self.release()


_watching = threading.local()


@pytest.fixture
def tracked_locks(monkeypatch):
    """Locks made while the fixture is active note their acquisitions (the objects under test
    are built inside it, so any lock they own is one of these)."""
    real_lock, real_rlock = threading.Lock, threading.RLock
    monkeypatch.setattr(threading, "Lock", lambda: _TrackedLock(real_lock(), "Lock"))
    monkeypatch.setattr(threading, "RLock", lambda: _TrackedLock(real_rlock(), "RLock"))


def _locks_and_logging(call) -> list[str]:
    """Run `call`; the locks it acquired (tracked ones, and any acquire() called by name) and
    the logging and threading functions it entered."""
    _watching.seen, _watching.on = [], True

    def hook(frame, event, arg):
        if event == "c_call" and getattr(arg, "__name__", "") == "acquire":
            _watching.seen.append(f"{type(getattr(arg, '__self__', None)).__name__}.acquire")
        elif event == "call" and frame.f_code.co_filename.endswith(
            ("logging/__init__.py", "threading.py")
        ):
            _watching.seen.append(f"{frame.f_code.co_name} ({frame.f_code.co_filename})")

    sys.setprofile(hook)
    try:
        call()
    finally:
        sys.setprofile(None)
        _watching.on = False
    return _watching.seen


def test_the_gc_callback_takes_no_lock_and_does_not_log(tracked_locks):
    watch = GcWatch(slow_s=0.0)

    def one_slow_pass() -> None:
        watch("start", {"generation": 2})
        watch("stop", {"generation": 2})

    assert _locks_and_logging(one_slow_pass) == []
    assert watch.slow == 1


async def test_the_radio_callback_takes_no_lock_and_does_not_log(tracked_locks):
    # The seam XBeeRadio hands digi-xbee as its packet callback.
    delivered = []
    seam = PacketSeam(asyncio.get_running_loop(), delivered.append, bound=2)
    packet = ReceivePacket(
        XBee64BitAddress(bytes(range(8))), XBee16BitAddress.UNKNOWN_ADDRESS, 0, bytearray(b"frame")
    )
    seen = []
    thread = threading.Thread(
        target=lambda: seen.extend(
            _locks_and_logging(lambda: [seam.callback(packet) for _ in range(3)])
        ),
        name="digi-xbee-callback",
    )
    thread.start()
    thread.join()
    assert seen == []
    for _ in range(100):  # the frames cross into the loop on its next turns
        if len(delivered) == 2:
            break
        await asyncio.sleep(0)
    assert delivered == [packet, packet]  # the third was past the bound: dropped, counted
    assert seam.dropped == 1


async def test_the_autopilot_callback_takes_no_lock_and_does_not_log(tracked_locks):
    delivered = []
    seam = MessageSeam(asyncio.get_running_loop(), delivered.append)
    message = MavlinkMessage(message_name="ATTITUDE", fields_json='{"roll": 0.1}')
    seen = []
    thread = threading.Thread(
        target=lambda: seen.extend(
            _locks_and_logging(lambda: [seam.callback(message) for _ in range(3)])
        ),
        name="mavsdk-callback",
    )
    thread.start()
    thread.join()
    assert seen == []
    for _ in range(100):
        if delivered:
            break
        await asyncio.sleep(0)
    assert delivered == [{"roll": 0.1}]  # the newest of the three, once
    assert seam.received == {"ATTITUDE": 3}


async def test_slow_collections_are_reported_from_the_loop(tmp_path, caplog):
    config = Config(recorder=Recorder(log_dir=str(tmp_path / "logs"), capacity_s=60.0))
    agent = Agent(config, base=tmp_path, clock=VirtualClock(100.0))
    agent.health.gc_watch.slow_s = 0.0  # every full pass is slow
    monitor = asyncio.create_task(agent.health.probe(), name="lag")
    try:
        await asyncio.sleep(0)  # the monitor registers its gc callback
        thread = threading.Thread(target=gc.collect, name="a-thread-collecting")
        thread.start()
        thread.join()
        with caplog.at_level(logging.WARNING, logger="agent.runtime.health"):
            for _ in range(1000):
                reports = [r for r in caplog.records if "garbage collection" in r.getMessage()]
                if reports:
                    break
                await asyncio.sleep(0.01)
    finally:
        monitor.cancel()
        await asyncio.gather(monitor, return_exceptions=True)
        agent.close()
    assert reports, "the loop never reported the slow collection"
    assert reports[0].threadName == threading.current_thread().name  # the loop's thread
    assert agent.health.gc_watch not in gc.callbacks
    assert agent.health.record(1.0, 0.0)["gc"]["slow"] >= 1


@pytest.mark.timeout(LOGGING_RUN_S)
def test_a_gc_callback_that_logs_cannot_deadlock_the_execution_log(execution_log):
    # A library's gc callback may log; the execution log's handler and queue take no lock, so
    # even a line logged from inside another line's put goes through.
    logger, _ = execution_log

    def logs_from_gc(phase: str, info: dict) -> None:
        if phase == "stop" and info.get("generation") == 2:
            logger.warning("from a gc callback")

    messages = _log_while_collecting(execution_log, logs_from_gc, ["library line"])
    assert "library line" in messages
    assert messages.count("from a gc callback") >= 10


HUNG = """
import threading

import pytest


@pytest.fixture
def held():
    lock = threading.Lock()
    lock.acquire()
    holder = threading.Thread(target=threading.Event().wait, name="lock-holder", daemon=True)
    holder.start()
    yield lock
    lock.acquire()  # teardown waits too, as a shutdown joining a deadlocked thread does


def test_waits_on_a_held_lock(held):
    held.acquire()  # never returns


def test_never_reached():
    pass
"""


HUNG_AFTER_FAILING = """
import threading

import pytest


@pytest.fixture
def held():
    lock = threading.Lock()
    lock.acquire()
    yield lock
    lock.acquire()  # the teardown waits for ever, as a shutdown joining a deadlocked thread


def test_fails_then_hangs_in_its_teardown(held):
    raise AssertionError("the test failed")
"""


def _run_pytest_on(tmp_path, text: str, *options: str) -> tuple[int, str]:
    """pytest with the suite's own settings (pyproject.toml, and the watchdog plugin) on one
    test file, with `options`; its exit code and its output."""
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    (tmp_path / "test_hung.py").write_text(text)
    done = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-c",
            str(root / "pyproject.toml"),
            "--rootdir",
            str(tmp_path),
            "-p",
            "no:cacheprovider",
            "-p",
            "tests.watchdog",
            "--timeout",
            "3",
            *options,
            str(tmp_path / "test_hung.py"),
        ],
        capture_output=True,
        text=True,
        timeout=DEADLOCK_S,
        check=False,
        cwd=root,
    )
    return done.returncode, done.stdout + done.stderr


def test_a_hung_test_ends_the_run_with_every_threads_stack(tmp_path):
    # A test stuck on a lock in its body and again in its teardown: pytest-timeout's thread
    # method ends the run, failing, with each thread's stack. The signal method interrupts the
    # body once, then hangs in the teardown for ever.
    code, out = _run_pytest_on(tmp_path, HUNG)
    assert code != 0
    assert "Timeout" in out
    assert "Stack of lock-holder" in out
    assert "held.acquire()  # never returns" in out  # the main thread, where it is stuck
    assert "passed" not in out  # the run ended there: no later test, no summary


def test_a_failed_test_that_hangs_in_its_teardown_ends_the_run(tmp_path):
    # pytest-timeout stops its timer when a test fails, so this used to hang the run for ever;
    # the watchdog (tests/watchdog.py) ends it with every thread's traceback.
    code, out = _run_pytest_on(tmp_path, HUNG_AFTER_FAILING)
    assert code == 1
    assert "Timeout (0:00:" in out  # faulthandler's dump: every thread, most recent call first
    assert "(most recent call first)" in out
    assert "line 12 in held" in out  # stuck in the fixture's teardown


def test_a_hung_test_in_a_worker_process_ends_it_with_every_threads_stack(tmp_path):
    # `make test TEST_WORKERS=2` runs two pytest-xdist workers, which do not show
    # pytest-timeout's report: a hung test left only "worker 'gw0' crashed". The watchdog's
    # timer writes it to stderr.
    code, out = _run_pytest_on(tmp_path, HUNG, "-n", "2")
    assert code != 0
    assert "Timeout: test_hung.py::test_waits_on_a_held_lock after 3 s" in out
    assert "Stack of lock-holder" in out
    assert "held.acquire()  # never returns" in out  # the test's thread, where it is stuck
    assert "crashed while running 'test_hung.py::test_waits_on_a_held_lock'" in out
