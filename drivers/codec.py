"""What every sans-I/O codec shares: counters, checksums, resynchronising, a stream wrapper.

A codec's `decode(buffer) -> (consumed, message | None)` never touches a port: 0 consumed means
"need more bytes"; consumed > 0 with no message means bytes were discarded (garbage before a
sync, a frame with a bad checksum, a rejected frame), and the codec's `stats` say why. Every
codec caps the length it will wait for, so a bogus length can delay but never stall decoding.
"""

from __future__ import annotations

import binascii
from dataclasses import asdict, dataclass
from typing import Any, Protocol


@dataclass
class CodecStats:
    """Counters a codec keeps while decoding (all only ever grow)."""

    frames: int = 0
    """Messages decoded."""
    crc_errors: int = 0
    """Frames whose checksum did not match."""
    resyncs: int = 0
    """Times the decoder dropped bytes to hunt for the next frame start."""
    bytes_skipped: int = 0
    """Bytes discarded (garbage, bad frames, rejected frames)."""
    rejected: int = 0
    """Well-formed frames refused: extension bits, unsupported fields, out-of-range values."""

    def as_dict(self) -> dict[str, int]:
        return asdict(self)


class Codec(Protocol):
    stats: CodecStats

    def decode(self, buffer: bytes | bytearray) -> tuple[int, Any | None]: ...

    def encode(self, message: Any) -> bytes: ...


def crc16_xmodem(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/XMODEM: polynomial 0x1021, initial 0, no reflection (binascii.crc_hqx)."""
    return binascii.crc_hqx(data, 0)


def xor8(data: bytes | bytearray | memoryview) -> int:
    """XOR of every byte (NMEA-style checksum)."""
    value = 0
    for byte in bytes(data):
        value ^= byte
    return value


def skip(stats: CodecStats, count: int, *, crc: bool = False, rejected: bool = False) -> int:
    """Account for `count` discarded bytes as one resync; returns count for `decode` to return."""
    stats.bytes_skipped += count
    stats.resyncs += 1
    stats.crc_errors += crc
    stats.rejected += rejected
    return count


def hunt(stats: CodecStats, buffer: bytes | bytearray, sync: int | bytes) -> int:
    """Bytes before the first one-byte `sync` (all of them when there is none), discarded as one
    resync; 0 when the buffer starts with it."""
    start = buffer.find(sync)
    return 0 if start == 0 else skip(stats, len(buffer) if start < 0 else start)


def resync(
    stats: CodecStats,
    buffer: bytes | bytearray,
    sync: int | bytes,
    *,
    crc: bool = False,
    rejected: bool = False,
) -> int:
    """A bad frame at the start of `buffer` discarded up to the next `sync` after its first
    byte (all of it when there is none); `crc` or `rejected` says why, for the stats."""
    following = buffer.find(sync, 1)
    return skip(stats, len(buffer) if following < 0 else following, crc=crc, rejected=rejected)


class StreamDecoder:
    """Feeds arbitrary chunks of a byte stream to a codec and returns whole messages.

    The pending buffer never grows beyond `limit` bytes: a codec always consumes once it has
    its maximum frame length, so the limit only guards against a codec bug.
    """

    def __init__(self, codec: Codec, limit: int = 1 << 16):
        self.codec = codec
        self._buffer = bytearray()
        self._limit = limit

    @property
    def stats(self) -> CodecStats:
        return self.codec.stats

    def feed(self, data: bytes) -> list[Any]:
        self._buffer += data
        messages = []
        while self._buffer:
            consumed, message = self.codec.decode(self._buffer)
            if consumed == 0:
                break
            del self._buffer[:consumed]
            if message is not None:
                messages.append(message)
        if len(self._buffer) > self._limit:  # defensive: drop the oldest bytes, counted
            excess = len(self._buffer) - self._limit
            skip(self.codec.stats, excess)
            del self._buffer[:excess]
        return messages

    @property
    def pending(self) -> int:
        """Bytes held waiting for the rest of a frame."""
        return len(self._buffer)
