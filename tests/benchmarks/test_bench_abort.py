"""Smoke test of benchmarks/bench_abort.py (`make bench-abort`): the whole simulated flight
with the real `sysid agent` process, one switch drop, its latency read off the MAVLink wire."""

from __future__ import annotations

import json

import pytest

from tests.benchmarks.bench import SLACK_S, help_text, run

TIMEOUT_S = 150


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_one_drop_is_measured_on_the_wire(tmp_path):
    # TMPDIR: the flight's directory, kept there if the run fails.
    done = run(
        "bench_abort.py",
        *("--drops", "1", "--json"),
        timeout_s=TIMEOUT_S,
        env={"TMPDIR": str(tmp_path)},
    )
    summary = json.loads(done.stdout)
    assert summary["drops"] == 1, summary
    report, flip = summary["report_to_trim"], summary["flip_to_trim"]
    # The trim followed the switch's report, which followed the pilot's flip.
    assert 0 < report["median_ms"] <= flip["median_ms"], summary
    assert summary["most_commands_before_trim"] >= 0
    assert not list(tmp_path.glob("bench-abort-*"))  # a measured flight leaves nothing behind


def test_help():
    assert "--drops" in help_text("bench_abort.py")
