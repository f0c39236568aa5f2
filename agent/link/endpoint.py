"""One end of the link from its [link] section: the XBee radio and the session over it."""

from __future__ import annotations

import logging
from collections.abc import Callable
from pathlib import Path

from agent.clock import Clock
from agent.config import Link, load_key
from agent.link.codec import LinkCodec, key_fingerprint
from agent.link.session import Guard, LinkSession
from agent.link.store import CounterStore, SeenStore
from drivers.xbee.driver import XBeeRadio

log = logging.getLogger(__name__)


def build_endpoint(
    cfg: Link,
    role: str,
    base: Path,
    clock: Clock,
    on_message: Callable,
    guard: Guard | None = None,
) -> tuple[XBeeRadio, LinkSession]:
    """The radio and the session: the shared key, this end's counter and replay state under
    `base`, the peer as the only source accepted; with a `guard` (the end that obeys
    commands), commands older than `command_max_age_s` are refused. The radio is not opened
    here: its `watch()` opens it and reopens it whenever it is lost, and the session's frames
    until then are counted as transport errors (reliable messages wait and retry). Raises
    ValueError (no peer, a bad key file, a bad replay state) or OSError with the reason."""
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
    key = load_key(base / cfg.key_file)
    first = not seen.exists()
    for state in (counter, seen):
        state.parent.mkdir(parents=True, exist_ok=True)
    store = SeenStore(seen, key_fingerprint(key))
    floors = store.load()  # refused before anything is written (the counter reserves a block)
    codec = LinkCodec(key, role, {peer}, counter=CounterStore(counter), floors=floors)
    if first:  # a first start under this key: the state starts here, saved and bound to it
        store.write({})
        log.info(
            "%s: a first start under key %s: its replay state starts empty. A key used "
            "before, from another directory, would accept every frame recorded under it "
            "again: make a new key for new state (sysid keygen)",
            seen,
            store.fingerprint,
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
        seen=store,
        heartbeat_s=cfg.heartbeat_s,
        deadline_s=cfg.deadline_s,
        guard=guard,
        max_age_s=cfg.command_max_age_s if guard is not None else None,
    )
    sessions.append(session)
    return radio, session
