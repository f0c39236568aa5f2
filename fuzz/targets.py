"""Fuzz targets: one function per parser, taking the fuzzer's bytes.

Each target raises only if the parser breaks its contract: the stream codecs and the link
codec never raise (they count what they drop), the config loader raises only ConfigError, and
digi-xbee's frame factory only InvalidPacketException (its reader thread dies, and closes the
port, on anything else). An assertion inside a target is a contract check (a stalled decoder, an
unbounded buffer), not a test of values.

Seeds for each target come from the encoders (`seeds(name)`), so the fuzzer starts from valid
frames and mutates them.
"""

from __future__ import annotations

import atexit
import hashlib
import tempfile
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import msgpack

from agent.config import Config, ConfigError, load_config
from agent.ground.config import GroundConfig
from agent.link import messages
from agent.link.codec import AIRCRAFT, GROUND, HEADER, TAG, VERSION, LinkCodec
from agent.link.session import LinkSession
from agent.link.store import CounterStore
from drivers.airdata.codec import MAX_LINE, AirData, AirDataCodec
from drivers.codec import StreamDecoder
from drivers.surfaces.codec import LENGTH, SurfaceCodec, SurfaceFrame
from drivers.vectornav.codec import (
    ASCII_FIELDS,
    MAX_ASCII,
    MAX_PACKET,
    AsciiCodec,
    BinaryCodec,
    VnAscii,
    VnPacket,
)
from drivers.xbee import codec as xbee

ROOT = Path(__file__).resolve().parents[1]
KEY = bytes(range(32))
AIR_ADDR, GROUND_ADDR = b"A" * 8, b"G" * 8

STREAMS: dict[str, tuple[Callable, int]] = {
    "vn200": (BinaryCodec, MAX_PACKET),
    "vn200-ascii": (AsciiCodec, MAX_ASCII),
    "airdata": (AirDataCodec, MAX_LINE),
    "surfaces": (SurfaceCodec, LENGTH),
    "xbee-ap1": (lambda: xbee.ApiCodec(escaped=False), 1 + 2 + xbee.MAX_DATA + 1),
    "xbee-ap2": (lambda: xbee.ApiCodec(escaped=True), 1 + 2 * (xbee.MAX_DATA + 3)),
}


def _stream(name: str) -> Callable[[bytes], None]:
    make, longest = STREAMS[name]

    def target(data: bytes) -> None:
        # The first byte chooses the chunk size: frames arrive split anywhere.
        step = 1 + (data[0] if data else 0)
        decoder = StreamDecoder(make())
        for k in range(1, len(data), step):
            decoder.feed(data[k : k + step])
            assert decoder.pending < longest, f"{name}: holding {decoder.pending} bytes"
        assert decoder.stats.bytes_skipped <= len(data)

    return target


def _link_unsigned(data: bytes) -> None:
    """Frames as a hostile transmitter sends them: no key. Nothing may get through."""
    ground = LinkCodec(KEY, GROUND, {AIR_ADDR}, counter=CounterStore(None), address=GROUND_ADDR)
    source = AIR_ADDR if data[:1] != b"\x00" else b"X" * 8
    for k in range(1, len(data), 64):
        assert ground.decode(source, data[k : k + 64], float(k)) is None


def _link_signed(data: bytes) -> None:
    """Frames signed with the key around fuzzed headers and bodies (a sender with the key and a
    bug, or a stolen key), received by the ground's session as its radio hands them on:
    reassembly, MessagePack, the session's own fields and the message validator."""
    ground = LinkCodec(KEY, GROUND, {AIR_ADDR}, counter=CounterStore(None), address=GROUND_ADDR)
    session = LinkSession(ground, None, AIR_ADDR, _StillClock(), lambda message, seq: None)
    now = 0.0
    for k in range(0, len(data), 80):
        piece = data[k : k + 80]
        if len(piece) < HEADER.size:
            break
        body = bytes([VERSION]) + piece[1:]
        frame = body + ground._tag(AIR_ADDR, GROUND_ADDR, body)
        now += piece[0] / 10
        session.receive(AIR_ADDR, frame, now)  # never raises, whatever the body
    assert ground.partial_bytes <= 8 * 255 * 256


class _StillClock:
    """The session's clock outside an event loop (receiving reads only the time it is given)."""

    def now(self) -> float:
        return 0.0


def _messages(data: bytes) -> None:
    """The validator behind the link: any MessagePack value."""
    try:
        value = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
        return
    try:
        message = messages.from_dict(value)
    except messages.LinkMessageError:
        return
    assert messages.from_dict(messages.to_dict(message)) == message


_CONFIG_DIR = Path(tempfile.mkdtemp(prefix="sysid-fuzz-config-"))


def _config(data: bytes) -> None:
    path = _CONFIG_DIR / "config.toml"
    path.write_bytes(data[1:])
    model = GroundConfig if data[:1] == b"g" else Config
    try:
        load_config(path, model)
    except ConfigError as exc:
        if not exc.problems:
            raise AssertionError("a ConfigError that names no problem") from exc


DIGI_RAISED: Counter[str] = Counter()


