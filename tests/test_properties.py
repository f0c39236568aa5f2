"""Property-based tests (hypothesis) of every byte-level parser and of the config loader.

The example-based tests (tests/drivers/test_codecs.py, tests/link/test_link_codec.py,
tests/test_config.py) pin chosen vectors; these search the input space. The same properties
run for far longer under coverage-guided fuzzing in `fuzz/` (`make fuzz`).

Bad input tried here: arbitrary bytes in arbitrary chunks for each stream codec (VN-200 binary
and ASCII, µADC, surface box, XBee API frames in AP=1 and AP=2); valid frames with arbitrary
garbage between them; arbitrary radio frames from allowed and unknown sources; frames signed
with the right key around arbitrary bodies (a sender with the key but a bug, or a stolen key);
arbitrary decoded values given to the link's message validator; arbitrary text and mutated
valid configs given to the config loader.
"""

from __future__ import annotations

import hashlib
import hmac
import itertools
import math
import random
from pathlib import Path

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from pydantic import BaseModel

from agent.config import Config, ConfigError, load_config
from agent.ground.config import GroundConfig
from agent.link import messages
from agent.link.codec import (
    AIRCRAFT,
    GROUND,
    HEADER,
    OVERHEAD,
    TAG,
    VERSION,
    WINDOW,
    LinkCodec,
)
from agent.link.session import LinkSession
from agent.link.store import CounterStore
from agent.logs import format_row
from drivers.airdata.codec import MAX_LINE, AirData, AirDataCodec
from drivers.codec import StreamDecoder
from drivers.surfaces.codec import LENGTH, SurfaceCodec, SurfaceFrame
from drivers.vectornav.codec import MAX_ASCII, MAX_PACKET, AsciiCodec, BinaryCodec
from drivers.xbee import codec as xbee

GROUND_TOML = Path(__file__).resolve().parents[1] / "ground.toml"
# Each stream codec, the longest frame it waits for (after that it must consume), and the
# bytes that can start a frame (garbage without them can never hide a frame).
STREAMS = {
    "vn200": (BinaryCodec, MAX_PACKET, b"\xfa"),
    "vn200-ascii": (AsciiCodec, MAX_ASCII, b"$"),
    "airdata": (AirDataCodec, MAX_LINE, b"0123456789\n"),
    "surfaces": (SurfaceCodec, LENGTH, b"\xaa"),
    "xbee-ap1": (lambda: xbee.ApiCodec(escaped=False), 1 + 2 + xbee.MAX_DATA + 1, b"\x7e"),
    "xbee-ap2": (lambda: xbee.ApiCodec(escaped=True), 1 + 2 * (xbee.MAX_DATA + 3), b"\x7e"),
}
PROPERTY = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _outcome(function, *args, error: type[Exception]):
    """(result, None), or (None, the exception) if it is the parser's own typed error; any
    other exception propagates and fails the property."""
    try:
        return function(*args), None
    except error as exc:
        return None, exc


def _chunked(data: bytes, cuts: list[int]) -> list[bytes]:
    points = sorted({c % (len(data) + 1) for c in cuts} | {0, len(data)})
    return [data[a:b] for a, b in itertools.pairwise(points)]


# -- stream codecs --------------------------------------------------------------------------


@pytest.mark.parametrize("name", STREAMS)
@PROPERTY
@given(data=st.binary(max_size=2048), cuts=st.lists(st.integers(0, 4096), max_size=20))
def test_any_bytes_in_any_chunks_never_raise_and_every_discard_is_counted(name, data, cuts):
    make, longest, _ = STREAMS[name]
    codec = make()
    buffer = bytearray()
    for chunk in _chunked(data, cuts):
        buffer += chunk
        while buffer:
            skipped_before = codec.stats.bytes_skipped
            consumed, message = codec.decode(buffer)
            assert 0 <= consumed <= len(buffer)
            if consumed == 0:
                assert message is None
                # Waiting for more bytes is only allowed below the longest frame.
                assert len(buffer) < longest, f"stalled holding {len(buffer)} bytes"
                break
            if message is None:  # a discard: exactly the bytes dropped are counted
                assert codec.stats.bytes_skipped - skipped_before == consumed
            del buffer[:consumed]
    stats = codec.stats
    assert stats.bytes_skipped <= len(data)
    assert stats.crc_errors + stats.rejected <= stats.resyncs + len(data)


