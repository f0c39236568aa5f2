"""`sysid --help` and `sysid --version` stay quick: building the parser (every command's
options) imports none of the heavy libraries, which each command imports when it runs
(measured with `python -X importtime -m agent --help`: README, *Commands*)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HEAVY = ("numpy", "scipy", "pydantic", "matplotlib", "jsbsim", "textual", "mavsdk", "digi.xbee")


def test_building_the_parser_imports_nothing_heavy():
    code = (
        "import sys; import agent.cli as c; c.build_parser(); "
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True
    )
    assert done.stdout.strip() == "[]"


@pytest.mark.parametrize("argv", [["--version"], ["--help"], ["identify", "--help"]])
def test_version_and_help(argv):
    done = subprocess.run(
        [sys.executable, "-m", "agent", *argv], capture_output=True, text=True, cwd=ROOT
    )
    assert done.returncode == 0
    assert ("sysid 0.1.0" if argv == ["--version"] else "usage: sysid") in done.stdout