def _digi_xbee(data: bytes) -> None:
    """digi-xbee's frame factory, given what its reader hands it: a whole frame with a good
    checksum (corruption on the UART passes an 8-bit checksum one time in 256). Its reader
    thread survives only InvalidPacketException; anything else ends it and closes the port,
    which our radio watchdog repairs (drivers/xbee/driver.py). Those exceptions are the known
    finding: counted by type and frame type (printed at exit), not a crash, so the run goes on
    to look for hangs and memory growth."""
    from digi.xbee.exception import InvalidPacketException
    from digi.xbee.models.mode import OperatingMode
    from digi.xbee.packets.factory import build_frame

    DIGI_RAISED["(inputs)"] += 1
    if DIGI_RAISED["(inputs)"] % 100_000 == 0:  # libFuzzer's exit may skip atexit
        _report_digi()
    body = data[:300]
    if not body:
        return
    frame = bytearray(xbee.ApiCodec(escaped=False).encode(xbee.ApiFrame(bytes(body))))
    try:
        build_frame(frame, OperatingMode.API_MODE)
    except InvalidPacketException:
        pass
    except Exception as exc:  # the reader would die: the watchdog's case
        DIGI_RAISED[f"{type(exc).__name__} on frame type 0x{body[0]:02X}"] += 1


def _report_digi() -> None:
    if not DIGI_RAISED["(inputs)"]:
        return
    print(
        f"digi-xbee: of {DIGI_RAISED['(inputs)']} inputs, exceptions that end its reader "
        "thread (by type and frame type):",
        flush=True,
    )
    for what, count in DIGI_RAISED.most_common():
        if what != "(inputs)":
            print(f"  {count:8d}  {what}", flush=True)


atexit.register(_report_digi)


TARGETS: dict[str, Callable[[bytes], None]] = {
    **{name: _stream(name) for name in STREAMS},
    "link": _link_unsigned,
    "link-signed": _link_signed,
    "messages": _messages,
    "config": _config,
    "digi-xbee": _digi_xbee,
}


def seeds(name: str) -> list[bytes]:
    """Valid inputs for a target, from the encoders."""
    if name in STREAMS:
        frames = {
            "vn200": lambda: [
                BinaryCodec().encode(
                    VnPacket(
                        {
                            "common.time_startup": 10**9,
                            "common.quaternion": (0.0, 0.0, 0.0, 1.0),
                            "common.angular_rate": (0.1, -0.2, 0.3),
                            "common.ins_status": 2,
                            "attitude.ypr": (10.0, 2.0, -1.0),
                        }
                    )
                )
            ],
            "vn200-ascii": lambda: [
                AsciiCodec().encode(
                    VnAscii(
                        "VNYMR",
                        dict.fromkeys(ASCII_FIELDS["VNYMR"], 1.5),
                    ),
                    crc=crc,
                )
                for crc in (False, True)
            ],
            "airdata": lambda: [
                AirDataCodec().encode(AirData(k, 21.5, -3.25, 1.5, 150, 101_600, 99_800))
                for k in range(2)
            ],
            "surfaces": lambda: [
                SurfaceCodec().encode(SurfaceFrame(k, 1000 * k, (512,) * 7, 5000)) for k in range(2)
            ],
            "xbee-ap1": lambda: [
                xbee.ApiCodec(escaped=False).encode(
                    xbee.receive_packet(AIR_ADDR, b"\x7e\x7d\x11\x13 payload")
                )
            ],
            "xbee-ap2": lambda: [
                xbee.ApiCodec(escaped=True).encode(
                    xbee.receive_packet(AIR_ADDR, b"\x7e\x7d\x11\x13 payload")
                )
            ],
        }[name]()
        return [bytes([7]) + b"".join(frames), bytes([0]) + frames[0]]
    if name in ("link", "link-signed"):
        air = LinkCodec(
            KEY,
            AIRCRAFT,
            {GROUND_ADDR},
            counter=CounterStore(None),
            address=AIR_ADDR,
            max_payload=64,
        )
        frames = air.encode(messages.to_dict(messages.Notice(text="seed " * 10)))
        if name == "link":
            return [b"\x01" + b"".join(f.ljust(64, b"\x00") for f in frames)]
        return [b"".join(bytes([1]) + f[1:-TAG].ljust(79, b"\x00") for f in frames)]
    if name == "messages":
        return [
            msgpack.packb(messages.to_dict(m), use_bin_type=True)
            for m in (messages.Abort(reason="seed"), messages.Notice(text="seed"))
        ]
    if name == "config":
        return [
            b"a" + (ROOT / "config.toml").read_bytes(),
            b"g" + (ROOT / "ground.toml").read_bytes(),
        ]
    if name == "digi-xbee":
        return [
            xbee.receive_packet(AIR_ADDR, b"payload").data,
            xbee.transmit_status(1, 0).data,
            xbee.at_response(1, b"DB", 0, b"\x28").data,
        ]
    raise KeyError(name)


def seed_digest(name: str) -> str:
    return hashlib.sha256(b"".join(seeds(name))).hexdigest()[:12]