@st.composite
def _frames(draw, name):
    """A few valid frames of one codec (values drawn from each field's full range)."""
    count = draw(st.integers(1, 5))
    if name == "surfaces":
        return [
            SurfaceFrame(
                draw(st.integers(0, 0xFFFF)),
                draw(st.integers(0, 0xFFFFFFFF)),
                tuple(draw(st.lists(st.integers(0, 1023), min_size=7, max_size=7))),
                draw(st.integers(0, 0xFFFF)),
            )
            for _ in range(count)
        ]
    if name == "airdata":
        return [
            AirData(
                draw(st.integers(0, 99_999)),
                draw(st.integers(0, 9999)) / 100,
                draw(st.integers(-9999, 9999)) / 100,
                draw(st.integers(-9999, 9999)) / 100,
                float(draw(st.integers(-999, 9999))),
                float(draw(st.integers(0, 999_999))),
                float(draw(st.integers(0, 999_999))),
            )
            for _ in range(count)
        ]
    payloads = st.binary(min_size=0, max_size=240)
    address = st.binary(min_size=8, max_size=8)
    return [xbee.receive_packet(draw(address), draw(payloads)) for _ in range(count)]


@pytest.mark.parametrize("name", ["surfaces", "airdata", "xbee-ap1", "xbee-ap2"])
@PROPERTY
@given(data=st.data())
def test_garbage_between_valid_frames_never_costs_a_frame(name, data):
    make, _, starts = STREAMS[name]
    frames = data.draw(_frames(name))
    garbage = st.binary(max_size=64).map(lambda b: bytes(x for x in b if x not in starts))
    if name == "airdata":  # a µADC line ends at a newline: garbage before a line is its own line
        garbage = garbage.map(lambda g: g + b"\n" if g else g)
    encoder = make()
    stream = b"".join(data.draw(garbage) + encoder.encode(f) for f in frames)
    cuts = data.draw(st.lists(st.integers(0, len(stream)), max_size=10))
    decoder = StreamDecoder(make())
    out = []
    for chunk in _chunked(stream, cuts):
        out += decoder.feed(chunk)
    assert out == frames
    assert decoder.pending == 0


# -- the radio link -------------------------------------------------------------------------

# A fixed key drawn at random (a patterned one, as bytes(range(32)) was, is refused).
KEY = bytes.fromhex("5f1e9c27d4a0b38e61c7f2094ad35be8c06f1a729e4d83b5f02c6e917ad4b358")
AIR_ADDR, GROUND_ADDR = b"A" * 8, b"G" * 8
PLAIN = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.text(max_size=20)
    | st.floats(allow_nan=False)
    | st.binary(max_size=20),
    lambda inner: (
        st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5)
    ),
    max_leaves=30,
)


def _tag(source: bytes, destination: bytes, data: bytes) -> bytes:
    """The frame's tag as docs/link.md specifies it, computed here independently of the codec:
    HMAC-SHA-256 under the key over both radios' addresses and the frame, first TAG bytes."""
    return hmac.new(KEY, source + destination + data, hashlib.sha256).digest()[:TAG]


def _ground() -> LinkCodec:
    # Counters from the clock: a counter file is fsynced at creation, 300 times per property.
    return LinkCodec(KEY, GROUND, {AIR_ADDR}, counter=CounterStore(None), address=GROUND_ADDR)


@PROPERTY
@given(
    source=st.sampled_from([AIR_ADDR, b"X" * 8, b""]),
    frames=st.lists(st.binary(max_size=300), max_size=20),
)
def test_arbitrary_radio_frames_are_dropped_and_counted(source, frames):
    ground = _ground()
    for frame in frames:
        assert ground.decode(source, frame, 0.0) is None  # without the key nothing gets in
    dropped = sum(v for k, v in ground.counters.items() if k not in ("frames", "messages"))
    assert dropped == len(frames)


