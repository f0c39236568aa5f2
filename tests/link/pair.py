"""Two ends of the link over emulated XBee modules, with the real digi-xbee on each side."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from agent.clock import LoopClock
from agent.link.codec import AIRCRAFT, GROUND, LinkCodec, key_fingerprint
from agent.link.session import Guard, LinkSession
from agent.link.store import CounterStore, SeenStore
from agent.sim.radio import EmulatedXBee, RfChannel
from drivers.xbee.driver import XBeeRadio
from tests import waiting

# A fixed key drawn at random (a patterned one, as bytes(range(32)) was, is refused).
KEY = bytes.fromhex("5f1e9c27d4a0b38e61c7f2094ad35be8c06f1a729e4d83b5f02c6e917ad4b358")
AIR_ADDR = bytes.fromhex("0013A20040000001")
GROUND_ADDR = bytes.fromhex("0013A20040000002")


@dataclass
class End:
    radio: XBeeRadio
    codec: LinkCodec
    session: LinkSession
    inbox: list = field(default_factory=list)
    on_frame: Callable[[bytes, bytes, float], None] | None = None
    """Where the radio's frames go (the session's `receive`): a test replaces it to hold
    frames back, record them, or hand them to another session."""


@dataclass
class Pair:
    channel: RfChannel
    air: End
    ground: End
    modules: tuple[EmulatedXBee, EmulatedXBee]
    tasks: list[asyncio.Task]


@contextlib.asynccontextmanager
async def link_pair(
    tmp_path: Path,
    *,
    escaped: bool = False,
    channel: RfChannel | None = None,
    deadline_s: float = 3.0,
    air_state: Path | None = None,
    air_guard: Guard | None = None,
    air_max_age_s: float | None = None,
):
    """Two ends joined by emulated XBees. `air_state`: the folder of the aircraft's counter
    and seen files (default `tmp_path`); `air_guard`, `air_max_age_s`: the aircraft's session
    as an end that obeys commands (agent.link.session.Guard)."""
    clock = LoopClock()
    channel = channel or RfChannel()
    air_module = EmulatedXBee("air", AIR_ADDR, tmp_path, channel, clock, escaped=escaped)
    ground_module = EmulatedXBee("ground", GROUND_ADDR, tmp_path, channel, clock, escaped=escaped)
    air_module.join(ground_module)
    ground_module.join(air_module)
    tasks = [
        asyncio.create_task(m.run(), name=f"xbee-{m.name}") for m in (air_module, ground_module)
    ]
    await asyncio.sleep(0.05)
    ends = {}
    for name, role, module, peer in (
        ("air", AIRCRAFT, air_module, GROUND_ADDR),
        ("ground", GROUND, ground_module, AIR_ADDR),
    ):
        inbox: list = []
        state = (air_state or tmp_path) if name == "air" else tmp_path
        seen = SeenStore(state / f"{name}.seen", key_fingerprint(KEY))
        codec = LinkCodec(
            KEY,
            role,
            {peer},
            counter=CounterStore(state / f"{name}.counter"),
            floors=seen.load(),
        )
        holder: list[End] = []
        radio = XBeeRadio(
            str(module.path), 115200, clock, lambda s, p, t, h=holder: h[0].on_frame(s, p, t)
        )
        await radio.open()
        codec.max_payload = radio.max_payload
        codec.address = radio.address
        session = LinkSession(
            codec,
            radio,
            peer,
            clock,
            lambda m, _seq, box=inbox: box.append(m),
            seen=seen,
            deadline_s=deadline_s,
            guard=air_guard if name == "air" else None,
            max_age_s=air_max_age_s if name == "air" else None,
        )
        ends[name] = End(radio, codec, session, inbox, on_frame=session.receive)
        holder.append(ends[name])
        tasks.append(asyncio.create_task(session.run(), name=f"session-{name}"))
        tasks.append(asyncio.create_task(radio.watch(), name=f"radio-{name}"))
    pair = Pair(channel, ends["air"], ends["ground"], (air_module, ground_module), tasks)
    try:
        yield pair
    finally:
        for task in tasks[2:]:
            task.cancel()
        await asyncio.gather(*tasks[2:], return_exceptions=True)
        for end in ends.values():
            await end.radio.close()
        for task in tasks[:2]:
            task.cancel()
        await asyncio.gather(*tasks[:2], return_exceptions=True)


async def wait_for(predicate) -> bool:
    """Whether predicate() came to hold within the test's budget (tests.waiting): a wait for
    an event, never a wall-clock margin."""
    try:
        await waiting.until(predicate, "the link")
    except AssertionError:
        return bool(predicate())
    return True
