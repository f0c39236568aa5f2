"""The Makefile's run counts reach the commands they are meant for, read with `make -n` (the
commands printed, not run). Inputs tried: `make fuzz` with no count (a million inputs per
parser), `make fuzz RUNS=5`, and `make test-loaded RUNS=3` (three suite runs, the spelling the
done-when of a loaded run uses); before, both targets shared one `RUNS ?=` and the first
definition (1) won, so `make fuzz` fuzzed one input per parser."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# `make -n` only prints, but it still reads the Makefile and runs $(shell ...): seconds at most.
MAKE_DEADLINE_S = 60

pytestmark = pytest.mark.skipif(shutil.which("make") is None, reason="needs GNU make")


def dry_run(*args: str) -> str:
    """The commands `make -n ARGS` would run, with no count inherited from a calling make."""
    inherited = ("MAKEFLAGS", "MFLAGS", "MAKELEVEL", "RUNS")
    env = {k: v for k, v in os.environ.items() if k not in inherited}
    done = subprocess.run(
        ["make", "--no-print-directory", "-n", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=MAKE_DEADLINE_S,
        check=True,
    )
    return done.stdout


@pytest.mark.parametrize(("args", "runs"), [((), 1_000_000), (("RUNS=5",), 5)])
def test_make_fuzz_runs_the_count_asked_for(args, runs):
    assert re.findall(r"fuzz\.py --runs (\d+)", dry_run("fuzz", *args)) == [str(runs)]


def test_make_test_loaded_runs_the_suite_runs_times():
    # A recipe line naming $(MAKE) runs even under -n: PYTHON=true starts no CPU hog and
    # MAKE=echo prints the suite run instead of starting it.
    out = dry_run("test-loaded", "RUNS=3", "PYTHON=true", "MAKE=echo")
    assert re.findall(r"loaded run (\d+) of (\d+)", out) == [("1", "3"), ("2", "3"), ("3", "3")]
