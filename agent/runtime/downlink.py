"""Messages from the agent to the ground, in one place."""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable

from agent.link import messages
from agent.link.codec import MessageTooLarge

log = logging.getLogger(__name__)


class Downlink:
    """Sends through the link session when there is one (none: the agent flies without a
    link) and hands every message to each subscriber (a test, a local display)."""

    def __init__(self) -> None:
        self.session = None  # the link session, once the radio is built
        self._subscribers: list[Callable[[messages.Message], None]] = []
        self.counters: Counter[str] = Counter()

    def subscribe(self, subscriber: Callable[[messages.Message], None]) -> None:
        self._subscribers.append(subscriber)

    def send(self, message: messages.Message, reliable: bool = True) -> None:
        """Reliable: delivered exactly once and in order (events, results, acks). Not
        reliable: best effort, the newest replacing any not yet on air (status)."""
        for subscriber in self._subscribers:
            subscriber(message)
        if self.session is None:
            return
        try:
            (self.session.send_reliable if reliable else self.session.send_status)(message)
        except MessageTooLarge as exc:  # one message never stops the link: the ground is told
            self.counters["too_large"] += 1
            what = f"{message.kind} {getattr(message, 'model_id', '')}".strip()
            text = f"{what} not sent: {exc}; it is kept on the aircraft"
            log.warning(text)
            self.session.send_reliable(messages.Notice(text=text[:200]))

    def air_share(self) -> float:
        """The share of the last seconds this end's radio spent transmitting (0: no link)."""
        return 0.0 if self.session is None else self.session.air_share()

    def send_live(self, message: messages.Live) -> None:
        """The live view: best effort, and only when nothing reliable is waiting to go."""
        for subscriber in self._subscribers:
            subscriber(message)
        if self.session is not None:
            self.session.send_live(message)
