"""`sysid import` on PX4 ULog files written here from the format specification.

The same known roll-rate model as the ArduPilot test, logged as PX4 logs it: attitude as a
quaternion, body rates, accelerations, true airspeed, the EKF's local velocity (briefly
flagged invalid), AoA/sideslip topics, PWM outputs.

Bad input tried: a file that is not a ULog, a ULog with none of the mapped topics.
"""

from __future__ import annotations

import numpy as np
import pytest

from agent.analysis.importers import LogImportError, import_log
from agent.config import Config
from agent.sim.ulog import ULogWriter
from tests.analysis.test_import_ardupilot import POLE, roll_response

SURFACES = Config().excitation.surfaces


def quaternion(phi, theta, psi):
    cr, sr = np.cos(phi / 2), np.sin(phi / 2)
    cp, sp = np.cos(theta / 2), np.sin(theta / 2)
    cy, sy = np.cos(psi / 2), np.sin(psi / 2)
    return [
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    ]


def px4_log(path, seconds=20.0, rate=100.0, pause=None):
    """The known roll model logged as PX4 does; `pause`: (from, to) s with nothing logged."""
    dt, n = 1.0 / rate, int(seconds * rate)
    t = np.arange(n) * dt
    aileron = np.where((t > 2) & (t < 18), 5.0 * np.sign(np.sin(2 * np.pi * 0.4 * t)), 0.0)
    p, phi = roll_response(aileron, dt)
    with ULogWriter(path) as log:
        for k in range(n):
            if pause is not None and pause[0] <= t[k] < pause[1]:
                continue
            us = 1_000_000 + int(t[k] * 1e6)
            log.write("vehicle_attitude", timestamp=us, q=quaternion(phi[k], 0.05, 1.0))
            log.write("vehicle_angular_velocity", timestamp=us + 100, xyz=[p[k], 0.0, 0.0])
            log.write("vehicle_acceleration", timestamp=us + 100, xyz=[0.0, 0.0, -9.81])
            log.write("airspeed_validated", timestamp=us + 200, true_airspeed_m_s=21.5)
            log.write(
                "vehicle_local_position",
                timestamp=us + 250,
                vx=20.0 + 0.1 * t[k],
                vy=1.0,
                vz=0.2,
                v_xy_valid=not 5.0 <= t[k] < 5.05,  # the EKF's velocity briefly invalid
                v_z_valid=True,
            )
            log.write("airflow_aoa", timestamp=us + 300, aoa_rad=0.06, valid=True)
            outputs = [1500.0] * 16
            outputs[0], outputs[2] = 1500.0 + 20.0 * aileron[k], 1350.0
            log.write("actuator_outputs", timestamp=us + 400, noutputs=8, output=outputs)
    return t, phi, p


def test_px4_topics_map_to_the_channels(tmp_path):
    t, phi, p = px4_log(tmp_path / "flight.ulg")
    imported = import_log(tmp_path / "flight.ulg", SURFACES, 50.0)
    c = imported.columns
    assert np.allclose(np.diff(imported.time), 0.02)
    assert np.allclose(c["theta"], 0.05, atol=1e-5)
    assert np.allclose(c["psi"], 1.0, atol=1e-5)
    assert np.interp(10.0, imported.time, c["phi"]) == pytest.approx(
        np.interp(10.0 + 0.0, t, phi), abs=2e-3
    )
    assert np.allclose(c["p"], np.interp(imported.time + 0.0004, t, p), atol=1e-3)
    assert np.allclose(c["Vt"], 21.5)
    assert np.allclose(c["alpha"], 0.06)
    assert np.allclose(c["throttle"], 1350.0)
    assert np.max(np.abs(c["aileron"])) == pytest.approx(5.0)
    # In eq. 3.1's sign: a larger roll output (ArduPlane rolls right) is a negative δA.
    moved = np.abs(c["aileron_pwm"] - 1500.0) > 1.0
    assert moved.any()
    assert np.all(np.sign(c["aileron"][moved]) == -np.sign(c["aileron_pwm"][moved] - 1500.0))
    # The EKF's velocity; the samples it flags invalid dropped (and said so), not imported.
    assert c["vn"] == pytest.approx(20.0 + 0.1 * (imported.time + 0.00125), abs=1e-3)
    assert np.allclose(c["ve"], 1.0)
    assert np.allclose(c["vd"], 0.2)
    assert any("vn 5" in note and "ve 5" in note for note in imported.notes)
    assert imported.missing == ["beta"]  # no airflow_slip topic in this log
    assert imported.kind == "PX4 ULog"


