"""Identify (3): the identification settings to send (type, p, order, batch, update period)
and the settings in effect."""

from __future__ import annotations

from collections.abc import Callable

from pydantic import ValidationError
from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.widgets import Button, Checkbox, Input, Label, Select, Static

from agent.ground.station import GroundStation
from agent.link import messages


class IdentifyTab(VerticalScroll):
    def __init__(self, station: GroundStation, send: Callable, **kwargs):
        super().__init__(**kwargs)
        self.station, self.send = station, send

    def compose(self) -> ComposeResult:
        axes = [(a, a) for a in ("lateral", "longitudinal", "full")]
        rows = [
            (
                "identification type",
                Select(axes, value="lateral", allow_blank=False, id="axes", compact=True),
            ),
            ("Markov parameters p", Input("auto", id="markov", compact=True)),
            ("model order n", Input("auto", id="order", compact=True)),
            ("batch (stack runs)", Checkbox("on", id="batch", compact=True)),
            ("update period s", Input("", placeholder="none", id="period", compact=True)),
        ]
        for label, widget in rows:
            with Horizontal():
                yield Label(label)
                yield widget
        with Horizontal(id="settings-buttons"):
            yield Button("Send settings", id="send-settings", variant="primary", compact=True)
        yield Static(id="settings-error")
        yield Static(id="settings-now")

    def show(self) -> None:
        now = self.station.settings_in_effect
        if now is None:
            text = "in effect: the aircraft's configured defaults (none sent yet)"
        else:
            period = f"every {now.update_period_s:g} s" if now.update_period_s else "no period"
            text = (
                f"in effect: {now.axes}, p {now.markov}, n {now.order}, "
                f"batch {'on' if now.batch else 'off'}, {period}"
            )
        self.query_one("#settings-now", Static).update(text)

    @on(Button.Pressed, "#send-settings")
    def _send_settings(self) -> None:
        error = self.query_one("#settings-error", Static)
        period = self.query_one("#period", Input).value.strip()
        try:
            settings = messages.IdentSettings(
                axes=self.query_one("#axes", Select).value,
                markov=_auto_int(self.query_one("#markov", Input).value),
                order=_auto_int(self.query_one("#order", Input).value),
                batch=self.query_one("#batch", Checkbox).value,
                update_period_s=float(period) if period else None,
            )
        except (ValidationError, ValueError) as exc:
            error.update(Text(f"not sent: {_first_error(exc)}", "red"))
            return
        error.update("")
        self.send(lambda: self.station.settings(settings))


def _auto_int(text: str) -> int | str:
    text = text.strip().lower()
    return "auto" if text in ("", "auto") else int(text)


def _first_error(exc: Exception) -> str:
    if isinstance(exc, ValidationError):
        e = exc.errors()[0]
        return f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
    return str(exc)
