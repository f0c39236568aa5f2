"""Smoke test of benchmarks/table.py (`make bench-table`): its identification section, one seed
without the peers (python-control and SIPPY are the `bench` extra, which `make test` does not
install), printed as the Markdown the README takes, under the machine and commit line.

Its other three sections are each one call of another benchmark's measurement, which that
benchmark's smoke test runs: bytes on air (`bench_link.measure`, test_bench_link), abort
latency (`bench_abort.measure`, test_bench_abort) and loop lag (`bench_agent.measure`,
test_bench_agent). Run here too they would add half a minute of emulated radios and two
simulated flights (a minute more) for the same code."""

from __future__ import annotations

import importlib.util
import re

import pytest

from tests.benchmarks.bench import SLACK_S, help_text, refused, run

TIMEOUT_S = 120


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_identification_section():
    done = run(
        "table.py",
        *("--sections", "identification", "--seeds", "1", "--no-peers"),
        timeout_s=TIMEOUT_S,
    )
    out = done.stdout
    assert out.startswith("Measured ")
    assert "Command: `make bench-table`" in out
    rows = re.findall(
        r"^\| (suas-sysid [^|]+) \| ([\d.]+) % \| ([\d.]+) % \| ([\d.]+) % \| ([\d.]+) "
        r"\| ([\d.]+) \| ([\d.]+) \|$",
        out,
        re.MULTILINE,
    )
    assert [r[0] for r in rows] == [
        "suas-sysid default (OKID/ERA + output error)",
        "suas-sysid OKID/ERA, no refinement",
    ], out
    for row in rows:  # each identified the record (every mode found) and was timed
        assert float(row[5]) > 0, row
    assert "Bytes on air" not in out
    assert "Event-loop lag" not in out


def test_help_and_missing_peers():
    assert "--sections" in help_text("table.py")
    if all(importlib.util.find_spec(module) for module in ("control", "sippy_unipi")):
        # With the peers the script runs the benchmark itself (tens of seconds) instead of
        # refusing: what this test checks needs them missing.
        pytest.skip("the peers are installed here")
    refused("table.py", "--sections", "identification", saying="--no-peers")
