"""`sysid console` refuses to start, with the reason, when it cannot reach its radio.

Bad input tried: a ground config with an unknown key and a bad address (exit 2, each key
named), a missing key file, a serial port that does not exist (exit 1, before any screen).
"""

from __future__ import annotations

import os
import secrets
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def sysid(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "agent", *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_the_bundled_ground_config_is_valid(tmp_path):
    done = sysid("config", "check", "--ground", str(ROOT / "ground.toml"), cwd=tmp_path)
    assert done.returncode == 0, done.stderr


def test_a_bad_ground_config_names_each_key(tmp_path):
    bad = tmp_path / "ground.toml"
    bad.write_text('stale = 3\n[link]\npeer = "not-an-address"\n')
    done = sysid("console", "--config", str(bad), cwd=tmp_path)
    assert done.returncode == 2
    assert "stale" in done.stderr
    assert "link.peer" in done.stderr


def test_no_key_file_or_no_port_is_reported_before_the_screen(tmp_path):
    config = tmp_path / "ground.toml"
    config.write_text('[link]\nport = "/dev/nonexistent-xbee"\npeer = "0013A20041000001"\n')
    done = sysid("console", "--config", str(config), "--base", str(tmp_path), cwd=tmp_path)
    assert done.returncode == 1
    assert "cannot read the link key" in done.stderr
    (tmp_path / "link.key").write_text(secrets.token_hex(32))
    (tmp_path / "link.key").chmod(0o600)
    done = sysid("console", "--config", str(config), "--base", str(tmp_path), cwd=tmp_path)
    assert done.returncode == 1
    assert "/dev/nonexistent-xbee: cannot open the XBee" in done.stderr
    assert "Traceback" not in done.stderr
    assert not list(
        (tmp_path / "ground-logs").glob("*.jsonl")
    )  # no log of a session that never was
