"""`sysid import` on ArduPilot DataFlash logs written here with pymavlink's DataFlash classes.

A generated SystemID log: ArduPilot's SystemID mode injects a chirp on the roll input (SIDS,
SIDD records) into a known roll-rate model p' = -4 p + 0.8 δa (δa in degrees of aileron from
RCOU, 20 µs per degree), logged the way ArduPlane logs (ATT in degrees, IMU, ARSP, AOA, RCOU,
each message at its own time stamp). The import must map units and names, resample uniformly,
recognise the SystemID run, and give a record `sysid identify` turns back into the known pole.

A flight's navigation: the EKF's velocities (EKF3's XKF1, EKF2's NKF1 where there is no
XKF1) and a heading that crosses north, unwrapped rather than interpolated through 180°.

Bad input tried: a file that is not a DataFlash log, a log cut off mid-message (what was read
before the cut is imported), a log with none of the mapped messages, a damaged FMT record
(pymavlink's thousands of lines about it kept off stdout), a missing file, an unknown
extension, a rate out of range.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from agent.analysis.importers import LogImportError, import_log
from agent.config import Config
from agent.sim.dataflash import DataFlashWriter

ROOT = Path(__file__).resolve().parents[2]
SURFACES = Config().excitation.surfaces
POLE, GAIN, RATE = -4.0, 0.8, 50.0


def roll_response(aileron: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """p and phi of the known roll model p' = POLE p + GAIN δa, δa held between samples."""
    p = np.zeros(aileron.size)
    a, b = np.exp(POLE * dt), GAIN * (np.exp(POLE * dt) - 1) / POLE
    for k in range(aileron.size - 1):
        p[k + 1] = a * p[k] + b * aileron[k]
    return p, np.cumsum(p) * dt


def systemid_log(path: Path, seconds: float = 30.0, seed: int = 0) -> dict:
    """The roll axis under ArduPilot's SystemID chirp; returns what was simulated."""
    rng = np.random.default_rng(seed)
    dt = 1.0 / RATE
    n = int(seconds * RATE)
    t = np.arange(n) * dt
    sid = (t >= 5.0) & (t < 25.0)
    tau = np.where(sid, t - 5.0, 0.0)
    f0, f1, span = 0.2, 3.0, 20.0
    freq = f0 + (f1 - f0) * tau / span
    chirp = np.where(
        sid, 4.0 * np.sin(2 * np.pi * (f0 * tau + (f1 - f0) * tau**2 / (2 * span))), 0.0
    )
    aileron = chirp  # degrees
    p, phi = roll_response(aileron, dt)
    with DataFlashWriter(path) as log:
        log.write("MODE", TimeUS=0, Mode=25, ModeNum=25)
        log.write("SIDS", TimeUS=int(5e6), Ax=1, Mag=4.0, FSt=f0, FSp=f1, TFin=0, TC=0, TR=span)
        for k in range(n):
            us = int(t[k] * 1e6)
            log.write("ATT", TimeUS=us + 300, Roll=np.degrees(phi[k]), Pitch=2.0, Yaw=90.0)
            log.write(
                "IMU",
                TimeUS=us + 600,
                I=0,
                GyrX=p[k] + rng.normal(0, 1e-4),
                GyrY=0.0,
                GyrZ=0.0,
                AccZ=-9.81,
            )
            log.write("IMU", TimeUS=us + 700, I=1, GyrX=99.0)  # a second IMU: not mapped
            log.write("ARSP", TimeUS=us + 900, I=0, Airspeed=22.0)
            log.write("AOA", TimeUS=us + 1000, AOA=3.0, SSA=-1.0)
            log.write("XKF1", TimeUS=us + 1100, C=0, Yaw=90.0, VN=0.5, VE=22.0, VD=-0.3)
            log.write("XKF1", TimeUS=us + 1150, C=1, VN=99.0)  # a second core: not mapped
            pwm = {f"C{ch}": 1500 for ch in range(1, 15)}
            pwm["C1"] = round(1500 + 20.0 * aileron[k])
            pwm["C3"] = 1300
            log.write("RCOU", TimeUS=us + 1200, **pwm)
            if sid[k]:
                log.write("SIDD", TimeUS=us + 1300, Time=tau[k], Targ=chirp[k], F=freq[k])
    return {"t": t, "p": p, "aileron": aileron, "sid": sid}


