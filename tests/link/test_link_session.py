"""The session under faults: a disk that refuses the replay state, authenticated bodies the
session never sends, a message longer than 255 frames, and a command held back on the way.

Bad input tried, each named in its test: the aircraft's link state on a full file system (a
real tmpfs, ENOSPC from the kernel); signed bodies `[1, 2]`, `{"s": "x"}`, `{"s": null}`, a
string, a number, a sequence number past 2**64, a non-integer clock reading and ack bound; a
result with 80 states (about 120 kB: over 255 frames); a command recorded while the radio was
jammed and injected 1.5 s later.
"""

from __future__ import annotations

import asyncio
import errno
import hashlib
import hmac
import json
import re

import msgpack
import pytest

from agent.clock import LoopClock
from agent.link import messages
from agent.link.codec import (
    AIRCRAFT,
    GROUND,
    HEADER,
    TAG,
    VERSION,
    LinkCodec,
    MessageTooLarge,
)
from agent.link.session import LinkSession
from agent.link.store import CounterStore
from agent.runtime.downlink import Downlink
from tests.link.pair import AIR_ADDR, GROUND_ADDR, KEY, link_pair, wait_for
from tests.sim.test_sim_hardening import fill

pytestmark = pytest.mark.usefixtures("no_leaked_tasks")


class Obeying:
    """The application's side of an end that obeys commands, as the agent's `Commands` is:
    an abort only makes things safer; everything it is told is kept for the test."""

    def __init__(self) -> None:
        self.refused: list[tuple[messages.Message, str]] = []
        self.overtaken_list: list[messages.Message] = []

    def changes_state(self, message: messages.Message) -> bool:
        return not isinstance(message, messages.Abort)

    def refuse(self, message: messages.Message, seq: int, reason: str) -> None:
        self.refused.append((message, reason))

    def overtaken(self, message: messages.Message, seq: int) -> None:
        self.overtaken_list.append(message)


async def test_an_abort_acts_at_once_while_the_replay_state_cannot_be_written(tmp_path, small_disk):
    """Bad input tried: the file system holding the aircraft's link state fills up (a real
    256 KiB tmpfs), so every write of the seen file fails with ENOSPC. The session used to
    hold every command until that write succeeded and restart on its error: the ground's
    Abort never acted (6 restarts in 20 s). Now the Abort acts the moment it arrives; a
    Revert is refused with the disk's reason and never acted; the session keeps serving
    (heartbeats, acks) without a restart; when space returns, commands act again and the
    file covers every frame accepted."""
    guard = Obeying()
    async with link_pair(tmp_path, air_state=small_disk, air_guard=guard) as pair:
        air, ground = pair.air, pair.ground
        assert await wait_for(lambda: air.session.link_up and ground.session.link_up)
        assert fill(small_disk / "filler") == errno.ENOSPC  # from the kernel
        ground.session.send_reliable(messages.Revert())
        ground.session.send_reliable(messages.Abort(reason="stop now"))
        assert await wait_for(lambda: any(isinstance(m, messages.Abort) for m in air.inbox))
        assert await wait_for(lambda: guard.refused)
        (refused, reason), *_ = guard.refused
        assert isinstance(refused, messages.Revert)
        assert "replay state cannot be saved" in reason
        assert "No space left" in reason
        assert not any(isinstance(m, messages.Revert) for m in air.inbox)  # never acted
        assert air.session.persist_error is not None
        assert air.session.counters["seen_write_failures"] >= 1
        assert air.session.unsaved  # the failed write did not count as saved
        # The session serves on: the ground still hears it, and its acks clear the outbox.
        assert await wait_for(lambda: ground.session.pending == 0)
        heard = ground.session.last_heard
        assert await wait_for(lambda: ground.session.last_heard > heard)
        (small_disk / "filler").unlink()  # space again
        ground.session.send_reliable(messages.Revert())
        assert await wait_for(lambda: any(isinstance(m, messages.Revert) for m in air.inbox))
        assert air.session.persist_error is None
        floors = json.loads((small_disk / "air.seen").read_text())["floors"]
        assert floors[GROUND_ADDR.hex()] >= air.codec.last_counter
    assert guard.overtaken_list == []


