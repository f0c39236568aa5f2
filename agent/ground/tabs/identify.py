"""Identify (3): the identification settings to send (type, p, order, batch, update period)
and the settings in effect.

What the aircraft's status reports is in effect (an older aircraft's status does not say:
then the last settings it acknowledged). The form starts from them and follows them until
the operator edits it; a form that differs from them says so, field by field, until the
aircraft reports them in effect — no field shows a value as if it were in effect when it is
not. The type "each plan's own" (the aircraft's default) identifies each run on its plan's
axes; the others identify every run on the axes chosen, whatever its plan."""

from __future__ import annotations

from collections.abc import Callable

from pydantic import ValidationError
from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.reactive import var
from textual.widgets import Button, Checkbox, Input, Label, Select, Static

from agent.ground.events import Command
from agent.ground.station import GroundStation
from agent.link import messages

PLAN = "plan"  # the type that leaves each run on its plan's axes (IdentSettings.axes None)
TYPES = [("each plan's own", PLAN), *((a, a) for a in ("lateral", "longitudinal", "full"))]
# Each field's name on the screen.
FIELDS = {
    "axes": "type",
    "markov": "p",
    "order": "n",
    "batch": "batch",
    "update_period_s": "update period",
}


class IdentifyTab(VerticalScroll):
    reported: var[messages.IdentSettings | None] = var(None)
    """The settings in effect, as the aircraft's status reports them (None: not reported)."""
    acknowledged: var[messages.IdentSettings | None] = var(None)
    """The last settings the aircraft acknowledged."""

    def __init__(self, station: GroundStation, send: Callable, **kwargs):
        super().__init__(**kwargs)
        self.station, self.send = station, send
        self._loaded = messages.IdentSettings()  # what the form was last set to
        self._sent: messages.IdentSettings | None = None  # sent, not yet reported in effect

    def compose(self) -> ComposeResult:
        # Kept as attributes: the watchers (first called once mounted) draw into them.
        self.axes_select = Select(TYPES, value=PLAN, allow_blank=False, id="axes", compact=True)
        self.markov_input = Input("auto", id="markov", compact=True)
        self.order_input = Input("auto", id="order", compact=True)
        self.batch_box = Checkbox("on", id="batch", compact=True)
        self.period_input = Input("", placeholder="none", id="period", compact=True)
        self.error = Static(id="settings-error")
        self.now = Static(id="settings-now")
        self.pending = Static(id="settings-pending")
        rows = [
            ("identification type", self.axes_select),
            ("Markov parameters p", self.markov_input),
            ("model order n", self.order_input),
            ("batch (stack runs)", self.batch_box),
            ("update period s", self.period_input),
        ]
        for label, widget in rows:
            with Horizontal():
                yield Label(label)
                yield widget
        self.send_button = Button(
            "Send settings", id="send-settings", variant="primary", compact=True
        )
        with Horizontal(id="settings-buttons"):
            yield self.send_button
        yield self.error
        yield self.now
        yield self.pending

    def in_effect(self) -> tuple[messages.IdentSettings | None, str]:
        """The settings in effect and how that is known ("" : not known)."""
        if self.reported is not None:
            return self.reported, "reported by the aircraft"
        if self.acknowledged is not None:
            return self.acknowledged, "acknowledged by the aircraft"
        return None, ""

    def answered(self, command: Command) -> None:
        """The aircraft's answer to settings sent from here."""
        if command.ack is not None and command.ack.ok:
            self.acknowledged = command.message
        elif command.message == self._sent:  # refused: they will not be in effect
            self._sent = None
            self._show_pending()

    def watch_reported(self) -> None:
        self._effect_changed()

    def watch_acknowledged(self) -> None:
        self._effect_changed()

    def _effect_changed(self) -> None:
        """Show what is in effect, and bring the form to it unless the operator is editing."""
        now, how = self.in_effect()
        form = self.form()
        if now is not None and form in (self._loaded, now):
            if form != now:
                self._load(now)
            self._loaded = now
        if now is not None and now == self._sent:
            self._sent = None
        self.now.update(_effect_text(now, how))
        self._show_pending()

    def _load(self, s: messages.IdentSettings) -> None:
        self.axes_select.value = s.axes or PLAN
        self.markov_input.value = str(s.markov)
        self.order_input.value = str(s.order)
        self.batch_box.value = s.batch
        self.period_input.value = "" if s.update_period_s is None else f"{s.update_period_s:g}"

    def form(self) -> messages.IdentSettings | None:
        """The settings the form holds (None: not valid)."""
        try:
            return self._read()
        except (ValidationError, ValueError):
            return None

    def _read(self) -> messages.IdentSettings:
        period = self.period_input.value.strip()
        axes = self.axes_select.value
        return messages.IdentSettings(
            axes=None if axes == PLAN else axes,
            markov=_auto_int(self.markov_input.value),
            order=_auto_int(self.order_input.value),
            batch=self.batch_box.value,
            update_period_s=float(period) if period else None,
        )

    @on(Input.Changed)
    @on(Select.Changed)
    @on(Checkbox.Changed)
    def _edited(self) -> None:
        # A press of Send lasts a moment (Textual's "active" effect), and a click meanwhile is
        # ignored as a double click: an edit ends it, so a click on Send after any change to
        # the form is a new press and sends what the form now shows.
        self.send_button.remove_class("-active")
        self._show_pending()

    def _show_pending(self) -> None:
        """Say which of the form's fields are not in effect (nothing when all are)."""
        form = self.form()
        now, _ = self.in_effect()
        if form is None:
            text = Text("the form is not valid: it cannot be sent", "yellow")
        elif now is None:
            text = Text("not sent; the settings in effect are not known here", "yellow")
        elif form == now:
            text = Text("")
        else:
            fields = ", ".join(
                label for key, label in FIELDS.items() if getattr(form, key) != getattr(now, key)
            )
            waiting = form == self._sent
            text = Text(
                f"sent, not yet in effect: {fields}"
                if waiting
                else f"not sent: {fields} differ from the settings in effect",
                "yellow",
            )
        self.pending.update(text)

    @on(Button.Pressed, "#send-settings")
    def _send_settings(self) -> None:
        try:
            settings = self._read()
        except (ValidationError, ValueError) as exc:
            self.error.update(Text(f"not sent: {_first_error(exc)}", "red"))
            return
        self.error.update("")
        self._sent = settings
        self._show_pending()
        self.send(lambda: self.station.settings(settings))


def _effect_text(s: messages.IdentSettings | None, how: str) -> str:
    if s is None:
        return "in effect: not known here yet (not reported by the aircraft, none acknowledged)"
    if s.update_period_s is None:
        period = "no update period"
    else:
        period = f"every {s.update_period_s:g} s"
        if s.axes is None:
            period += " (periodic windows on the aircraft's configured axes)"
    axes = s.axes or "each plan's own axes"
    return (
        f"in effect ({how}): {axes}, p {s.markov}, n {s.order}, "
        f"batch {'on' if s.batch else 'off'}, {period}"
    )


def _auto_int(text: str) -> int | str:
    text = text.strip().lower()
    return "auto" if text in ("", "auto") else int(text)


def _first_error(exc: Exception) -> str:
    if isinstance(exc, ValidationError):
        e = exc.errors()[0]
        return f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}"
    return str(exc)
