"""The run's last-resort watchdog (a pytest plugin; tests/conftest.py loads it).

pytest-timeout ends a hung test with every thread's stack, but it stops its timer as soon as a
test fails (its `pytest_exception_interact` hook, meant for pdb), and so does pytest's own
faulthandler plugin. A failing test whose teardown then waits on a deadlocked thread (an agent's
shutdown joining one, say) would hang the run forever. This watchdog is Python's
`faulthandler`, whose timer runs in C on its own thread and needs neither the GIL nor a lock.
It is re-armed at the start of each phase (setup, call, teardown) for the test's timeout plus a
margin. When it fires, it writes every thread's traceback to the terminal's stderr, past
pytest's capture, and ends the process with exit code 1.

In a pytest-xdist worker (`make test TEST_WORKERS=2` runs two), pytest-timeout's own report
would be lost: it writes to the worker's terminal writer, which xdist never shows, so a hung
test left only "worker 'gw0' crashed while running …". There its timer is this plugin's
(`pytest_timeout_set_timer`): the same thread timer, writing the test's name and every thread's
stack to the real stderr before it ends the worker; xdist then fails the test and goes on with
a new worker.
"""

from __future__ import annotations

import faulthandler
import os
import sys
import threading
import traceback

import pytest

_stderr: int | None = None  # a copy of the real stderr, taken before any test runs


def _margin(limit: float) -> float:
    """Leave pytest-timeout, whose report names the test, the first chance."""
    return max(10.0, 0.25 * limit)


def _limit(item: pytest.Item) -> float:
    marker = item.get_closest_marker("timeout")
    if marker is not None and marker.args:
        return float(marker.args[0])
    option = item.config.getoption("timeout", None)
    if option is not None:
        return float(option)
    return float(item.config.getini("timeout") or 0)


def pytest_configure(config: pytest.Config) -> None:
    global _stderr
    # pytest captures file descriptor 2 during tests; its capture keeps the real one aside.
    capture = config.pluginmanager.getplugin("capturemanager")
    err = getattr(getattr(capture, "_global_capturing", None), "err", None)
    _stderr = os.dup(getattr(err, "targetfd_save", 2))


def pytest_unconfigure(config: pytest.Config) -> None:
    global _stderr
    faulthandler.cancel_dump_traceback_later()
    if _stderr is not None:
        os.close(_stderr)
        _stderr = None


def _arm(item: pytest.Item) -> None:
    limit = _limit(item)
    if limit > 0 and _stderr is not None:
        faulthandler.dump_traceback_later(limit + _margin(limit), exit=True, file=_stderr)


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_setup(item: pytest.Item):
    _arm(item)
    yield


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_call(item: pytest.Item):
    _arm(item)
    yield


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_teardown(item: pytest.Item, nextitem: pytest.Item | None):
    _arm(item)
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    yield
    faulthandler.cancel_dump_traceback_later()


def _stacks() -> str:
    """Every thread's stack, named, most recent call last (as pytest-timeout prints them)."""
    names = {t.ident: t.name for t in threading.enumerate()}
    out = []
    for ident, frame in sys._current_frames().items():
        if ident == threading.get_ident():
            continue  # the timer's own
        out.append(f"~~~ Stack of {names.get(ident, '?')} ({ident}) ~~~\n")
        out.append("".join(traceback.format_stack(frame)))
    return "".join(out)


@pytest.hookimpl(tryfirst=True, optionalhook=True)
def pytest_timeout_set_timer(item: pytest.Item, settings) -> bool | None:
    """In an xdist worker: pytest-timeout's thread method, its report on the real stderr."""
    # xdist gives its workers' configs `workerinput` (the environment's PYTEST_XDIST_WORKER is
    # inherited by a pytest the test starts, which is no worker).
    worker = getattr(item.config, "workerinput", {}).get("workerid")
    if worker is None or _stderr is None or not settings.timeout or settings.timeout <= 0:
        return None  # pytest-timeout's own
    err = _stderr

    def expire() -> None:
        head = f"\n+++ Timeout: {item.nodeid} after {settings.timeout:g} s (worker {worker}) +++\n"
        os.write(err, (head + _stacks() + "+++ Timeout +++\n").encode(errors="replace"))
        os._exit(1)

    timer = threading.Timer(settings.timeout, expire)
    timer.name, timer.daemon = "pytest-timeout", True
    timer.start()
    item.cancel_timeout = timer.cancel  # pytest-timeout's cancel hook calls it
    return True
