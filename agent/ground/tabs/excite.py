"""Excite (2): pick a preset or edit a plan, see what it would play (and whether the aircraft
would refuse it) before arming; have the aircraft size it (F3: the amplitudes it would fly,
why, and the response it predicts, agent/sizing.py), then arm the sized plan (F2), or the plan
as written when it was not sized; abort."""

from __future__ import annotations

import json
from collections.abc import Callable

from pydantic import ValidationError
from rich.text import Text
from textual import on
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.widgets import Button, Select, Static, TextArea

from agent import sizing as sz
from agent.excitation.plan import PRESETS, Plan, preset, refusals, render, summary
from agent.ground.station import GroundStation
from agent.link import messages


class ExciteTab(Vertical):
    def __init__(self, station: GroundStation, send: Callable, **kwargs):
        super().__init__(**kwargs)
        self.station, self.send = station, send
        self.plan: Plan | None = None  # the editor's plan, when valid
        self.sizing: messages.Sizing | None = None  # the aircraft's sizing of that plan
        self._asked: Plan | None = None  # the plan a size request was sent for

    def compose(self) -> ComposeResult:
        with Horizontal(id="preset-row"):
            yield Select(
                [(p, p) for p in PRESETS],
                value="lateral",
                allow_blank=False,
                id="preset",
                compact=True,
            )
            yield Button("Size F3", id="size", compact=True)
            yield Button("Arm F2", id="arm", variant="primary", compact=True)
            yield Button("ABORT F5", id="abort", variant="error", compact=True)
        with Horizontal(id="editor"):
            yield TextArea(id="plan", soft_wrap=False)
            with Vertical(id="preview-column"):
                yield Static(id="preview")
                yield Static(id="sizing")

    def on_mount(self) -> None:
        self.load_preset("lateral")

    def load_preset(self, name: str) -> None:
        self.query_one("#plan", TextArea).text = json.dumps(preset(name).to_compact(), indent=1)

    @on(Select.Changed, "#preset")
    def _preset_changed(self, event: Select.Changed) -> None:
        self.load_preset(str(event.value))

    @on(TextArea.Changed, "#plan")
    def _plan_changed(self, event: TextArea.Changed) -> None:
        self.preview(event.text_area.text)

    def preview(self, text: str) -> None:
        """Validate the editor's plan and show what it would play, or what is wrong; a sizing
        of another plan is dropped."""
        panel = self.query_one("#preview", Static)
        self._show_sizing(None)
        try:
            plan = Plan.model_validate_json(text)
        except ValidationError as exc:
            self.plan = None
            problems = "\n".join(
                f"{'.'.join(str(p) for p in e['loc']) or 'plan'}: {e['msg']}"
                for e in exc.errors()[:6]
            )
            panel.update(Text(f"not a valid plan:\n{problems}", "red"))
            return
        self.plan = plan
        excitation = self.station.config.excitation
        timeline = render(plan, excitation.rate_hz)
        info = summary(timeline, excitation.surfaces)
        text = Text()
        text.append(f"{plan.id} · {plan.axes} · {info['duration_s']:.1f} s\n", "bold")
        for name, c in info["controls"].items():
            band = "–".join(f"{f:.2f}" for f in c["band_hz"])
            text.append(
                f"{name:<9} peak ±{c['peak']:.1f} {c['unit'] or ''}  "
                f"RPF {c['rpf']:.2f}  {band} Hz\n"
            )
        for warning in info["warnings"]:
            text.append(f"warning: {warning}\n", "yellow")
        for reason in refusals(plan, excitation.rate_hz, excitation.surfaces, excitation.envelope):
            text.append(f"would be refused: {reason}\n", "bold red")
        panel.update(text)

    def request_sizing(self) -> None:
        """Ask the aircraft how it would fly the editor's plan (not `size`: a widget's size
        is Textual's)."""
        if self.plan is None:
            self.station.note("error", "the plan in the editor is not valid: not sent")
            return
        plan = self._asked = self.plan
        self.send(lambda: self.station.size(plan))

    def sized(self, sizing: messages.Sizing) -> None:
        """The aircraft's sizing: shown, and armed by F2, while the editor holds the plan it
        was asked for."""
        if self._asked is not None and self._asked == self.plan:
            self._show_sizing(sizing)

    def _show_sizing(self, sizing: messages.Sizing | None) -> None:
        self.sizing = sizing
        panel = self.query_one("#sizing", Static)
        button = self.query_one("#arm", Button)
        if sizing is None:
            panel.update(Text("not sized: F3 has the aircraft size it; F2 arms it as written"))
            button.label = "Arm F2"
            return
        text = Text()
        for line in sz.message_lines(sizing):
            text.append(line + "\n", "bold red" if line.startswith("REFUSED") else "")
        panel.update(text)
        button.label = "Arm sized F2" if not sizing.refusals else "Arm F2"

    def arm(self) -> None:
        """Arm the sized plan when the aircraft sized the editor's plan, else the plan as
        written (the aircraft still refuses one its prediction takes out of the envelope)."""
        if self.plan is None:
            self.station.note("error", "the plan in the editor is not valid: not sent")
            return
        plan = self.sizing.plan if self.sizing is not None else self.plan
        self.send(lambda: self.station.arm(plan))

    @on(Button.Pressed, "#size")
    def _size_pressed(self) -> None:
        self.request_sizing()

    @on(Button.Pressed, "#arm")
    def _arm_pressed(self) -> None:
        self.arm()

    @on(Button.Pressed, "#abort")
    def _abort_pressed(self) -> None:
        self.send(self.station.abort)
