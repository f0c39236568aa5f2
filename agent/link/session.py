"""Reliable and best-effort delivery over the authenticated link.

Reliable (commands, results, acknowledgements): each message gets a sequence number within a
session epoch (a random number drawn at start, so a restarted end is recognised rather than
taken for a replay of old numbers); each reliable frame also carries the lowest number still
unacknowledged, where a receiver that meets a new epoch — the sender restarted, or the
receiver itself did and knows none — starts counting (so a restarted aircraft still takes
the ground's next command; the message in flight when it died may come twice, the only
duplicate across a restart); the receiver delivers in order exactly once, buffers up to 64
ahead, and answers every reliable frame with a cumulative link ack; the sender keeps up
to 4 messages in flight, retransmits each after 0.5 s, doubling to at most 4 s, and keeps the
rest queued (up to 64; the oldest is dropped and counted beyond that) — so results queued
during an outage go out when the link returns. Best effort (status, heartbeat): sent once;
status is latest-wins. Liveness: the link is up while an authenticated frame arrived within
`deadline_s`; a heartbeat goes out when nothing else did for `heartbeat_s`.

An end that obeys commands (the aircraft) gives a `Guard`. Then a message that only makes the
aircraft safer (an Abort) is handed on the moment it arrives, whatever the disk does:
replaying it is harmless. Any other reliable message is held until the replay state that
covers it is on disk (fsynced), and refused through the guard, with the reason, when that
write fails or when the message is older than `max_age_s` (a command jammed on the way and
injected later). The age is read on the receiver's own clock, so the two clocks need not
agree: every message carries its sender's clock ("t", ms), and a reliable message carries
"r", what the receiver's clock read when it was first queued — the last "t" heard from the
receiver plus the time since, measured on the sender's clock. A message queued before the
receiver's clock began (it restarted) reads as from before it, and is refused too.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
from collections import Counter, deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from agent.clock import Clock
from agent.link import messages
from agent.link.codec import LinkCodec, MessageTooLarge, pack
from agent.link.store import SeenStore

log = logging.getLogger(__name__)

IN_FLIGHT = 4
OUTBOX = 64
AHEAD = 64
RETRY_FIRST_S, RETRY_MAX_S = 0.5, 4.0
TICK_S = 0.05
# How often the highest counters accepted are written (the replay bound after a crash).
SAVE_SEEN_S = 1.0
# The air share (`air_share`) is measured over this long.
AIR_WINDOW_S = 10.0
# The session's own fields in a message (stripped before it is validated).
SESSION_KEYS = frozenset({"e", "s", "b", "t", "r"})
# A message's age below zero by more than this reads as from before this end's clock began
# (the clock counts in whole milliseconds on each side: a few of them are rounding).
BEFORE_CLOCK_S = 0.1
# Sequence numbers, epochs and clocks are whole numbers below this (msgpack's uint64).
WHOLE_MAX = 1 << 64


class Guard(Protocol):
    """What an end that obeys commands demands before acting on one (the aircraft's
    `Commands`)."""

    def changes_state(self, message: messages.Message) -> bool:
        """False for a message that only makes the aircraft safer: acted on at once."""

    def refuse(self, message: messages.Message, seq: int, reason: str) -> None:
        """A command not carried out (its replay state could not be saved, or it came late)."""

    def overtaken(self, message: messages.Message, seq: int) -> None:
        """A command handed on after a later safe message (an Abort) already acted."""


class Malformed(ValueError):
    """A session field of an authenticated message that is not what the session sends."""


def whole(data: dict, key: str, default: int | None = None) -> int:
    """The session field `key` as a whole number (Malformed when it is anything else)."""
    value = data.get(key, default)
    if type(value) is not int or not 0 <= value < WHOLE_MAX:
        raise Malformed(f"session field {key!r} is {str(value)[:20]!r}, not a whole number")
    return value


class Transport(Protocol):
    max_payload: int

    async def send(self, destination: bytes, payload: bytes): ...


@dataclass
class _Held:
    message: messages.Message
    seq: int
    overtaken: bool = False


@dataclass
class _InFlight:
    seq: int
    data: dict
    due: float
    backoff: float


class LinkSession:
    """One end's session with its peer (see the module docstring)."""

    def __init__(
        self,
        codec: LinkCodec,
        transport: Transport,
        peer: bytes,
        clock: Clock,
        on_message: Callable[[messages.Message, int | None], None],
        *,
        seen: SeenStore | None = None,
        heartbeat_s: float = 1.0,
        deadline_s: float = 3.0,
        guard: Guard | None = None,
        max_age_s: float | None = None,
    ):
        self._codec, self._transport, self._peer, self._clock = codec, transport, peer, clock
        self._seen = seen  # None: no replay state kept (nothing is written)
        self._on_message = on_message
        self._heartbeat_s, self._deadline_s = heartbeat_s, deadline_s
        self._guard, self._max_age_s = guard, max_age_s
        # The peer's clock as last heard: (its "t", our clock then).
        self._peer_time: tuple[int, float] | None = None
        self.persist_error: str | None = None
        """Why the replay state cannot be saved now (None: it can); the status says it."""
        self._epoch = random.SystemRandom().getrandbits(32)
        self._next_seq = 1
        self._outbox: deque[tuple[int, dict]] = deque()
        self._flight: dict[int, _InFlight] = {}
        self._peer_epoch: int | None = None
        self._epoch_counter = -1  # the frame counter at which the peer's epoch began
        self._expected = 1
        self._ahead: dict[int, dict] = {}
        self._acks_due = False
        self._status: dict | None = None
        self._live: dict | None = None  # best effort, after every reliable message
        self._air: deque[tuple[float, float]] = deque()  # (end, seconds) of recent sends
        self._first_send: float | None = None
        self._last_heard: float | None = None
        self._last_sent = -1e9
        self._wake = asyncio.Event()
        self._saved_at = -1e9
        # Reliable messages (the ground's commands) held until the replay state that covers
        # them is on disk: a command acted on is never accepted again after a reboot.
        self._acting: list[_Held] = []
        self.counters: Counter[str] = Counter()

    # -- application side -----------------------------------------------------------------

    def send_reliable(self, message: messages.Message) -> int:
        """Queue a message for exactly-once, in-order delivery; returns its sequence number.
        MessageTooLarge (counted) when it needs more frames than a message may have."""
        data = messages.to_dict(message) | {"e": self._epoch}
        if self._peer_time is not None:  # the receiver's clock now, as the sender reckons it
            heard, at = self._peer_time
            data["r"] = heard + self._now_ms() - int(at * 1000)
        try:
            # Measured with the session's largest fields, so no later frame of it can fail.
            self._codec.frames_needed(len(pack(data | {"s": WHOLE_MAX - 1, "b": WHOLE_MAX - 1})))
        except MessageTooLarge:
            self.counters["too_large"] += 1
            raise
        seq = self._next_seq
        self._next_seq += 1
        if len(self._outbox) >= OUTBOX:
            # The oldest message that is not an Abort goes: an abort queued during an outage
            # must still reach the aircraft (if all are aborts, the oldest, as they repeat).
            drop = next((k for k, (_, d) in enumerate(self._outbox) if d.get("kind") != "abort"), 0)
            del self._outbox[drop]
            self.counters["outbox_dropped"] += 1
        self._outbox.append((seq, data | {"s": seq}))
        self._wake.set()
        return seq

    def send_status(self, message: messages.Message) -> None:
        """Best effort, latest wins."""
        self._status = messages.to_dict(message)
        self._wake.set()

    def send_live(self, message: messages.Message) -> None:
        """Best effort, latest wins, and last: it goes out only when no reliable message is
        waiting or unacknowledged, so commands' answers and results are never behind it."""
        self._live = messages.to_dict(message)
        self._wake.set()

    @property
    def last_heard(self) -> float | None:
        """Clock time of the last authenticated frame from the peer."""
        return self._last_heard

    @property
    def codec(self) -> LinkCodec:
        """The framing underneath: its counters say what was dropped, and why."""
        return self._codec

    @property
    def unsaved(self) -> bool:
        """Frames accepted that the replay state on disk does not cover yet (False without
        one)."""
        return self._seen is not None and self._seen.changed(self._codec.floors()) is not None

    @property
    def link_up(self) -> bool:
        heard = self._last_heard
        return heard is not None and self._clock.now() - heard <= self._deadline_s

    @property
    def pending(self) -> int:
        """Reliable messages not yet acknowledged."""
        return len(self._outbox) + len(self._flight)

    # -- receiving --------------------------------------------------------------------------

    def receive(self, source: bytes, frame: bytes, now: float) -> None:
        """A frame from the radio (call on the loop). Never raises: an authenticated body the
        session does not understand (a sender with a bug, or a stolen key) is counted."""
        data = self._codec.decode(source, frame, now)
        if data is None:
            return
        self._last_heard = now
        try:
            if not isinstance(data, dict):
                raise Malformed(f"a message is a map, not {type(data).__name__}")
            sent = data.get("t")
            if type(sent) is int and 0 <= sent < WHOLE_MAX:
                self._peer_time = (sent, now)
            if data.get("kind") == "lack":
                self._acked(data)
            elif "s" in data:
                self._reliable(data, now)
            else:
                self._deliver(data, None, now)
        except Malformed as exc:
            self.counters["malformed_bodies"] += 1
            log.warning("link: an authenticated message dropped: %s", exc)

    def _acked(self, data: dict) -> None:
        upto = whole(data, "upto", 0)
        if data.get("e") != self._epoch:
            return
        for seq in [s for s in self._flight if s <= upto]:
            del self._flight[seq]
            self.counters["acked"] += 1
        self._wake.set()

    def _reliable(self, data: dict, now: float) -> None:
        epoch, seq, base = whole(data, "e"), whole(data, "s"), whole(data, "b", 1)
        if "r" in data:
            whole(data, "r")  # checked now: a bad one must not stop the in-order delivery
        counter = self._codec.last_counter
        if epoch != self._peer_epoch:
            if counter < self._epoch_counter:
                # A frame of an older session, reordered behind the new one's: switching back
                # would deliver that session's messages again. The sender's frame counter never
                # goes back, across its restarts too, so the newer session has the higher one.
                self.counters["old_epoch"] += 1
                return
            # The other end, or this one, (re)started: its numbering.
            self._peer_epoch, self._expected, self._ahead = epoch, base, {}
            self._epoch_counter = counter
            self.counters["peer_epochs"] += 1
        elif base > self._expected:
            # Acknowledged below `base` — by this end before a restart (an ack it sent then
            # arrived late): they will never come again, so stop waiting for them.
            self._ahead = {k: v for k, v in self._ahead.items() if k >= base}
            self._expected = base
            self.counters["skipped_to_base"] += 1
        self._acks_due = True
        self._wake.set()
        if seq < self._expected or seq in self._ahead:
            self.counters["duplicates"] += 1
        elif seq >= self._expected + AHEAD:
            self.counters["too_far_ahead"] += 1
        else:
            self._ahead[seq] = data
        while self._expected in self._ahead:
            self._deliver(self._ahead.pop(self._expected), self._expected, now)
            self._expected += 1

    def _deliver(self, data: dict, seq: int | None, now: float) -> None:
        fields = {k: v for k, v in data.items() if k not in SESSION_KEYS}
        try:
            message = messages.from_dict(fields)
        except messages.LinkMessageError as exc:
            self.counters["rejected_messages"] += 1
            log.warning("link: %s", exc)
            return
        self.counters["delivered"] += 1
        if isinstance(message, messages.Ping):
            return
        guard = self._guard
        if seq is None:  # status and the like: acted on at once
            self._on_message(message, seq)
        elif guard is not None and not guard.changes_state(message):
            # It only makes the aircraft safer: at once, whatever the disk does (replaying it
            # is harmless); the commands held before it learn that it overtook them.
            for held in self._acting:
                held.overtaken = True
            self.counters["acted_at_once"] += 1
            self._on_message(message, seq)
        elif guard is not None and (late := self._late(data, now)) is not None:
            self.counters["too_late"] += 1
            guard.refuse(message, seq, late)
        else:
            self._acting.append(_Held(message, seq))
            self._wake.set()

    def _late(self, data: dict, now: float) -> str | None:
        """Why a command is too old to obey, or None. One queued before the sender had heard
        this end carries no reading of its clock: it is taken (counted)."""
        if self._max_age_s is None:
            return None
        if "r" not in data:
            self.counters["commands_unaged"] += 1
            return None
        age = self._now_ms(now) / 1000.0 - whole(data, "r") / 1000.0
        if age < -BEFORE_CLOCK_S:
            return "not carried out: it was sent before this end restarted; send it again"
        if age <= self._max_age_s:
            return None
        return (
            f"not carried out: it was sent {age:.1f} s ago (at most {self._max_age_s:g} s, so "
            "that a command held back on the way is never obeyed late); send it again"
        )

    async def _act(self) -> None:
        """Save the replay state (fsynced, off the loop), then hand on the held messages; when
        the disk refuses, a guarded end refuses them with the reason."""
        saved = await self._save()
        held, self._acting = self._acting, []
        guard = self._guard
        for h in held:
            if guard is None:
                self._on_message(h.message, h.seq)
            elif not saved:
                self.counters["refused_unsaved"] += 1
                guard.refuse(h.message, h.seq, f"not carried out: {self.persist_error}")
            elif h.overtaken:
                guard.overtaken(h.message, h.seq)
            else:
                self._on_message(h.message, h.seq)

    async def _save(self) -> bool:
        """Write the replay state if anything is new; False when the disk refused (counted,
        and the reason kept in `persist_error` until a write succeeds)."""
        seen = self._seen
        snapshot = None if seen is None else seen.changed(self._codec.floors())
        if snapshot is None:
            return True
        try:
            # A rename can wait on the disk (ext4 flushes the data first): off the loop.
            await asyncio.to_thread(seen.write, snapshot)
        except OSError as exc:
            self.counters["seen_write_failures"] += 1
            if self.persist_error is None:
                log.error("link: the replay state cannot be saved: %s", exc)
            self.persist_error = (
                f"the replay state cannot be saved ({exc.strerror or exc}): only an Abort is "
                "obeyed until it can"
            )
            return False
        seen.mark_saved(snapshot)
        if self.persist_error is not None:
            log.warning("link: the replay state is saved again")
            self.persist_error = None
        return True

    def _now_ms(self, now: float | None = None) -> int:
        return max(0, int((self._clock.now() if now is None else now) * 1000))

    # -- sending ----------------------------------------------------------------------------

    async def run(self) -> None:
        """Send acks, reliable messages, status and heartbeats until cancelled."""
        try:
            await self._serve()
        finally:  # stopping: the replay state as it stands, whatever the last save was
            if self._seen is not None:
                with contextlib.suppress(OSError):
                    self._seen.save(self._codec.floors())

    async def _serve(self) -> None:
        while True:
            # asyncio.timeout, not wait_for: on Python 3.11 wait_for can swallow a
            # cancellation that lands as the wait completes, and this loop would never stop.
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(TICK_S):
                    await self._wake.wait()
            self._wake.clear()
            if self._acting:
                await self._act()
            await self._send_due()
            now = self._clock.now()
            if now - self._saved_at >= SAVE_SEEN_S:
                self._saved_at = now
                await self._save()

    async def _send_due(self) -> None:
        now = self._clock.now()
        if self._acks_due:
            self._acks_due = False
            await self._send({"kind": "lack", "e": self._peer_epoch, "upto": self._expected - 1})
        while self._outbox and len(self._flight) < IN_FLIGHT:
            seq, data = self._outbox.popleft()
            self._flight[seq] = _InFlight(seq, data, now, RETRY_FIRST_S)
        for item in sorted(self._flight.values(), key=lambda f: f.seq):
            if item.due <= now and item.seq in self._flight:
                if item.backoff > RETRY_FIRST_S:
                    self.counters["retransmissions"] += 1
                if not await self._send(item.data | {"b": min(self._flight)}):
                    del self._flight[item.seq]  # it can never go (the radio's payload shrank)
                    continue
                item.due = self._clock.now() + item.backoff
                item.backoff = min(item.backoff * 2, RETRY_MAX_S)
        if self._status is not None:
            status, self._status = self._status, None
            await self._send(status)
        if self._live is not None and not self._outbox and not self._flight:
            live, self._live = self._live, None
            await self._send(live)
        if self._clock.now() - self._last_sent >= self._heartbeat_s:
            await self._send(messages.to_dict(messages.Ping()))

    def air_share(self) -> float:
        """The share of the last AIR_WINDOW_S this end spent sending frames (each send lasts
        until the radio reports the transmission done: the air time, retries included)."""
        now = self._clock.now()
        while self._air and self._air[0][0] < now - AIR_WINDOW_S:
            self._air.popleft()
        if self._first_send is None:
            return 0.0
        span = min(AIR_WINDOW_S, now - self._first_send)  # shorter at first: not diluted
        return min(1.0, sum(seconds for _, seconds in self._air) / span) if span > 0 else 0.0

    async def _send(self, data: dict) -> bool:
        """Put one message on air; False when it can never go (too large: counted)."""
        self._last_sent = self._clock.now()
        try:
            frames = self._codec.encode(data | {"t": self._now_ms()})
        except MessageTooLarge as exc:
            self.counters["too_large"] += 1
            log.warning("link: %s %s not sent: %s", data.get("kind"), data.get("s", ""), exc)
            return False
        except OSError as exc:  # the frame counters cannot be reserved: nothing can go
            self.counters["counter_failures"] += 1
            log.debug("link: frame counters not reserved: %s", exc)
            return True
        for frame in frames:
            began = self._clock.now()
            if self._first_send is None:
                self._first_send = began
            try:
                result = await self._transport.send(self._peer, frame)
                ended = self._clock.now()
                self._air.append((ended, ended - began))
            except Exception as exc:  # a radio error: counted; reliable messages retry
                self.counters["transport_errors"] += 1
                log.debug("link: send failed: %s", exc)
                return True
            if not result.ok:
                self.counters["frames_failed"] += 1
                return True
            self.counters["frames_sent"] += 1
        return True
