"""Smoke test of benchmarks/bench_jsbsim.py (`make bench-jsbsim`), as far as it runs in seconds.

What it cannot do briefly: every row is judged against the aircraft's validated linear truth
(`agent.sim.truth.linear_truth`), whose linearisation of JSBSim alone takes about 15 s here,
and the smallest run (`--quick --aircraft J3Cub --turbulence 0 --excitation full --nav ins
--seeds 1`: the calibration runs that size the preset, then one flight) 27 s. The suite's
smoke tests share a budget of about a minute and a half with two real-time simulated flights
(test_bench_agent, test_bench_abort), so this one stops short of the flights: the script
starts with no aircraft,
after its imports, its arguments and its `--without` terms are applied (the terms reach into
the aircraft method, whose options have moved before), and prints its table's head. The
truth is checked in the suite by tests/sim/test_truth.py and an offline flight through the full
preset identified by tests/sim/test_wind_job.py; the whole benchmark runs by `make
bench-jsbsim`."""

from __future__ import annotations

import pytest

from tests.benchmarks.bench import SLACK_S, help_text, run

TIMEOUT_S = 60


@pytest.mark.timeout(TIMEOUT_S + SLACK_S)
def test_starts_with_every_term_left_out():
    done = run(
        "bench_jsbsim.py",
        *("--aircraft", "--no-peers", "--without", "alpha-products", "sideslip-drag"),
        timeout_s=TIMEOUT_S,
    )
    assert done.stdout.startswith("cells: median / worst over seeds"), done.stdout
    assert "short period" in done.stdout


def test_help_and_arguments():
    assert "--without" in help_text("bench_jsbsim.py")
    done = run("bench_jsbsim.py", "--without", "wings", timeout_s=TIMEOUT_S, ok=False)
    assert done.returncode == 2
    assert "invalid choice: 'wings'" in done.stderr, done.stderr
