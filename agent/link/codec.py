"""Bytes on the air: MessagePack encoding, fragmentation into radio-sized frames, HMAC-SHA-256
authentication, and replay protection.

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
import json
import logging
import os
import struct
import time
from collections import Counter, OrderedDict
from dataclasses import dataclass
from pathlib import Path

import msgpack

log = logging.getLogger(__name__)

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
# Counters reserved per write of the counter file: a reboot skips at most this many.
COUNTER_BLOCK = 1 << 16
# The header's counter is a uint64; files holding more (or a jump near it) are refused.
COUNTER_MAX = 1 << 63


class CounterStore:
    """The sender's frame counter, never reused across restarts.

    With a file, counters are reserved in blocks: the file holds the end of the reserved block,
    written (and fsynced) before any counter of the block is used. A disk that cannot be
    written costs this end its sending (each attempt to reserve raises OSError, which the
    session counts; at start it is logged), never its receiving, so an Abort still arrives
    and acts. Without a file, the counter starts at the wall clock in
    microseconds (monotonic across restarts while the clock is)."""

    def __init__(self, path: Path | None = None):
        self._path = path
        if path is None:
            self._next, self._reserved = time.time_ns() // 1000, 1 << 63
        else:
            start = _read_counter(path) if path.exists() else 0
            self._next, self._reserved = start, start
            try:  # the file says from the start that this end has used the key
                self._reserve()
            except OSError as exc:
                log.error("%s: frame counters not reserved (%s); sending waits for it", path, exc)

    def _reserve(self) -> None:
        end = self._next + COUNTER_BLOCK
        tmp = self._path.with_suffix(".tmp")
        with open(tmp, "w") as handle:
            handle.write(str(end))
            handle.flush()
            os.fsync(handle.fileno())
        tmp.replace(self._path)
        self._reserved = end  # only once it is on disk

    def next(self) -> int:
        """The next counter; OSError when its block cannot be reserved on disk."""
        if self._next >= self._reserved:
            self._reserve()
        value = self._next
        self._next += 1
        return value


def _read_counter(path: Path) -> int:
    """The counter file's number; ValueError naming the file when it is not one in range."""
    try:
        text = path.read_text().strip()
        value = int(text) if text.isdigit() and len(text) <= 20 else -1
    except (OSError, ValueError) as exc:  # UnicodeDecodeError is a ValueError
        raise ValueError(f"{path}: the frame counter is unreadable ({exc})") from exc
    if not 0 <= value < COUNTER_MAX:
        raise ValueError(
            f"{path}: the frame counter {text[:40]!r} is not a whole number below 2**63: "
            "restore the file or give both ends a new key (sysid keygen)"
        )
    return value


def key_fingerprint(key: bytes) -> str:
    """A short public name of a key (it reveals nothing of it): the replay state is bound to
    it, and `sysid keygen` prints it so both ends can be compared."""
    return hashlib.sha256(b"suas-sysid link key fingerprint\0" + key).hexdigest()[:16]


def read_floors(path: Path, fingerprint: str) -> dict[bytes, int]:
    """The highest counter accepted from each source, from the seen file; ValueError naming
    the file and what to do when it is not a replay state. A state of another key (its
    fingerprint differs) says nothing of this key's frames: empty."""
    try:
        document = json.loads(path.read_text())
        if isinstance(document, dict) and "floors" in document:
            if document.get("key") != fingerprint:
                log.warning("%s: replay state of another key; starting empty", path)
                return {}
            document = document["floors"]
        if not isinstance(document, dict):
            raise ValueError(f"a map of sources, not {type(document).__name__}")
        floors = {_address(k): _floor(v) for k, v in document.items()}
    except (OSError, ValueError, RecursionError) as exc:  # json and Unicode errors included
        raise ValueError(
            f"{path}: the replay state is unreadable ({exc}); without it every frame "
            "recorded under this key would be accepted again: restore the file or "
            "give both ends a new key (sysid keygen)"
        ) from exc
    return floors


def _address(text: object) -> bytes:
    if not isinstance(text, str) or len(text) != 16:
        raise ValueError(f"{str(text)[:40]!r} is not a 64-bit radio address in hex")
    return bytes.fromhex(text)


def _floor(value: object) -> int:
    # JSON's Infinity and 1e400 are floats, and a bool is an int to Python: neither is a counter.
    if type(value) is not int or not -1 <= value < COUNTER_MAX:
        raise ValueError(f"{str(value)[:40]!r} is not a frame counter (a whole number ≥ -1)")
    return value


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
    """One end of the link: frames our messages, checks and reassembles the other end's."""

    def __init__(
        self,
        key: bytes,
        role: int,
        allow: set[bytes],
        *,
        counter: CounterStore,
        max_payload: int = 256,
        seen: Path | None = None,
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
        self._seen_path = seen
        self.fingerprint = key_fingerprint(key)
        floors = read_floors(seen, self.fingerprint) if seen is not None and seen.exists() else {}
        self._windows: dict[bytes, ReplayWindow] = {a: ReplayWindow(f) for a, f in floors.items()}
        self._saved: dict[bytes, int] = dict(floors)
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

    def save_seen(self) -> bool:
        """Write the highest counter accepted from each source, so a restarted receiver refuses
        frames it accepted before (True: written; False: nothing new). OSError when the disk
        refuses: the state is then still unsaved, and the next call tries again."""
        snapshot = self.seen_snapshot()
        if snapshot is None:
            return False
        self.write_seen(snapshot)
        self.mark_saved(snapshot)
        return True

    def seen_snapshot(self) -> dict[bytes, int] | None:
        """What save_seen would write, taken on the caller's thread; None: nothing new."""
        current = {a: w.highest for a, w in self._windows.items()}
        if self._seen_path is None or current == self._saved:
            return None
        return current

    def write_seen(self, snapshot: dict[bytes, int]) -> None:
        """Write a snapshot, fsynced, through a temporary file (file-system work: the session
        runs it off the event loop). Raises OSError as the disk does."""
        tmp = self._seen_path.with_suffix(".tmp")
        floors = {a.hex(): h for a, h in snapshot.items()}
        with open(tmp, "w") as handle:
            handle.write(json.dumps({"key": self.fingerprint, "floors": floors}))
            handle.flush()
            os.fsync(handle.fileno())
        tmp.replace(self._seen_path)

    def mark_saved(self, snapshot: dict[bytes, int]) -> None:
        """A snapshot is on disk (call only once write_seen has returned)."""
        self._saved = snapshot

    @property
    def unsaved(self) -> bool:
        """Frames accepted that the seen file does not cover yet."""
        return self.seen_snapshot() is not None

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
