"""What the ground station tells whoever draws it, one typed event per thing heard or done:
the station hands each to its subscribers (`GroundStation.subscribe`) as it happens, and the
console turns them into Textual messages (`agent.ground.posted`). Plain dataclasses, so the
station needs no screen."""

from __future__ import annotations

from dataclasses import dataclass

from agent.link import messages


@dataclass(kw_only=True)
class Command:
    """A command sent to the aircraft and, once it arrives, its answer."""

    seq: int
    label: str
    sent_at: float
    message: messages.Message
    ack: messages.Ack | None = None


@dataclass(frozen=True)
class Line:
    """One line of the event log."""

    time: float
    level: str  # "info", "warning", "error"
    text: str


@dataclass(frozen=True)
class StatusHeard:
    """The aircraft's status (about once a second; the latest is all that matters)."""

    status: messages.Status
    at: float
    """When it was heard (the station's clock)."""


@dataclass(frozen=True)
class LiveFrame:
    """The live view moved on: `live` is the latest frame (its samples are already in the
    station's strips), or None when a result or failure ended the run."""

    live: messages.Live | None


@dataclass(frozen=True)
class ResultHeard:
    """An identification result, kept in the station's results."""

    result: messages.Result


@dataclass(frozen=True)
class FrfHeard:
    """A pair's measured frequency response, kept in the station's responses."""

    report: messages.FrfReport


@dataclass(frozen=True)
class SizingHeard:
    """How the aircraft would fly a plan (the answer to a size request)."""

    sizing: messages.Sizing


@dataclass(frozen=True)
class GainsHeard:
    """A gain proposal (`gains`) or what became of the autopilot's gains (`report`)."""

    gains: messages.Gains | None = None
    report: messages.GainsReport | None = None


@dataclass(frozen=True)
class AckHeard:
    """The aircraft answered a command (`command.ack`: done, or refused with the reason)."""

    command: Command


@dataclass(frozen=True)
class Noted:
    """A line for the event log."""

    line: Line


Event = (
    StatusHeard | LiveFrame | ResultHeard | FrfHeard | SizingHeard | GainsHeard | AckHeard | Noted
)
