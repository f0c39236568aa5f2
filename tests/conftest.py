"""Shared fixtures: reference records and a guard against leaked threads."""

from __future__ import annotations

import asyncio
import threading

import numpy as np
import pytest

from agent.ident import Experiment, reference
from tests import waiting

# The last-resort watchdog: a test hung after pytest-timeout gave up on it still ends the run.
pytest_plugins = ["tests.watchdog"]

DT = 0.02  # 50 Hz, as the thesis's appendix models are used in the known-answer tests
LEAD_IN = 1.0


@pytest.fixture(autouse=True)
def wait_budget(request):
    """Every `tests.waiting.until` in the test is bounded by the test's own pytest-timeout."""
    marker = request.node.get_closest_marker("timeout")
    if marker is not None:
        timeout = marker.args[0] if marker.args else marker.kwargs.get("timeout")
    else:
        timeout = float(request.config.getini("timeout") or 0)
    waiting.budget(timeout)
    yield
    waiting.budget(None)


@pytest.fixture(autouse=True)
def no_leaked_threads():
    """Fail a test that leaves threads running (docs/contributing.md, *Fakes at the transport
    seam*)."""
    before = set(threading.enumerate())
    yield
    leaked = [
        t
        for t in threading.enumerate()
        if t not in before and t.is_alive() and not _library_pool(t)
    ]
    assert not leaked, f"test leaked threads: {leaked}"


def _library_pool(thread: threading.Thread) -> bool:
    """Library pools that live as long as the process — digi-xbee's callback pool
    (digi.xbee.reader.EXECUTOR) and dask.distributed's offload executor: their threads are
    the libraries', not a leak of ours."""
    import sys

    reader = sys.modules.get("digi.xbee.reader")
    if reader is not None and thread in getattr(reader.EXECUTOR, "_threads", ()):
        return True
    # dask.distributed's process-wide offload executor (distributed.utils._offload_executor),
    # started by the first Client or LocalCluster and kept for the process.
    utils = sys.modules.get("distributed.utils")
    offload = getattr(utils, "_offload_executor", None) if utils is not None else None
    return offload is not None and thread in getattr(offload, "_threads", ())


@pytest.fixture
async def no_leaked_tasks():
    """Fail an async test that leaves tasks running (docs/contributing.md, *Fakes at the
    transport seam*); use it per module."""
    yield
    current = asyncio.current_task()
    leaked = [t for t in asyncio.all_tasks() if t is not current and not t.done()]
    assert not leaked, f"test leaked tasks: {[t.get_name() for t in leaked]}"


def detrimmed(record: reference.Record, seconds: float = 0.5) -> Experiment:
    """The record with the mean of its first `seconds` removed, as `sysid identify` does."""
    count = round(seconds / DT)
    u = record.inputs - record.inputs[:count].mean(axis=0)
    y = record.outputs - record.outputs[:count].mean(axis=0)
    return Experiment(u=u, y=y)


def true_eigenvalues(model: reference.ReferenceModel) -> np.ndarray:
    return np.linalg.eigvals(model.A)


def matched_relative_errors(found: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Relative error of each true eigenvalue against its nearest found one (one-to-one)."""
    remaining = list(found)
    errors = []
    for t in sorted(truth, key=abs):
        k = int(np.argmin([abs(f - t) for f in remaining]))
        errors.append(abs(remaining.pop(k) - t) / abs(t))
    return np.array(errors)


@pytest.fixture
def small_disk_at():
    """Mount a real file system that fills up — a tmpfs of the given size — on a directory
    (root or passwordless sudo, as CI has); unmounted afterwards. Writes past it fail with
    ENOSPC from the kernel, partial writes included: no simulated error."""
    import os
    import subprocess

    prefix = [] if os.geteuid() == 0 else ["sudo", "-n"]
    mounted = []

    def mount(where, size: str = "256k"):
        where.mkdir(parents=True, exist_ok=True)
        command = [
            *prefix,
            "mount",
            "-t",
            "tmpfs",
            "-o",
            f"size={size},mode=0777",
            "tmpfs",
            str(where),
        ]
        done = subprocess.run(command, capture_output=True, text=True, check=False)
        assert done.returncode == 0, (
            f"the disk-full tests need to mount a small tmpfs (root or `sudo -n`): {done.stderr}"
        )
        mounted.append(where)
        return where

    yield mount
    for where in mounted:
        subprocess.run([*prefix, "umount", "-l", str(where)], check=False)


@pytest.fixture
def small_disk(tmp_path, small_disk_at):
    """A 256 KiB tmpfs on a fresh directory (see small_disk_at)."""
    return small_disk_at(tmp_path / "disk")
