"""VectorNav VN-200 codecs: binary output packets and ASCII $VNYMR / $VNINS (docs/protocols.md).

Binary packet: 0xFA sync, a group byte, one little-endian uint16 field mask per group bit
set, the payload (fields in group order, then bit order, little-endian, no padding), and a
CRC-16/XMODEM sent big-endian over every byte after the sync — so the CRC over the whole
packet after the sync, CRC included, is 0. Field sizes are VectorNav's binary group length
table; fields whose meaning or size differs between firmware versions are not decoded, and a
packet carrying one is rejected explicitly, as is a packet with an extension bit (bit 7 of
the group byte, bit 15 of a mask).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field

from drivers.codec import CodecStats, crc16_xmodem, hunt, resync, xor8

SYNC = 0xFA
# (name, struct format) per group, by field bit. Sizes follow from the formats.
_TIME_UTC = "<bBBBBBH"  # year − 2000, month, day, hour, minute, second, millisecond
_GNSS = [
    ("utc", _TIME_UTC),
    ("tow", "<Q"),
    ("week", "<H"),
    ("num_sats", "<B"),
    ("fix", "<B"),
    ("pos_lla", "<3d"),
    ("pos_ecef", "<3d"),
    ("vel_ned", "<3f"),
    ("vel_ecef", "<3f"),
    ("pos_u", "<3f"),
    ("vel_u", "<f"),
    ("time_u", "<f"),
]
GROUPS: list[tuple[str, list[tuple[str, str]]]] = [
    (
        "common",
        [
            ("time_startup", "<Q"),
            ("time_gps", "<Q"),
            ("time_syncin", "<Q"),
            ("ypr", "<3f"),
            ("quaternion", "<4f"),
            ("angular_rate", "<3f"),
            ("position", "<3d"),
            ("vel_ned", "<3f"),
            ("accel", "<3f"),
            ("imu", "<6f"),
            ("mag_pres", "<5f"),
            ("delta_theta_vel", "<7f"),
            ("ins_status", "<H"),
            ("sync_in_cnt", "<I"),
            ("time_gps_pps", "<Q"),
        ],
    ),
    (
        "time",
        [
            ("time_startup", "<Q"),
            ("time_gps", "<Q"),
            ("gps_tow", "<Q"),
            ("gps_week", "<H"),
            ("time_syncin", "<Q"),
            ("time_gps_pps", "<Q"),
            ("time_utc", _TIME_UTC),
            ("sync_in_cnt", "<I"),
            ("sync_out_cnt", "<I"),
            ("time_status", "<B"),
        ],
    ),
    (
        "imu",
        [
            ("imu_status", "<H"),
            ("uncomp_mag", "<3f"),
            ("uncomp_accel", "<3f"),
            ("uncomp_gyro", "<3f"),
            ("temp", "<f"),
            ("pres", "<f"),
            ("delta_theta", "<4f"),
            ("delta_vel", "<3f"),
            ("mag", "<3f"),
            ("accel", "<3f"),
            ("angular_rate", "<3f"),
            ("sens_sat", "<H"),
        ],
    ),
    ("gnss1", _GNSS),
    (
        "attitude",
        [
            ("vpe_status", "<H"),
            ("ypr", "<3f"),
            ("quaternion", "<4f"),
            ("dcm", "<9f"),
            ("mag_ned", "<3f"),
            ("accel_ned", "<3f"),
            ("linear_accel_body", "<3f"),
            ("linear_accel_ned", "<3f"),
            ("ypr_u", "<3f"),
        ],
    ),
    (
        "ins",
        [
            ("ins_status", "<H"),
            ("pos_lla", "<3d"),
            ("pos_ecef", "<3d"),
            ("vel_body", "<3f"),
            ("vel_ned", "<3f"),
            ("vel_ecef", "<3f"),
            ("mag_ecef", "<3f"),
            ("accel_ecef", "<3f"),
            ("linear_accel_ecef", "<3f"),
            ("pos_u", "<f"),
            ("vel_u", "<f"),
        ],
    ),
    ("gnss2", _GNSS),
]
_STRUCTS = [[struct.Struct(fmt) for _, fmt in fields] for _, fields in GROUPS]
# Longest packet the decoder will wait for: every supported field of every group.
MAX_PACKET = 1 + 1 + 2 * len(GROUPS) + sum(s.size for g in _STRUCTS for s in g) + 2
_BY_NAME = {
    f"{group}.{name}": (g, bit)
    for g, (group, fields) in enumerate(GROUPS)
    for bit, (name, _) in enumerate(fields)
}


@dataclass(frozen=True)
class VnPacket:
    """A decoded binary packet: values by "group.field" (tuples for vectors)."""

    fields: dict[str, int | float | tuple] = field(default_factory=dict)


def field_names() -> list[str]:
    """Every "group.field" the codec decodes and encodes."""
    return list(_BY_NAME)


def masks_for(names: list[str]) -> dict[int, int]:
    """Group index → field mask for these "group.field" names (ValueError naming a bad one)."""
    masks: dict[int, int] = {}
    for name in names:
        if name not in _BY_NAME:
            raise ValueError(f"unknown VN-200 binary field {name!r}")
        g, bit = _BY_NAME[name]
        masks[g] = masks.get(g, 0) | (1 << bit)
    return masks


class BinaryCodec:
    """VN-200 binary output packets (decode any supported layout; encode for fake devices)."""

    def __init__(self) -> None:
        self.stats = CodecStats()

    def decode(self, buffer: bytes | bytearray) -> tuple[int, VnPacket | None]:
        if skipped := hunt(self.stats, buffer, SYNC):
            return skipped, None
        if len(buffer) < 2:
            return 0, None
        groups = buffer[1]
        if groups & 0x80 or groups == 0:  # extension bit, or no group at all
            return resync(self.stats, buffer, SYNC, rejected=True), None
        present = [g for g in range(len(GROUPS)) if groups >> g & 1]
        header = 2 + 2 * len(present)
        if len(buffer) < header:
            return 0, None
        layout, payload = [], 0
        for k, g in enumerate(present):
            (mask,) = struct.unpack_from("<H", buffer, 2 + 2 * k)
            if mask & 0x8000 or mask >> len(GROUPS[g][1]) or mask == 0:
                return resync(self.stats, buffer, SYNC, rejected=True), None
            bits = [b for b in range(len(GROUPS[g][1])) if mask >> b & 1]
            layout.append((g, bits))
            payload += sum(_STRUCTS[g][b].size for b in bits)
        length = header + payload + 2
        if len(buffer) < length:
            return 0, None
        if crc16_xmodem(memoryview(buffer)[1:length]) != 0:
            return resync(self.stats, buffer, SYNC, crc=True), None
        values: dict[str, int | float | tuple] = {}
        offset = header
        for g, bits in layout:
            for b in bits:
                unpacker = _STRUCTS[g][b]
                raw = unpacker.unpack_from(buffer, offset)
                offset += unpacker.size
                values[f"{GROUPS[g][0]}.{GROUPS[g][1][b][0]}"] = raw[0] if len(raw) == 1 else raw
        self.stats.frames += 1
        return length, VnPacket(values)

    def encode(self, packet: VnPacket) -> bytes:
        masks = masks_for(list(packet.fields))
        groups = sum(1 << g for g in masks)
        body = bytearray([groups])
        for g in sorted(masks):
            body += struct.pack("<H", masks[g])
        for g in sorted(masks):
            for b in range(len(GROUPS[g][1])):
                if masks[g] >> b & 1:
                    value = packet.fields[f"{GROUPS[g][0]}.{GROUPS[g][1][b][0]}"]
                    value = value if isinstance(value, tuple) else (value,)
                    body += _STRUCTS[g][b].pack(*value)
        return bytes([SYNC]) + bytes(body) + struct.pack(">H", crc16_xmodem(body))


# --- ASCII ---------------------------------------------------------------------------------

MAX_ASCII = 256  # the longest VN ASCII line is ~200 bytes; anything longer is garbage
ASCII_FIELDS = {
    "VNYMR": (
        "yaw",
        "pitch",
        "roll",
        "mag_x",
        "mag_y",
        "mag_z",
        "accel_x",
        "accel_y",
        "accel_z",
        "gyro_x",
        "gyro_y",
        "gyro_z",
    ),
    "VNINS": (
        "tow",
        "week",
        "status",
        "yaw",
        "pitch",
        "roll",
        "lat",
        "lon",
        "alt",
        "vel_n",
        "vel_e",
        "vel_d",
        "att_u",
        "pos_u",
        "vel_u",
    ),
}


@dataclass(frozen=True)
class VnAscii:
    """A decoded ASCII sentence: its type ("VNYMR", "VNINS") and its values by name."""

    kind: str
    values: dict[str, float | int]


class AsciiCodec:
    """$VNYMR and $VNINS sentences with *HH (XOR) or *HHHH (CRC-16) checksums."""

    def __init__(self) -> None:
        self.stats = CodecStats()

    def decode(self, buffer: bytes | bytearray) -> tuple[int, VnAscii | None]:
        if skipped := hunt(self.stats, buffer, b"$"):
            return skipped, None
        end = buffer.find(b"\n", 0, MAX_ASCII)
        if end < 0:
            if len(buffer) >= MAX_ASCII:
                return resync(self.stats, buffer, b"$"), None
            return 0, None
        line = bytes(buffer[: end + 1])
        message = self._parse(line.rstrip(b"\r\n"))
        if message is None:
            return resync(self.stats, buffer, b"$"), None
        self.stats.frames += 1
        return end + 1, message

    def _parse(self, line: bytes) -> VnAscii | None:
        body, star, check = line[1:].partition(b"*")
        if not star:  # no checksum at all: not a sentence we accept
            self.stats.rejected += 1
            return None
        if not _checksum_ok(body, check):
            self.stats.crc_errors += 1
            return None
        kind, *items = body.decode("ascii", "replace").split(",")
        names = ASCII_FIELDS.get(kind)
        if names is None or len(items) != len(names):
            self.stats.rejected += 1
            return None
        try:
            values = {
                n: int(v, 16) if n == "status" else int(v) if n == "week" else float(v)
                for n, v in zip(names, items, strict=True)
            }
        except ValueError:
            self.stats.rejected += 1
            return None
        return VnAscii(kind, values)

    def encode(self, message: VnAscii, crc: bool = False) -> bytes:
        items = []
        for name in ASCII_FIELDS[message.kind]:
            v = message.values[name]
            items.append(f"{int(v):04X}" if name == "status" else str(v))
        body = ",".join([message.kind, *items]).encode()
        check = f"{crc16_xmodem(body):04X}" if crc else f"{xor8(body):02X}"
        return b"$" + body + b"*" + check.encode() + b"\r\n"


def _checksum_ok(body: bytes, check: bytes) -> bool:
    try:
        value = int(check, 16)
    except ValueError:
        return False
    if len(check) == 2:
        return xor8(body) == value
    if len(check) == 4:
        return crc16_xmodem(body) == value
    return False
