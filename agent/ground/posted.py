"""The station's events (`agent.ground.events`) as Textual messages, as toolong's messages.py
has them: the console posts each event to itself (`posted`), and its handlers set the tabs'
reactive state, so a tab redraws when, and what, its state changed.

A status, or a live frame, still waiting when a newer one arrives is dropped for it
(`can_replace`): each carries all it shows (a frame's samples are already in the station's
strips), so only the latest matters. Results, answers and event-log lines each count."""

from __future__ import annotations

from dataclasses import dataclass

from textual.message import Message

from agent.ground import events


@dataclass
class StatusHeard(Message, bubble=False):
    heard: events.StatusHeard

    def can_replace(self, message: Message) -> bool:
        return isinstance(message, StatusHeard)


@dataclass
class LiveFrame(Message, bubble=False):
    heard: events.LiveFrame

    def can_replace(self, message: Message) -> bool:
        return isinstance(message, LiveFrame)


@dataclass
class ResultHeard(Message, bubble=False):
    heard: events.ResultHeard


@dataclass
class FrfHeard(Message, bubble=False):
    heard: events.FrfHeard


@dataclass
class SizingHeard(Message, bubble=False):
    heard: events.SizingHeard


@dataclass
class GainsHeard(Message, bubble=False):
    heard: events.GainsHeard


@dataclass
class AckHeard(Message, bubble=False):
    heard: events.AckHeard


@dataclass
class Noted(Message, bubble=False):
    heard: events.Noted


_MESSAGES: dict[type, type[Message]] = {
    events.StatusHeard: StatusHeard,
    events.LiveFrame: LiveFrame,
    events.ResultHeard: ResultHeard,
    events.FrfHeard: FrfHeard,
    events.SizingHeard: SizingHeard,
    events.GainsHeard: GainsHeard,
    events.AckHeard: AckHeard,
    events.Noted: Noted,
}


def posted(event: events.Event) -> Message:
    """The Textual message that carries `event`."""
    return _MESSAGES[type(event)](event)
