"""Smoke test of benchmarks/phugoid_check.py, as far as it runs in seconds: its help, and its
arguments checked before anything is flown.

What it cannot do briefly: it sizes the full preset (its build-up runs), flies three free
decays and four noise-free records, and the validated truth it judges against takes about
15 s of JSBSim to linearise: about two minutes on one aircraft, by hand
(benchmarks/README.md)."""

from __future__ import annotations

from tests.benchmarks.bench import help_text, refused


def test_help():
    assert "--aircraft" in help_text("phugoid_check.py")


def test_arguments_are_checked_before_flying():
    refused("phugoid_check.py", "--aircraft", "f16", saying="invalid choice: 'f16'")
