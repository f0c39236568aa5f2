"""Autopilot logs → the channel names of `sysid identify` (`sysid import`).

ArduPilot DataFlash (.bin, read with pymavlink's DFReader). The mapping:

- ATT.Roll, Pitch, Yaw → phi, theta, psi (rad; logged in degrees);
- IMU.GyrX, GyrY, GyrZ → p, q, r (rad/s) and AccX, AccY, AccZ → ax, ay, az (m/s²), instance 0;
- ARSP.Airspeed → Vt (m/s), instance 0;
- XKF1.VN, VE, VD (EKF3's velocity over the ground, core 0, the primary unless EK3_PRIMARY
  says otherwise) → vn, ve, vd (m/s); EKF2's NKF1 where the log has no XKF1: with ψ, the
  navigation the whole-aircraft method measures the wind with;
- AOA.AOA, SSA → aoa_ahrs, ssa_ahrs (rad; logged in degrees). Not vanes: ArduPilot computes
  them from the airspeed, its EKF's wind estimate and the velocity over the ground
  (AP_AHRS), so they are named apart and `sysid identify` synthesises α and β itself from
  the INS channels (agent.ident.aircraft.airangles), saying so; name them as the alpha and
  beta channels in `[identification.channels]` to use ArduPilot's instead;
- RCOU.C<n> of each [excitation.surfaces] control (its `channel`) → <control>_pwm (µs, as
  logged) and <control>: surfaces in degrees from 1500 µs by the control's `us_per_unit` and
  `direction` (the RC input's sense: in MANUAL an output follows its input while
  SERVOn_REVERSED is 0), throttle in µs (PWM, as the thesis);
- SIDD (ArduPilot's SystemID mode) Targ, F, Time → sid_target (the injected input),
  sid_frequency_hz, sid_time (0 outside the run), and sid_active (1 while SIDD is logged).

PX4 ULog (.ulg, read with pyulog), instance 0 of each topic:

- vehicle_attitude.q (w, x, y, z) → phi, theta, psi (rad, ZYX Euler angles);
- vehicle_angular_velocity.xyz → p, q, r; vehicle_acceleration.xyz → ax, ay, az;
- vehicle_local_position.vx, vy, vz (the EKF's velocity, north, east, down) → vn, ve, vd, the
  samples its v_xy_valid / v_z_valid flags mark invalid dropped;
- airspeed_validated.true_airspeed_m_s → Vt; airflow_aoa.aoa_rad → alpha and
  airflow_slip.slip_rad → beta where the vehicle logs them;
- actuator_outputs.output[channel − 1] → <control>_pwm and <control>, as for ArduPilot.

Angles that wrap (ψ logged from 0 to 360°, φ past ±180°) are unwrapped before they are
interpolated: a heading crossing north would otherwise pass through 180° between two samples.
Every channel is interpolated linearly onto one uniform time grid (`rate_hz`, default 50 Hz,
ArduPilot's usual ATT/IMU rate) over the span all mapped channels cover; `time` is seconds
since the log's first sample. A channel the log does not have is left out and listed in
`missing`; SIDS (the SystemID settings: axis, magnitude, frequency span) goes to `notes`.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agent.analysis.records import COMMANDS
from agent.config import Surface

DEG = np.pi / 180.0
# ArduPilot's SID_AXIS values (SystemID mode).
SID_AXES = {
    1: "input roll",
    2: "input pitch",
    3: "input yaw",
    4: "recovery roll",
    5: "recovery pitch",
    6: "recovery yaw",
    7: "rate roll",
    8: "rate pitch",
    9: "rate yaw",
    10: "mixer roll",
    11: "mixer pitch",
    12: "mixer yaw",
    13: "mixer thrust",
}
# EKF2's velocities are kept under this suffix and used only where the log has no EKF3's.
EKF2 = "@NKF1"
# The columns whose angle wraps (rad), unwrapped before the interpolation.
WRAPPING = ("phi", "psi")
# (message, field, column, scale, instance field or None)
DATAFLASH = [
    ("ATT", "Roll", "phi", DEG, None),
    ("ATT", "Pitch", "theta", DEG, None),
    ("ATT", "Yaw", "psi", DEG, None),
    ("IMU", "GyrX", "p", 1.0, "I"),
    ("IMU", "GyrY", "q", 1.0, "I"),
    ("IMU", "GyrZ", "r", 1.0, "I"),
    ("IMU", "AccX", "ax", 1.0, "I"),
    ("IMU", "AccY", "ay", 1.0, "I"),
    ("IMU", "AccZ", "az", 1.0, "I"),
    ("ARSP", "Airspeed", "Vt", 1.0, "I"),
    ("AOA", "AOA", "aoa_ahrs", DEG, None),
    ("AOA", "SSA", "ssa_ahrs", DEG, None),
    ("XKF1", "VN", "vn", 1.0, "C"),
    ("XKF1", "VE", "ve", 1.0, "C"),
    ("XKF1", "VD", "vd", 1.0, "C"),
    ("NKF1", "VN", "vn" + EKF2, 1.0, "C"),
    ("NKF1", "VE", "ve" + EKF2, 1.0, "C"),
    ("NKF1", "VD", "vd" + EKF2, 1.0, "C"),
    ("SIDD", "Targ", "sid_target", 1.0, None),
    ("SIDD", "F", "sid_frequency_hz", 1.0, None),
    ("SIDD", "Time", "sid_time", 1.0, None),
]
# What a PX4 log gives where it has every topic mapped (module docstring).
PX4_COLUMNS = [
    "phi", "theta", "psi", "p", "q", "r", "ax", "ay", "az", "Vt", "alpha", "beta", "vn", "ve", "vd"
]  # fmt: skip
DEFAULT_RATE_HZ = 50.0


class LogImportError(ValueError):
    """A log that cannot be imported; the message says which file and why."""


@dataclass
class Imported:
    path: Path
    kind: str
    time: np.ndarray
    columns: dict[str, np.ndarray]
    missing: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def csv(self) -> str:
        """The record as `sysid identify` reads it, with "# " lines saying where it came from."""
        out = io.StringIO()
        out.write(f"# imported from {self.path.name} ({self.kind}) by sysid import\n")
        for note in self.notes:
            out.write(f"# {note}\n")
        if self.missing:
            out.write(f"# not in the log: {', '.join(self.missing)}\n")
        # The surfaces come from the servo outputs: commands, held between updates
        # (`sysid identify` holds them; agent.analysis.records.COMMANDS).
        commands = [c for c in self.columns if c.endswith("_pwm") or f"{c}_pwm" in self.columns]
        if commands:
            out.write(f"{COMMANDS} {', '.join(commands)}\n")
        names = list(self.columns)
        out.write(",".join(["time", *names]) + "\n")
        table = np.column_stack([self.time, *(self.columns[n] for n in names)])
        np.savetxt(out, table, delimiter=",", fmt="%.9g")
        return out.getvalue()


def import_log(
    path: str | Path, surfaces: Mapping[str, Surface], rate_hz: float = DEFAULT_RATE_HZ
) -> Imported:
    """Read an autopilot log (by its extension) into uniformly sampled columns."""
    path = Path(path)
    if not path.exists():
        raise LogImportError(f"{path}: no such file")
    if path.suffix.lower() == ".bin":
        return _dataflash(path, surfaces, rate_hz)
    if path.suffix.lower() == ".ulg":
        return _ulog(path, surfaces, rate_hz)
    raise LogImportError(f"{path}: unknown log type {path.suffix!r} (ArduPilot .bin, PX4 .ulg)")


class _Chatter(io.TextIOBase):
    """Where pymavlink's prints go while a log is read: counted, the first kept, none shown.
    It prints to stdout and stderr a line or two per damaged record (thousands for one
    damaged FMT), and stdout is the command's."""

    def __init__(self) -> None:
        self.lines, self.first = 0, ""

    def writable(self) -> bool:
        return True

    def write(self, text: str) -> int:
        self.lines += text.count("\n")
        if not self.first and text.strip():
            self.first = next(ln.strip() for ln in text.splitlines() if ln.strip())[:200]
        return len(text)


