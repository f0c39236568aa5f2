"""The run's last-resort watchdog (a pytest plugin; tests/conftest.py loads it).

pytest-timeout ends a hung test with every thread's stack, but it stops its timer as soon as a
test fails (its `pytest_exception_interact` hook, meant for pdb), and so does pytest's own
faulthandler plugin. A failing test whose teardown then waits on a deadlocked thread (an agent's
shutdown joining one, say) would hang the run forever. This watchdog is Python's
`faulthandler`, whose timer runs in C on its own thread and needs neither the GIL nor a lock.
It is re-armed at the start of each phase (setup, call, teardown) for the test's timeout plus a
margin. When it fires, it writes every thread's traceback to the terminal's stderr, past
pytest's capture, and ends the process with exit code 1.
"""

from __future__ import annotations

import faulthandler
import os

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
