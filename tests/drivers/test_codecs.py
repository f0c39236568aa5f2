"""Byte-vector tests of every sans-I/O codec (docs/contributing.md, *Byte-vector tests*).

Each codec's vectors are fed whole, split in halves, one byte at a time, concatenated, and
corrupted. Bad input tried: a flipped bit in the payload and in the checksum, a frame cut in
half, random garbage between frames, a bogus header claiming the longest possible frame,
an extension bit (VN-200), a version byte and an ADC count out of range (surface box), an
overlong line (ASCII). Every good frame after a bad one must come out, `bytes_skipped` must
equal exactly the bad bytes injected, and nothing may raise.
"""

from __future__ import annotations

import random
import struct
import zlib
from dataclasses import dataclass
from typing import Any

import pytest

from drivers.airdata.codec import AirData, AirDataCodec
from drivers.codec import StreamDecoder, crc16_xmodem
from drivers.surfaces.codec import SurfaceCodec, SurfaceFrame
from drivers.vectornav.codec import ASCII_FIELDS, AsciiCodec, BinaryCodec, VnAscii, VnPacket
from drivers.xbee import codec as xbee


def _vn_packets() -> list[VnPacket]:
    out = []
    for k in range(6):
        fields: dict[str, Any] = {
            "common.time_startup": 1_000_000_000 + 10_000_000 * k,
            "common.time_gps": 1_400_000_000_000_000_000 + k,
            "common.quaternion": (0.01 * k, -0.02, 0.03, 0.99),
            "common.angular_rate": (0.1, -0.2 * k, 0.3),
            "common.position": (30.6 + k * 1e-6, -96.3, 120.0 + k),
            "common.vel_ned": (20.0, 1.0, -0.5),
            "common.accel": (0.1, 0.2, -9.8),
            "common.ins_status": 0x0002,
        }
        if k % 2:  # other layouts in the same stream: Attitude and INS groups
            fields["attitude.ypr"] = (10.0 * k, 2.0, -1.0)
            fields["ins.vel_body"] = (20.0, 0.5, 1.0)
        out.append(VnPacket(fields))
    return out


ASCII = [
    VnAscii(
        "VNYMR",
        dict(
            zip(
                ASCII_FIELDS["VNYMR"],
                [12.5 + k, 1.25, -3.5, 0.25, 0.5, 0.75, 0.125, -0.25, -9.75, 0.0625, -0.03125, 0.5],
                strict=True,
            )
        ),
    )
    for k in range(3)
] + [
    VnAscii(
        "VNINS",
        {
            "tow": 345600.5,
            "week": 2390,
            "status": 0x0A12,
            "yaw": 45.5,
            "pitch": 2.25,
            "roll": -1.5,
            "lat": 30.625,
            "lon": -96.375,
            "alt": 120.5,
            "vel_n": 20.5,
            "vel_e": 1.5,
            "vel_d": -0.5,
            "att_u": 0.25,
            "pos_u": 1.5,
            "vel_u": 0.125,
        },
    )
]


@dataclass
class Case:
    name: str
    codec: type
    messages: list
    payload_index: int  # a byte inside the payload that a bit flip turns into a checksum error


CASES = [
    Case("vn200", BinaryCodec, _vn_packets(), 20),
    Case("vn200-ascii", AsciiCodec, ASCII, 9),
    Case(
        "airdata",
        AirDataCodec,
        [
            AirData(99_990 + k, 21.5 + k / 4, -3.25, 1.5, 150 + k, 101_600, 99_800)
            for k in range(14)
        ],
        8,
    ),
    Case(
        "surfaces",
        SurfaceCodec,
        [
            SurfaceFrame(
                65_530 + k, 4_294_967_000 + 10 * k, tuple(500 + j + k for j in range(7)), 5_000 + k
            )
            for k in range(10)
        ],
        12,
    ),
]
SPECIAL = bytes([0x7E, 0x7D, 0x11, 0x13]) * 3  # every byte AP=2 must escape
XBEE_FRAMES = [
    xbee.transmit_request(k + 1, bytes.fromhex("0013A20040000002"), SPECIAL + bytes([k]))
    for k in range(5)
] + [
    xbee.receive_packet(bytes.fromhex("0013A20040000001"), b"plain payload " * 4),
    xbee.transmit_status(7, 0x21, 3),
    xbee.at_response(1, b"NP", 0, b"\x01\x00"),
]
CASES += [
    Case("xbee-ap1", lambda: xbee.ApiCodec(escaped=False), XBEE_FRAMES, 20),
    Case("xbee-ap2", lambda: xbee.ApiCodec(escaped=True), XBEE_FRAMES, 30),
]
IDS = [c.name for c in CASES]


def _encoded(case: Case) -> list[bytes]:
    return [case.codec().encode(m) for m in case.messages]


def _stream(case: Case, chunks: list[bytes]) -> tuple[list[bytes], StreamDecoder]:
    decoder = StreamDecoder(case.codec())
    out = []
    for chunk in chunks:
        out += decoder.feed(chunk)
    encoder = case.codec()
    return [encoder.encode(m) for m in out], decoder


