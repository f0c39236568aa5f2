"""Bytes on the air: MessagePack encoding, fragmentation into radio-sized frames, HMAC-SHA-256
authentication, and replay protection. Sans-I/O: the frame counters come from a `FrameCounter`
and the replay state is handed in and read out as `floors`; keeping them on disk is
agent.link.store's job.

Frame (each at most the radio's payload, NP):

    offset  size  field
    0       1     version (2)
    1       1     sender role: 0 ground, 1 aircraft (a frame is only accepted from the other role)
    2       8     counter, uint64 big-endian, +1 per frame sent, never reused under a key
    10      2     message number, uint16 (groups the fragments of one message)
    12      1     fragment index
    13      1     fragment count
    14      …     chunk of the MessagePack-encoded message
    end−12  12    tag: HMAC-SHA-256(key, source address ‖ destination address ‖ every byte
                  before it), first 12 bytes

The tag covers the two radios' 64-bit addresses, which travel in the XBee frame, not in ours:
with one key on two aircraft (a fleet, a cloned card), a frame for one fails the other's tag,
whatever source it claims. Still: one key per aircraft–ground pair.

Receiving, in order, each failure dropped and counted before anything is decoded: source
address not in the allow-list (`wrong_source`), too short or another version (`malformed`),
tag mismatch (`bad_tag`: forged or tampered), same role as ours (`wrong_direction`), counter
seen before (`replayed`) or older than the 64-frame window (`stale`). Fragments are reassembled
per (source, message number) with a timeout and a bound on partial messages and bytes.
"""

from __future__ import annotations

import hashlib
import hmac
import struct
from collections import Counter, OrderedDict
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import msgpack

VERSION = 2
GROUND, AIRCRAFT = 0, 1
HEADER = struct.Struct(">BBQHBB")
TAG = 12
OVERHEAD = HEADER.size + TAG
WINDOW = 64
# Reassembly bounds: partial messages per source, and how long one may stay incomplete.
MAX_PARTIAL = 8
# Frames of one message at most: the header's fragment index and count are one byte each.
MAX_FRAMES = 255
PARTIAL_TIMEOUT_S = 10.0


class FrameCounter(Protocol):
    """Where a sender's frame counters come from (agent.link.store.CounterStore)."""

    def next(self) -> int:
        """The next counter, never used before under the key; OSError when it cannot be had."""


def key_fingerprint(key: bytes) -> str:
    """A short public name of a key (it reveals nothing of it): the replay state is bound to
    it, and `sysid keygen` prints it so both ends can be compared."""
    return hashlib.sha256(b"suas-sysid link key fingerprint\0" + key).hexdigest()[:16]


class ReplayWindow:
    """Highest counter seen and a 64-frame bitmap below it (IPsec-style)."""

    def __init__(self, floor: int = -1) -> None:
        self.highest = floor
        self._bits = (1 << WINDOW) - 1 if floor >= 0 else 0  # nothing at or below the floor

    def check(self, counter: int) -> str | None:
        """None if fresh (and record it), else "replayed" or "stale"."""
        if counter > self.highest:
            shift = counter - self.highest
            # A jump past the window clears it (shifting by the jump itself could ask for
            # petabytes: a counter of 2**64 − 1 after 5 raised MemoryError, found by hypothesis).
            kept = self._bits << shift if shift < WINDOW else 0
            self._bits = (kept | 1) & ((1 << WINDOW) - 1)
            self.highest = counter
            return None
        age = self.highest - counter
        if age >= WINDOW:
            return "stale"
        if self._bits >> age & 1:
            return "replayed"
        self._bits |= 1 << age
        return None


class MessageTooLarge(ValueError):
    """A message that needs more frames than one message may have."""


def pack(message: dict) -> bytes:
    """A message's MessagePack body, as it goes on air."""
    return msgpack.packb(message, use_bin_type=True, use_single_float=False)


@dataclass
class _Partial:
    count: int
    chunks: dict[int, bytes]
    first_seen: float


