"""One end of the link from its [link] section: the XBee radio and the session over it."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from agent.clock import Clock
from agent.config import Link, load_key
from agent.link.codec import CounterStore, LinkCodec
from agent.link.session import LinkSession
from drivers.xbee.driver import XBeeRadio


def build_endpoint(
    cfg: Link, role: str, base: Path, clock: Clock, on_message: Callable
) -> tuple[XBeeRadio, LinkSession]:
    """The radio and the session: the shared key, this end's counter and replay state under
    `base`, the peer as the only source accepted. The radio is not opened here: its `watch()`
    opens it and reopens it whenever it is lost, and the session's frames until then are
    counted as transport errors (reliable messages wait and retry). Raises ValueError (no
    peer, a bad key file) with the reason."""
    if cfg.peer is None:
        raise ValueError("[link] peer (the other end's 64-bit address) is not set")
    peer = bytes.fromhex(cfg.peer)
    counter, seen = base / cfg.counter_file, base / cfg.seen_file
    if counter.exists() and not seen.exists():
        raise ValueError(
            f"{seen} is missing while {counter} exists: this end has used the key before, and "
            "without its replay state every frame recorded under the key would be accepted "
            "again (a recorded Revert or Arm replayed): restore the file or give both ends a "
            "new key"
        )
    if not seen.exists():  # a first start under this key: the state starts here, saved
        seen.write_text("{}")
    codec = LinkCodec(
        load_key(base / cfg.key_file),
        role,
        {peer},
        counter=CounterStore(counter),
        seen=seen,
    )
    sessions: list[LinkSession] = []

    def receive(source: bytes, payload: bytes, t: float) -> None:
        if sessions:  # a frame before the session exists is dropped, as noise would be
            sessions[0].receive(source, payload, t)

    def opened(radio: XBeeRadio) -> None:  # the module's NP and address, read at every open
        codec.max_payload = radio.max_payload
        codec.address = radio.address

    radio = XBeeRadio(
        cfg.port,
        cfg.baud,
        clock,
        receive,
        on_open=opened,
        require_encryption=cfg.require_encryption,
    )
    session = LinkSession(
        codec,
        radio,
        peer,
        clock,
        on_message,
        heartbeat_s=cfg.heartbeat_s,
        deadline_s=cfg.deadline_s,
    )
    sessions.append(session)
    return radio, session


async def open_endpoint(
    cfg: Link, role: str, base: Path, clock: Clock, on_message: Callable
) -> tuple[XBeeRadio, LinkSession]:
    """`build_endpoint` with the radio opened now (the ground console: an operator at the
    keyboard is told at once). Raises ValueError or the radio's error with the reason."""
    radio, session = build_endpoint(cfg, role, base, clock, on_message)
    await radio.open()
    return radio, session
