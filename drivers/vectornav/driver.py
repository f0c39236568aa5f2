"""The VN-200 driver: packets → attitude, rates, accelerations, position, velocity, UTC."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

from drivers.codec import crc16_xmodem
from drivers.config import Sensors
from drivers.sensor import Reading, Sample, SensorDriver
from drivers.serialio import Backoff
from drivers.values import Clock
from drivers.vectornav.codec import AsciiCodec, BinaryCodec, VnAscii, VnPacket, masks_for

# Unix time of the GPS epoch, 1980-01-06T00:00:00Z.
GPS_EPOCH_UNIX = 315_964_800
SECONDS_PER_WEEK = 604_800
# The register 75 rate divisor divides this base rate, the IMU's (docs/protocols.md, *VN-200*).
BASE_RATE_HZ = 800
DEG = math.pi / 180
# Three-axis outputs taken as they are: their channels, then the binary field in the common
# group and in its own group (a packet carries one or the other).
BINARY_VECTORS = (
    (("p", "q", "r"), ("common.angular_rate", "imu.angular_rate")),
    (("ax", "ay", "az"), ("common.accel", "imu.accel")),
    (("lat", "lon", "alt_gps"), ("common.position", "ins.pos_lla")),
    (("vn", "ve", "vd"), ("common.vel_ned", "ins.vel_ned")),
)
# ASCII fields taken as they are: channel → field, per sentence.
ASCII_COPIED = {
    "VNYMR": {
        "p": "gyro_x",
        "q": "gyro_y",
        "r": "gyro_z",
        "ax": "accel_x",
        "ay": "accel_y",
        "az": "accel_z",
    },
    "VNINS": {
        "lat": "lat",
        "lon": "lon",
        "alt_gps": "alt",
        "vn": "vel_n",
        "ve": "vel_e",
        "vd": "vel_d",
    },
}


def quaternion_to_euler(x: float, y: float, z: float, w: float) -> tuple[float, float, float]:
    """(roll φ, pitch θ, yaw ψ) in rad, 3-2-1 sequence, from a unit quaternion, scalar last."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def euler_to_quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """Inverse of quaternion_to_euler: (x, y, z, w)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
        cr * cp * cy + sr * sp * sy,
    )


def gps_to_unix(gps_seconds: float, leap_seconds: int) -> float:
    """UTC (Unix seconds) of a time in seconds since the GPS epoch."""
    return GPS_EPOCH_UNIX + gps_seconds - leap_seconds


def _first(fields: dict, *names: str):
    return next((fields[n] for n in names if n in fields), None)


def convert_binary(leap_seconds: int) -> Callable[[VnPacket], Reading | None]:
    def convert(packet: VnPacket) -> Reading | None:
        f = packet.fields
        values: dict[str, float] = {}
        quaternion = _first(f, "common.quaternion", "attitude.quaternion")
        ypr = _first(f, "common.ypr", "attitude.ypr")
        if quaternion is not None:
            values["phi"], values["theta"], values["psi"] = quaternion_to_euler(*quaternion)
        elif ypr is not None:
            values["psi"], values["theta"], values["phi"] = (a * DEG for a in ypr)
        for channels, fields in BINARY_VECTORS:
            vector = _first(f, *fields)
            if vector is not None:
                values.update(zip(channels, vector, strict=True))
        status = _first(f, "common.ins_status", "ins.ins_status")
        if status is not None:
            values["ins_status"] = float(status)
        gps = _first(f, "common.time_gps", "time.time_gps")
        if gps is not None:
            values["utc"] = gps_to_unix(gps * 1e-9, leap_seconds)
        startup = _first(f, "common.time_startup", "time.time_startup")
        if startup is not None:
            values["vn_time"] = startup * 1e-9
        if not all(math.isfinite(v) for v in values.values()):
            return None
        return Reading(None if startup is None else startup * 1e-9, values)

    return convert


def convert_ascii(leap_seconds: int) -> Callable[[VnAscii], Reading | None]:
    def convert(message: VnAscii) -> Reading | None:
        v = message.values
        values = {"psi": v["yaw"] * DEG, "theta": v["pitch"] * DEG, "phi": v["roll"] * DEG}
        device_time = None
        values.update((channel, v[name]) for channel, name in ASCII_COPIED[message.kind].items())
        if message.kind == "VNINS":
            gps = v["week"] * SECONDS_PER_WEEK + v["tow"]
            device_time = gps
            values.update(ins_status=float(v["status"]), utc=gps_to_unix(gps, leap_seconds))
        if not all(math.isfinite(x) for x in values.values()):
            return None
        return Reading(device_time, values)

    return convert


def register_75(rate_hz: float, fields: list[str]) -> bytes:
    """$VNWRG,75,… writing binary output 1: both ports, divisor for rate_hz, groups, masks."""
    masks = masks_for(fields)
    groups = sum(1 << g for g in masks)
    divisor = max(1, round(BASE_RATE_HZ / rate_hz))
    body = ",".join(
        ["VNWRG", "75", "3", str(divisor), f"{groups:02X}"]
        + [f"{masks[g]:04X}" for g in sorted(masks)]
    ).encode()
    return b"$" + body + f"*{crc16_xmodem(body):04X}".encode() + b"\r\n"


def make_driver(sensors: Sensors, clock: Clock, publish: Callable[[Sample], None]) -> SensorDriver:
    cfg = sensors.vn200
    backoff = Backoff(sensors.backoff_initial_s, sensors.backoff_max_s)
    if cfg.protocol == "binary":
        codec, convert = BinaryCodec(), convert_binary(cfg.gps_leap_seconds)
    else:
        codec, convert = AsciiCodec(), convert_ascii(cfg.gps_leap_seconds)
    command = register_75(cfg.rate_hz, list(cfg.fields))

    def configure(transport: asyncio.Transport) -> None:
        if cfg.configure and cfg.protocol == "binary":
            transport.write(command)

    return SensorDriver("vn200", cfg, backoff, codec, convert, publish, clock, on_open=configure)
