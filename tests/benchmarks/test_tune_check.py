"""Smoke test of benchmarks/tune_check.py, as far as it runs in seconds: its help, and its
arguments checked before anything is flown.

What it cannot do briefly: the validated truth it designs on takes about 10 s of JSBSim to
linearise per aircraft, and each aircraft flies eight steps and two 30 s holds: a few minutes
for the six, by hand (benchmarks/README.md). tests/sim/test_tune.py flies the J-3 Cub's."""

from __future__ import annotations

from tests.benchmarks.bench import help_text, refused


def test_help():
    assert "--aircraft" in help_text("tune_check.py")


def test_arguments_are_checked_before_flying():
    refused("tune_check.py", "--aircraft", "f16", saying="invalid choice: 'f16'")
