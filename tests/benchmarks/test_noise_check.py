"""Smoke test of benchmarks/noise_check.py, as far as it runs in seconds: its help, and its
arguments checked before anything is flown.

What it cannot do briefly: it sizes the manoeuvres (two calibration runs), flies a noise-free
record per seed and identifies each five times, and the validated truth it judges against
takes about 15 s of JSBSim to linearise: about a minute on one aircraft, by hand
(benchmarks/README.md)."""

from __future__ import annotations

from tests.benchmarks.bench import help_text, refused


def test_help():
    text = help_text("noise_check.py")
    assert "--aircraft" in text
    assert "--excitation" in text


def test_arguments_are_checked_before_flying():
    refused("noise_check.py", "--aircraft", "f16", saying="invalid choice: 'f16'")
    refused("noise_check.py", "--excitation", "doublet", saying="invalid choice: 'doublet'")
    refused("noise_check.py", "--seeds", "0", saying="--seeds must be at least 1")