@pytest.mark.parametrize("case", CASES, ids=IDS)
def test_each_vector_whole(case):
    for frame in _encoded(case):
        codec = case.codec()
        consumed, message = codec.decode(frame)
        assert consumed == len(frame)
        assert codec.encode(message) == frame
        assert codec.stats.frames == 1
        assert codec.stats.bytes_skipped == 0
        # Any strict prefix asks for more bytes and consumes nothing.
        for cut in (1, len(frame) // 2, len(frame) - 1):
            assert codec.decode(frame[:cut]) == (0, None)


@pytest.mark.parametrize("case", CASES, ids=IDS)
@pytest.mark.parametrize("split", ["halves", "bytes", "concatenated"])
def test_split_and_concatenated(case, split):
    frames = _encoded(case)
    if split == "halves":
        chunks = [part for f in frames for part in (f[: len(f) // 2], f[len(f) // 2 :])]
    elif split == "bytes":
        chunks = [bytes([b]) for f in frames for b in f]
    else:
        chunks = [b"".join(frames)]
    out, decoder = _stream(case, chunks)
    assert out == frames
    assert decoder.stats.frames == len(frames)
    assert decoder.stats.bytes_skipped == 0
    assert decoder.pending == 0


def _corrupt(case: Case, kind: str, rng: random.Random) -> tuple[list[bytes], int, list[bytes]]:
    """Stream chunks with frame 2 spoiled; (chunks, bad bytes injected, frames expected)."""
    frames = _encoded(case)
    bad = bytearray(frames[2])
    expected = frames[:2] + frames[3:]
    if kind == "flip-payload":
        bad[case.payload_index] ^= 0x01
    elif kind == "flip-checksum":
        bad[-3 if case.name in ("vn200-ascii", "airdata") else -1] ^= 0x01
    elif kind == "truncated":
        bad = bad[: len(bad) // 2]
    elif kind == "garbage":
        junk = bytes(rng.randrange(256) for _ in range(97))
        return [*frames[:2], junk, *frames[2:]], len(junk), frames
    chunks = [*frames[:2], bytes(bad), *frames[3:]]
    return chunks, len(bad), expected


@pytest.mark.parametrize("case", CASES, ids=IDS)
@pytest.mark.parametrize("kind", ["flip-payload", "flip-checksum", "truncated", "garbage"])
@pytest.mark.parametrize("feeding", ["whole", "bytes"])
def test_corruption_loses_only_the_bad_frame(case, kind, feeding):
    rng = random.Random(zlib.crc32(f"{case.name}/{kind}".encode()))
    chunks, injected, expected = _corrupt(case, kind, rng)
    if feeding == "bytes":
        chunks = [bytes([b]) for c in chunks for b in c]
    out, decoder = _stream(case, chunks)
    assert out == expected
    assert decoder.stats.frames == len(expected)
    assert decoder.stats.bytes_skipped == injected
    assert decoder.stats.resyncs >= 1
    if kind.startswith("flip"):
        assert decoder.stats.crc_errors == 1


def test_vn200_bogus_length_header_delays_but_loses_nothing():
    # A sync, all seven groups, every supported field: the decoder waits for the longest
    # packet there is, the CRC fails, and it resumes at the next sync byte.
    frames = _encoded(CASES[0]) * 12
    masks = [0x7FFF, 0x03FF, 0x0FFF, 0x0FFF, 0x01FF, 0x07FF, 0x0FFF]
    bogus = bytes([0xFA, 0x7F]) + b"".join(struct.pack("<H", m) for m in masks)
    out, decoder = _stream(CASES[0], [frames[0], bogus, *frames[1:]])
    assert out == frames
    assert decoder.stats.bytes_skipped == len(bogus)
    assert decoder.stats.crc_errors == 1


def _vn_frame(groups: int, masks: list[int], payload: bytes) -> bytes:
    body = bytes([groups]) + b"".join(struct.pack("<H", m) for m in masks) + payload
    return b"\xfa" + body + struct.pack(">H", crc16_xmodem(body))


def test_vn200_extension_bits_and_unknown_fields_are_rejected_explicitly():
    good = _encoded(CASES[0])[0]
    cases = [
        _vn_frame(0x81, [0x0001], bytes(8)),  # extension bit in the group byte
        _vn_frame(0x01, [0x8001], bytes(8)),  # extension bit in a field mask
        _vn_frame(0x04, [0x1001], bytes(42)),  # an IMU field whose size varies by firmware
    ]
    for bad in cases:
        out, decoder = _stream(CASES[0], [bad, good])
        assert out == [good]
        assert decoder.stats.rejected == 1
        assert decoder.stats.bytes_skipped == len(bad)


def test_surface_box_rejects_bad_version_and_out_of_range_counts():
    good = _encoded(CASES[3])[0]
    body = struct.pack("<BHI7HH", 2, 1, 1, *(500,) * 7, 0)  # version 2
    counts = struct.pack("<BHI7HH", 1, 1, 1, *(500,) * 6, 4000, 0)  # 12-bit count on 10 bits
    for payload in (body, counts):
        bad = b"\xaa\x55" + payload + struct.pack(">H", crc16_xmodem(payload))
        out, decoder = _stream(CASES[3], [bad, good])
        assert out == [good]
        assert decoder.stats.rejected == 1


@pytest.mark.parametrize("case", [CASES[1], CASES[2]], ids=["vn200-ascii", "airdata"])
def test_overlong_lines_are_dropped(case):
    frames = _encoded(case)
    junk = b"$" + b"7" * 400 if case.name == "vn200-ascii" else b"12345, " * 60
    out, decoder = _stream(case, [frames[0], junk, *frames[1:]])
    assert out == frames
    assert decoder.stats.bytes_skipped == len(junk)


def test_ascii_checksums_xor_and_crc_forms_and_hex_status():
    codec = AsciiCodec()
    message = ASCII[-1]
    for crc in (False, True):
        line = codec.encode(message, crc=crc)
        assert len(line.split(b"*")[1].strip()) == (4 if crc else 2)
        consumed, decoded = codec.decode(line)
        assert consumed == len(line)
        assert decoded == message
    assert message.values["status"] == 0x0A12  # "0A12" parsed as hex, not decimal
