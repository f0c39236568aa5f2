"""Fake sensors: real frames from a state source, written into pseudo-terminals at the
devices' real rates, with optional corruption and dropouts.

A `PtyPort` stands in for a serial device. Its `path` is a stable symbolic link (like
/dev/serial/by-id/...) to the current pty, so unplugging (closing the pty) and plugging in
again (a new pty behind the same link) looks to a driver exactly like a USB adapter coming
and going. An `Emitter` plays one device against absolute deadlines of the injected clock and
remembers when each frame was sampled (the truth that tests compare time stamps with).
"""

from __future__ import annotations

import contextlib
import errno
import os
import random
import tty
from collections import deque
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from agent.clock import Clock
from agent.config import Calibration
from drivers.airdata.codec import AirData, AirDataCodec
from drivers.airdata.driver import LAPSE, R_AIR, RHO0, T0
from drivers.surfaces.codec import CHANNELS, SurfaceCodec, SurfaceFrame
from drivers.vectornav.codec import AsciiCodec, BinaryCodec, VnAscii, VnPacket
from drivers.vectornav.driver import euler_to_quaternion

State = Mapping[str, float]
# Frames remembered per emitter for truth (10 minutes at 100 Hz).
TRUTH = 60_000


class PtyPort:
    """A pseudo-terminal behind a stable link path; plug() and unplug() as a cable would."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._master: int | None = None
        self._slave: int | None = None
        self.dropped_bytes = 0
        self.received = bytearray()

    @property
    def plugged(self) -> bool:
        return self._master is not None

    @property
    def master_fd(self) -> int | None:
        """The device side of the pty (for a fake device that also reads)."""
        return self._master

    def plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no echo, no CR/LF translation: bytes pass unchanged
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        tmp = self.path.with_suffix(".new")
        tmp.unlink(missing_ok=True)
        tmp.symlink_to(os.ttyname(slave))
        tmp.replace(self.path)

    def unplug(self) -> None:
        self.path.unlink(missing_ok=True)
        for fd in (self._master, self._slave):
            if fd is not None:
                os.close(fd)
        self._master = self._slave = None

    def write(self, data: bytes) -> None:
        """Write what the pty takes now; the rest is dropped and counted (a full buffer)."""
        if self._master is None:
            self.dropped_bytes += len(data)
            return
        try:
            written = os.write(self._master, data)
        except BlockingIOError:
            written = 0
        except OSError as exc:
            if exc.errno != errno.EIO:
                raise
            written = 0
        self.dropped_bytes += len(data) - written

    def read_commands(self) -> bytes:
        """Bytes the driver wrote to the device (configuration commands)."""
        if self._master is None:
            return b""
        with contextlib.suppress(BlockingIOError, OSError):
            self.received += os.read(self._master, 4096)
        return bytes(self.received)


class Emitter:
    """Plays one device: at t_k = start + k/rate, encodes the state at t_k and writes it."""

    def __init__(
        self,
        port: PtyPort,
        encode: Callable[[float, int], bytes],
        rate_hz: float,
        clock: Clock,
        *,
        corrupt: float = 0.0,
        dropout: float = 0.0,
        seed: int = 0,
    ):
        self.port, self._encode, self._rate, self._clock = port, encode, rate_hz, clock
        self.corrupt = corrupt
        """The chance that a frame goes out with one bit flipped (a fault test may change it
        while the emitter runs)."""
        self.dropout = dropout
        """The chance that a frame is not sent at all (likewise)."""
        self._rng = random.Random(seed)
        self.sent = 0
        self.corrupted = 0
        self.dropped = 0
        self.truth: deque[tuple[int, float]] = deque(maxlen=TRUTH)
        """(frame number, sample time) of every frame written whole and uncorrupted."""
        self._start = 0.0  # set when `run` starts
        self._next = 0  # the next frame's number

    @property
    def rate_hz(self) -> float:
        return self._rate

    async def run(self) -> None:
        """Emit on the clock's deadlines (a device with its own oscillator), one frame a turn
        of the loop when it is behind."""
        self._start = self._clock.now()
        while True:
            await self._clock.sleep_until(self._start + self._next / self._rate)
            self.emit_owed(self._clock.now(), most=1)

    def emit_owed(self, now: float, most: int | None = None) -> None:
        """Emit the frames due by `now` not yet emitted (at most `most`): what a device with
        its own oscillator sends while the loop that runs `run` is held up."""
        sent = 0
        while self._start + self._next / self._rate <= now and (most is None or sent < most):
            self.emit(self._start + self._next / self._rate, self._next)
            self._next += 1
            sent += 1

    def emit(self, t: float, k: int) -> None:
        """Encode and write frame k sampled at time t (a simulator calls this in step with
        its physics, so every frame carries the state of its own time stamp)."""
        frame = self._encode(t, k)
        if self._rng.random() < self.dropout:
            self.dropped += 1
        elif self.port.plugged:
            if self._rng.random() < self.corrupt:
                frame = self._spoil(frame)
                self.corrupted += 1
            else:
                self.truth.append((k, t))
            self.port.write(frame)
            self.sent += 1

    def _spoil(self, frame: bytes) -> bytes:
        spoilt = bytearray(frame)
        spoilt[self._rng.randrange(1, len(spoilt) - 1)] ^= 1 << self._rng.randrange(8)
        return bytes(spoilt)


# --- frame encoders from a state source ------------------------------------------------------


def vn200_binary(state: Callable[[float], State], boot: float) -> Callable[[float, int], bytes]:
    """VN-200 binary packets (the default field set) of the state at each time."""
    codec = BinaryCodec()
    gps_at_boot = 1_400_000_000.0  # s since the GPS epoch when the fake unit booted

    def encode(t: float, k: int) -> bytes:
        s = state(t)
        fields = {
            "common.time_startup": round((t - boot) * 1e9),
            "common.time_gps": round((gps_at_boot + t - boot) * 1e9),
            "common.quaternion": euler_to_quaternion(s["phi"], s["theta"], s["psi"]),
            "common.angular_rate": (s["p"], s["q"], s["r"]),
            "common.position": (s.get("lat", 30.6), s.get("lon", -96.3), s.get("alt", 120.0)),
            "common.vel_ned": (s.get("vn", 20.0), s.get("ve", 0.0), s.get("vd", 0.0)),
            "common.accel": (s.get("ax", 0.0), s.get("ay", 0.0), s.get("az", -9.81)),
            "common.ins_status": 0x0002,
        }
        return codec.encode(VnPacket(fields))

    return encode


def vn200_ascii(state: Callable[[float], State]) -> Callable[[float, int], bytes]:
    """$VNYMR sentences of the state (degrees, as the device sends them)."""
    codec = AsciiCodec()

    def encode(t: float, k: int) -> bytes:
        s = state(t)
        deg = 180 / np.pi
        values = {
            "yaw": round(s["psi"] * deg, 3),
            "pitch": round(s["theta"] * deg, 3),
            "roll": round(s["phi"] * deg, 3),
            "mag_x": 0.2,
            "mag_y": 0.0,
            "mag_z": 0.45,
            "accel_x": s.get("ax", 0.0),
            "accel_y": s.get("ay", 0.0),
            "accel_z": s.get("az", -9.81),
            "gyro_x": round(s["p"], 6),
            "gyro_y": round(s["q"], 6),
            "gyro_z": round(s["r"], 6),
        }
        return codec.encode(VnAscii("VNYMR", values))

    return encode


def airdata(state: Callable[[float], State], vanes: bool = True) -> Callable[[float, int], bytes]:
    """µADC lines: IAS from the true airspeed at the ISA density of the altitude; without
    `vanes` (an airspeed-only probe) α and β read zero."""
    codec = AirDataCodec()

    def encode(t: float, k: int) -> bytes:
        s = state(t)
        h = s.get("alt", 120.0)
        static = 101_325.0 * (1 - LAPSE * h / T0) ** 5.2559
        rho = static / (R_AIR * (T0 - LAPSE * h))
        ias = s["Vt"] * np.sqrt(rho / RHO0)
        deg = 180 / np.pi
        return codec.encode(
            AirData(
                k,
                ias,
                float(np.clip(s["alpha"] * deg, -20, 20)) if vanes else 0.0,
                float(np.clip(s["beta"] * deg, -20, 20)) if vanes else 0.0,
                h,
                static + 0.5 * rho * s["Vt"] ** 2,
                static,
            )
        )

    return encode


def surfaces(
    state: Callable[[float], State], calibration: Mapping[str, Calibration], boot: float
) -> Callable[[float, int], bytes]:
    """Surface-box frames: ganged aileron/elevator/rudder split onto the seven pots."""
    codec = SurfaceCodec()

    def encode(t: float, k: int) -> bytes:
        s = state(t)
        deflection = {
            "aileron_left": s.get("aileron_left", -s.get("aileron", 0.0)),
            "aileron_right": s.get("aileron_right", s.get("aileron", 0.0)),
            "elevator_left": s.get("elevator", 0.0),
            "elevator_right": s.get("elevator", 0.0),
            "rudder": s.get("rudder", 0.0),
            "flap_left": 0.0,
            "flap_right": 0.0,
        }
        counts = tuple(
            int(np.clip(round(degrees_to_counts(deflection[n], calibration[n])), 0, 1023))
            for n in CHANNELS
        )
        millis = round((t - boot) * 1000) & 0xFFFFFFFF
        return codec.encode(SurfaceFrame(k, millis, counts, int(s.get("rpm", 5200))))

    return encode


def degrees_to_counts(degrees: float, calibration: Calibration) -> float:
    """Inverse of the calibration (tables and linear polynomials)."""
    if calibration.table is not None:
        points = np.asarray(calibration.table, dtype=float)
        return float(np.interp(degrees, points[:, 1], points[:, 0]))
    c = calibration.poly
    if len(c) != 2:
        raise ValueError("the fake surface box inverts tables and linear polynomials only")
    return (degrees - c[0]) / c[1]