class LinkCodec:
    """One end of the link: frames our messages, checks and reassembles the other end's.
    `floors`: the highest counter accepted from each source before (the replay state as
    loaded from disk), at or below which nothing from that source is accepted again."""

    def __init__(
        self,
        key: bytes,
        role: int,
        allow: set[bytes],
        *,
        counter: FrameCounter,
        max_payload: int = 256,
        floors: Mapping[bytes, int] | None = None,
        address: bytes = b"",
    ):
        if len(key) < 16:
            raise ValueError("the link key must be at least 16 bytes (32 random bytes advised)")
        self._key, self.role, self.allow = key, role, set(allow)
        # Our radio's 64-bit address, in every tag (the endpoint sets it when the radio opens).
        self.address = address
        self._counter = counter
        self.max_payload = max_payload
        self._message_number = 0
        self.fingerprint = key_fingerprint(key)
        self._windows: dict[bytes, ReplayWindow] = {
            a: ReplayWindow(f) for a, f in (floors or {}).items()
        }
        self._partials: dict[bytes, OrderedDict[int, _Partial]] = {}
        self.last_counter = -1
        self.counters: Counter[str] = Counter()

    # -- sending ----------------------------------------------------------------------------

    def encode(self, message: dict, destination: bytes | None = None) -> list[bytes]:
        """The frames carrying one message (a dict of plain values) to `destination` (default:
        the one allowed peer). MessageTooLarge when it needs more frames than a message may
        have; OSError when the frame counters cannot be reserved on disk."""
        if destination is None:
            if len(self.allow) != 1:
                raise ValueError("give the destination: more than one peer is allowed")
            (destination,) = self.allow
        body = pack(message)
        chunk = self.max_payload - OVERHEAD
        count = self.frames_needed(len(body))
        self._message_number = (self._message_number + 1) & 0xFFFF
        frames = []
        for index in range(count):
            header = HEADER.pack(
                VERSION, self.role, self._counter.next(), self._message_number, index, count
            )
            data = header + body[index * chunk : (index + 1) * chunk]
            frames.append(data + self._tag(self.address, destination, data))
        return frames

    def frames_needed(self, size: int) -> int:
        """Frames for a body of `size` bytes at the radio's payload; MessageTooLarge past
        MAX_FRAMES (the header's fragment count is one byte)."""
        count = max(1, -(-size // (self.max_payload - OVERHEAD)))
        if count > MAX_FRAMES:
            raise MessageTooLarge(
                f"a message of {size} bytes needs {count} frames of {self.max_payload} bytes; "
                f"at most {MAX_FRAMES} ({MAX_FRAMES * (self.max_payload - OVERHEAD)} bytes)"
            )
        return count

    def _tag(self, source: bytes, destination: bytes, data: bytes) -> bytes:
        mac = hmac.new(self._key, source.rjust(8, b"\0"), hashlib.sha256)
        mac.update(destination.rjust(8, b"\0"))
        mac.update(data)
        return mac.digest()[:TAG]

    # -- receiving --------------------------------------------------------------------------

    def decode(self, source: bytes, frame: bytes, now: float) -> dict | None:
        """The message a frame completes, or None (a fragment, or a frame dropped and counted)."""
        if source not in self.allow:
            return self._drop("wrong_source")
        if len(frame) < OVERHEAD or frame[0] != VERSION:
            return self._drop("malformed")
        data, tag = frame[:-TAG], frame[-TAG:]
        if not hmac.compare_digest(tag, self._tag(source, self.address, data)):
            return self._drop("bad_tag")
        _, role, counter, number, index, count = HEADER.unpack_from(data)
        if role == self.role:
            return self._drop("wrong_direction")
        verdict = self._windows.setdefault(source, ReplayWindow()).check(counter)
        if verdict is not None:
            return self._drop(verdict)
        if count == 0 or index >= count:
            return self._drop("malformed")
        self.counters["frames"] += 1
        body = self._reassemble(source, number, index, count, data[HEADER.size :], now)
        if body is None:
            return None
        try:
            message = msgpack.unpackb(body, raw=False, strict_map_key=True)
        except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError):
            return self._drop("undecodable")
        self.counters["messages"] += 1
        self.last_counter = counter  # the frame counter that completed it (the session's epochs)
        return message

    def floors(self) -> dict[bytes, int]:
        """The highest counter accepted from each source: what the replay state on disk must
        cover (agent.link.store.SeenStore) for a restarted receiver to refuse them again."""
        return {a: w.highest for a, w in self._windows.items()}

    def _drop(self, reason: str) -> None:
        self.counters[reason] += 1
        return None

    def _reassemble(
        self, source: bytes, number: int, index: int, count: int, chunk: bytes, now: float
    ) -> bytes | None:
        if count == 1:
            return chunk
        partials = self._partials.setdefault(source, OrderedDict())
        for key in [k for k, p in partials.items() if now - p.first_seen > PARTIAL_TIMEOUT_S]:
            del partials[key]
            self.counters["partial_timeouts"] += 1
        partial = partials.get(number)
        if partial is None or partial.count != count:
            while len(partials) >= MAX_PARTIAL:
                partials.popitem(last=False)
                self.counters["partial_evicted"] += 1
            partial = partials[number] = _Partial(count, {}, now)
        partial.chunks[index] = chunk
        if len(partial.chunks) < count:
            return None
        del partials[number]
        return b"".join(partial.chunks[i] for i in range(count))

    @property
    def partial_bytes(self) -> int:
        """Bytes held in incomplete messages (bounded by MAX_PARTIAL × 255 × NP per source)."""
        return sum(
            len(c) for ps in self._partials.values() for p in ps.values() for c in p.chunks.values()
        )