@PROPERTY
@given(data=st.data())
def test_frames_signed_around_arbitrary_bodies_never_raise(data):
    """A sender holding the key but sending garbage (a bug, or a stolen key): every frame is
    delivered as a plain value, held as a fragment, or dropped and counted."""
    ground = _ground()
    for counter in range(data.draw(st.integers(1, 12))):
        header = HEADER.pack(
            VERSION,
            data.draw(st.sampled_from([AIRCRAFT, GROUND, 7])),
            data.draw(st.sampled_from([counter, 0, 2**64 - 1])),
            data.draw(st.integers(0, 3)),
            data.draw(st.integers(0, 4)),
            data.draw(st.integers(0, 4)),
        )
        body = header + data.draw(st.binary(max_size=200))
        frame = body + _tag(AIR_ADDR, GROUND_ADDR, body)
        out = ground.decode(AIR_ADDR, frame, float(counter))
        assert out is None or isinstance(out, (dict, list, str, int, float, bytes, bool))
        if out is not None:  # the application's validator then refuses it clearly or takes it
            _outcome(messages.from_dict, out, error=messages.LinkMessageError)
    assert ground.partial_bytes <= 8 * 255 * 256


SESSION_FIELD = st.sampled_from(["s", "e", "b", "r", "t", "upto", "kind"])


class _StillClock:
    def now(self) -> float:
        return 0.0


@PROPERTY
@given(
    bodies=st.lists(
        PLAIN | st.dictionaries(SESSION_FIELD, PLAIN | st.sampled_from(["lack", "abort", "ping"])),
        max_size=8,
    )
)
def test_a_session_given_any_signed_value_never_raises(bodies):
    """A sender holding the key but sending values the session never sends (`[1, 2]`,
    `{"s": "x"}`, `{"s": null}`, a "lack" with a bad bound …): `LinkSession.receive`
    counts them and never raises; whatever it hands on is a validated message."""
    air = LinkCodec(KEY, AIRCRAFT, {GROUND_ADDR}, counter=CounterStore(None), address=AIR_ADDR)
    handed: list = []
    session = LinkSession(air, None, GROUND_ADDR, _StillClock(), lambda m, s: handed.append(m))
    for counter, body in enumerate(bodies):
        header = HEADER.pack(VERSION, GROUND, counter, counter, 0, 1)
        data = header + msgpack.packb(body, use_bin_type=True)
        session.receive(GROUND_ADDR, data + _tag(GROUND_ADDR, AIR_ADDR, data), 0.0)
    assert all(isinstance(m, BaseModel) for m in handed)  # validated, never a raw value


@PROPERTY
@given(
    message=st.dictionaries(st.text(max_size=10), PLAIN, max_size=8),
    payload=st.integers(OVERHEAD + 1, 256),
    seed=st.integers(0, 2**32),
)
def test_any_message_survives_fragmentation_and_reordering(message, payload, seed):
    """Any message, any radio payload size, frames reordered by up to the replay window (64
    frames: a frame older than that is refused as stale, so deeper reordering loses it)."""
    air = LinkCodec(
        KEY,
        AIRCRAFT,
        {GROUND_ADDR},
        counter=CounterStore(None),
        address=AIR_ADDR,
        max_payload=payload,
    )
    ground = _ground()
    body = msgpack.packb(message, use_bin_type=True)
    assume(len(body) <= 255 * (payload - OVERHEAD))
    frames = air.encode(message)
    assert all(len(f) <= payload for f in frames)
    rng = random.Random(seed)
    shuffled = []
    for start in range(0, len(frames), WINDOW):
        block = frames[start : start + WINDOW]
        rng.shuffle(block)
        shuffled += block
    out = [ground.decode(AIR_ADDR, f, 0.0) for f in shuffled]
    assert out[:-1] == [None] * (len(frames) - 1)
    assert out[-1] == message
    for frame in frames:  # and every frame played again is refused
        assert ground.decode(AIR_ADDR, frame, 0.0) is None
    assert ground.counters["replayed"] + ground.counters["stale"] == len(frames)


