"""A benchmark run as its smoke test runs it: `benchmarks/SCRIPT` in a child process of the
suite's own Python (the venv `make test` sets up), one BLAS thread, a deadline.

At the deadline the benchmark's whole process group gets SIGINT, so a benchmark with children
(the simulated world, the agent) stops them and says where it kept its logs; SIGKILL follows
if it does not end. Whatever is left of the group when it ends is killed too: no benchmark
outlives its test.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = ROOT / "benchmarks"
# From SIGINT at the deadline to SIGKILL: a benchmark stopping its children waits up to 30 s
# for each (bench_agent.STOP_S), most of them end at once.
STOP_S = 45.0
# A smoke test's pytest-timeout beyond its benchmark's deadline: the stop above and teardown.
SLACK_S = STOP_S + 15.0


def run(
    script: str, *args: str, timeout_s: float, ok: bool = True, env: dict | None = None
) -> subprocess.CompletedProcess:
    """`python benchmarks/SCRIPT ARGS` to its end; with `ok`, the test fails (with the run's
    output) unless it exits with 0. Fails the test if it does not end in `timeout_s`."""
    command = [sys.executable, str(BENCHMARKS / script), *args]
    proc = subprocess.Popen(
        command,
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # its own process group: the deadline reaches its children
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1", "JSBSIM_DEBUG": "0", **(env or {})},
    )
    try:
        stdout, stderr = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        _signal_group(proc, signal.SIGINT)
        try:
            stdout, stderr = proc.communicate(timeout=STOP_S)
        except subprocess.TimeoutExpired:
            _signal_group(proc, signal.SIGKILL)
            stdout, stderr = proc.communicate()
        pytest.fail(f"{script} did not end in {timeout_s:g} s\n{_output(stdout, stderr)}")
    finally:
        _signal_group(proc, signal.SIGKILL)  # anything of the benchmark's still running
    done = subprocess.CompletedProcess(command, proc.returncode, stdout, stderr)
    if ok and done.returncode != 0:
        pytest.fail(f"{script} exited with {done.returncode}\n{_output(stdout, stderr)}")
    return done


def _signal_group(proc: subprocess.Popen, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, sig)


def _output(stdout: str, stderr: str) -> str:
    return f"--- stdout (end) ---\n{stdout[-4000:]}\n--- stderr (end) ---\n{stderr[-6000:]}"


def help_text(script: str) -> str:
    """`SCRIPT --help`: asserted to print its usage and exit 0 at once, measuring nothing."""
    done = run(script, "--help", timeout_s=60)
    assert done.stdout.startswith("usage:"), done.stdout
    return done.stdout


def refused(script: str, *args: str, saying: str, timeout_s: float = 60) -> None:
    """`SCRIPT ARGS` asserted to stop with argparse's usage error (exit 2) before measuring
    anything, its stderr saying `saying`."""
    done = run(script, *args, timeout_s=timeout_s, ok=False)
    assert done.returncode == 2, done.returncode
    assert saying in done.stderr, done.stderr
