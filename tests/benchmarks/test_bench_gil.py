"""Smoke test of benchmarks/bench_gil.py: one switch interval, two excitation logs written
while the loop's probe measures its lag."""

from __future__ import annotations

import re

import pytest

from tests.benchmarks.bench import SLACK_S, help_text, run

TIMEOUT_S = 60
ROW = re.compile(
    r"^\| 0\.25 ms \| (?P<writing>[\d.]+ / [\d.]+ / [\d.]+) \| (?P<idle>[\d.]+ / [\d.]+ / [\d.]+) "
    r"\| (?P<n_writing>\d+) \+ (?P<n_idle>\d+) \| (?P<loop>[^|]+) \|$",
    re.MULTILINE,
)


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_the_probe_measures_while_the_writer_formats():
    done = run("bench_gil.py", "--cycles", "2", "--intervals", "0.25", timeout_s=TIMEOUT_S)
    row = ROW.search(done.stdout)
    assert row, done.stdout
    assert int(row["n_writing"]) > 0  # the probe ran in both phases
    assert int(row["n_idle"]) > 0
    for phase in ("writing", "idle"):
        p50, p99, worst = (float(v) for v in row[phase].split(" / "))
        assert 0 <= p50 <= p99 <= worst, row[0]


def test_help():
    assert "--intervals" in help_text("bench_gil.py")