def test_units_names_and_the_systemid_run(tmp_path):
    truth = systemid_log(tmp_path / "sid.bin")
    imported = import_log(tmp_path / "sid.bin", SURFACES, RATE)
    c = imported.columns
    assert np.allclose(np.diff(imported.time), 1 / RATE)
    assert np.allclose(c["theta"], np.radians(2.0), atol=1e-4)
    assert np.allclose(c["psi"], np.radians(90.0), atol=1e-4)
    # ArduPilot's AOA and SSA are its AHRS's estimates, not vanes: named apart.
    assert np.allclose(c["aoa_ahrs"], np.radians(3.0), atol=1e-6)
    assert np.allclose(c["ssa_ahrs"], np.radians(-1.0), atol=1e-6)
    assert "alpha" not in c
    assert "beta" not in c
    assert np.allclose(c["vn"], 0.5, atol=1e-6)  # EKF core 0 (core 1 reads 99)
    assert np.allclose(c["ve"], 22.0, atol=1e-6)
    assert np.allclose(c["vd"], -0.3, atol=1e-6)
    assert np.allclose(c["Vt"], 22.0)
    assert np.allclose(c["az"], -9.81, atol=1e-5)
    assert c["p"].max() < 50  # instance 1 (GyrX = 99) is not mixed in
    assert np.allclose(c["throttle"], 1300.0)  # throttle stays in µs
    assert set(c["aileron_pwm"]) >= {1500.0}
    # The aileron in degrees follows the simulated deflection (20 µs per degree).
    assert np.max(np.abs(c["aileron"])) == pytest.approx(4.0, abs=0.1)
    # In eq. 3.1's sign: a larger roll output (ArduPlane rolls right) is a negative δA.
    moved = np.abs(c["aileron_pwm"] - 1500.0) > 1.0
    assert moved.any()
    assert np.all(np.sign(c["aileron"][moved]) == -np.sign(c["aileron_pwm"][moved] - 1500.0))
    # SystemID: active from 5 to 25 s, its target is the injected chirp.
    active = imported.time[c["sid_active"] == 1.0]
    assert active[0] == pytest.approx(5.0, abs=0.05)
    assert active[-1] == pytest.approx(25.0, abs=0.05)
    assert np.max(np.abs(c["sid_target"])) == pytest.approx(4.0, abs=0.1)
    assert any(
        "SystemID run: input roll, magnitude 4, 0.2–3 Hz over 20 s" in n for n in imported.notes
    )
    assert imported.missing == []
    assert len(truth["t"]) == 1500


@pytest.mark.parametrize("ekf", ["XKF1", "NKF1"])
def test_the_ekfs_velocities_and_a_heading_across_north(tmp_path, ekf):
    rate, n = 50.0, 500
    t = np.arange(n) / rate
    heading = (350.0 + 2.0 * t) % 360.0  # 350° to 10° and on, as ArduPilot logs it
    with DataFlashWriter(tmp_path / "nav.bin") as log:
        for k in range(n):
            us = int(t[k] * 1e6)
            log.write("ATT", TimeUS=us + 300, Roll=0.0, Pitch=2.0, Yaw=heading[k])
            log.write("IMU", TimeUS=us + 600, I=0, AccZ=-9.81)
            log.write("ARSP", TimeUS=us + 900, I=0, Airspeed=22.0)
            log.write(ekf, TimeUS=us + 1000, C=0, VN=20.0 + t[k], VE=-3.0, VD=0.5)
            log.write("RCOU", TimeUS=us + 1200, **{f"C{ch}": 1500 for ch in range(1, 15)})
    imported = import_log(tmp_path / "nav.bin", SURFACES, rate)
    c = imported.columns
    psi = np.degrees(c["psi"])
    assert np.all(np.abs(np.diff(psi)) < 0.1)  # never through 180° between samples
    assert psi - psi[0] == pytest.approx(2.0 * imported.time, abs=0.1)  # 2°/s throughout
    assert psi[-1] > 360.0  # crossed north, and kept going
    assert c["vn"] - c["vn"][0] == pytest.approx(imported.time, abs=0.05)
    assert np.allclose(c["ve"], -3.0)
    assert np.allclose(c["vd"], 0.5)
    assert not any("vn" in m for m in imported.missing)
    assert ("EKF2" in "\n".join(imported.notes)) == (ekf == "NKF1")


