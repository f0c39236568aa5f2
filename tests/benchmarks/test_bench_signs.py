"""Smoke test of benchmarks/bench_signs.py, as far as it runs in seconds: its help, and its
arguments checked before anything is flown.

What it cannot do briefly: its first step is the aircraft's validated linear truth
(`agent.sim.truth.linear_truth`, about 15 s of JSBSim here) and FGLinearization's model, then
a flight through the full preset per sign and seed; the smallest run (`--seeds 1 --signs ++`)
takes 27 s, more than its share of the suite's smoke-test budget. Its flights, identification
and mode errors are bench_jsbsim's functions (`fly`, `experiment`, `ours`, `mode_errors`),
which it imports, so an import that rots fails here; the whole benchmark runs by hand
(benchmarks/README.md)."""

from __future__ import annotations

from tests.benchmarks.bench import help_text, refused


def test_help():
    assert "--signs" in help_text("bench_signs.py")


def test_arguments_are_checked_before_flying():
    refused("bench_signs.py", "--signs", "+", saying="invalid choice: '+'")
