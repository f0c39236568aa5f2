"""XBee API frames (docs/protocols.md, *XBee*), sans-I/O, for the emulated radios and for
tests; the radio transport itself talks through digi-xbee.

Frame: 0x7E, length (2 bytes big-endian, frame data only), frame data, checksum =
0xFF − (sum of frame data & 0xFF). AP=2 (escaped): every byte after the 0x7E that is 0x7E,
0x7D, 0x11 or 0x13 is sent as 0x7D, byte ^ 0x20 (length and checksum included; the checksum is
over unescaped data). AP=1: 0x7E may appear inside a frame, so frames are cut by length.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

from drivers.codec import CodecStats, hunt, resync

START = 0x7E
ESCAPE = 0x7D
ESCAPED = {0x7E, 0x7D, 0x11, 0x13}
# Longest frame data accepted: a 900HP's 256-byte payload plus a 0x10 header (14), with
# margin. In AP=1 a stray 0x7E followed by a bogus length delays decoding until that many
# bytes have arrived (then the checksum fails and decoding resumes at the next 0x7E): the cap
# bounds that delay; no frame is lost to it.
MAX_DATA = 300

TRANSMIT_REQUEST, TRANSMIT_STATUS, RECEIVE_PACKET = 0x10, 0x8B, 0x90
AT_COMMAND, AT_COMMAND_QUEUED, AT_RESPONSE = 0x08, 0x09, 0x88
DELIVERY = {
    0x00: "ok",
    0x21: "network ACK failure",
    0x25: "route not found",
    0x74: "payload too large",
}


@dataclass(frozen=True)
class ApiFrame:
    """Frame data: the API identifier byte, then the rest."""

    data: bytes

    @property
    def kind(self) -> int:
        return self.data[0]


def checksum(data: bytes) -> int:
    return 0xFF - (sum(data) & 0xFF)


def escape(raw: bytes) -> bytes:
    out = bytearray()
    for b in raw:
        if b in ESCAPED:
            out += bytes([ESCAPE, b ^ 0x20])
        else:
            out.append(b)
    return bytes(out)


class ApiCodec:
    """API frames in AP=1 (escaped=False) or AP=2 (escaped=True)."""

    def __init__(self, escaped: bool):
        self.escaped = escaped
        self.stats = CodecStats()

    def encode(self, frame: ApiFrame) -> bytes:
        body = struct.pack(">H", len(frame.data)) + frame.data + bytes([checksum(frame.data)])
        return bytes([START]) + (escape(body) if self.escaped else body)

    def decode(self, buffer: bytes | bytearray) -> tuple[int, ApiFrame | None]:
        if skipped := hunt(self.stats, buffer, START):
            return skipped, None
        raw, used, interrupted = self._unescape(buffer)
        if len(raw) < 2:
            return (resync(self.stats, buffer, START), None) if interrupted else (0, None)
        (length,) = struct.unpack_from(">H", raw)
        if length == 0 or length > MAX_DATA:
            return resync(self.stats, buffer, START, rejected=True), None
        if len(raw) < 2 + length + 1:
            # A start byte inside an escaped frame means the frame was cut short.
            return (resync(self.stats, buffer, START), None) if interrupted else (0, None)
        data = bytes(raw[2 : 2 + length])
        if checksum(data) != raw[2 + length]:
            return resync(self.stats, buffer, START, crc=True), None
        self.stats.frames += 1
        return used[2 + length], ApiFrame(data)

    def _unescape(self, buffer: bytes | bytearray):
        """(unescaped bytes after the start byte, the buffer offset after each, whether an
        escaped stream hit a start byte — which cannot occur inside a frame)."""
        raw, ends = bytearray(), []
        i = 1
        limit = min(len(buffer), 1 + 2 * (MAX_DATA + 3))
        while i < limit and len(raw) < MAX_DATA + 3:
            b = buffer[i]
            if self.escaped:
                if b == START:
                    return raw, ends, True
                if b == ESCAPE:
                    if i + 1 >= len(buffer):
                        break
                    b = buffer[i + 1] ^ 0x20
                    i += 1
            raw.append(b)
            i += 1
            ends.append(i)
        return raw, ends, False


def transmit_request(
    frame_id: int, destination: bytes, payload: bytes, options: int = 0
) -> ApiFrame:
    return ApiFrame(
        bytes([TRANSMIT_REQUEST, frame_id])
        + destination
        + b"\xff\xfe\x00"
        + bytes([options])
        + payload
    )


def parse_transmit_request(frame: ApiFrame) -> tuple[int, bytes, bytes]:
    """(frame id, 64-bit destination, payload)."""
    d = frame.data
    return d[1], d[2:10], d[14:]


def transmit_status(frame_id: int, status: int, retries: int = 0) -> ApiFrame:
    return ApiFrame(bytes([TRANSMIT_STATUS, frame_id, 0xFF, 0xFE, retries, status, 0]))


def receive_packet(source: bytes, payload: bytes) -> ApiFrame:
    return ApiFrame(bytes([RECEIVE_PACKET]) + source + b"\xff\xfe\x01" + payload)


def at_response(frame_id: int, command: bytes, status: int, value: bytes = b"") -> ApiFrame:
    return ApiFrame(bytes([AT_RESPONSE, frame_id]) + command + bytes([status]) + value)
