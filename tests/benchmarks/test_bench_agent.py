"""Smoke test of benchmarks/bench_agent.py (`make bench-agent`, `make soak`): the three
processes of the benchmark (the world, the real `sysid agent`, the sampler) over one lateral
excitation: the link comes up, the excitation is identified in the worker and delivered over
the radio, /proc is sampled, the agent stops cleanly on SIGTERM.

What it cannot check briefly: the loop-lag percentiles. They come from the agent's health
records, written once a minute (`agent.runtime.health.HEALTH_S`), and one excitation's flight
is over in about 30 s; the report then says the lag was not measured, and a flight of two
minutes or more without a health record fails. `make bench-agent` measures the lag.

And a flight that fails (here: an agent configuration the agent refuses) ends the benchmark
with exit code 1, a message saying what failed, and its directory kept and named.
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from tests.benchmarks.bench import SLACK_S, help_text, run

TIMEOUT_S = 180


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_one_excitation_identified_over_the_link(tmp_path):
    flight = tmp_path / "flight"
    done = run(
        "bench_agent.py",
        *("--minutes", "3", "--until-runs", "1", "--settle", "2", "--json"),
        *("--keep", str(flight)),
        timeout_s=TIMEOUT_S,
    )
    result = json.loads(done.stdout)
    assert (flight / "link.json").exists()  # the ground heard the agent over the link
    assert (flight / "link.key").stat().st_mode & 0o777 == 0o600  # as `sysid keygen` makes it
    assert result["runs"] == 1
    assert result["runs_identified"] == 1, result["run_errors"]
    assert result["result_after_s"]["max"] > 0  # after the excitation's end, at the ground
    assert result["agent_cpu_percent"] > 0
    assert result["worker_cpu_percent"] >= 0  # sampled (its share is below /proc's tick here)
    assert result["agent_rss_mb"]["max"] > 50
    assert result["baseline_lag"]["p99_ms"] > 0  # the idle loop's probe ran beside it
    assert result["lag"] == {"minutes": 0}  # no health record yet (module docstring)
    assert result["agent_exit_code"] == 0  # SIGTERM: a clean stop


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_a_failed_flight_says_why_and_keeps_its_logs(tmp_path):
    # SCHED_FIFO priority 100 is out of range: the agent refuses its configuration and exits.
    done = run(
        "bench_agent.py",
        *("--minutes", "1", "--realtime", "100"),
        timeout_s=TIMEOUT_S,
        ok=False,
        env={"TMPDIR": str(tmp_path)},
    )
    assert done.returncode == 1, done.stderr
    assert "the agent process stopped early" in done.stderr, done.stderr
    kept = re.search(r"the logs are kept in (\S+)", done.stderr)
    assert kept, done.stderr
    directory = Path(kept[1])
    assert directory.parent == tmp_path
    for log in ("agent.log", "world.log", "agent.toml", "link.key"):
        assert (directory / log).exists(), log
    assert "realtime_priority" in (directory / "agent.log").read_text()
    shutil.rmtree(directory)


def test_help():
    assert "--until-runs" in help_text("bench_agent.py")
