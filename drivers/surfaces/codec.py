"""The surface box (Arduino UNO: seven surface potentiometers and engine RPM) — our protocol.

One little-endian frame per sample, 27 bytes:

    offset  size  field
    0       2     sync 0xAA 0x55
    2       1     version (1)
    3       2     sequence number, uint16, +1 per frame, wraps
    5       4     Arduino millis() at the ADC read, uint32, wraps after 49.7 days
    9       14    7 × uint16 raw ADC counts (10-bit, 0–1023), in the order of CHANNELS
    23      2     engine RPM, uint16
    25      2     CRC-16/XMODEM of bytes 2–24, big-endian (so bytes 2–26 check to 0)

The fixed length is the length cap; a version other than 1 or a count above 1023 is rejected.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from drivers.codec import CodecStats, crc16_xmodem, resync, skip

SYNC = b"\xaa\x55"
VERSION = 1
CHANNELS = (
    "aileron_left",
    "aileron_right",
    "elevator_left",
    "elevator_right",
    "rudder",
    "flap_left",
    "flap_right",
)
_BODY = struct.Struct("<BHI7HH")
LENGTH = len(SYNC) + _BODY.size + 2
ADC_MAX = 1023


@dataclass(frozen=True)
class SurfaceFrame:
    """One surface-box sample: raw counts in CHANNELS order."""

    seq: int
    millis: int
    counts: tuple[int, ...]
    rpm: int


class SurfaceCodec:
    """Surface-box frames."""

    def __init__(self) -> None:
        self.stats = CodecStats()

    def decode(self, buffer: bytes | bytearray) -> tuple[int, SurfaceFrame | None]:
        start = buffer.find(SYNC)
        if start != 0:
            if start < 0:  # keep a trailing 0xAA: it may be the first half of a sync
                keep = 1 if buffer[-1:] == SYNC[:1] else 0
                return (
                    (skip(self.stats, len(buffer) - keep), None)
                    if len(buffer) > keep
                    else (0, None)
                )
            return skip(self.stats, start), None
        if len(buffer) < LENGTH:
            return 0, None
        if crc16_xmodem(memoryview(buffer)[2:LENGTH]) != 0:
            return resync(self.stats, buffer, SYNC, crc=True), None
        version, seq, millis, *rest = _BODY.unpack_from(buffer, 2)
        counts, rpm = tuple(rest[:7]), rest[7]
        if version != VERSION or max(counts) > ADC_MAX:
            return resync(self.stats, buffer, SYNC, rejected=True), None
        self.stats.frames += 1
        return LENGTH, SurfaceFrame(seq, millis, counts, rpm)

    def encode(self, frame: SurfaceFrame) -> bytes:
        body = _BODY.pack(
            VERSION, frame.seq & 0xFFFF, frame.millis & 0xFFFFFFFF, *frame.counts, frame.rpm
        )
        return SYNC + body + struct.pack(">H", crc16_xmodem(body))