@PROPERTY
@given(value=PLAIN)
def test_the_message_validator_takes_or_refuses_clearly(value):
    for candidate in (
        value,
        {"kind": "arm", "plan": value},
        {"kind": "decision", "id": value},
        {"kind": "status", "v": value},
    ):
        message, error = _outcome(messages.from_dict, candidate, error=messages.LinkMessageError)
        if error is not None:
            assert str(error)
        else:
            assert messages.from_dict(messages.to_dict(message)) == message


# -- the config loader ----------------------------------------------------------------------


def _toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(value)


def _flatten(tree: dict, prefix: str = "") -> dict[str, object]:
    out = {}
    for key, value in tree.items():
        name = f"{prefix}.{key}" if prefix else key
        if isinstance(value, dict) and value:
            out |= _flatten(value, name)
        elif isinstance(value, bool | int | float | str) or (
            isinstance(value, list) and all(isinstance(v, int | float | str) for v in value)
        ):
            out[name] = value
    return out


def _toml(flat: dict[str, object]) -> str:
    """Dotted keys at the top level are valid TOML and need no table headers."""
    return "\n".join(
        ".".join(f'"{p}"' for p in key.split(".")) + " = " + _toml_value(v)
        for key, v in flat.items()
    )


MODELS = {
    "aircraft": (Config, _flatten(Config().model_dump(mode="json"))),
    "ground": (
        GroundConfig,
        _flatten(load_config(GROUND_TOML, GroundConfig).model_dump(mode="json")),
    ),
}
SCALARS = (
    st.booleans()
    | st.integers(-(10**6), 10**6)
    | st.floats(allow_nan=True)
    | st.text(max_size=12)
    | st.lists(st.integers(-5, 5), max_size=3)
)


@pytest.mark.parametrize("which", MODELS)
@PROPERTY
@given(data=st.data())
def test_a_mutated_config_loads_or_is_refused_with_a_config_error(tmp_path_factory, which, data):
    model, defaults = MODELS[which]
    flat = dict(defaults)
    for _ in range(data.draw(st.integers(1, 4))):
        key = data.draw(st.sampled_from(sorted(flat)))
        action = data.draw(st.sampled_from(["retype", "drop", "unknown"]))
        if action == "retype":
            flat[key] = data.draw(SCALARS)
        elif action == "drop":
            del flat[key]
            if not flat:
                break
        else:
            flat[key.rsplit(".", 1)[0] + ".not_a_key"] = data.draw(SCALARS)
    path = tmp_path_factory.mktemp("config") / "config.toml"
    path.write_text(_toml(flat))
    config, error = _outcome(load_config, path, model, error=ConfigError)
    if error is not None:
        assert error.problems  # each names the key and the reason (by example in test_config)
    else:
        assert isinstance(config, model)


@PROPERTY
@given(text=st.text(max_size=400) | st.binary(max_size=400).map(lambda b: b.decode("latin-1")))
def test_any_text_loads_or_is_refused_with_a_config_error(tmp_path_factory, text):
    path = tmp_path_factory.mktemp("config") / "config.toml"
    path.write_bytes(text.encode("utf-8", "surrogateescape"))
    config, error = _outcome(load_config, path, error=ConfigError)
    assert isinstance(config, Config) if error is None else error.problems


# -- the log line format --------------------------------------------------------------------


@PROPERTY
@given(row=st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=2, max_size=90))
def test_a_log_row_reads_back_to_nine_significant_digits_with_nan_empty(row):
    time = abs(row[0]) % 1e6 if math.isfinite(row[0]) else 0.0  # the time: finite, seconds
    values = np.array([time, *row[1:]])
    line = format_row(values)
    assert line.endswith(b"\n")
    assert line.count(b"\n") == 1
    cells = line.decode().rstrip("\n").split(",")
    assert len(cells) == len(values)
    assert float(cells[0]) == pytest.approx(values[0], abs=5.01e-7)  # µs, a tie rounds to even
    for cell, value in zip(cells[1:], values[1:], strict=True):
        if math.isnan(value):
            assert cell == ""
        else:
            assert float(cell) == pytest.approx(value, rel=5e-9, abs=0)