def test_the_imported_record_identifies_the_known_pole(tmp_path):
    systemid_log(tmp_path / "sid.bin")
    csv = tmp_path / "sid.csv"
    run = lambda *args: subprocess.run(  # noqa: E731
        [sys.executable, "-m", "agent", *args],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={"PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin"},
    )
    # The SystemID run's roll axis, as `sysid identify` and `sysid analyze` are told it.
    window = (
        "--inputs",
        "aileron",
        "--outputs",
        "p",
        "--start",
        "4",
        "--end",
        "27",
        "--order",
        "1",
    )
    done = run("import", str(tmp_path / "sid.bin"), "--out", str(csv))
    assert done.returncode == 0, done.stderr
    assert "1 rows" not in done.stdout
    assert "note: ArduPilot SystemID run" in done.stdout
    done = run(
        "identify",
        str(csv),
        *window,
        "--json",
    )
    assert done.returncode == 0, done.stderr
    modes = json.loads(done.stdout)["modes"]
    assert modes[0]["eigenvalue"][0] == pytest.approx(POLE, rel=0.05)
    # The post-flight tools take the imported record too: a p sweep, and the report.
    done = run(
        "analyze",
        str(csv),
        *window,
        "--sweep",
        "markov=1:3",
        "--json",
    )
    assert done.returncode == 0, done.stderr
    sweep = json.loads(done.stdout)
    for case in sweep["cases"]:
        assert case["result"]["modes"][0]["eigenvalue"][0] == pytest.approx(POLE, rel=0.05)
    done = run(
        "report",
        str(csv),
        *window,
        "--out",
        str(tmp_path / "report"),
    )
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "report" / "excitation_1_bode.png").exists()


@pytest.mark.parametrize("damage", ["cut mid-message", "not a log", "no mapped messages"])
def test_damaged_logs(tmp_path, damage):
    path = tmp_path / "bad.bin"
    if damage == "cut mid-message":
        systemid_log(path, seconds=10.0)
        path.write_bytes(path.read_bytes()[:-7])
        imported = import_log(path, SURFACES, RATE)
        assert imported.time[-1] > 9.0  # everything before the cut
        return
    if damage == "not a log":
        path.write_bytes(bytes(range(256)) * 10)
    else:
        with DataFlashWriter(path) as log:
            log.write("MODE", TimeUS=0, Mode=0, ModeNum=0)
    with pytest.raises(LogImportError, match=r"bad\.bin"):
        import_log(path, SURFACES, RATE)