async def test_a_command_held_for_the_disk_and_overtaken_by_an_abort_is_handed_on_as_such(
    tmp_path, small_disk
):
    """Bad input tried: an Arm and an Abort arriving together while the seen file's write is
    slow to fail (a full disk): the Abort acts at once, and the Arm, sent before it, reaches
    the application marked as overtaken (the agent cancels it), never as a fresh command."""
    guard = Obeying()
    async with link_pair(tmp_path, air_state=small_disk, air_guard=guard) as pair:
        air, ground = pair.air, pair.ground
        assert await wait_for(lambda: air.session.link_up)
        # One window of the loop: both messages are decoded before the session's task runs.
        frames: list[tuple[bytes, bytes]] = []
        deliver = air.on_frame
        air.on_frame = lambda s, p, t: frames.append((s, p))
        ground.session.send_reliable(messages.Start())
        ground.session.send_reliable(messages.Abort(reason="stop"))
        assert await wait_for(lambda: len(frames) >= 2)
        air.on_frame = deliver
        now = LoopClock().now()
        for source, payload in frames:
            deliver(source, payload, now)
        assert any(isinstance(m, messages.Abort) for m in air.inbox)  # at once, in the callback
        assert await wait_for(lambda: guard.overtaken_list)
    assert [type(m) for m in guard.overtaken_list] == [messages.Start]
    assert not any(isinstance(m, messages.Start) for m in air.inbox)


def _frame(body: object, counter: int) -> bytes:
    """A frame of the ground's around any body, signed with the key as the codec signs (a
    sender with a bug, or a stolen key): HMAC-SHA-256 over both addresses and the frame."""
    data = HEADER.pack(VERSION, GROUND, counter, counter & 0xFFFF, 0, 1)
    data += msgpack.packb(body, use_bin_type=True)
    tag = hmac.new(KEY, GROUND_ADDR + AIR_ADDR + data, hashlib.sha256).digest()[:TAG]
    return data + tag


async def test_authenticated_bodies_the_session_never_sends_are_counted_not_raised(tmp_path):
    """Bad input tried, each signed with the key: `[1, 2]`, `{"s": "x"}`, `{"s": null}`,
    `"text"`, `5`, `{"s": 2**70}` (as msgpack can carry it: a float), `{"s": 1, "e": [1]}`,
    `{"s": 1, "e": 7, "r": "x"}`, `{"kind": "lack", "e": 7, "upto": "x"}`. They used to
    raise out of `LinkSession.receive` (docs/hardening.md said signed frames never raise).
    Each is counted; a good message after them is still delivered."""
    inbox: list = []
    air = LinkCodec(
        KEY, AIRCRAFT, {GROUND_ADDR}, counter=CounterStore(tmp_path / "c"), address=AIR_ADDR
    )
    session = LinkSession(air, None, GROUND_ADDR, LoopClock(), lambda m, s: inbox.append(m))
    bodies = [
        [1, 2],
        {"s": "x"},
        {"s": None},
        "text",
        5,
        {"s": float(2**70)},
        {"s": 1, "e": [1]},
        {"s": 1, "e": 7, "r": "x"},
        {"kind": "lack", "e": 7, "upto": "x"},
    ]
    for k, body in enumerate(bodies):
        session.receive(GROUND_ADDR, _frame(body, 100 + k), 0.0)
    assert session.counters["malformed_bodies"] == len(bodies)
    good = messages.to_dict(messages.Notice(text="still here"))
    session.receive(GROUND_ADDR, _frame(good, 200), 0.0)
    assert [m.text for m in inbox] == ["still here"]


def _big_result(states: int) -> messages.Result:
    square = [[0.5 + 1e-9 * (i * states + j) for j in range(states)] for i in range(states)]
    return messages.Result(
        model_id="lat-1-0badcafe",
        axes="lateral",
        dt=0.04,
        inputs=["aileron"],
        outputs=["p"] * states,
        modes=[],
        tic=[0.1] * states,
        tic_avg=0.1,
        stable=True,
        suggest_update=False,
        A=square,
        B=[[0.0]] * states,
        C=square,
        D=[[0.0]] * states,
    )


