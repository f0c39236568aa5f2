"""Smoke test of benchmarks/bench_memory.py: `sysid identify` on a one-minute record (6,000
rows) in a child process, its peak memory and time; and a child that fails, whose error
output the benchmark shows before it exits non-zero."""

from __future__ import annotations

import re

import pytest

from tests.benchmarks.bench import SLACK_S, help_text, run

TIMEOUT_S = 90
ROW = re.compile(
    r"^6000\s+(?P<mb>\d+)\s+(?P<exit>-?\d+)\s+(?P<wall>[\d.]+)\s+(?P<peak>\d+)", re.MULTILINE
)


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_identify_on_a_one_minute_record():
    done = run("bench_memory.py", "--rows", "6000", timeout_s=TIMEOUT_S)
    row = ROW.search(done.stdout)
    assert row, done.stdout
    assert int(row["exit"]) == 0
    assert float(row["wall"]) > 0
    assert int(row["peak"]) > 50  # MB: the child's peak resident memory, Python and numpy at least


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_a_failed_child_is_shown_and_fails_the_benchmark():
    done = run(
        "bench_memory.py", "--rows", "6000", "--method", "nonsense", timeout_s=TIMEOUT_S, ok=False
    )
    assert done.returncode == 1, done.stderr
    assert "identification failed on [6000] rows" in done.stderr
    assert "nonsense" in done.stderr  # the child's own error, not just that it failed


def test_help():
    assert "--parse-only" in help_text("bench_memory.py")
