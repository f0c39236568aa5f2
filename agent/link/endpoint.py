"""One end of the link from its [link] section: the XBee radio and the session over it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from agent.clock import Clock
from agent.config import Link, load_key
from agent.link.codec import CounterStore, LinkCodec
from agent.link.session import LinkSession
from drivers.xbee.driver import XBeeRadio


async def open_endpoint(cfg: Link, role: str, base: Path, clock: Clock,
                        on_message: Callable) -> tuple[XBeeRadio, LinkSession]:  # fmt: skip
    """Open the radio and build the session: the shared key, this end's counter and replay
    state under `base`, the peer as the only source accepted. Raises ValueError (no peer, a
    bad key file) or the radio's error with the reason."""
    if cfg.peer is None:
        raise ValueError("[link] peer (the other end's 64-bit address) is not set")
    peer = bytes.fromhex(cfg.peer)
    codec = LinkCodec(
        load_key(base / cfg.key_file),
        role,
        {peer},
        counter=CounterStore(base / cfg.counter_file),
        seen=base / cfg.seen_file,
    )
    sessions: list[LinkSession] = []

    def receive(source: bytes, payload: bytes, t: float) -> None:
        if sessions:  # a frame before the session exists is dropped, as noise would be
            sessions[0].receive(source, payload, t)

    radio = XBeeRadio(cfg.port, cfg.baud, clock, receive)
    await radio.open()
    codec.max_payload = radio.max_payload
    session = LinkSession(codec, radio, peer, clock, on_message,
                          heartbeat_s=cfg.heartbeat_s, deadline_s=cfg.deadline_s)  # fmt: skip
    sessions.append(session)
    return radio, session
