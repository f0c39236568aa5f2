"""`sysid sim-aircraft`: announces where to connect, runs, and cleans up its ports.

Bad input tried: an aircraft JSBSim does not have; sensor rates that are not 100 Hz divided
or multiplied by a whole number, zero, negative and over 1000 Hz.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _run(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, "-m", "agent", "sim-aircraft", *args],
        env=env,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def test_announces_the_mavlink_url_and_sensor_ports_then_stops(tmp_path):
    result = _run("--duration", "1.5", "--pty-dir", str(tmp_path), "--mavlink-port", "0")
    assert result.returncode == 0, result.stderr
    out = result.stdout
    assert re.search(r'\[autopilot\] url = "udpout://127\.0\.0\.1:\d+"', out)
    for name in ("vn200", "airdata", "surfaces"):
        assert f'port = "{tmp_path / name}"' in out
    assert not any(tmp_path.iterdir())  # the ports are unplugged on exit


def test_an_airspeed_only_probe_is_announced_with_the_config_it_needs(tmp_path):
    # --no-vanes: the µADC's α and β fields read zero, so the agent must be told they carry
    # nothing ([sensors.airdata] vanes = false), or it would record them as measured.
    result = _run(
        "--duration", "1", "--pty-dir", str(tmp_path), "--mavlink-port", "0", "--no-vanes"
    )
    assert result.returncode == 0, result.stderr
    port = tmp_path / "airdata"
    line = f'µADC (100 Hz, airspeed only): [sensors.airdata] port = "{port}", vanes = false'
    assert line in result.stdout


def test_unknown_aircraft_is_a_clear_error(tmp_path):
    result = _run("--aircraft", "NoSuchPlane", "--duration", "1", "--pty-dir", str(tmp_path))
    assert result.returncode == 2
    assert "JSBSim has no aircraft 'NoSuchPlane'" in result.stderr


def test_sensor_rate_is_announced_and_checked(tmp_path):
    result = _run(
        "--duration", "1", "--pty-dir", str(tmp_path), "--mavlink-port", "0", "--sensor-rate", "400"
    )
    assert result.returncode == 0, result.stderr
    assert "VN-200 (binary, 400 Hz)" in result.stdout
    for rate in ("250", "0", "-100", "1200", "30"):
        bad = _run("--duration", "1", "--pty-dir", str(tmp_path), "--sensor-rate", rate)
        assert bad.returncode == 2, (rate, bad.stderr)
        assert f"sensor rate {float(rate):g} Hz: must be 100 Hz divided or multiplied" in bad.stderr


@pytest.mark.parametrize("port", ["99999", "-1", "udp"])
def test_a_port_that_is_not_one_is_a_usage_error(port, capsys):
    """Bad input tried: --mavlink-port 99999, -1 and a word (99999 used to reach bind() and
    end in an OverflowError traceback)."""
    from agent.cli import main

    assert main(["sim-aircraft", "--mavlink-port", port]) == 2
    assert "argument --mavlink-port" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["sim", "sim-aircraft"])
@pytest.mark.parametrize("value", ["-5", "nan", "inf", "16"])
def test_a_turbulence_outside_calm_to_severe_is_a_usage_error(command, value, capsys):
    """Bad input tried: --turbulence -5 (`sysid sim` flew it, in calm air), nan, inf and 16
    (beyond MIL-F-8785C's severe): refused before anything starts, with the range."""
    from agent.cli import main

    assert main([command, "--turbulence", value]) == 2
    err = capsys.readouterr().err
    assert f"argument --turbulence: {value}: give 0 (calm) to 15 (severe)" in err
