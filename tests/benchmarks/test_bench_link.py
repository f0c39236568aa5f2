"""Smoke test of benchmarks/bench_link.py (`make bench-link`): one full-model result over the
emulated 200 kb/s radios at 20 % loss per attempt, both ends built as the agent and the
console build theirs, and a 2-second run with and without the live view."""

from __future__ import annotations

import re

import pytest

from tests.benchmarks.bench import SLACK_S, help_text, run

TIMEOUT_S = 90
RESULT = re.compile(
    r"^\s+200k\s+20%\s+(?P<frames>\d+)\s+(?P<air>\d+)\s+(?P<median>[\d.]+)\s+(?P<worst>[\d.]+)$",
    re.MULTILINE,
)
DURING = re.compile(
    r"^\s+200k\s+(?P<live>on|off)\s+(?P<air>\d+)\s+(?P<result>[\d.]+)\s+(?P<abort>[\d.]+)"
    r"\s+(?P<views>\d+)$",
    re.MULTILINE,
)


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_a_result_and_a_run_over_the_radios():
    done = run(
        "bench_link.py",
        *("--results", "1", "--rates", "200", "--losses", "0.2", "--run-s", "2"),
        timeout_s=TIMEOUT_S,
    )
    size = int(re.search(r"full-model result: (\d+) bytes", done.stdout)[1])
    result = RESULT.search(done.stdout)
    assert result, done.stdout
    # The result went out in several frames, all of them on air, and arrived.
    assert int(result["frames"]) > 1
    assert int(result["air"]) >= size
    assert 0 < float(result["median"]) <= float(result["worst"])
    rows = {m["live"]: m for m in DURING.finditer(done.stdout)}
    assert set(rows) == {"on", "off"}, done.stdout
    for row in rows.values():  # the mid-run result and the ground's abort were delivered
        assert float(row["result"]) > 0, row[0]
        assert float(row["abort"]) > 0, row[0]
    assert int(rows["off"]["views"]) == 0 < int(rows["on"]["views"])
    assert int(rows["on"]["air"]) > int(rows["off"]["air"])


def test_help_prints_help_and_measures_nothing():
    assert "--live-only" in help_text("bench_link.py")