@contextlib.contextmanager
def _quiet(chatter: _Chatter):
    """pymavlink's prints into `chatter`: Python's (stdout and stderr), and its C indexer's,
    which fprintf a line per bad header to file descriptor 2 itself (caught in a temporary
    file, then counted)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
                    yield
            finally:
                os.dup2(saved, 2)
                sink.seek(0)
                for chunk in iter(lambda: sink.read(1 << 16), b""):
                    chatter.write(chunk.decode(errors="replace"))
    finally:
        os.close(saved)


def _dataflash(path: Path, surfaces: Mapping[str, Surface], rate_hz: float) -> Imported:
    chatter = _Chatter()
    with _quiet(chatter):
        series, notes = _read_dataflash(path, surfaces)
    if chatter.lines:
        notes.append(
            f"pymavlink reported {chatter.lines} line(s) of damage while reading, the first: "
            f"{chatter.first}"
        )
    for control, surface in surfaces.items():
        pwm = series.get(f"{control}_pwm")
        if pwm is not None:
            values = np.asarray(pwm[1])
            series[control] = (pwm[0], list(_deflection(control, values, surface)))
    expected = [
        c for _, _, c, _, _ in DATAFLASH if not c.startswith("sid_") and not c.endswith(EKF2)
    ]
    return _resample(path, "ArduPilot DataFlash", series, rate_hz, notes, expected)


def _read_dataflash(
    path: Path, surfaces: Mapping[str, Surface]
) -> tuple[dict[str, tuple[list[float], list[float]]], list[str]]:
    """Every mapped message's (times, values) by column, and notes on what was found."""
    from pymavlink import DFReader

    try:
        reader = DFReader.DFReader_binary(str(path), zero_time_base=True)
    except Exception as exc:  # pymavlink raises bare exceptions on a damaged header
        raise LogImportError(f"{path}: not a DataFlash log ({exc})") from exc
    wanted = {m for m, *_ in DATAFLASH} | {"RCOU", "SIDS"}
    series: dict[str, tuple[list[float], list[float]]] = {}
    notes: list[str] = []
    channels = {name: s.channel for name, s in surfaces.items()}
    damaged = 0
    while True:
        before = reader.offset
        # Message by message, not recv_match(type=…): that jumps through pymavlink's index
        # of message offsets, which ends at the first unknown message type (one flipped byte),
        # so everything after it was silently lost. _parse_next resyncs past damage.
        try:
            m = reader.recv_msg()
            if m is not None and m.get_type() not in wanted:
                continue
        except Exception:  # a damaged message: skip it and read on (pymavlink resyncs)
            damaged += 1
            if reader.offset <= before:  # never stuck on one spot
                reader.offset, reader.remaining = before + 1, reader.remaining - 1
            continue
        if m is None:
            break
        kind, t = m.get_type(), m.TimeUS * 1e-6
        if kind == "SIDS":
            axis = SID_AXES.get(int(m.Ax), f"axis {m.Ax}")
            notes.append(
                f"ArduPilot SystemID run: {axis}, magnitude {m.Mag:g}, "
                f"{m.FSt:g}–{m.FSp:g} Hz over {m.TR:g} s"
            )
            continue
        if kind == "RCOU":
            for control, ch in channels.items():
                _append(series, f"{control}_pwm", t, float(getattr(m, f"C{ch}")))
            continue
        for message, name, column, scale, instance in DATAFLASH:
            if message == kind and (instance is None or getattr(m, instance) == 0):
                _append(series, column, t, float(getattr(m, name)) * scale)
    if damaged:
        notes.append(f"{damaged} damaged message(s) skipped; reading went on past each")
    ekf2 = [c for c in series if c.endswith(EKF2)]
    if ekf2 and "vn" not in series:
        notes.append("velocities from EKF2 (NKF1): the log has no EKF3 (XKF1)")
    for column in ekf2:
        values = series.pop(column)
        series.setdefault(column.removesuffix(EKF2), values)
    return series, notes