async def test_a_result_longer_than_255_frames_is_refused_and_the_link_goes_on(tmp_path):
    """Bad input tried: a result of 80 states (order_max allows it; about 120 kB, over 255
    frames), sent the way the agent sends results. encode used to raise inside the session's
    task, which died again at every restart, so no status or heartbeat went out again. It is
    refused (counted), the ground is told by a notice, and the next message arrives; a
    message that fitted when queued but not after the radio's payload shrank is dropped from
    the flight (counted) and the next goes."""
    async with link_pair(tmp_path) as pair:
        air, ground = pair.air, pair.ground
        downlink = Downlink()
        downlink.session = air.session
        with pytest.raises(MessageTooLarge, match="at most 255"):
            air.session.send_reliable(_big_result(80))
        downlink.send(_big_result(80))
        assert downlink.counters["too_large"] == 1
        assert air.session.counters["too_large"] == 2
        assert await wait_for(lambda: any(isinstance(m, messages.Notice) for m in ground.inbox))
        notice = next(m for m in ground.inbox if isinstance(m, messages.Notice))
        assert "result lat-1-0badcafe not sent" in notice.text
        assert "at most 255" in notice.text
        # Queued while it fitted; the radio's payload then shrank (a module of smaller NP).
        air.session.send_reliable(_big_result(20))
        air.codec.max_payload = 40
        air.session.send_reliable(messages.Notice(text="after"))
        assert await wait_for(lambda: air.session.counters["too_large"] == 3)
        assert await wait_for(lambda: any(getattr(m, "text", "") == "after" for m in ground.inbox))
        assert not any(isinstance(m, messages.Result) for m in ground.inbox)
        heard = ground.session.last_heard
        assert await wait_for(lambda: ground.session.last_heard > heard)  # heartbeats go on


async def test_a_command_held_back_on_the_way_and_injected_later_is_refused(tmp_path):
    """Bad input tried: the ground's Revert recorded off the air while the aircraft's
    reception is jammed, and injected 1.5 s later, past the aircraft's 1 s age limit. It used
    to be delivered whenever it arrived (an Arm arrived late in the campaign). It is refused
    with its age; the ground's own retries, as old, are refused too; a Revert sent afresh
    acts."""
    guard = Obeying()
    async with link_pair(tmp_path, air_guard=guard, air_max_age_s=1.0) as pair:
        air, ground = pair.air, pair.ground
        assert await wait_for(lambda: air.session.link_up and ground.session.link_up)
        recorded: list[tuple[bytes, bytes]] = []
        deliver = air.on_frame
        air.on_frame = lambda s, p, t: recorded.append((s, p))  # jammed, and recorded
        ground.session.send_reliable(messages.Revert())
        # The attacker, holding the key for the test's sake, picks the Revert out.
        reader = LinkCodec(KEY, AIRCRAFT, {GROUND_ADDR}, counter=CounterStore(None))
        reader.address = AIR_ADDR

        found: list[tuple[bytes, bytes]] = []

        def revert_frame() -> bool:
            while len(recorded) > len(found) and not any(found):
                source, payload = recorded[len(found)]
                data = reader.decode(source, payload, 0.0)
                is_revert = isinstance(data, dict) and data.get("kind") == "revert"
                found.append((source, payload) if is_revert else ())
            return any(found)

        assert await wait_for(revert_frame)
        source, payload = next(f for f in found if f)
        clock = LoopClock()
        jammed_at = clock.now()
        await asyncio.sleep(1.5)  # the attacker's hold: the age limit is what is tested
        assert clock.now() - jammed_at >= 1.5
        deliver(source, payload, clock.now())  # injected
        assert guard.refused, "the late command was not refused"
        message, reason = guard.refused[0]
        assert isinstance(message, messages.Revert)
        assert re.search(r"sent \d+\.\d s ago \(at most 1 s", reason), reason
        air.on_frame = deliver  # the jamming ends: the ground's retries are as old
        assert await wait_for(lambda: ground.session.pending == 0)
        assert not any(isinstance(m, messages.Revert) for m in air.inbox)
        ground.session.send_reliable(messages.Revert())  # afresh
        assert await wait_for(lambda: any(isinstance(m, messages.Revert) for m in air.inbox))