def test_fifty_flipped_bytes_cost_the_damaged_messages_not_the_rest(tmp_path):
    """Bad input tried: 50 bytes flipped at random through a 10 s DataFlash log: it used to be
    cut silently (1.9 s of 10 s here, exit 0; another seed made the grid 1.1e6 s long).
    pymavlink resyncs past each damaged message; the import keeps reading, and what it
    skipped or dropped is noted."""
    path = tmp_path / "flipped.bin"
    systemid_log(path, seconds=10.0)
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(0)
    for at in rng.choice(np.arange(len(data) // 10, len(data)), 50, replace=False):
        data[at] ^= 0xFF
    path.write_bytes(bytes(data))
    imported = import_log(path, SURFACES, RATE)
    # Cut at 1.9 s before: pymavlink's index of message offsets (what recv_match(type=…)
    # jumps through) ends at the first unknown message type.
    assert imported.time[-1] > 9.5
    assert imported.notes, "the damage was not reported"


def test_a_damaged_fmt_record_is_one_note_not_thousands_of_lines(tmp_path):
    """Input: a DataFlash log whose ATT format record says 27 bytes where its messages have 28
    (one damaged FMT). pymavlink printed about 3,000 lines for it, a thousand to stdout, which
    is the command's; they are counted into one note now, and the rest of the log imported."""
    path = tmp_path / "fmt.bin"
    systemid_log(path, seconds=10.0)
    data = bytearray(path.read_bytes())
    at = data.index(b"\xa3\x95\x80\x83")  # FMT (0x80) of type 0x83, ATT: Length is next
    assert data[at + 5 : at + 8] == b"ATT"
    data[at + 4] -= 1
    path.write_bytes(bytes(data))
    done = subprocess.run(
        [sys.executable, "-m", "agent", "import", "fmt.bin", "--out", "fmt.csv"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60,
        env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    rows = re.match(r"fmt\.csv: (\d+) rows over", lines[0])
    assert rows is not None, lines[0]
    assert int(rows.group(1)) > 450  # 10 s at 50 Hz: the rest of the log is there
    assert all(ln.startswith(("note: ", "not in the log: ")) for ln in lines[1:]), lines[:5]
    assert any(ln.startswith("note: pymavlink reported ") for ln in lines)
    assert "not in the log: phi, theta, psi" in lines  # ATT's columns, lost with its format
    assert done.stderr == ""


def test_command_line_refusals(tmp_path):
    def run(*args):
        return subprocess.run(
            [sys.executable, "-m", "agent", "import", *args],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=60,
            env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
        )

    missing = run("nope.bin", "--out", "x.csv")
    assert missing.returncode == 2
    assert "nope.bin: no such file" in missing.stderr
    (tmp_path / "log.txt").write_text("x")
    assert "unknown log type '.txt'" in run("log.txt", "--out", "x.csv").stderr
    assert "give 1 to 1000 Hz" in run("log.txt", "--out", "x.csv", "--rate", "0").stderr
    # Bad input tried: --out naming the flight log itself (it used to be overwritten by the
    # CSV), under another spelling of the same path.
    systemid_log(tmp_path / "c.bin", seconds=2.0)
    before = (tmp_path / "c.bin").read_bytes()
    same = run("c.bin", "--out", "./c.bin")
    assert same.returncode == 2
    assert "that is c.bin, the log being imported" in same.stderr
    assert (tmp_path / "c.bin").read_bytes() == before


@pytest.mark.parametrize("link", ["hard", "symbolic"])
def test_an_out_linked_to_the_log_is_refused_and_the_log_kept(tmp_path, capsys, link):
    """Bad input tried: `import ok.bin --out hard.bin` where hard.bin is a hard link to ok.bin
    (the path strings differ, so the log used to be overwritten by the CSV), and the same
    through a symbolic link: exit 2 naming both, the log's bytes unchanged."""
    from agent.cli import main

    log = tmp_path / "ok.bin"
    systemid_log(log, seconds=2.0)
    before = log.read_bytes()
    out = tmp_path / "hard.bin"
    if link == "hard":
        out.hardlink_to(log)
    else:
        out.symlink_to(log)
    assert main(["import", str(log), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"--out {out}: that is {log}, the log being imported" in err, err
    assert log.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hard.bin", "ok.bin"]


def test_a_full_disk_leaves_the_old_output_whole(small_disk, capsys):
    """Bad input tried: `import` onto a disk that fills up while the CSV is written (a real
    256 KiB tmpfs): exit 1, and the CSV from before is still there, whole, with no temporary
    file beside it (the write used to truncate it first and stop halfway)."""
    from agent.cli import main

    log = small_disk.parent / "sid.bin"
    systemid_log(log, seconds=5.0)
    out = small_disk / "sid.csv"
    assert main(["import", str(log), "--out", str(out)]) == 0
    capsys.readouterr()
    before = out.read_bytes()
    disk = os.statvfs(small_disk)
    # Half the old CSV free: the new one (at twice the rate, twice the size) fits neither
    # beside the old one nor in its place.
    (small_disk / "filler").write_bytes(b"x" * (disk.f_bavail * disk.f_frsize - len(before) // 2))
    assert main(["import", str(log), "--out", str(out), "--rate", "100"]) == 1
    assert "cannot be written" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert sorted(p.name for p in small_disk.iterdir()) == ["filler", "sid.csv"]