def _ulog(path: Path, surfaces: Mapping[str, Surface], rate_hz: float) -> Imported:
    from pyulog import ULog

    topics = [
        "vehicle_attitude",
        "vehicle_local_position",
        "vehicle_angular_velocity",
        "vehicle_acceleration",
        "airspeed_validated",
        "airflow_aoa",
        "airflow_slip",
        "actuator_outputs",
    ]
    try:
        log = ULog(str(path), message_name_filter_list=topics)
    except Exception as exc:  # pyulog raises bare exceptions on a file that is not a ULog
        raise LogImportError(f"{path}: not a ULog file ({exc})") from exc
    data = {d.name: d.data for d in log.data_list if d.multi_id == 0}
    series: dict[str, tuple[list[float], list[float]]] = {}

    def put(column: str, t: np.ndarray, values: np.ndarray) -> None:
        series[column] = (list(t), list(np.asarray(values, dtype=float)))

    if "vehicle_attitude" in data:
        d = data["vehicle_attitude"]
        w, x, y, z = (d[f"q[{k}]"] for k in range(4))
        t = d["timestamp"] * 1e-6
        put("phi", t, np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)))
        put("theta", t, np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0)))
        put("psi", t, np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
    for topic, columns in (
        ("vehicle_angular_velocity", ("p", "q", "r")),
        ("vehicle_acceleration", ("ax", "ay", "az")),
    ):
        if topic in data:
            d = data[topic]
            for k, column in enumerate(columns):
                put(column, d["timestamp"] * 1e-6, d[f"xyz[{k}]"])
    if "vehicle_local_position" in data:
        d = data["vehicle_local_position"]
        t = d["timestamp"] * 1e-6
        for name, column, flag in (
            ("vx", "vn", "v_xy_valid"),
            ("vy", "ve", "v_xy_valid"),
            ("vz", "vd", "v_z_valid"),
        ):
            valid = d[flag].astype(bool) if flag in d else np.ones(t.size, bool)
            put(column, t, np.where(valid, d[name], np.nan))  # invalid: dropped, counted
    for topic, name, column in (
        ("airspeed_validated", "true_airspeed_m_s", "Vt"),
        ("airflow_aoa", "aoa_rad", "alpha"),
        ("airflow_slip", "slip_rad", "beta"),
    ):
        if topic in data:
            put(column, data[topic]["timestamp"] * 1e-6, data[topic][name])
    if "actuator_outputs" in data:
        d = data["actuator_outputs"]
        for control, surface in surfaces.items():
            pwm = d[f"output[{surface.channel - 1}]"]
            t = d["timestamp"] * 1e-6
            put(f"{control}_pwm", t, pwm)
            put(control, t, _deflection(control, pwm, surface))
    if not series:
        raise LogImportError(f"{path}: none of the mapped topics are in this log")
    notes = [f"PX4 ({log.msg_info_dict.get('sys_name', '?')}), dropouts: {len(log.dropouts)}"]
    return _resample(path, "PX4 ULog", series, rate_hz, notes, PX4_COLUMNS)


def _deflection(control: str, pwm: np.ndarray, surface: Surface) -> np.ndarray:
    """A logged output's PWM as the control's value: throttle as is (µs), a surface in degrees
    from 1500 µs in the sign of eq. 3.1."""
    if control == "throttle":
        return pwm
    return surface.direction * (np.asarray(pwm, dtype=float) - 1500.0) / surface.us_per_unit


def _append(series, column: str, t: float, value: float) -> None:
    times, values = series.setdefault(column, ([], []))
    times.append(t)
    values.append(value)


# A timestamp this far (s) from both its neighbours, one way and back, is damage (a flipped
# bit), not time: the sample is dropped. A real gap this long (logging paused) is not
# interpolated across: the record is the longest stretch without one.
JUMP_S = 1.0
# The most rows an import writes (the record reader's own limit).
MAX_ROWS = 5_000_000


def _clean(column: str, t: np.ndarray, v: np.ndarray, skipped: dict[str, int]):
    """The samples of one channel with non-finite values and damaged timestamps removed."""
    good = np.isfinite(t) & np.isfinite(v)
    if t.size >= 3:
        into, out = np.diff(t, prepend=t[0]), np.diff(t, append=t[-1])
        spike = ((into > JUMP_S) & (out < -JUMP_S)) | ((into < -JUMP_S) & (out > JUMP_S))
        good &= ~spike
    if (~good).any():
        skipped[column] = int((~good).sum())
    return t[good], v[good]


def _stretch(core: dict, start: float, end: float) -> tuple[float, float, list[tuple]]:
    """The longest time span within [start, end] where no channel has a gap over JUMP_S, and
    the gaps (channel, from, to) that bound it."""
    gaps = []
    for column, (t, _) in core.items():
        ts = np.sort(t)
        k = np.flatnonzero(np.diff(ts) > JUMP_S)
        gaps += [(column, float(ts[i]), float(ts[i + 1])) for i in k]
    best, span, covered = (start, end), -1.0, start
    for a, b in sorted([(a, b) for _, a, b in gaps] + [(end, end)]):
        lo, hi = max(covered, start), min(a, end)  # free from the last gap's end to this one
        if hi - lo > span:
            best, span = (lo, hi), hi - lo
        covered = max(covered, b)
    return best[0], best[1], gaps


def _resample(
    path: Path, kind: str, series, rate_hz: float, notes: list[str], expected: list[str]
) -> Imported:
    skipped: dict[str, int] = {}
    series = {
        c: _clean(c, np.asarray(t, float), np.asarray(v, float), skipped)
        for c, (t, v) in series.items()
    }
    if skipped:
        listed = ", ".join(f"{c} {n}" for c, n in skipped.items())
        notes.append(
            f"samples dropped (a non-finite value or a timestamp jumping away and back "
            f"by over {JUMP_S:g} s): {listed}"
        )
    core = {c: s for c, s in series.items() if not c.startswith("sid_") and s[0].size}
    if not core:
        raise LogImportError(f"{path}: none of the mapped messages are in this log")
    start = max(float(np.min(s[0])) for s in core.values())
    end = min(float(np.max(s[0])) for s in core.values())
    if end - start >= 2.0 / rate_hz:
        lo, hi, gaps = _stretch(core, start, end)
        if (lo, hi) != (start, end):
            notes.append(
                f"kept {lo - start:.3f}–{hi - start:.3f} s of {end - start:.3f} s: the longest "
                f"stretch without a gap over {JUMP_S:g} s (gaps: "
                + ", ".join(f"{c} {a - start:.3f}–{b - start:.3f} s" for c, a, b in gaps[:5])
                + (" …" if len(gaps) > 5 else "")
                + ")"
            )
            start, end = lo, hi
    if end - start < 2.0 / rate_hz:
        raise LogImportError(f"{path}: the mapped channels overlap for less than two samples")
    if (end - start) * rate_hz > MAX_ROWS:
        raise LogImportError(
            f"{path}: {end - start:.0f} s at {rate_hz:g} Hz is over {MAX_ROWS} rows; "
            "import at a lower --rate or split the log"
        )
    time = np.arange(start, end, 1.0 / rate_hz)
    columns = {}
    for column, (t, v) in series.items():
        t, v = np.asarray(t), np.asarray(v)
        order = np.argsort(t, kind="stable")
        if column in WRAPPING:
            v = v.copy()
            v[order] = np.unwrap(v[order])
        if column.startswith("sid_"):
            inside = (time >= t.min()) & (time <= t.max())
            columns[column] = np.where(inside, np.interp(time, t[order], v[order]), 0.0)
        else:
            columns[column] = np.interp(time, t[order], v[order])
    if "sid_time" in series:
        t = np.asarray(series["sid_time"][0])
        columns["sid_active"] = ((time >= t.min()) & (time <= t.max())).astype(float)
    expected = list(dict.fromkeys(expected))
    missing = [c for c in expected if c not in columns]
    return Imported(path, kind, time - time[0], columns, missing, notes)