@pytest.mark.parametrize("damage", ["not a ulog", "no mapped topics"])
def test_bad_ulog_files(tmp_path, damage):
    path = tmp_path / "bad.ulg"
    if damage == "not a ulog":
        path.write_bytes(b"\x00" * 500)
    else:
        ULogWriter(path).close()
    with pytest.raises(LogImportError, match=r"bad\.ulg"):
        import_log(path, SURFACES, 50.0)


def test_imported_px4_record_through_the_post_flight_tools(tmp_path):
    import json
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    env = {"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin", "OPENBLAS_NUM_THREADS": "1"}

    def sysid(*args):
        done = subprocess.run(
            [sys.executable, "-m", "agent", *args],
            capture_output=True,
            text=True,
            timeout=120,
            env=env,
            cwd=tmp_path,
        )
        assert done.returncode == 0, done.stderr
        return done.stdout

    px4_log(tmp_path / "flight.ulg")
    sysid("import", "flight.ulg", "--out", "flight.csv", "--rate", "50")
    out = json.loads(
        sysid(
            "analyze",
            "flight.csv",
            "--inputs",
            "aileron",
            "--outputs",
            "p",
            "--order",
            "1",
            "--json",
        )
    )
    pole = out["cases"][0]["result"]["modes"][0]["eigenvalue"][0]
    assert pole == pytest.approx(POLE, rel=0.05)
    sysid(
        "report",
        "flight.csv",
        "--inputs",
        "aileron",
        "--outputs",
        "p",
        "--order",
        "1",
        "--out",
        "report",
    )
    assert (tmp_path / "report" / "excitation_1_time.png").exists()


def test_a_corrupted_timestamp_is_dropped_not_gridded(tmp_path):
    """Bad input tried: one vehicle_attitude timestamp 102 h off (a flipped bit) in a 20 s
    log: it used to stretch the grid to 18.5 million rows (6 GB). The sample is dropped and
    named; the record keeps its 20 s."""
    path = tmp_path / "flight.ulg"
    px4_log(path, seconds=20.0)
    data = bytearray(path.read_bytes())
    # The 500th attitude sample's timestamp (uint64 little-endian after the msg_id).
    stamp = (1_000_000 + int(499 * 0.01 * 1e6)).to_bytes(8, "little")
    at = data.find(stamp)
    assert at > 0
    data[at : at + 8] = (1_000_000 + 102 * 3600 * 10**6).to_bytes(8, "little")
    path.write_bytes(bytes(data))
    imported = import_log(path, SURFACES, 50.0)
    assert imported.time[-1] == pytest.approx(19.98, abs=0.05)
    assert any("samples dropped" in n and "phi 1" in n for n in imported.notes), imported.notes


def test_a_gap_in_the_log_is_not_interpolated_across(tmp_path):
    """Bad input tried: logging paused for 5 s mid-flight (every topic): the record is the
    longer stretch, and the note says what was cut."""
    path = tmp_path / "gap.ulg"
    px4_log(path, seconds=20.0, pause=(6.0, 11.0))
    imported = import_log(path, SURFACES, 50.0)
    assert imported.time[-1] == pytest.approx(9.0 - 0.0004, abs=0.05)  # 11–20 s: the longer
    assert any("the longest stretch without a gap" in n for n in imported.notes), imported.notes
