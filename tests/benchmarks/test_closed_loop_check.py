"""Smoke test of benchmarks/closed_loop_check.py, as far as it runs in seconds: its help, and
its arguments checked before anything is flown.

What it cannot do briefly: each aircraft's validated truth takes about 10 s of JSBSim, its
calibration runs size the plan per condition, and each seed flies and identifies two 80 s
records: about 8 minutes for the six aircraft, calm and in light turbulence, by hand
(benchmarks/README.md). tests/sim/test_autopilot.py flies a plan in
FBWA through the real driver; tests/sim/test_offline_fbwa.py the offline closed-loop record."""

from __future__ import annotations

from tests.benchmarks.bench import help_text, refused


def test_help():
    assert "--turbulence" in help_text("closed_loop_check.py")


def test_arguments_are_checked_before_flying():
    refused("closed_loop_check.py", "--aircraft", "f16", saying="invalid choice: 'f16'")


def test_the_sizing_is_one_of_the_two():
    refused("closed_loop_check.py", "--sizing", "twice", saying="invalid choice: 'twice'")
