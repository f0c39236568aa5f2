"""Authenticated framing: fragmentation, reassembly bounds, and the attacks.

Attacks tried, each counted and none reaching the application: a forged frame (a valid header
with a made-up tag), a tampered frame (one bit flipped in the body, and one in the header), a
replayed frame, a stale frame (an old counter outside the window), a frame from a source not
in the allow-list, a frame reflected back to its own sender, a message of another protocol
version, and a flood of fragments that never complete.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from agent.link import codec, messages
from agent.link.codec import (
    AIRCRAFT,
    GROUND,
    MAX_PARTIAL,
    PARTIAL_TIMEOUT_S,
    LinkCodec,
)
from agent.link.store import CounterStore, SeenStore

# A fixed key drawn at random (a patterned one, as bytes(range(32)) was, is refused).
KEY = bytes.fromhex("5f1e9c27d4a0b38e61c7f2094ad35be8c06f1a729e4d83b5f02c6e917ad4b358")
AIR, GROUND_ADDR, INTRUDER = b"A" * 8, b"G" * 8, b"X" * 8


def ends(tmp_path, max_payload: int = 256):
    ground = LinkCodec(
        KEY,
        GROUND,
        {AIR},
        counter=CounterStore(tmp_path / "g"),
        max_payload=max_payload,
        address=GROUND_ADDR,
    )
    air = LinkCodec(
        KEY,
        AIRCRAFT,
        {GROUND_ADDR},
        counter=CounterStore(tmp_path / "a"),
        max_payload=max_payload,
        address=AIR,
    )
    return ground, air


def big() -> dict:
    return messages.to_dict(messages.Notice(text="x" * 150)) | {"pad": list(range(300))}


def test_fragments_reassemble_in_any_order(tmp_path):
    ground, air = ends(tmp_path)
    frames = air.encode(big())
    assert len(frames) > 2
    assert all(len(f) <= 256 for f in frames)
    out = [ground.decode(AIR, f, 0.0) for f in reversed(frames)]
    assert out[:-1] == [None] * (len(frames) - 1)
    assert out[-1] == big()


def test_attacks_are_counted_and_never_delivered(tmp_path):
    ground, air = ends(tmp_path)
    message = messages.to_dict(messages.Abort(reason="go"))
    (frame,) = air.encode(message)
    forged = frame[:-12] + bytes(12)
    body_flip = bytearray(frame)
    body_flip[20] ^= 0x01
    header_flip = bytearray(frame)
    header_flip[5] ^= 0x01  # the counter
    assert ground.decode(AIR, forged, 0) is None
    assert ground.decode(AIR, bytes(body_flip), 0) is None
    assert ground.decode(AIR, bytes(header_flip), 0) is None
    assert ground.counters["bad_tag"] == 3
    assert ground.decode(INTRUDER, frame, 0) is None  # a radio not in the allow-list
    assert ground.counters["wrong_source"] == 1
    assert ground.decode(AIR, frame, 0) == message  # the genuine frame
    assert ground.decode(AIR, frame, 0) is None  # replayed
    assert ground.counters["replayed"] == 1
    # Stale: an old frame held back while 70 newer ones passed.
    old = air.encode(message)[0]
    for _ in range(70):
        assert ground.decode(AIR, air.encode(message)[0], 0) == message
    assert ground.decode(AIR, old, 0) is None
    assert ground.counters["stale"] == 1
    # Reflected: the ground's own frame sent back to it as if from the aircraft. Its tag
    # binds ground → aircraft, so it fails as a forgery before the direction byte is read.
    (own,) = ground.encode(message)
    assert ground.decode(AIR, own, 0) is None
    assert ground.counters["bad_tag"] == 4
    assert ground.counters["messages"] == 71


def test_reordered_frames_inside_the_window_are_accepted_once(tmp_path):
    ground, air = ends(tmp_path)
    frames = [air.encode({"kind": "ping", "v": 1, "n": k})[0] for k in range(10)]
    order = [3, 0, 1, 9, 2, 8, 4, 7, 5, 6]
    got = [ground.decode(AIR, frames[k], 0) for k in order]
    assert [g["n"] for g in got] == order
    assert ground.decode(AIR, frames[4], 0) is None
    assert ground.counters["replayed"] == 1


def test_another_protocol_version_is_refused_clearly():
    with pytest.raises(messages.LinkMessageError, match="version 2 is not supported"):
        messages.from_dict({"kind": "abort", "v": 2})
    with pytest.raises(messages.LinkMessageError, match="not a valid message"):
        messages.from_dict({"kind": "warp", "v": 1})


def test_a_flood_of_incomplete_fragments_stays_bounded(tmp_path):
    ground, air = ends(tmp_path)
    for _ in range(500):  # first fragments only: none ever completes
        frames = air.encode(big())
        assert ground.decode(AIR, frames[0], 0.0) is None
    per_message = len(air.encode(big())[0])
    assert ground.partial_bytes <= MAX_PARTIAL * per_message
    assert ground.counters["partial_evicted"] == 500 - MAX_PARTIAL
    # And a partial message times out.
    ground.decode(AIR, air.encode(big())[1], PARTIAL_TIMEOUT_S + 1.0)
    assert ground.counters["partial_timeouts"] == MAX_PARTIAL


def test_counters_are_never_reused_across_restarts(tmp_path):
    path = tmp_path / "counter"
    first = CounterStore(path)
    used = [first.next() for _ in range(5)]
    second = CounterStore(path)  # a restart: the block already reserved is skipped
    assert second.next() > max(used)


def test_short_keys_are_refused(tmp_path):
    with pytest.raises(ValueError, match="at least 16 bytes"):
        LinkCodec(b"short", GROUND, set(), counter=CounterStore(tmp_path / "c"))


def test_a_restarted_receiver_still_refuses_old_frames(tmp_path):
    seen = SeenStore(tmp_path / "seen", "fingerprint")
    air = LinkCodec(KEY, AIRCRAFT, {GROUND_ADDR}, counter=CounterStore(tmp_path / "a"), address=AIR)
    ground = LinkCodec(
        KEY, GROUND, {AIR}, counter=CounterStore(tmp_path / "g"), address=GROUND_ADDR
    )
    frames = [air.encode({"kind": "ping", "v": 1, "n": k})[0] for k in range(3)]
    for frame in frames:
        assert ground.decode(AIR, frame, 0) is not None
    assert seen.save(ground.floors())
    assert not seen.save(ground.floors())  # nothing new
    reloaded = SeenStore(tmp_path / "seen", "fingerprint").load()
    restarted = LinkCodec(
        KEY,
        GROUND,
        {AIR},
        counter=CounterStore(tmp_path / "g"),
        floors=reloaded,
        address=GROUND_ADDR,
    )
    assert all(restarted.decode(AIR, f, 0) is None for f in frames)  # replayed after restart
    assert restarted.counters["replayed"] + restarted.counters["stale"] == 3
    assert restarted.decode(AIR, air.encode({"kind": "ping", "v": 1})[0], 0) is not None


def test_a_counter_jump_far_past_the_window_is_accepted_without_blowing_up(tmp_path):
    """A sender whose counter file was lost falls back to the wall clock in µs (≈ 2**50): the
    receiver, which had seen small counters, must take the jump (hypothesis found the window
    shift asking for petabytes at a jump to 2**64 − 1)."""
    ground = LinkCodec(
        KEY, GROUND, {AIR}, counter=CounterStore(tmp_path / "g"), address=GROUND_ADDR
    )
    air = LinkCodec(KEY, AIRCRAFT, {GROUND_ADDR}, counter=CounterStore(tmp_path / "a"), address=AIR)
    assert ground.decode(AIR, air.encode({"kind": "ping", "v": 1})[0], 0) is not None
    clocked = LinkCodec(KEY, AIRCRAFT, {GROUND_ADDR}, counter=CounterStore(None), address=AIR)
    frames = [clocked.encode({"kind": "ping", "v": 1, "n": k})[0] for k in range(3)]
    assert [ground.decode(AIR, f, 0) is not None for f in frames] == [True] * 3
    assert ground.decode(AIR, frames[0], 0) is None  # and the window works after the jump
    assert ground.counters["replayed"] == 1


def test_the_codec_does_no_file_io():
    """The codec stays sans-I/O, as the drivers' codecs are: its counters come from a
    FrameCounter and its replay state goes in and out as floors; the files are
    agent/link/store.py's."""
    tree = ast.parse(Path(codec.__file__).read_text())
    imported = {
        a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names
    }
    imported |= {
        n.module.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module
    }
    assert not imported & {"os", "io", "pathlib", "json", "shutil", "tempfile", "time"}
    called = {
        n.func.id
        for n in ast.walk(tree)
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
    }
    assert "open" not in called
