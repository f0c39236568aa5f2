"""Smoke test of benchmarks/truth_check.py, as far as it runs in seconds: its help, and its
arguments checked before anything is flown.

What it cannot do briefly: it is the check of the validated linear truth itself, whose
linearisation of JSBSim takes about 15 s per aircraft here; one aircraft
(`--aircraft J3Cub`) takes 19 s, more than its share of the suite's smoke-test budget.
tests/sim/test_truth.py checks the truth against JSBSim in the suite; the whole benchmark
runs by hand (benchmarks/README.md)."""

from __future__ import annotations

from tests.benchmarks.bench import help_text, refused


def test_help():
    text = help_text("truth_check.py")
    assert "--aircraft" in text
    assert "--amplitudes" in text


def test_amplitudes_are_checked_before_flying():
    refused("truth_check.py", "--amplitudes", "two", saying="invalid float value: 'two'")


def test_arguments_are_checked_before_flying():
    refused("truth_check.py", "--aircraft", "f16", saying="invalid choice: 'f16'")
